"""Topology of a saved frame: ``selfas-graph topology RUN.h5 [--frame K | --time T] [--json]``.

Reads the run file alone: the structures, which rods are current-carrying
filaments and which are dead ends, the current in each, the total current, the
effective resistance between the electrodes and the event history up to the frame (each
short circuit with the total current and the rods in series when it closed, from the run
file's circuit log).
"""

from __future__ import annotations

import json

import numpy as np

from ..analysis.frame_topology import filament_words, frame_topology
from ..io.h5md import RunFile, RunFileError
from ..model import events as ev
from .main import CliError, add_run_and_frame, counted
from .paths import status_note


def add_arguments(p):
    add_run_and_frame(p)
    p.add_argument("--json", action="store_true", help="print JSON for scripts instead of tables")
    p.add_argument(
        "--events",
        type=int,
        default=10,
        metavar="N",
        help="show the last N events (default 10); --json lists every event up to the frame",
    )


def _finite_or_null(obj):
    if isinstance(obj, float):
        return obj if np.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _finite_or_null(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return [_finite_or_null(v) for v in obj]
    return obj


def _describe(e, circuit=True) -> str:
    """What the a and b columns of an event row name (docs of selfas_graph.model.events); ``circuit``:
    whether the run has one (without, the filaments carry no current)."""
    kind, a, b = e["kind"], e["a"], e["b"]
    if kind in ("tip_contact", "tip_release"):
        return f"a, b = tips (rods {a // 2} and {b // 2})"
    if kind in ("conductor_contact", "conductor_release"):
        return f"a = tip (rod {a // 2}), b = conductor ({ev.CONDUCTOR_NAMES.get(b, str(b))})"
    if kind == "short_circuit":
        if not circuit:
            return f"a = rods in filaments joining conductors ({a}; no circuit: no current)"
        text = f"a = rods in current-carrying filaments ({a})"
        if "total_current" in e:
            text += f"; total current {e['total_current']:.6g} J0, {e['rods_in_series']} rods in series"
        return text
    return ""


def _fmt(x, unit=""):
    if x is None:
        return "n/a (no circuit)"
    return ("inf" if np.isinf(x) else f"{x:.6g}") + unit


def _resistance_line(data) -> str:
    """The total current and the effective resistance between the conductors the frame has: n/a
    where the run has no circuit, infinite where its circuit is open."""
    where = "the electrodes" if set(data["conductors"]) <= {"anode", "cathode"} else "the conductors"
    r = data["effective_resistance"]
    if r is None and data["total_current"] is not None:
        resistance = "infinite (open: no current-carrying path)"
    else:
        resistance = _fmt(r, " R0")
    return f"total current: {_fmt(data['total_current'], ' J0')}; effective resistance between {where}: {resistance}"


def run(args):
    if args.events < 0:
        raise CliError(f"--events {args.events}: the number of events to show, >= 0")
    if args.time is not None and not np.isfinite(args.time):
        raise CliError(f"--time {args.time} names no frame; give a finite simulated time")
    try:
        with RunFile(args.run) as f:
            try:
                data = frame_topology(f, frame=args.frame, t=args.time)
            except RunFileError:
                raise  # the reader's own explanation (a frame or time the run does not have)
            except (KeyError, IndexError, TypeError, ValueError) as exc:
                # a file with the run layout but inconsistent contents (foreign or damaged)
                raise RunFileError(f"{f.path}: inconsistent graph data ({type(exc).__name__}: {exc})") from None
    except RunFileError as exc:
        raise CliError(str(exc)) from None
    if args.json:
        # strict JSON for scripts: an infinite resistance (no current) is written as null
        print(json.dumps(_finite_or_null(data), indent=1, allow_nan=False))
        return 0
    r = data["rods"]
    # the role is topological (a path between two conductors): without a circuit no current flows in it
    filaments = filament_words(data["circuit"])
    lines = [
        f"{data['file']}: frame {data['frame']} of 0..{data['frames'] - 1}, step {data['step']}, t = {data['time']:.6g}"
        + status_note(data["run_status"]),
        "conductors: "
        + (
            ", ".join(
                f"{k} psi = {v:+.6g}" if v is not None else f"{k} psi = -delta_J0 z per contact"
                for k, v in data["conductors"].items()
            )
            or "none"
        ),
        f"rods: {r['total']} = {r['filament']} in {filaments} + {r['dead_end']} dead ends + "
        f"{r['cluster']} in floating clusters + {r['free']} free",
        f"structures: {len(data['structures'])}, rods joined by tip contacts or touching a conductor alone "
        f"(largest: {counted(data['largest_structure'], 'rod')})",
        "short circuit: "
        + ("yes" if data["short_circuit"] else "no")
        + (
            f" (first at step {data['first_short_circuit']['step']}, t = {data['first_short_circuit']['time']:.6g})"
            if data["first_short_circuit"]
            else ""
        ),
        _resistance_line(data),
    ]
    touching = [s for s in data["structures"] if s["conductors"]]
    if touching:
        lines.append("\nstructures touching a conductor:")
        lines.append(f"  {'id':>5} {'rods':>6} {'filament':>9} {'dead end':>9}  conductors")
        for s in touching[:20]:
            lines.append(
                f"  {s['id']:>5} {s['rods']:>6} {s['filament']:>9} {s['dead_end']:>9}  {', '.join(s['conductors'])}"
            )
        if len(touching) > 20:
            lines.append(f"  ... and {len(touching) - 20} more")
    if data["filament_rods"]:
        lines.append(
            "\ncurrent-carrying filament rods (current in J0, + from tip a to tip b):"
            if data["circuit"]
            else "\nrods of filaments joining conductors (no circuit: no current):"
        )
        cells = [f"{d['rod']:>6} {d['current']:+10.4g}" for d in data["filament_rods"]]
        for i in range(0, min(len(cells), 60), 4):
            lines.append("  " + "   ".join(cells[i : i + 4]))
        if len(cells) > 60:
            lines.append(f"  ... and {len(cells) - 60} more (use --json for all)")
    if data["dead_end_rods"]:
        d = data["dead_end_rods"]
        lines.append(f"\ndead-end rods: {' '.join(map(str, d[:30]))}" + (" ..." if len(d) > 30 else ""))
    lines.append(
        "\nevents up to this frame: "
        + (", ".join(f"{k} {v}" for k, v in sorted(data["event_counts"].items())) or "none")
    )
    shown = data["events"][-args.events :] if args.events > 0 else []
    if shown:
        lines.append(f"  {'step':>13}  {'t':<14} {'kind':<18} {'a':>7} {'b':>7}  (what a and b are)")
    for e in shown:
        lines.append(
            f"  step {e['step']:>8}  t = {e['time']:<10.6g} {e['kind']:<18} {e['a']:>7} {e['b']:>7}  {_describe(e, data['circuit'])}"
        )
    print("\n".join(lines))
    return 0
