"""The tip tree's walk by part: its lists, near field and far field, and the pairs each group takes.

Usage: selfas-graph bench walk_parts [--rods 6000 24000] [--config fig2] [--reps 5]

The evaluation of the tip tree as the scenes take it (``kernels/treewalk.py::evaluate_groups``,
mixed precision, the tree's defaults: leaves of 64, groups of 1024, hexadecapoles, opening angle
0.55) on the tips of a configuration of selfas_graph/bench/tree.py, timed whole and in parts by a
kernel of this module that runs the walk's own stages (inlined functions of kernels/treewalk.py)
with the near sum, the far sum or both left out:

- ``lists``: per group the targets, the walk of the tree (the interaction lists, the far cells
  recorded) and the copies of the near tips, stages 1-3;
- ``near``: the near field's pair sums, ``(lists + near) - lists``;
- ``far``: the recorded far cells summed on every target, ``(lists + far) - lists``;
- ``rest``: the shipped kernel less the three (the rod partner's exact force, writing the rows).

It also counts, over all targets, the near pairs and the far cells evaluated, and weighs a near
field that counts each pair once: at best (half the near pairs' time gone, if a pair then cost what
it costs now) and as a prototype, :func:`near_once`, which takes each target's pairs with the near
tips after it in Morton order only (about half the pairs) and adds each pair's reaction to the
other tip (its forces are not the tree's: it is there for its time). With both sums on, the parts'
kernel must give the shipped kernel's forces bit for bit; the tool says whether it does, so that
the parts are those of the code a run executes.

``--separation`` times nothing: it asks what a local expansion about each group's centre could take
over from the far cells. For every cell the walk accepts (the shipped test, :func:`far_separation`) it
gives the ratio ``(b + r_g) / D`` of the cell's radius b plus the group's (half its box's diagonal)
to the distance D of their centres, the ratio an expansion about the group's centre converges by (its
error of order p about ``ratio^(p + 1)``), and prints the share of the far work (cells times targets)
below each ratio.

Each figure is the shortest of ``--reps`` runs (wall time, all numba threads), the five calls
timed in turns. The header names the
CPU and the instruction set numba compiled for; run it again with ``NUMBA_CPU_NAME=haswell
NUMBA_CPU_FEATURES=`` for the AVX2 build.
"""

import argparse
import math
import time

import numba
import numpy as np

from selfas_graph.kernels._jit import inline, inline_sum, njit, njit_parallel_sum, prange, set_parallel_chunksize
from selfas_graph.kernels.laws import tip_force_over_r, tip_force_over_r_f32
from selfas_graph.kernels.tree import build_tip_tree, evaluate_tip_tree
from selfas_graph.kernels.treewalk import (
    FAR_CHUNK,
    _far32_on_target_3,
    _far32_on_target_4,
    _near_copies,
    _near_on_target_f32,
    _targets,
    _walk,
    accepts,
)

from .tree import CONFIGS, KAPPA, RSTAR

#: the parts' kernel: which sums it takes
LISTS, NEAR, FAR = 0, 1, 2


@inline
def _group_walk(gi, x, y, z, index, rank, start, end, nxt, box, centre, radius, moment, group, order, theta2, rstar):
    """Stages 1 and 2 of ``evaluate_groups`` for group ``gi`` (all its tips as targets, mixed precision):
    ``(gs, gcx, gcy, gcz, (sel, n_w, tx, ty, tz, partner), walk)``, ``walk`` the tuple :func:`_walk`
    returns (empty lists when the group has no target)."""
    g = group[gi]
    gs = start[g]
    xl, yl, zl, xh, yh, zh = box[g, 0], box[g, 1], box[g, 2], box[g, 3], box[g, 4], box[g, 5]
    gcx = 0.5 * (xl + xh)
    gcy = 0.5 * (yl + yh)
    gcz = 0.5 * (zl + zh)
    targets = _targets(x, y, z, index, rank, gs, end[g], 0, x.shape[0], gcx, gcy, gcz)
    tx, ty, tz = targets[2], targets[3], targets[4]
    walk = _walk(
        start, end, nxt, centre, radius, moment, order, True, theta2, rstar, xl, yl, zl, xh, yh, zh, tx, ty, tz
    )
    return gs, gcx, gcy, gcz, targets, walk


