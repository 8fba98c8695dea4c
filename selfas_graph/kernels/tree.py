"""Tip-tip magnetic force (docs/model.md 'Term 1') by a multipole tree.

Every rod is a dipole (tips +q and -q), so the net charge of a cell of tips is
near zero and a monopole-only Barnes-Hut tree is badly wrong (median relative
force error about 4 % at opening angle 0.7). Cells here carry Cartesian
multipole moments up to quadrupole, octupole or hexadecapole order about a fixed
expansion centre: the centre of the cell's tight bounding box (never the centre of
charge, which is undefined for a neutral cell).

Build (O(N log N)):

1. Morton keys of the tips (21 bits per axis over the cube that holds them all),
   sorted, so that every cell of the octree is a contiguous range of sorted tips.
2. Cells top-down with an explicit stack, in depth-first preorder: a range of
   keys splits at the first 3-bit digit in which its first and last key
   differ (cells with one child are skipped, so every inner cell has at least
   two children and there are fewer than ``2 n_tips`` cells). A range stops
   splitting when it holds at most ``leaf_size`` tips or when all its keys are
   equal (coincident tips, or tips closer than the key resolution: the depth is
   capped at 21 levels and such a leaf may exceed ``leaf_size``). Each cell
   stores ``next``, the index after its subtree, so that a walk needs no stack.
3. Per cell (parallel over cells): the tight bounding box, its centre ``c``,
   the radius ``b = max |x_l - c|`` and the moments, summed directly from the
   cell's tips: O(N depth) work, no shift of moments between levels and so no
   round-off from it.

Moments of a cell, with ``s = x_l - c`` (all traceless, so that only
independent components are stored)::

    M = sum q,  P_i = sum q s_i,  Q_ij = sum q (3 s_i s_j - s^2 d_ij),
    O_ijk = sum q (15 s_i s_j s_k - 3 s^2 (s_i d_jk + s_j d_ik + s_k d_ij)),
    H_ijkl = sum q (105 s_i s_j s_k s_l - 15 s^2 (d_ij s_k s_l + 5 more pairings)
                    + 3 s^4 (d_ij d_kl + d_ik d_jl + d_il d_jk))

(the moment of order n is ``(2n - 1)!!`` times the traceless part of ``sum q s^n``)
and the field ``E = -grad phi`` of ``phi = sum q / |r - x_l|`` at ``d = r - c``
(R = |d|), from the expansion of 1/|d - s| in Cartesian derivatives of 1/R::

    phi = M / R + P.d / R^3 + (dQd) / (2 R^5) + O(ddd) / (6 R^7) + H(dddd) / (24 R^9)
    E   = d (M / R^3 + 3 P.d / R^5 + 5 dQd / (2 R^7) + 7 O(ddd) / (6 R^9) + 3 H(dddd) / (8 R^11))
          - P / R^3 - Q.d / R^5 - O(dd.) / (2 R^7) - H(ddd.) / (6 R^9)

The force on tip k is ``q_k E`` (Coulomb law of term 1 outside r*). Leaving out
the moments above order p leaves a field error falling as ``1/R^(p+3)``, a
relative error of about ``(b/R)^(p+1)`` (tests/physics/test_tree.py
``test_multipole_field_falls_with_its_order``).

Evaluation walks the tree once per *group* of targets (a cell with at most
``group_size`` tips) rather than once per tip: a source cell is accepted for
the whole group when, with ``d_min`` the distance from its centre to the
group's bounding box, ``b < theta d_min`` (Barnes-Hut opening angle measured
with the cell radius) and ``d_min > b + r*``: then no source tip of the cell is
within r* of any target, so every pair inside the soft core is summed exactly
with :func:`tip_force_over_r`. Leaves that are not accepted are summed exactly
with the same law, skipping the target's own rod: their tips (runs of sorted tips,
next leaves merged) are copied into one contiguous buffer per group and each
target runs one long branch-free reduction over it, like the direct sum. In float64
each accepted cell is applied to the group's targets in one loop over them
(vectorised across targets, padded to a multiple of ``PAD``; the cell's moments are
read once). When the target's rod partner lies in an accepted cell, its exact pair
force is subtracted (the multipole included it). ``theta = 0`` accepts no cell and
gives the direct sum.

With ``precision="mixed"`` (:func:`evaluate_tip_tree`) the near pairs are summed in
float32 (coordinates held by the tree as float32 pairs hi + lo relative to the root
cell's centre, the law of :func:`.laws.tip_force_over_r_f32`, one float32 sum per
target), and each accepted cell is recorded once per group in float32 (its offset
from the group's box centre, and its moments, in units of its distance from the
box, :data:`.treewalk.FAR_ROWS` numbers); each target then sums the recorded cells in one
loop over them, vectorised across cells, in float32 (:func:`.multipole.make_fields`,
float32 variant), like the near pairs. Both float32 sums are added
in float64. The float64 path is unchanged by it, bit for bit.

The defaults (hexadecapoles, leaves of at most 64 tips, groups of at most 1024,
theta 0.55; ``GROUP_SIZE`` and ``THETA`` below) err as little as groups of 128 at
theta 0.475 but for a uniform gas of 10^5 rods (7.9e-4 against 7.4e-4; median 2e-4 to
9.6e-4 in a uniform rod gas and the Fig. 2 slab of 3000 to 10^5 rods) and evaluate
1.05 to 2.2 times faster (docs/performance.md 'Tip-tip
force by a multipole tree', selfas_graph/bench/tree.py). On one AVX2 core of a
Zen 4 (mixed), at groups of 128 and theta 0.475, a near pair cost about 0.67 ns and
an accepted cell about 4 ns per target; at 24 000 rods of the Fig. 2 slab a target
saw about 1650 near tips and 160 cells, the near pairs about 55 % of the evaluation,
the far field 35 %.

Limits: coordinates must be finite (the front end raises on NaN or inf);
tips closer than the key resolution ``extent / 2**21`` share a leaf of any
size (correct, but a dense lump in a huge box is summed directly); theta must
be below 1.

Parallel over groups, one group at a time per thread; a group writes only the
rows of its own tips (gather). Only the targets in the asked row range are
computed, and a target's force depends only on the tree, not on which rows are
asked for, so row ranges evaluated separately equal one evaluation bitwise.
:func:`evaluate_tip_tree` takes either a range of tip numbers (which are in no
spatial order: every group holding one of them walks the tree) or a range of groups
(``groups=(g0, g1)``: the tips of those groups, contiguous in Morton order, each
group walked once), which is how MPI ranks share the walks out.

The code is in stages, each in a module of its own: :mod:`.treebuild` (Morton keys, their sort,
the cells, and the upward pass: boxes, centres, radii and moments), :mod:`.treewalk` (per target
group: the interaction lists of the walk, the far field, the near field) and :mod:`.multipole`
(the field of a cell's moments, one definition for float64 and float32); this module holds the
tree's arrays (:class:`TipTree`) and the front end that checks inputs and calls the stages.
"""

