"""Step benchmark: milliseconds per full step for the Fig. 2 scene and a 6000-rod variant.

Usage: selfas-graph bench step [--rods 1200 6000] [--steps 200] [--scenario scenarios/fig2.toml]
                                  [--set KEY=VALUE ...]
       mpiexec -n 2 selfas-graph bench step ...   (the force rows split over the ranks; rank 0 prints)
       selfas-graph bench step --compare --repeat 7 ...
                                                     (1 rank x 1 thread, 2 ranks x 1 thread and
                                                      1 rank x 2 threads taking turns, in one table)

For each size it builds the scene (all its force terms, random placement), takes
warm-up steps (numba compilation, neighbour lists), then times ``--steps`` steps and
prints ms/step, steps/s, the cost of each force term, and, as the reference measured
in the same run, the tip-tip direct sum alone: its tip pairs per second per core
and the ratio of a full step to it. Under ``mpiexec`` the per-term times are rank 0's,
and ``gather`` is the time its force rows take to reach the other ranks.
"""

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numba
import numpy as np

from selfas_graph import Simulation, load_scenario
from selfas_graph.kernels.tips import tip_tip_direct
from selfas_graph.parallel import world

from .peer import machine_line

ROOT = Path(__file__).resolve().parents[2]

#: (label, ranks, numba threads) of ``--compare``
CONFIGS = [("1 rank x 1 thread", 1, 1), ("2 ranks x 1 thread", 2, 1), ("1 rank x 2 threads", 1, 2)]