@njit_parallel_sum
def walk_parts(
    x, y, z, charge, rod, index, rank, start, end, nxt, box, centre, radius, moment, group, order,
    near32, charge32, rod32, theta, rstar, kappa, parts, out, counts,
):  # fmt: skip
    """``kernels/treewalk.py::evaluate_groups`` in mixed precision over all tips, its stages in its
    order, with the near sum (``parts & NEAR``) and the far sum (``parts & FAR``) each taken or left
    out; ``counts[gi]`` gets group gi's near pairs and far cells (over its targets)."""
    theta2 = theta * theta
    rstar32 = np.float32(rstar)
    kappa32 = np.float32(kappa)
    for gi in prange(group.shape[0]):
        gs, gcx, gcy, gcz, targets, walk = _group_walk(
            gi, x, y, z, index, rank, start, end, nxt, box, centre, radius, moment, group, order, theta2, rstar
        )
        sel, n_w, tx, ty, tz, partner = targets
        if n_w == 0:
            continue
        ex, ey, ez, far32, n_chunks, near_start, near_end, n_near, n_near_tips = walk
        partner_near, fx, fy, fz, lx, ly, lz, fq, frod, nx, ny, nz, nq, nrod = _near_copies(
            near_start, near_end, n_near, n_near_tips, partner, True, x, y, z, charge, rod, near32, charge32, rod32
        )
        counts[gi, 0] = n_w * n_near_tips
        counts[gi, 1] = n_w * n_chunks * FAR_CHUNK
        for w in range(n_w):
            i = sel[w]
            qk = charge[i]
            bx = by = bz = np.float32(0.0)
            cx32 = cy32 = cz32 = np.float32(0.0)
            if parts & NEAR:
                bx, by, bz = _near_on_target_f32(
                    i, near32, charge32, rod32, fx, fy, fz, lx, ly, lz, fq, frod, n_near_tips, rstar32, kappa32
                )
            if parts & FAR:
                gx32 = np.float32(tx[w] - gcx)
                gy32 = np.float32(ty[w] - gcy)
                gz32 = np.float32(tz[w] - gcz)
                if order >= 4:
                    cx32, cy32, cz32 = _far32_on_target_4(far32, n_chunks, gx32, gy32, gz32)
                else:
                    cx32, cy32, cz32 = _far32_on_target_3(far32, n_chunks, gx32, gy32, gz32)
            sx = np.float64(bx) + qk * np.float64(cx32)
            sy = np.float64(by) + qk * np.float64(cy32)
            sz = np.float64(bz) + qk * np.float64(cz32)
            sx += qk * ex[w]
            sy += qk * ey[w]
            sz += qk * ez[w]
            if not partner_near[w]:  # the rod partner in an accepted cell's moments: its exact force out
                p = partner[w]
                dx = tx[w] - x[p]
                dy = ty[w] - y[p]
                dz = tz[w] - z[p]
                gp = tip_force_over_r(dx * dx + dy * dy + dz * dz, qk * charge[p], rstar, kappa)
                sx -= gp * dx
                sy -= gp * dy
                sz -= gp * dz
            k = index[i]
            out[k, 0] = sx
            out[k, 1] = sy
            out[k, 2] = sz


_ZERO32 = np.float32(0.0)


@inline_sum
def _pairs_once(i, near32, charge32, rod32, buf, j0, n, rstar32, kappa32, react):
    """The near pairs of the target at sorted position ``i`` with the copied tips ``j0..n-1``
    (``buf``: rows hi x, y, z, lo x, y, z, charge, rod as float32), the law of the near field; each
    pair's force is also taken from the other tip's row of ``react`` (its reaction). One loop from 0
    over views: a loop from ``j0`` keeps numba's negative-index check, and LLVM then does not
    vectorise the stores."""
    xk32 = near32[0, i]
    yk32 = near32[1, i]
    zk32 = near32[2, i]
    xl32 = near32[3, i]
    yl32 = near32[4, i]
    zl32 = near32[5, i]
    qk32 = charge32[i]
    rk32 = np.float32(rod32[i])
    fx, fy, fz, lx, ly, lz = buf[0, j0:n], buf[1, j0:n], buf[2, j0:n], buf[3, j0:n], buf[4, j0:n], buf[5, j0:n]
    fq, frod = buf[6, j0:n], buf[7, j0:n]
    rx, ry, rz = react[0, j0:n], react[1, j0:n], react[2, j0:n]
    bx = _ZERO32
    by = _ZERO32
    bz = _ZERO32
    for j in range(n - j0):
        ux = (xk32 - fx[j]) + (xl32 - lx[j])
        uy = (yk32 - fy[j]) + (yl32 - ly[j])
        uz = (zk32 - fz[j]) + (zl32 - lz[j])
        g32 = tip_force_over_r_f32(ux * ux + uy * uy + uz * uz, qk32 * fq[j], rstar32, kappa32)
        g32 = _ZERO32 if frod[j] == rk32 else g32
        px = g32 * ux
        py = g32 * uy
        pz = g32 * uz
        bx += px
        by += py
        bz += pz
        rx[j] -= px
        ry[j] -= py
        rz[j] -= pz
    return bx, by, bz