from typing import NamedTuple

import numpy as np

from ._jit import set_parallel_chunksize
from .treebuild import N_MOMENT, argsort_keys, build_cells, cell_moments, morton_keys, split_hi_lo, target_groups
from .treeenergy import tree_energy_groups
from .treewalk import evaluate_groups

# Defaults from selfas_graph/bench/tree.py (docs/performance.md 'Tip-tip force by a multipole
# tree'): hexadecapoles, and groups of up to 1024 tips at opening angle 0.55, 1.05 to 2.2 times faster
# than groups of 128 at 0.475 with a median relative error as small or smaller but in a gas of 10^5
# rods (7.9e-4 against 7.4e-4; 2e-4 to 9.6e-4 in a
# uniform rod gas and the Fig. 2 slab of 3000 to 10^5 rods; in aggregates the contact
# forces dominate and the relative error is 30 to 100 times smaller). A cell is accepted for a whole group
# by its distance from the group's box, so the tips of a larger group sit farther from the cells
# they take as multipoles: a larger opening angle for the same error, and one walk for more tips.
LEAF_SIZE = 64
GROUP_SIZE = 1024
ORDER = 4
THETA = 0.55
#: precisions of the evaluation (:func:`evaluate_tip_tree`)
PRECISIONS = ("float64", "mixed")


