"""Short-circuit episodes of runs: how long the gap stays closed, what opens it, and the currents.

Usage: selfas-graph bench short_circuits RUN.h5 [RUN.h5 ...] [--json out.json]
       selfas-graph bench short_circuits --replay RUN.h5 --scenario SCENARIO --frame K --for T
           [--set key=value ...] [--json out.json]

The first form reads the event records of each run file and prints, per run, the number of
short-circuit episodes (docs/model.md 'Contacts and events'), the median and longest time the
gap stayed closed, how many episodes a tip-tip release inside the filament opened and how many a
tip leaving an electrode (or the case (ii) filament), and whether the gap is closed at the last
event (:func:`selfas_graph.analysis.episodes.circuit_episodes`); with ``--json``, also the total
current and the rods in series at each closing, from the run file's circuit log.

The stored frames are too far apart to catch an episode of 0.05 t0, so ``--replay`` restarts
the scene from frame K of RUN.h5 (tip positions and velocities, the rods' charges; the contacts
are found again from the positions; the time starts at 0) and runs it for T t0 at the
scenario's parameters (with ``--set`` overrides, e.g. ``forces.current_lorentz=false``). At every
short circuit it prints the total current, the rods carrying current and the rods carrying all
of it (in series: a single chain that every current-carrying path passes through), and at every
open circuit the releases that opened it. The restart is a new trajectory of the chaotic system
(the integrator history and the float32 frames differ from the original run), not a replay bit
for bit: read its episodes as samples of the same physics.

Prints the CPU model and the instruction set numba compiled for. One numba thread unless
NUMBA_NUM_THREADS says otherwise.
"""

import argparse
import json
import os
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
#: set (unless set) by the command line, not on import (tests import this): a running job's file
#: is read only here (``selfas-graph bench`` sets them too)
COMMAND_ENV = {"HDF5_USE_FILE_LOCKING": "FALSE"}

KIND = {2: "tip-tip release", 4: "electrode release", -2: "both", 0: "unknown", -1: "still closed"}


def summarise(path) -> dict:
    """The episodes of one run file as a JSON-ready dict."""
    from selfas_graph.analysis.episodes import CONDUCTOR_RELEASE, STILL_CLOSED, TIP_RELEASE, circuit_episodes
    from selfas_graph.io.h5md import RunFile

    with RunFile(path) as run:
        events, log = run.events(), run.circuit_log()
    ep = circuit_episodes(events, log)
    ended = np.isfinite(ep.end)
    d = ep.duration[ended]
    return {
        "file": str(path),
        "episodes": len(ep),
        "first_short_circuit": float(ep.start[0]) if len(ep) else None,
        "median_duration": float(np.median(d)) if d.size else None,
        "longest_duration": float(d.max()) if d.size else None,
        "opened_by_tip_release": int((ep.opened_by == TIP_RELEASE).sum()),
        "opened_by_electrode_release": int((ep.opened_by == CONDUCTOR_RELEASE).sum()),
        "opened_otherwise": int((ended & (ep.opened_by != TIP_RELEASE) & (ep.opened_by != CONDUCTOR_RELEASE)).sum()),
        "closed_at_end": bool(len(ep) and ep.opened_by[-1] == STILL_CLOSED),
        "closed_since": float(ep.start[-1]) if len(ep) and ep.opened_by[-1] == STILL_CLOSED else None,
        "last_event_time": float(events["time"][-1]) if len(events) else None,
        # the current through the gap and the rods in series at each closing (files with a circuit log;
        # null for a closing the log has no row of)
        "closing_current": None if log is None else [float(j) if np.isfinite(j) else None for j in ep.total_current],
        "closing_rods_in_series": None if log is None else [int(n) if n >= 0 else None for n in ep.rods_in_series],
    }


def print_summary(rows):
    print(
        "| run | episodes | first | median closed (t0) | longest | opened by tip-tip / electrode / other | closed at the end |"
    )
    print("|---|---|---|---|---|---|---|")

    def f(v):
        return "-" if v is None else f"{v:.3g}"

    for r in rows:
        closed = f"since t = {r['closed_since']:.4g}" if r["closed_at_end"] else "no"
        file = Path(r["file"])
        label = f"{file.parent.name}/{file.name}" if file.parent.name else file.name  # "run.h5", not "/run.h5"
        print(
            f"| {label} | {r['episodes']} | {f(r['first_short_circuit'])} | {f(r['median_duration'])} | "
            f"{f(r['longest_duration'])} | {r['opened_by_tip_release']} / {r['opened_by_electrode_release']} / "
            f"{r['opened_otherwise']} | {closed} (last event t = {f(r['last_event_time'])}) |"
        )


def restart_state(path, frame):
    """The State of frame ``frame`` of a run file: rods from the tip positions, the tips'
    velocities and the rods' charges (the contacts are found again by the Simulation)."""
    import selfas_graph as sg
    from selfas_graph.io.h5md import RunFile

    with RunFile(path) as run:
        n = run.n_frames
        if not -n <= frame < n:
            raise SystemExit(f"error: --frame {frame} is outside the {n} frames of {path}")
        x = run.position(frame=frame)
        v = run.velocity(frame=frame)
        q_tip = run.tip_charge
        z_rod = run.rod_charge
        # ones (equal rods, R0) are what a run without them stores: pass None, the scene's own case
        length = None if np.all(run.rod_length == 1.0) else run.rod_length
        resistance = None if np.all(run.rod_resistance == 1.0) else run.rod_resistance
        t = run.time[frame]
    xa, xb = x[0::2], x[1::2]
    state = sg.State.from_rods(
        0.5 * (xa + xb), xb - xa, q_tip[1::2], z_rod, velocity=v, length=length, resistance=resistance
    )
    return state, float(t)