@njit_parallel_sum
def near_once(
    x, y, z, charge, rod, index, rank, start, end, nxt, box, centre, radius, moment, group, order,
    near32, charge32, rod32, theta, rstar, kappa, out,
):  # fmt: skip
    """A prototype, for its time only: each group's walk and near copies as
    :func:`walk_parts` makes them, then the pairs of each target with the near tips after it in
    Morton order only (about half the near pairs: the tips of the group itself after the target,
    and of the groups after it), each pair's reaction added to the other tip's row. The forces are
    not the tree's (the near sets of two groups are not each other's); ``out[t]`` holds thread t's
    sums (rows in original order), zeroed by the caller."""
    theta2 = theta * theta
    rstar32 = np.float32(rstar)
    kappa32 = np.float32(kappa)
    for gi in prange(group.shape[0]):
        t = numba.get_thread_id()
        gs, _, _, _, targets, walk = _group_walk(
            gi, x, y, z, index, rank, start, end, nxt, box, centre, radius, moment, group, order, theta2, rstar
        )
        sel, n_w = targets[0], targets[1]
        if n_w == 0:
            continue
        near_start, near_end, n_near = walk[5], walk[6], walk[7]
        m = 0
        n_after = 0
        for a in range(n_near):  # the runs from the group's first tip on
            s = max(near_start[a], gs)
            if near_end[a] > s:
                near_start[m] = s
                near_end[m] = near_end[a]
                n_after += near_end[a] - s
                m += 1
        buf = np.empty((8, n_after), np.float32)
        pos = np.empty(n_after, np.int64)
        j = 0
        for a in range(m):
            for p in range(near_start[a], near_end[a]):
                for r in range(6):
                    buf[r, j] = near32[r, p]
                buf[6, j] = charge32[p]
                buf[7, j] = np.float32(rod32[p])
                pos[j] = p
                j += 1
        react = np.zeros((3, n_after), np.float32)
        j0 = 0
        for w in range(n_w):
            i = sel[w]
            while j0 < n_after and pos[j0] <= i:
                j0 += 1
            bx, by, bz = _pairs_once(i, near32, charge32, rod32, buf, j0, n_after, rstar32, kappa32, react)
            k = index[i]
            out[t, k, 0] += bx
            out[t, k, 1] += by
            out[t, k, 2] += bz
        for j in range(n_after):
            k = index[pos[j]]
            out[t, k, 0] += react[0, j]
            out[t, k, 1] += react[1, j]
            out[t, k, 2] += react[2, j]


def run_once(tree, theta, out):
    """:func:`near_once` over the tree, ``out`` (threads, tips, 3) zeroed first."""
    out[:] = 0.0
    chunk = set_parallel_chunksize(1)
    try:
        near_once(
            tree.x, tree.y, tree.z, tree.charge, tree.rod, tree.index, tree.rank, tree.start, tree.end, tree.next,
            tree.box, tree.centre, tree.radius, tree.moment, tree.group, tree.order, tree.near32, tree.charge32,
            tree.rod32, float(theta), RSTAR, KAPPA, out,
        )  # fmt: skip
    finally:
        set_parallel_chunksize(chunk)


def run_parts(tree, theta, parts, out, counts):
    chunk = set_parallel_chunksize(1)  # one group at a time, as evaluate_tip_tree hands them out
    try:
        walk_parts(
            tree.x, tree.y, tree.z, tree.charge, tree.rod, tree.index, tree.rank, tree.start, tree.end, tree.next,
            tree.box, tree.centre, tree.radius, tree.moment, tree.group, tree.order, tree.near32, tree.charge32,
            tree.rod32, float(theta), RSTAR, KAPPA, parts, out, counts,
        )  # fmt: skip
    finally:
        set_parallel_chunksize(chunk)


@njit
def far_separation(start, end, nxt, box, centre, radius, group, theta, rstar):
    """For every (group, accepted cell) pair of the walk (the acceptance test of
    ``kernels/treewalk.py::accepts``): the ratio ``(b + r_g) / D`` (module docstring) and the group's
    number of tips, the work the cell costs there."""
    theta2 = theta * theta
    ratio = np.empty(1024)
    work = np.empty(1024, np.int64)
    n = 0
    for gi in range(group.shape[0]):
        g = group[gi]
        xl, yl, zl, xh, yh, zh = box[g, 0], box[g, 1], box[g, 2], box[g, 3], box[g, 4], box[g, 5]
        gx, gy, gz = 0.5 * (xl + xh), 0.5 * (yl + yh), 0.5 * (zl + zh)
        rg = 0.5 * math.sqrt((xh - xl) ** 2 + (yh - yl) ** 2 + (zh - zl) ** 2)
        c = 0
        while c < start.shape[0]:
            take, _ = accepts(centre, radius, c, xl, yl, zl, xh, yh, zh, theta2, rstar)
            if take:
                if n == ratio.shape[0]:
                    ratio = np.concatenate((ratio, np.empty(n)))
                    work = np.concatenate((work, np.empty(n, np.int64)))
                d = math.sqrt((centre[c, 0] - gx) ** 2 + (centre[c, 1] - gy) ** 2 + (centre[c, 2] - gz) ** 2)
                ratio[n] = (radius[c] + rg) / d
                work[n] = end[g] - start[g]
                n += 1
                c = nxt[c]
            else:
                c += 1
    return ratio[:n], work[:n]