def scene(path, n_rods, extra=()):
    """The scenario with ``n_rods`` rods, the box scaled in x, y to keep the Fig. 2 density,
    and the overrides ``extra`` (``KEY=VALUE`` strings)."""
    base = load_scenario(path, overrides=extra)
    box = np.array(base.params.placement.box)
    scale = (n_rods / base.params.rods.count) ** 0.5
    xy = [[float(box[0][0] * scale), float(box[0][1] * scale)], [float(box[1][0] * scale), float(box[1][1] * scale)]]
    z = [float(v) for v in box[2]]
    over = [*extra, f"rods.count={n_rods}", f"placement.box=[{xy[0]}, {xy[1]}, {z}]"]
    return load_scenario(path, overrides=over)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default=str(ROOT / "scenarios" / "fig2.toml"))
    ap.add_argument("--rods", type=int, nargs="+", default=[1200, 6000])
    ap.add_argument("--steps", type=int, default=200)
    ap.add_argument(
        "--compare",
        action="store_true",
        help="run 1 rank x 1 thread, 2 ranks x 1 thread and 1 rank x 2 threads; print one table",
    )
    ap.add_argument(
        "--repeat",
        type=int,
        default=1,
        help="with --compare: rounds in which the configurations take turns; each figure is the "
        "median [min-max] over the rounds and each ratio the median of the per-round ratios",
    )
    ap.add_argument("--json", action="store_true", help="print only a JSON line of ms/step per size (rank 0)")
    ap.add_argument(
        "--set",
        dest="extra",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="change the scene, e.g. --set integrator.slow_every=1 (repeatable)",
    )
    args = ap.parse_args(argv)
    if args.compare:
        return compare(args)
    say = print if world.rank == 0 and not args.json else (lambda *a, **k: None)
    threads = numba.get_num_threads()
    say(machine_line())
    say(f"numba threads: {threads} x {world.size} MPI ranks; scenario {args.scenario}")
    rows = []
    for n in args.rods:
        sc = scene(args.scenario, n, args.extra)
        sim = Simulation.from_scenario(sc, timing=True, comm=world)
        sim.step(10)
        ff = sim.force_field
        ff.seconds.clear()
        steps = max(10, args.steps if n <= 2000 else args.steps // 4)
        world.Barrier()
        t0 = time.perf_counter()
        sim.step(steps)
        world.Barrier()
        per_step = (time.perf_counter() - t0) / steps
        # reference in the same run: the tip-tip direct sum alone on the same positions (rank 0, all rows)
        x, y, z = (np.ascontiguousarray(sim.state.position[:, d]) for d in range(3))
        out = np.empty_like(sim.state.position)
        reps = max(3, steps // 4)
        t0 = time.perf_counter()
        if world.rank == 0:
            for _ in range(reps):
                tip_tip_direct(x, y, z, sim.state.tip_charge, sc.params.rods.rstar, 1.0, 0, len(x), out)
        direct = (time.perf_counter() - t0) / reps
        world.Barrier()
        pairs = (2 * n) ** 2 / direct / threads
        evals = ff.calls["tip_magnetic"] / max(1, sim.state.step)
        say(
            f"\n{n} rods: {per_step * 1e3:.2f} ms/step ({1 / per_step:.0f} steps/s); "
            f"tip-tip direct sum alone {direct * 1e3:.2f} ms = {pairs / 1e9:.2f}e9 tip pairs/s/core; "
            f"step / direct-sum ratio {per_step / direct:.2f}"
        )
        for name, sec in sorted(ff.seconds.items(), key=lambda kv: -kv[1]):
            say(f"    {name:16s} {sec / steps * 1e3:8.3f} ms/step")
        say(
            f"    (force evaluations per step: {evals:.2f}; Yukawa cut-off {ff.describe().get('yukawa_cutoff', 0):.2f})"
        )
        rows.append((n, per_step * 1e3, 1 / per_step, direct * 1e3, pairs / 1e9))
    if args.json:
        if world.rank == 0:
            print(json.dumps({str(n): ms for n, ms, *_ in rows}))
        return
    say("\n| rods | ms/step | steps/s | tip-tip direct alone (ms) | 1e9 tip pairs/s/core |")
    say("|---|---|---|---|---|")
    for n, ms, sps, d, gp in rows:
        say(f"| {n} | {ms:.2f} | {sps:.0f} | {d:.2f} | {gp:.2f} |")


def compare(args):
    """Run this tool once per entry of CONFIGS (under mpiexec for several ranks) and tabulate ms/step."""
    mpiexec = Path(sys.executable).parent / "mpiexec"
    from .peer import tool_command, tool_env

    base = [
        *tool_command("step"),
        "--json",
        "--steps",
        str(args.steps),
        "--scenario",
        args.scenario,
        "--rods",
        *map(str, args.rods),
        *(a for e in args.extra for a in ("--set", e)),
    ]
    rounds = [[{} for _ in CONFIGS] for _ in range(args.repeat)]
    for r in range(args.repeat):
        # the configurations take turns, in reversed order every other round, so that none always
        # runs just after another (a warm cache, a machine quieting down)
        order = list(range(len(CONFIGS)))
        for c in order if r % 2 == 0 else order[::-1]:
            label, ranks, threads = CONFIGS[c]
            env = tool_env({**os.environ, "NUMBA_NUM_THREADS": str(threads)})
            cmd = base if ranks == 1 else [str(mpiexec if mpiexec.exists() else "mpiexec"), "-n", str(ranks), *base]
            res = subprocess.run(cmd, env=env, capture_output=True, text=True, check=True)
            got = json.loads(res.stdout.strip().splitlines()[-1])
            print(f"round {r + 1}, {label}: {got}", file=sys.stderr, flush=True)
            rounds[r][c] = got
    print(machine_line())
    print(
        "| rods | "
        + " | ".join(f"{label} (ms/step)" for label, _, _ in CONFIGS)
        + " | speed-up, 2 ranks | speed-up, 2 threads | 2 ranks / 2 threads, per round |"
    )
    print("|---" * (len(CONFIGS) + 4) + "|")
    for n in args.rods:
        ms = np.array([[rnd[c][str(n)] for c in range(len(CONFIGS))] for rnd in rounds])  # (rounds, configs)
        med = np.median(ms, axis=0)
        ratio = ms[:, 1] / ms[:, 2]
        print(
            f"| {n} | "
            + " | ".join(f"{m:.2f} [{lo:.2f}-{hi:.2f}]" for m, lo, hi in zip(med, ms.min(0), ms.max(0)))
            + f" | {np.median(ms[:, 0] / ms[:, 1]):.2f} | {np.median(ms[:, 0] / ms[:, 2]):.2f}"
            + f" | {np.median(ratio):.2f} [{ratio.min():.2f}-{ratio.max():.2f}] |"
        )
    print(
        f"(median [min-max] of {args.repeat} rounds; the ratios are medians of the per-round ratios; "
        f"load average at the end {os.getloadavg()[0]:.1f})"
    )


if __name__ == "__main__":
    main()
