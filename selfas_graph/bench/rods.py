"""What rods that differ cost: equal rods against per-rod lengths, resistances and contacts.

Usage: selfas-graph bench rods [--steps 300] [--rounds 3] [--tips 600 100000]

Two tables, each with its peer measured in the same run:

* the rigid-bond kernels (``bond_length_error`` twice and ``constrain_bonds`` once, as in
  one step) with the empty length array of equal rods against an array of lengths, per
  size; the ratio is per-rod / equal;
* a full step of ``scenarios/quick.toml`` as shipped (equal rods, ideal contacts), of the
  same scene with ``rods.length = 1``, ``rods.resistance = 1`` and ``contacts.resistance = 0``
  written out (the per-rod code paths, same physics), and of ``scenarios/quick_mixed.toml``
  (lengths, resistances and contacts that differ; a different scene, so its ratio includes
  its other dynamics). Each is timed after warm-up steps, in rounds that alternate the
  scenes (a shared machine's load then hits all alike), best round kept.

The CPU model and the instruction set numba compiles for are printed first.
"""

import argparse
import time
from pathlib import Path

import numba
import numpy as np

from selfas_graph import Simulation, load_scenario
from selfas_graph.kernels.rigid import bond_length_error, constrain_bonds

from .peer import machine_line

ROOT = Path(__file__).resolve().parents[2]

DEFAULT_KEYS = ["rods.length=1.0", "rods.resistance=1.0", "contacts.resistance=0.0"]


def cpu():
    """The CPU, the instruction set numba compiles for (``NUMBA_CPU_NAME``) and the thread count."""
    return f"{machine_line()}; {numba.get_num_threads()} numba threads"


def bench_kernels(n_tips, repeat=50):
    rng = np.random.default_rng(1)
    n = n_tips // 2
    centre = rng.uniform(-10, 10, (n, 3))
    axis = rng.normal(size=(n, 3))
    axis /= np.linalg.norm(axis, axis=1)[:, None]
    length = rng.uniform(0.5, 1.5, n)
    x0 = np.empty((n_tips, 3))
    times = {}
    for label, ell, half in (("equal", np.zeros(0), 0.5 * axis), ("per-rod", length, (0.5 * length)[:, None] * axis)):
        x0[0::2], x0[1::2] = centre - half, centre + half
        x0 += 1e-4 * rng.normal(size=x0.shape)
        v0 = rng.normal(size=x0.shape)
        best = np.inf
        for _ in range(3):
            x, v = x0.copy(), v0.copy()
            bond_length_error(x, ell)  # compile outside the timing
            constrain_bonds(x, v, True, True, ell)
            t0 = time.perf_counter()
            for _ in range(repeat):
                bond_length_error(x, ell)
                constrain_bonds(x, v, True, True, ell)
                bond_length_error(x, ell)
            best = min(best, (time.perf_counter() - t0) / repeat)
        times[label] = best
    return times


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=300, help="timed steps per scene and round")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--tips", type=int, nargs="+", default=[600, 100_000])
    args = parser.parse_args(argv)
    print(cpu())

    print("\nrigid-bond kernels per step (2 x bond_length_error + constrain_bonds)")
    print(f"{'tips':>8s} {'equal us':>10s} {'per-rod us':>11s} {'ratio':>6s}")
    for n in args.tips:
        t = bench_kernels(n)
        print(f"{n:8d} {1e6 * t['equal']:10.2f} {1e6 * t['per-rod']:11.2f} {t['per-rod'] / t['equal']:6.3f}")

    quick = ROOT / "scenarios" / "quick.toml"
    scenes = {
        "quick.toml (equal rods)": load_scenario(quick),
        "quick.toml, keys at defaults": load_scenario(quick, overrides=DEFAULT_KEYS),
        "quick_mixed.toml": load_scenario(ROOT / "scenarios" / "quick_mixed.toml"),
    }
    sims = {}
    for label, sc in scenes.items():
        sims[label] = Simulation.from_scenario(sc)
        sims[label].step(50)  # warm-up: compilation, neighbour lists, the multiple-time-stepping start
    best = {label: np.inf for label in sims}
    for _ in range(args.rounds):
        for label, sim in sims.items():
            t0 = time.perf_counter()
            sim.step(args.steps)
            best[label] = min(best[label], (time.perf_counter() - t0) / args.steps)
    ref = best["quick.toml (equal rods)"]
    print(f"\nfull step, {args.steps} steps x {args.rounds} rounds after 50 warm-up steps, best round")
    print(f"{'scene':32s} {'ms/step':>8s} {'ratio':>6s}")
    for label, t in best.items():
        print(f"{label:32s} {1e3 * t:8.3f} {t / ref:6.3f}")


if __name__ == "__main__":
    main()