def replay(args) -> dict:
    import selfas_graph as sg
    from selfas_graph.model.events import CONDUCTOR_RELEASE, OPEN_CIRCUIT, SHORT_CIRCUIT, TIP_RELEASE

    scenario = sg.load_scenario(args.scenario, overrides=args.set)
    state, t_frame = restart_state(args.replay, args.frame)
    sim = sg.Simulation(scenario.params, state=state)
    if sim.network is None or not sim.network.circuit:
        raise SystemExit(f"error: {args.scenario} has no [circuit]: there are no currents to follow")
    p = scenario.params
    print(
        f"restart of {args.replay} at frame {args.frame} (t = {t_frame:g}), {sim.state.n_rods} rods, for {args.__dict__['for']:g} t0"
    )
    dt = p.integrator.dt
    chunk = max(1, int(round(args.chunk / dt)))
    n_steps = sim.steps_to(args.__dict__["for"])
    episodes = []
    n_seen = len(sim.events)
    done = 0
    while done < n_steps:
        k = min(chunk, n_steps - done)
        sim.run(sim.state.time + k * dt)
        done += k
        new = sim.events[n_seen:]
        n_seen = len(sim.events)
        kinds = [int(e[2]) for e in new]
        if SHORT_CIRCUIT in kinds:
            cur = np.abs(sim.network.current)
            total = float(sim.status()["total_current"])
            ep = {
                "closed": float([e[1] for e in new if int(e[2]) == SHORT_CIRCUIT][0]),
                "total_current": total,
                "current_rods": int((cur > 0).sum()),
                # a rod in series carries the whole current (to the solve's round-off)
                "series_rods": int((cur >= total * (1 - 1e-9)).sum()) if total > 0 else 0,
                "opened": None,
                "opened_by": None,
            }
            episodes.append(ep)
            print(
                f"  t = {ep['closed']:.3f}: closed; total current {total:.3g} J0 through {ep['current_rods']} rods, "
                f"{ep['series_rods']} of them in series (carrying all of it)"
            )
        if OPEN_CIRCUIT in kinds and episodes and episodes[-1]["opened"] is None:
            t_open = float([e[1] for e in new if int(e[2]) == OPEN_CIRCUIT][0])
            rel = [e for e in new if int(e[2]) in (TIP_RELEASE, CONDUCTOR_RELEASE)]
            ep = episodes[-1]
            ep["opened"] = t_open
            ep["opened_by"] = [[KIND[int(e[2])], int(e[3]), int(e[4])] for e in rel]
            print(
                f"  t = {t_open:.3f}: open after {t_open - ep['closed']:.3f} t0; "
                + ", ".join(f"{k} ({a}, {b})" for k, a, b in ep["opened_by"])
            )
    return {
        "file": str(args.replay),
        "frame": args.frame,
        "frame_time": t_frame,
        "for": args.__dict__["for"],
        "set": args.set,
        "episodes": episodes,
    }


def build_parser():
    ap = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("runs", nargs="*", help="run files (HDF5) to summarise")
    ap.add_argument("--replay", metavar="RUN.h5", help="restart a scene from a frame of this run file")
    ap.add_argument("--scenario", help="the scenario of --replay (its parameters are used)")
    ap.add_argument("--frame", type=int, default=None, help="frame of --replay to start from")
    ap.add_argument("--for", type=float, default=None, help="t0 to run the restarted scene for")
    ap.add_argument("--chunk", type=float, default=0.005, help="t0 between checks for events (default 0.005)")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="scenario override (repeatable)")
    ap.add_argument("--json", help="write the results as JSON here")
    return ap


def main(argv=None):
    ap = build_parser()
    args = ap.parse_args(argv)
    from selfas_graph.cli.paths import same_file
    from selfas_graph.io.h5md import RunFileError
    from selfas_graph.io.scenario import ScenarioError

    from .peer import machine_line

    inputs = list(args.runs) + ([args.replay] if args.replay else [])
    if args.json and any(same_file(args.json, r) for r in inputs):
        ap.error(f"--json {args.json} is one of the run files read: choose another output file")
    if args.replay:
        if args.runs:
            ap.error("give either run files to summarise or --replay, not both")
        missing = [
            o
            for o, v in (("--scenario", args.scenario), ("--frame", args.frame), ("--for", args.__dict__["for"]))
            if v is None
        ]
        if missing:
            ap.error(f"--replay needs {', '.join(missing)}")
        if args.__dict__["for"] <= 0 or args.chunk <= 0:
            ap.error("--for and --chunk must be positive")
        print(machine_line())
        try:
            result = replay(args)
        except (ScenarioError, RunFileError) as exc:
            ap.error(str(exc))
    else:
        if not args.runs:
            ap.error("give run files to summarise, or --replay RUN.h5 --scenario S --frame K --for T")
        for r in args.runs:
            if not Path(r).is_file():
                ap.error(f"no such run file: {r}")
        try:
            result = [summarise(r) for r in args.runs]
        except (RunFileError, ValueError) as exc:
            ap.error(str(exc))
        print_summary(result)
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    for key, value in COMMAND_ENV.items():
        os.environ.setdefault(key, value)
    sys.exit(main())