class TipTree(NamedTuple):
    """An octree over tips with multipole moments; arrays only, built by :func:`build_tip_tree`.

    ``index[i]`` is the original number of the i-th tip in Morton order and
    ``rank`` its inverse; ``x, y, z, charge, rod`` are the tips in Morton order.
    Cell ``c`` holds sorted tips ``start[c]:end[c]``; its subtree ends before cell
    ``next[c]`` (so it is a leaf when ``next[c] == c + 1``). ``box`` is
    ``(n_cells, 6)``: low x, y, z then high x, y, z of the tight bounding box;
    ``centre`` ``(n_cells, 3)`` the expansion centre, ``radius`` ``(n_cells,)``
    the largest distance of a tip from it, ``moment`` ``(n_cells, 16)`` as in
    the module docstring (zero columns above ``order``). ``group``
    lists the cells whose tips are evaluated together. For the mixed-precision near
    field, ``near32`` (6, n_tips) float32 holds each coordinate relative to the root
    cell's centre as a pair hi + lo (rows x hi, y hi, z hi, x lo, y lo, z lo; lo the
    float32 rounding of what hi misses), ``charge32`` and ``rod32`` (int32) the
    charges and rods, all in Morton order.
    """

    index: np.ndarray
    rank: np.ndarray
    x: np.ndarray
    y: np.ndarray
    z: np.ndarray
    charge: np.ndarray
    rod: np.ndarray
    start: np.ndarray
    end: np.ndarray
    next: np.ndarray
    box: np.ndarray
    centre: np.ndarray
    radius: np.ndarray
    moment: np.ndarray
    group: np.ndarray
    order: int
    near32: np.ndarray
    charge32: np.ndarray
    rod32: np.ndarray


# ------------------------------------------------------------------ front end


def _coords(x, y, z, charge):
    arrays = [np.ascontiguousarray(a, dtype=np.float64) for a in (x, y, z, charge)]
    n = arrays[0].shape[0]
    for name, a in zip(("x", "y", "z", "charge"), arrays):
        if a.ndim != 1 or a.shape[0] != n:
            raise ValueError(f"{name} must have shape (n_tips,) = ({n},), got {a.shape}")
    if n == 0 or n % 2:
        raise ValueError(f"n_tips must be even and positive (two tips per rod), got {n}")
    for name, a in zip(("x", "y", "z", "charge"), arrays):
        if not np.isfinite(a).all():
            raise ValueError(f"{name} holds NaN or inf: the tree cannot place such a tip")
    return arrays


def build_tip_tree(x, y, z, charge, leaf_size=LEAF_SIZE, group_size=GROUP_SIZE, order=ORDER):
    """Build the octree and its multipole moments over tips.

    Parameters
    ----------
    x, y, z : (n_tips,) float64
        Tip coordinates; tips ``2 i`` and ``2 i + 1`` belong to rod i.
    charge : (n_tips,) float64
        Magnetic charge of each tip.
    leaf_size : int
        A cell with at most this many tips is not split (tips closer than the key
        resolution, ``extent / 2**21``, share a leaf of any size).
    group_size : int
        Targets are walked together in cells of at most this many tips.
    order : int
        Multipole order: 2 (quadrupole), 3 (octupole) or 4 (hexadecapole).

    Raises
    ------
    ValueError
        On shapes that disagree, an odd or zero number of tips, NaN or inf input,
        or knobs out of range.

    The same as :func:`plan_tip_tree`, :func:`fill_cells` over all cells and
    :func:`finish_tip_tree`, the stages between which processes that share the work of the
    moments exchange their cells.
    """
    tree = plan_tip_tree(x, y, z, charge, leaf_size, group_size, order)
    fill_cells(tree, 0, tree.start.shape[0])
    return finish_tip_tree(tree)