#: the ratios ``(b + r_g) / D`` of ``--separation``'s table
SEPARATIONS = (0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 1.0)


def separation_table(args):
    """``--separation``: the share of the far work an expansion about each group's centre could take."""
    print(f"opening angle {args.theta:g}; share of the far work (cells x targets) with (b + r_g) / D below:")
    print("| config | rods | groups | far cells a target | " + " | ".join(f"< {r:g}" for r in SEPARATIONS) + " |")
    print("|---|---|---|---|" + "---|" * len(SEPARATIONS))
    make = CONFIGS
    for config in args.config:
        for n_rods in args.rods:
            t = build_tip_tree(*make[config](n_rods, np.random.default_rng(args.seed)))
            ratio, work = far_separation(t.start, t.end, t.next, t.box, t.centre, t.radius, t.group, args.theta, RSTAR)
            share = [work[ratio < r].sum() / work.sum() for r in SEPARATIONS]
            print(
                f"| {config} | {n_rods} | {t.group.shape[0]} | {work.sum() / t.x.shape[0]:.0f} | "
                + " | ".join(f"{s:.3f}" for s in share)
                + " |"
            )
    return 0


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rods", type=int, nargs="+", default=[6000, 24000])
    ap.add_argument("--config", nargs="+", default=["fig2"], choices=["uniform", "chains", "fig2"])
    ap.add_argument("--theta", type=float, default=0.55, help="opening angle (default 0.55, the tree's)")
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument(
        "--separation", action="store_true", help="no timing: how far the accepted cells are from their groups"
    )
    args = ap.parse_args(argv)
    from .peer import machine_line

    print(machine_line())
    if args.separation:
        return separation_table(args)
    print(f"numba threads: {numba.get_num_threads()}; mixed precision, opening angle {args.theta:g}")
    print(
        "| config | rods | groups | whole ms | lists | near | far | rest | near pairs / far cells a target "
        "| near, each pair once (prototype) | the whole with it: at best / prototype |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    make = CONFIGS
    for config in args.config:
        for n_rods in args.rods:
            tips = make[config](n_rods, np.random.default_rng(args.seed))
            tree = build_tip_tree(*tips)
            n = tree.x.shape[0]
            whole, mine = np.empty((n, 3)), np.empty((n, 3))
            counts = np.zeros((tree.group.shape[0], 2), np.int64)
            calls = {"whole": lambda: evaluate_tip_tree(tree, RSTAR, KAPPA, args.theta, whole, precision="mixed")}
            for name, parts in (("lists", LISTS), ("near", NEAR), ("far", FAR), ("both", NEAR | FAR)):
                calls[name] = lambda parts=parts: run_parts(tree, args.theta, parts, mine, counts)
            per_thread = np.zeros((numba.get_num_threads(), n, 3))
            calls["once"] = lambda: run_once(tree, args.theta, per_thread)
            for call in calls.values():
                call()  # compiled, caches warm
            ms = {name: np.inf for name in calls}
            for _ in range(args.reps):  # in turns, so that a slow spell of the machine hits them alike
                for name, call in calls.items():
                    t0 = time.perf_counter()
                    call()
                    ms[name] = min(ms[name], 1e3 * (time.perf_counter() - t0))
            run_parts(tree, args.theta, NEAR | FAR, mine, counts)
            same = bool(np.array_equal(whole, mine))
            near, far = ms["near"] - ms["lists"], ms["far"] - ms["lists"]
            rest = ms["whole"] - ms["lists"] - near - far
            once = ms["once"] - ms["lists"]
            pairs, cells = counts.sum(axis=0) / n
            best, proto = (ms["whole"] - near / 2) / ms["whole"], (ms["whole"] - near + once) / ms["whole"]
            print(
                f"| {config} | {n_rods} | {tree.group.shape[0]} | {ms['whole']:.2f} | {ms['lists']:.2f} | {near:.2f} | "
                f"{far:.2f} | {rest:.2f} | {pairs:.0f} / {cells:.0f} | {once:.2f} | {best:.2f} / {proto:.2f} |"
            )
            if not same:
                print(f"  note: with both sums the parts' kernel differs from the shipped one here "
                      f"(largest {np.abs(whole - mine).max():.3g}): its parts are not the shipped code's")  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
