"""A fast multipole method for the tip-tip force against the tip tree's walk, in one run.

Usage: selfas-graph bench fmm [--rods 6000 24000] [--config fig2] [--order 5 6] [--theta 0.5 0.6]
       [--leaf 64] [--reps 3]

Times the cell-cell expansions of ``kernels/fmm.py`` (float64, not used by the model) by stage, with
their error against the direct sum, beside the walk the scenes take (``kernels/treewalk.py``, mixed
precision, the tree's defaults) on the same tips of a configuration of selfas_graph/bench/tree.py:

- the shipped walk: the evaluation whole, its lists, its far cells and its near pairs (as
  ``bench walk_parts``), the near tips and far cells a target, its error;
- each FMM setting (``--order`` p, ``--theta``, ``--leaf``): the dual walk's lists, the moments
  (P2M, M2M), M2L, L2L with L2P, and the near pairs in float64 with the rod partners taken off;
  the cell pairs taken as expansions, the near tips a target, the time of one M2L a pair (one way),
  and its error.

The question it answers is whether expansions about target cells (each far pair of cells taken
once, whatever the number of tips) make the far field cheaper than the walk's cells applied to
every target, at the walk's error; and how many near pairs the cell-cell test leaves. Each time is
the shortest of ``--reps`` (wall, all numba threads). The header names the CPU and the instruction
set; run it again with ``NUMBA_CPU_NAME=haswell NUMBA_CPU_FEATURES=`` for the AVX2 build.
"""

import argparse

import numba
import numpy as np

from selfas_graph.kernels import fmm
from selfas_graph.kernels.tree import build_tip_tree, evaluate_tip_tree

from .args import below_one, positive
from .tree import CONFIGS, KAPPA, RSTAR, Reference, best_of
from .walk_parts import FAR, LISTS, NEAR, run_parts


def shipped_row(config, n_rods, tips, ref, reps):
    """The walk the scenes take, whole and by part: a row of the table."""
    tree = build_tip_tree(*tips)
    n = tree.x.shape[0]
    whole, parts = np.empty((n, 3)), np.empty((n, 3))
    counts = np.zeros((tree.group.shape[0], 2), np.int64)
    calls = {"whole": lambda: evaluate_tip_tree(tree, RSTAR, KAPPA, 0.55, whole, precision="mixed")}
    for name, bits in (("lists", LISTS), ("near", NEAR), ("far", FAR)):
        calls[name] = lambda bits=bits: run_parts(tree, 0.55, bits, parts, counts)
    for call in calls.values():
        call()  # compiled, caches warm
    ms = {name: 1e3 * best_of(reps, call) for name, call in calls.items()}
    near_pairs, far_cells = counts.sum(axis=0) / n
    med, p99 = ref.error(whole)
    return (
        f"| {config} | {n_rods} | walk (mixed), leaves 64, groups 1024, order 4, 0.55 | {med:.2e} / {p99:.2e} "
        f"| {far_cells:.0f} far cells a target | {near_pairs:.0f} | {ms['whole']:.2f} | {ms['lists']:.2f} "
        f"| far cells {ms['far'] - ms['lists']:.2f} | | | near (float32) {ms['near'] - ms['lists']:.2f} | |"
    )


def fmm_row(config, n_rods, tips, ref, reps, leaf, order, theta):
    """One FMM setting, by stage: a row of the table."""
    tree = build_tip_tree(*tips, leaf_size=leaf)
    tab = fmm.tables(order)
    n = tree.x.shape[0]
    lists = fmm.interaction_lists(tree, theta, RSTAR)
    moment = fmm.moments(tree, tab)
    local = fmm.locals_of(tree, tab, lists, moment)
    out = fmm.fields(tree, tab, local.copy())
    fmm.near_and_partners(tree, lists, RSTAR, KAPPA, out)
    med, p99 = ref.error(out[tree.rank])
    ms = {
        "lists": best_of(reps, lambda: fmm.interaction_lists(tree, theta, RSTAR)),
        "moments": best_of(reps, lambda: fmm.moments(tree, tab)),
        "m2l": best_of(reps, lambda: fmm.locals_of(tree, tab, lists, moment)),
        "down": best_of(reps, lambda: fmm.fields(tree, tab, local.copy())),
        "near": best_of(reps, lambda: fmm.near_and_partners(tree, lists, RSTAR, KAPPA, out)),
    }
    ms = {k: 1e3 * v for k, v in ms.items()}
    size = tree.end - tree.start
    a, b = lists.near[:, 0], lists.near[:, 1]
    near_pairs = np.where(a == b, 1, 2) @ (size[a] * size[b]) / n
    n_pairs = lists.far.shape[0]
    ns_pair = 1e6 * ms["m2l"] / max(2 * n_pairs, 1)
    return (
        f"| {config} | {n_rods} | FMM, leaves {leaf}, order {order}, {theta:g} | {med:.2e} / {p99:.2e} "
        f"| {n_pairs} cell pairs | {near_pairs:.0f} | {sum(ms.values()):.2f} | {ms['lists']:.2f} "
        f"| {ms['moments'] + ms['m2l'] + ms['down']:.2f} | {ms['m2l']:.2f} | {ns_pair:.0f} "
        f"| near (float64) {ms['near']:.2f} | {ms['down']:.2f} |"
    )


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rods", type=positive(int), nargs="+", default=[6000, 24000])
    ap.add_argument("--config", nargs="+", default=["fig2"], choices=["uniform", "chains", "fig2"])
    ap.add_argument(
        "--order", type=positive(int), nargs="+", default=[5, 6], help="FMM expansion orders p (default 5 6)"
    )
    ap.add_argument(
        "--theta", type=below_one, nargs="+", default=[0.5, 0.6], help="FMM opening angles (default 0.5 0.6)"
    )
    ap.add_argument(
        "--leaf", type=positive(int), nargs="+", default=[64], help="FMM leaf sizes (default 64, the walk's)"
    )
    ap.add_argument("--reps", type=positive(int), default=3)
    ap.add_argument("--sample", type=positive(int), default=3000, help="tips the error is measured on (default 3000)")
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args(argv)
    from .peer import machine_line

    print(machine_line())
    print(f"numba threads: {numba.get_num_threads()}; error: median / 99th percentile against the direct sum")
    print(
        "| config | rods | method | error | far | near tips a target | whole ms | lists | far field "
        "| M2L | ns an M2L (one way) | near | L2L + L2P |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    make = CONFIGS
    for config in args.config:
        for n_rods in args.rods:
            rng = np.random.default_rng(args.seed)
            tips = make[config](n_rods, rng)
            ref = Reference(tips, min(args.sample, 2 * n_rods), 0, rng)
            print(shipped_row(config, n_rods, tips, ref, args.reps), flush=True)
            for leaf in args.leaf:
                for order in args.order:
                    for theta in args.theta:
                        print(fmm_row(config, n_rods, tips, ref, args.reps, leaf, order, theta), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