def plan_tip_tree(x, y, z, charge, leaf_size=LEAF_SIZE, group_size=GROUP_SIZE, order=ORDER):
    """The octree over tips (sorted tips, cells, groups) with its cells' boxes, centres, radii and
    moments not yet computed (:func:`fill_cells`) and without its float32 copies
    (:func:`finish_tip_tree`). Arguments and errors as :func:`build_tip_tree`."""
    x, y, z, charge = _coords(x, y, z, charge)
    if order not in (2, 3, 4):
        raise ValueError(f"order must be 2, 3 or 4, got {order}")
    if leaf_size < 1 or group_size < 1:
        raise ValueError(f"leaf_size and group_size must be >= 1, got {leaf_size}, {group_size}")
    key = np.empty(x.shape[0], np.int64)
    morton_keys(x, y, z, key)
    index = argsort_keys(key)
    rank = np.empty_like(index)
    rank[index] = np.arange(index.shape[0])
    start, end, nxt = build_cells(key[index], int(leaf_size))
    n_cells = start.shape[0]
    empty32 = np.empty(0, np.float32)
    return TipTree(
        index,
        rank,
        x[index],
        y[index],
        z[index],
        charge[index],
        index // 2,
        start,
        end,
        nxt,
        np.empty((n_cells, 6)),
        np.empty((n_cells, 3)),
        np.empty(n_cells),
        np.empty((n_cells, N_MOMENT)),
        target_groups(start, end, nxt, int(group_size)),
        int(order),
        np.empty((6, 0), np.float32),
        empty32,
        np.empty(0, np.int32),
    )


def fill_cells(tree, c0, c1):
    """Compute the boxes, centres, radii and moments of cells ``c0..c1-1`` of a planned tree, in place."""
    s = slice(int(c0), int(c1))
    cell_moments(
        tree.x,
        tree.y,
        tree.z,
        tree.charge,
        tree.start[s],
        tree.end[s],
        tree.order,
        tree.box[s],
        tree.centre[s],
        tree.radius[s],
        tree.moment[s],
    )


def cell_bounds(tree, parts):
    """Cut the cells into ``parts`` runs of about equal work for :func:`fill_cells` (a cell's work goes
    with its tips): run r is cells ``bounds[r]:bounds[r + 1]``. Returns (parts + 1,) int64."""
    work = np.cumsum(tree.end - tree.start)
    want = (work[-1] * np.arange(1, parts, dtype=np.int64)) // parts
    return np.concatenate(([0], np.searchsorted(work, want, side="right"), [work.shape[0]])).astype(np.int64)


def finish_tip_tree(tree):
    """The tree with its float32 copies for the mixed precision (``near32``, ``charge32``, ``rod32``),
    once every cell is filled (the coordinates are taken relative to the root cell's centre)."""
    near32 = np.empty((6, tree.x.shape[0]), np.float32)
    split_hi_lo(tree.x, tree.y, tree.z, tree.centre[0], near32)
    return tree._replace(near32=near32, charge32=tree.charge.astype(np.float32), rod32=tree.rod.astype(np.int32))


def group_bounds(tree, parts):
    """Cut the groups into ``parts`` runs of about equal numbers of tips (for :func:`evaluate_tip_tree`'s
    ``groups``): run r is groups ``bounds[r]:bounds[r + 1]``, tips ``tips[r]:tips[r + 1]`` in Morton order.

    Returns
    -------
    bounds, tips : (parts + 1,) int64
    """
    first = tree.start[tree.group]
    n = tree.x.shape[0]
    want = (n * np.arange(parts + 1, dtype=np.int64)) // parts
    bounds = np.searchsorted(first, want, side="left").astype(np.int64)
    tips = np.append(first, n)[bounds]
    return bounds, tips


