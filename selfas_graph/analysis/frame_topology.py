"""The topology of a saved frame, from the run file alone (:func:`frame_topology`): structures, current-carrying
filaments and dead ends, the currents, the effective resistance and the events up to the frame
(docs/model.md 'Connectivity graph and topology'). ``selfas-graph topology`` prints it."""

from __future__ import annotations

import math
from collections import Counter

import numpy as np

from ..model import events as ev
from ..model.graph import DEAD_END, FILAMENT, ROLE_NAMES, ConnectivityGraph

__all__ = ["frame_topology"]


def has_circuit(run) -> bool:
    """Whether the run solved a circuit (it then stores the total current at its frames)."""
    return "total_current" in run.observable_names()


def filament_words(circuit: bool) -> str:
    """What the rods of the FILAMENT role are called: current-carrying filaments in a run with a circuit;
    without one no current flows, and the role is topological (docs/model.md 'Connectivity graph and
    topology': a path between two conductors)."""
    return "current-carrying filaments" if circuit else "filaments joining conductors (no circuit)"


def frame_topology(run, frame=None, t=None) -> dict:
    """The topology of one saved frame as plain Python data (what ``selfas-graph topology --json`` prints):
    the structures by size with their filament and dead-end rods and the conductors they touch, the rods by
    role, whether the conductors are short-circuited, the filament rods' currents, the total current and
    effective resistance, and the events up to the frame (each short circuit with its circuit-log row).
    ``run``: an open :class:`~selfas_graph.io.h5md.RunFile`."""
    if not hasattr(run, "graph"):
        raise TypeError(f"frame_topology(run, ...): an open RunFile (with RunFile(path) as run: ...), got {run!r}")
    g = run.graph_of_frame(run.frame_index(frame=frame, t=t))
    n_rods = g["role"].shape[0]
    graph = ConnectivityGraph.from_arrays(n_rods, g["conductors"], g, contact_resistance=run.contact_resistance)
    topo = graph.topology()
    # roles by the current topology rule from the saved contacts (the stored roles are what
    # the run used; they differ only for files written before a change of the rule)
    role, current = topo.role, g["current"]
    structures = []
    for sid in np.argsort(-topo.structure_size, kind="stable"):
        rods = np.flatnonzero(topo.structure == sid)
        tips = set((2 * rods).tolist()) | set((2 * rods + 1).tolist())
        touching = sorted(
            {
                ev.CONDUCTOR_NAMES.get(int(c), str(c))
                for k, c in zip(g["conductor_tip"], g["conductor_id"])
                if int(k) in tips
            }
        )
        structures.append(
            {
                "id": int(sid),
                "rods": int(len(rods)),
                "filament": int((role[rods] == FILAMENT).sum()),
                "dead_end": int((role[rods] == DEAD_END).sum()),
                "conductors": touching,
            }
        )
    fil = np.flatnonzero(role == FILAMENT)
    events = run.events(until_step=g["step"])
    counts = Counter(ev.KIND_NAMES.get(int(k), str(k)) for k in events["kind"])
    sc = events[events["kind"] == ev.SHORT_CIRCUIT]
    # the current through the gap at each closing, where the file has a circuit log
    log = run.circuit_log(until_step=g["step"])
    closing = {} if log is None else {int(r["step"]): r for r in log[log["kind"] == ev.SHORT_CIRCUIT]}
    obs = {}
    for name in ("total_current", "effective_conductance", "effective_resistance"):
        if name in run.observable_names():
            times, values = run.observable(name)
            # the row of this frame's time: none where the frame's row was not written (not another frame's)
            k = np.flatnonzero(times == g["time"])
            if k.size:
                obs[name] = float(values[k[-1]])
    if "effective_conductance" in obs:  # since 0.4: 0 for an open circuit, which has no finite resistance
        g_eff = obs["effective_conductance"]
        obs["effective_resistance"] = 1.0 / g_eff if g_eff > 0 else None
    elif obs.get("effective_resistance") is not None and not math.isfinite(obs["effective_resistance"]):
        obs["effective_resistance"] = None  # files before 0.4: inf for an open circuit
    return {
        "file": str(run.path),
        "run_status": run.status,
        "frame": g["frame"],
        "frames": int(run.n_frames),
        "step": g["step"],
        "time": g["time"],
        "conductors": {ev.CONDUCTOR_NAMES.get(c, str(c)): p for c, p in g["conductors"].items()},
        "rods": {ROLE_NAMES[r]: int((role == r).sum()) for r in sorted(ROLE_NAMES)} | {"total": int(n_rods)},
        "structures": structures,
        "largest_structure": structures[0]["rods"] if structures else 0,
        "short_circuit": bool(topo.has_short_circuit),
        "first_short_circuit": ({"step": int(sc[0]["step"]), "time": float(sc[0]["time"])} if len(sc) else None),
        "circuit": has_circuit(run),
        "total_current": obs.get("total_current"),
        "effective_resistance": obs.get("effective_resistance"),
        "filament_rods": [{"rod": int(i), "current": float(current[i])} for i in fil],
        "dead_end_rods": [int(i) for i in np.flatnonzero(role == DEAD_END)],
        "event_counts": dict(counts),
        "events": [
            {
                "step": int(e["step"]),
                "time": float(e["time"]),
                "kind": ev.KIND_NAMES.get(int(e["kind"]), "?"),
                "a": int(e["a"]),
                "b": int(e["b"]),
                **(_closing(closing.get(int(e["step"]))) if int(e["kind"]) == ev.SHORT_CIRCUIT else {}),
            }
            for e in events
        ],
    }


def _closing(row) -> dict:
    """A SHORT_CIRCUIT's total current and rods in series from its circuit-log row (none without one)."""
    if row is None:
        return {}
    return {"total_current": float(row["total_current"]), "rods_in_series": int(row["rods_in_series"])}
