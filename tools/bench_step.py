"""Step benchmark: milliseconds per full step for the Fig. 2 scene and a 6000-rod variant.

Usage: python tools/bench_step.py [--rods 1200 6000] [--steps 200] [--scenario scenarios/fig2.toml]

For each size it builds the scene (all its force terms, random placement), takes
warm-up steps (numba compilation, neighbour lists), then times ``--steps`` steps and
prints ms/step, steps/s, the cost of each force term, and, as the reference measured
in the same run, the tip-tip direct sum alone: its tip pairs per second per core
and the ratio of a full step to it.
"""
import argparse
import sys
import time
from pathlib import Path

import numba
import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from selfas_graph import Simulation, load_scenario  # noqa: E402
from selfas_graph.kernels.tips import tip_tip_direct  # noqa: E402


def scene(path, n_rods):
    """The scenario with ``n_rods`` rods, the box scaled in x, y to keep the Fig. 2 density."""
    base = load_scenario(path)
    box = np.array(base.params.placement.box)
    scale = (n_rods / base.params.rods.count) ** 0.5
    xy = [[float(box[0][0] * scale), float(box[0][1] * scale)], [float(box[1][0] * scale), float(box[1][1] * scale)]]
    z = [float(v) for v in box[2]]
    over = [f"rods.count={n_rods}", f"placement.box=[{xy[0]}, {xy[1]}, {z}]"]
    return load_scenario(path, overrides=over)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default=str(ROOT / "scenarios" / "fig2.toml"))
    ap.add_argument("--rods", type=int, nargs="+", default=[1200, 6000])
    ap.add_argument("--steps", type=int, default=200)
    args = ap.parse_args()
    threads = numba.get_num_threads()
    print(f"numba threads: {threads}; scenario {args.scenario}")
    rows = []
    for n in args.rods:
        sc = scene(args.scenario, n)
        sim = Simulation.from_scenario(sc, timing=True)
        sim.step(10)
        ff = sim.force_field
        ff.seconds.clear()
        steps = max(10, args.steps if n <= 2000 else args.steps // 4)
        t0 = time.perf_counter()
        sim.step(steps)
        per_step = (time.perf_counter() - t0) / steps
        # reference in the same run: the tip-tip direct sum alone on the same positions
        x, y, z = (np.ascontiguousarray(sim.state.position[:, d]) for d in range(3))
        out = np.empty_like(sim.state.position)
        reps = max(3, steps // 4)
        t0 = time.perf_counter()
        for _ in range(reps):
            tip_tip_direct(x, y, z, sim.state.tip_charge, sc.params.rods.rstar, 1.0, 0, len(x), out)
        direct = (time.perf_counter() - t0) / reps
        pairs = (2 * n) ** 2 / direct / threads
        evals = ff.calls["tip_magnetic"] / max(1, sim.state.step)
        print(f"\n{n} rods: {per_step * 1e3:.2f} ms/step ({1 / per_step:.0f} steps/s); "
              f"tip-tip direct sum alone {direct * 1e3:.2f} ms = {pairs / 1e9:.2f}e9 tip pairs/s/core; "
              f"step / direct-sum ratio {per_step / direct:.2f}")
        for name, sec in sorted(ff.seconds.items(), key=lambda kv: -kv[1]):
            print(f"    {name:16s} {sec / steps * 1e3:8.3f} ms/step")
        print(f"    (force evaluations per step: {evals:.2f}; Yukawa cut-off {ff.describe().get('yukawa_cutoff', 0):.2f})")
        rows.append((n, per_step * 1e3, 1 / per_step, direct * 1e3, pairs / 1e9))
    print("\n| rods | ms/step | steps/s | tip-tip direct alone (ms) | 1e9 tip pairs/s/core |")
    print("|---|---|---|---|---|")
    for n, ms, sps, d, gp in rows:
        print(f"| {n} | {ms:.2f} | {sps:.0f} | {d:.2f} | {gp:.2f} |")


if __name__ == "__main__":
    main()