def evaluate_tip_tree(tree, rstar, kappa, theta, out, lo=0, hi=None, precision="float64", groups=None):
    """Tip-tip force (docs/model.md 'Term 1') on tips ``lo..hi-1`` from all tips, by the tree.

    Parameters
    ----------
    tree : TipTree
        From :func:`build_tip_tree` on the current positions.
    rstar, kappa : float
        Transition radius r* and core stiffness of the tip law.
    theta : float
        Opening angle in [0, 1): a cell is used as a multipole when its radius is
        below ``theta`` times its distance to the target group; 0 gives the direct
        sum. ``THETA`` (0.55) with the default knobs (hexadecapoles, groups of up to
        1024 tips) gives a median relative error of 2e-4 to 9.6e-4 in a uniform rod gas
        and in the Fig. 2 slab of 3000 to 1e5 rods, 30 to 100 times less in aggregates
        (docs/performance.md).
    out : (n_tips, 3) float64, C-contiguous
        Rows ``lo:hi`` (original tip numbers) are overwritten; others untouched.
    lo, hi : int
        Target rows; ``hi=None`` means ``n_tips``.
    groups : (g0, g1), optional
        Evaluate only the tips of groups ``g0..g1-1`` (tips ``tree.index[tree.start[tree.group[g0]]:...]``,
        a contiguous run in Morton order; :func:`group_bounds` cuts the groups into runs of equal
        size); with ``lo, hi`` at their defaults. Each group is walked once, so that runs of groups
        share the walks out, where ranges of tip numbers do not. The same forces bit for bit.
    precision : str
        ``"float64"``: every sum in float64. ``"mixed"``: the exact near pairs are summed in
        float32: coordinates relative to the root cell's centre, each as two float32 numbers
        ``hi + lo`` (``tree.near32``) so that the difference of two close tips keeps float32
        precision relative to itself; the law in float32 (:func:`.laws.tip_force_over_r_f32`);
        one float32 sum per target, added in float64; the subtraction of the rod partner stays
        float64. The far field: each accepted cell's field in float32
        (:mod:`.multipole`, the float32 variant), with the offsets and the
        moments in units of the cell's distance from the group's box (every power of ``1/R``
        then near 1), summed over the cells in float32 per target and added in float64; a cell
        whose offsets exceed ``treewalk.SPAN32`` times that distance takes the float64 loop.
        AVX2 runs 8 float32 lanes per instruction against 4 float64, and LLVM replaces the
        float32 square root and division by a reciprocal square root estimate and one Newton
        step (``vrsqrtps``): no divider in the loop. Measured (docs/performance.md,
        selfas_graph/bench/tree.py ``--precision``): the difference from float64 is about 4e-7 of a
        tip's force (median), at most 2e-4 of it in aggregates, where contact forces nearly
        cancel; the estimate differs between CPU makers, so the last float32 bits are not the
        same on every machine.

    Raises
    ------
    ValueError
        On rows out of range, theta out of [0, 1), an unknown precision or a bad ``out``.
    """
    n = tree.x.shape[0]
    hi = n if hi is None else int(hi)
    lo = int(lo)
    if not 0 <= lo <= hi <= n:
        raise ValueError(f"need 0 <= lo <= hi <= n_tips = {n}, got lo={lo}, hi={hi}")
    if not 0.0 <= theta < 1.0:
        raise ValueError(f"theta must be in [0, 1), got {theta}")
    if precision not in PRECISIONS:
        raise ValueError(f"precision must be one of {', '.join(map(repr, PRECISIONS))}, got {precision!r}")
    if out.shape != (n, 3) or out.dtype != np.float64 or not out.flags.c_contiguous:
        raise ValueError(f"out must be a C-contiguous float64 array of shape ({n}, 3)")
    n_groups = tree.group.shape[0]
    g_lo, g_hi = (0, n_groups) if groups is None else (int(groups[0]), int(groups[1]))
    if not 0 <= g_lo <= g_hi <= n_groups:
        raise ValueError(f"need 0 <= g0 <= g1 <= {n_groups} groups, got {groups}")
    if lo == hi or g_lo == g_hi:
        return out
    # groups differ in cost (dense clusters, the edge of the system): threads take
    # one group at a time. Measured on 2 threads: 428 against 469 ms for 1e5 uniform
    # rods, 192 against 227 ms for three clusters of chains with numba's static
    # blocks. Set here, not in the kernel, which could then not be cached. The groups
    # go in tree (Morton) order: largest first, tried at t = 100 of Fig. 6 (44 groups of
    # 5-549 tips, Zen 4, 2 threads), took 10.7 against 7.0 ms, a random order 7.6.
    chunk = set_parallel_chunksize(1)
    try:
        evaluate_groups(
            tree.x,
            tree.y,
            tree.z,
            tree.charge,
            tree.rod,
            tree.index,
            tree.rank,
            tree.start,
            tree.end,
            tree.next,
            tree.box,
            tree.centre,
            tree.radius,
            tree.moment,
            tree.group,
            tree.order,
            tree.near32,
            tree.charge32,
            tree.rod32,
            float(theta),
            float(rstar),
            float(kappa),
            lo,
            hi,
            g_lo,
            g_hi,
            precision == "mixed",
            out,
        )
    finally:
        set_parallel_chunksize(chunk)
    return out


def tip_tip_tree(
    x,
    y,
    z,
    charge,
    rstar,
    kappa,
    theta,
    out,
    lo=0,
    hi=None,
    leaf_size=LEAF_SIZE,
    group_size=GROUP_SIZE,
    order=ORDER,
    precision="float64",
):
    """Tip-tip force on tips ``lo..hi-1`` by a multipole tree: build, then evaluate.

    Same arguments and result as :func:`selfas_graph.kernels.tips.tip_tip_direct`
    (``x, y, z, charge`` of shape (n_tips,), ``out`` of shape (n_tips, 3)), up to the
    tree's truncation error, plus the opening angle ``theta`` (see
    :func:`evaluate_tip_tree`), the row range, the knobs of :func:`build_tip_tree` and the
    ``precision`` of the near field (:func:`evaluate_tip_tree`). Returns ``out``.
    """
    tree = build_tip_tree(x, y, z, charge, leaf_size, group_size, order)
    return evaluate_tip_tree(tree, rstar, kappa, theta, out, lo, hi, precision)


def tip_tree_energy(tree, rstar, kappa, theta, out, groups=None):
    """Tip-tip potential energy by rows (docs/model.md 'Term 1'), by the tree: ``out[k]`` is half the
    energy of tip k with the tips of all other rods (:mod:`.treeenergy`), so that ``out.sum()`` is
    the energy, up to the tree's truncation error (exact at ``theta = 0``).

    Parameters
    ----------
    tree : TipTree
        From :func:`build_tip_tree` on the positions of the frame.
    rstar, kappa, theta : float
        As for :func:`evaluate_tip_tree`.
    out : (n_tips,) float64, C-contiguous
        The rows of the evaluated groups' tips are overwritten (original tip numbers); others untouched.
    groups : (g0, g1), optional
        Only the tips of groups ``g0..g1-1`` (:func:`group_bounds`); default all.

    Raises
    ------
    ValueError
        On theta out of [0, 1), a bad ``out`` or groups out of range.
    """
    n = tree.x.shape[0]
    if not 0.0 <= theta < 1.0:
        raise ValueError(f"theta must be in [0, 1), got {theta}")
    if out.shape != (n,) or out.dtype != np.float64 or not out.flags.c_contiguous:
        raise ValueError(f"out must be a C-contiguous float64 array of shape ({n},)")
    n_groups = tree.group.shape[0]
    g_lo, g_hi = (0, n_groups) if groups is None else (int(groups[0]), int(groups[1]))
    if not 0 <= g_lo <= g_hi <= n_groups:
        raise ValueError(f"need 0 <= g0 <= g1 <= {n_groups} groups, got {groups}")
    if g_lo == g_hi:
        return out
    chunk = set_parallel_chunksize(1)  # groups differ in cost: one at a time (evaluate_tip_tree)
    try:
        tree_energy_groups(
            tree.x, tree.y, tree.z, tree.charge, tree.rod, tree.index, tree.rank, tree.start, tree.end, tree.next,
            tree.box, tree.centre, tree.radius, tree.moment, tree.group, float(theta), float(rstar), float(kappa),
            g_lo, g_hi, out,
        )  # fmt: skip
    finally:
        set_parallel_chunksize(chunk)
    return out
