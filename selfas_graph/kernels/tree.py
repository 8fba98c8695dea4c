"""Tip-tip magnetic force (docs/model.md 'Term 1') by a multipole tree.

Every rod is a dipole (tips +q and -q), so the net charge of a cell of tips is
near zero and a monopole-only Barnes-Hut tree is badly wrong (median relative
force error about 4 % at opening angle 0.7). Cells here carry Cartesian
multipole moments up to quadrupole or octupole order about a fixed expansion
centre: the centre of the cell's tight bounding box (never the centre of
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
    O_ijk = sum q (15 s_i s_j s_k - 3 s^2 (s_i d_jk + s_j d_ik + s_k d_ij))

and the field ``E = -grad phi`` of ``phi = sum q / |r - x_l|`` at ``d = r - c``
(R = |d|), from the expansion of 1/|d - s| in Cartesian derivatives of 1/R::

    phi = M / R + P.d / R^3 + (dQd) / (2 R^5) + O(ddd) / (6 R^7)
    E   = d (M / R^3 + 3 P.d / R^5 + 5 dQd / (2 R^7) + 7 O(ddd) / (6 R^9))
          - P / R^3 - Q.d / R^5 - O(dd.) / (2 R^7)

The force on tip k is ``q_k E`` (Coulomb law of term 1 outside r*).

Evaluation walks the tree once per *group* of targets (a cell with at most
``group_size`` tips) rather than once per tip: a source cell is accepted for
the whole group when, with ``d_min`` the distance from its centre to the
group's bounding box, ``b < theta d_min`` (Barnes-Hut opening angle measured
with the cell radius) and ``d_min > b + r*``: then no source tip of the cell is
within r* of any target, so every pair inside the soft core is summed exactly
with :func:`tip_force_over_r`. Leaves that are not accepted are summed exactly
with the same law, skipping the target's own rod: their tips are copied into
one contiguous buffer per group and each target runs one long branch-free
reduction over it, like the direct sum. Each accepted cell is applied to the
group's targets in one loop over them (vectorised across targets, padded to a
multiple of ``PAD``; the cell's moments are read once). When the target's rod partner lies
in an accepted cell, its exact pair force is subtracted (the multipole included
it). ``theta = 0`` accepts no cell and gives the direct sum.

With ``precision="mixed"`` (:func:`evaluate_tip_tree`) the near pairs are summed in
float32 (coordinates relative to the group's box centre, the law of
:func:`.laws.tip_force_over_r_f32`, one float32 sum per target), and each accepted
cell's field is taken in float32 (:func:`_field_octupole_f32`, offsets and moments in
units of the cell's distance from the group's box) and added in float64 to the sum
over cells. The float64 path is unchanged by it, bit for bit.

Measured on one core of an AVX-512 machine, the accepted-cell loop costs
about 2 ns per cell and target with octupoles, the near loop about 0.6 ns per
tip pair, as the direct sum (about 1.7 ns on an AVX2 Zen 3 core, bound by the
square root and division of each pair); at the defaults and 1e5 rods the near
part is the larger (3100 near tips against 460 accepted cells per target; at
6000 rods in the Fig. 2 scene 1980 against 150, about 80 % of the evaluation). Accuracy and
speed against the direct sum: tools/bench_tree.py, docs/performance.md.

Limits: coordinates must be finite (the front end raises on NaN or inf);
tips closer than the key resolution ``extent / 2**21`` share a leaf of any
size (correct, but a dense lump in a huge box is summed directly); theta must
be below 1.

Parallel over groups, one group at a time per thread; a group writes only the
rows of its own tips (gather). Only the targets in the asked row range are
computed (half the rows cost 0.55 of all rows at 1e5 rods: the walks are not
shared out), and a target's force depends only on the tree, not on which rows
are asked for, so row ranges evaluated separately equal one evaluation bitwise.
Rows are tip numbers, which are in no spatial order: a caller that splits rows
over MPI ranks gets every group walked on every rank (a split in Morton order,
``TipTree.index``, would share the walks out too; the kernel takes tip numbers).
"""

import math
from typing import NamedTuple

import numpy as np

from ._jit import inline_sum, njit, njit_parallel, njit_parallel_sum, prange, set_parallel_chunksize
from .laws import tip_force_over_r, tip_force_over_r_f32

#: bits of the Morton key per axis; also the depth cap of the tree
KEY_BITS = 21
#: stored moments per cell: M, P (3), Q (5 independent), O (7 independent)
N_MOMENT = 16

# Defaults from tools/bench_tree.py (docs/performance.md): the fastest setting
# with median relative error <= 1e-3 in a uniform rod gas at 1e4 and 1e5 rods,
# the hardest of the measured configurations (in aggregates the contact forces
# dominate and the relative error is 30 times smaller). Octupoles reach that
# error 1.2 (1e4 rods) to 2 (1e5) times faster than quadrupoles.
LEAF_SIZE = 64
GROUP_SIZE = 128
ORDER = 3
THETA = 0.4
#: far-field targets are padded to a multiple of this (one AVX-512 vector of
#: doubles, two AVX2 vectors: whole vectors on both); measured at 1e5 rods on an
#: AVX-512 machine: 1.13 to 1.28 times faster than no padding, padding to 16 or 32
#: gained less (1.08) or lost (0.88)
PAD = 8
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
    the module docstring (zero octupole columns when ``order == 2``). ``group``
    lists the cells whose tips are evaluated together.
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


# ---------------------------------------------------------------- build kernels


@njit
def _spread_bits(v):
    """Put bit i of a 21-bit integer at bit 3 i (the usual Morton magic numbers)."""
    v &= 0x1FFFFF
    v = (v | (v << 32)) & 0x1F00000000FFFF
    v = (v | (v << 16)) & 0x1F0000FF0000FF
    v = (v | (v << 8)) & 0x100F00F00F00F00F
    v = (v | (v << 4)) & 0x10C30C30C30C30C3
    v = (v | (v << 2)) & 0x1249249249249249
    return v


@njit_parallel
def morton_keys(x, y, z, out):
    """63-bit Morton keys of points over the cube that holds them all.

    Parameters
    ----------
    x, y, z : (n,) float64
        Finite coordinates.
    out : (n,) int64
        Overwritten with the keys. The cube's side is the largest extent; an
        extent of 0 or inf gives all keys 0 (one leaf: the direct sum).
    """
    n = x.shape[0]
    x0, y0, z0 = x.min(), y.min(), z.min()
    extent = max(x.max() - x0, y.max() - y0, z.max() - z0)
    top = float((1 << KEY_BITS) - 1)
    scale = (1 << KEY_BITS) / extent if 0.0 < extent < np.inf else 0.0
    if not scale < np.inf:  # a subnormal extent
        scale = 0.0
    for i in prange(n):
        ix = int(min(max((x[i] - x0) * scale, 0.0), top))
        iy = int(min(max((y[i] - y0) * scale, 0.0), top))
        iz = int(min(max((z[i] - z0) * scale, 0.0), top))
        out[i] = (_spread_bits(ix) << 2) | (_spread_bits(iy) << 1) | _spread_bits(iz)


@njit
def _first_with_digit(key, lo, hi, shift, digit):
    """First i in [lo, hi) with ``(key[i] >> shift) & 7 >= digit`` (keys sorted, common prefix)."""
    while lo < hi:
        mid = (lo + hi) // 2
        if ((key[mid] >> shift) & 7) >= digit:
            hi = mid
        else:
            lo = mid + 1
    return lo


@njit
def build_cells(key, leaf_size):
    """Octree cells over sorted Morton keys, in depth-first preorder.

    Parameters
    ----------
    key : (n,) int64
        Sorted keys, n >= 1.
    leaf_size : int
        A range of at most this many tips is a leaf.

    Returns
    -------
    start, end, next : (n_cells,) int64
        Tip range of each cell and the index of the cell after its subtree.
    """
    n = key.shape[0]
    cap = 2 * n + 1  # every inner cell has >= 2 children, so fewer than 2 n cells
    start = np.empty(cap, np.int64)
    end = np.empty(cap, np.int64)
    parent = np.empty(cap, np.int64)
    # depth-first stack: each split pushes at most 8 ranges and pops one, and
    # there are at most KEY_BITS splits on any path
    stack = np.empty((8 * KEY_BITS + 8, 3), np.int64)
    stack[0, 0] = 0
    stack[0, 1] = n
    stack[0, 2] = -1
    sp = 1
    nc = 0
    bounds = np.empty(9, np.int64)
    while sp > 0:
        sp -= 1
        s = stack[sp, 0]
        e = stack[sp, 1]
        c = nc
        nc += 1
        start[c] = s
        end[c] = e
        parent[c] = stack[sp, 2]
        diff = key[s] ^ key[e - 1]
        if e - s <= leaf_size or diff == 0:
            continue
        top = 0
        while (diff >> (top + 1)) != 0:
            top += 1
        shift = (top // 3) * 3
        bounds[0] = s
        bounds[8] = e
        for digit in range(1, 8):
            bounds[digit] = _first_with_digit(key, bounds[digit - 1], e, shift, digit)
        for digit in range(7, -1, -1):  # reversed, so the first child is popped first
            if bounds[digit + 1] > bounds[digit]:
                stack[sp, 0] = bounds[digit]
                stack[sp, 1] = bounds[digit + 1]
                stack[sp, 2] = c
                sp += 1
    size = np.ones(nc, np.int64)
    for c in range(nc - 1, 0, -1):  # children come after their parent in preorder
        size[parent[c]] += size[c]
    nxt = np.arange(nc) + size
    return start[:nc].copy(), end[:nc].copy(), nxt


@njit_parallel
def cell_moments(x, y, z, charge, start, end, order, box, centre, radius, moment):
    """Bounding box, expansion centre, radius and multipole moments of every cell.

    Parameters
    ----------
    x, y, z, charge : (n_tips,) float64
        Tips in Morton order.
    start, end : (n_cells,) int64
        Tip range of each cell.
    order : int
        2 (quadrupole) or 3 (octupole); octupole columns are zero for 2.
    box : (n_cells, 6) float64
    centre : (n_cells, 3) float64
    radius : (n_cells,) float64
    moment : (n_cells, 16) float64
        Overwritten (layout in :class:`TipTree`).
    """
    for c in prange(start.shape[0]):
        s = start[c]
        e = end[c]
        xl = xh = x[s]
        yl = yh = y[s]
        zl = zh = z[s]
        for i in range(s + 1, e):
            xl = min(xl, x[i])
            xh = max(xh, x[i])
            yl = min(yl, y[i])
            yh = max(yh, y[i])
            zl = min(zl, z[i])
            zh = max(zh, z[i])
        box[c, 0] = xl
        box[c, 1] = yl
        box[c, 2] = zl
        box[c, 3] = xh
        box[c, 4] = yh
        box[c, 5] = zh
        cx = 0.5 * (xl + xh)
        cy = 0.5 * (yl + yh)
        cz = 0.5 * (zl + zh)
        centre[c, 0] = cx
        centre[c, 1] = cy
        centre[c, 2] = cz
        b2 = 0.0
        m = px = py = pz = 0.0
        qxx = qxy = qxz = qyy = qyz = 0.0
        oxxx = oxxy = oxxz = oxyy = oxyz = oyyy = oyyz = 0.0
        for i in range(s, e):
            sx = x[i] - cx
            sy = y[i] - cy
            sz = z[i] - cz
            q = charge[i]
            s2 = sx * sx + sy * sy + sz * sz
            b2 = max(b2, s2)
            m += q
            px += q * sx
            py += q * sy
            pz += q * sz
            qxx += q * (3.0 * sx * sx - s2)
            qxy += q * 3.0 * sx * sy
            qxz += q * 3.0 * sx * sz
            qyy += q * (3.0 * sy * sy - s2)
            qyz += q * 3.0 * sy * sz
            if order >= 3:
                t = 3.0 * q * s2
                oxxx += q * 15.0 * sx * sx * sx - 3.0 * t * sx
                oxxy += q * 15.0 * sx * sx * sy - t * sy
                oxxz += q * 15.0 * sx * sx * sz - t * sz
                oxyy += q * 15.0 * sx * sy * sy - t * sx
                oxyz += q * 15.0 * sx * sy * sz
                oyyy += q * 15.0 * sy * sy * sy - 3.0 * t * sy
                oyyz += q * 15.0 * sy * sy * sz - t * sz
        radius[c] = math.sqrt(b2)
        mc = moment[c]
        mc[0] = m
        mc[1] = px
        mc[2] = py
        mc[3] = pz
        mc[4] = qxx
        mc[5] = qxy
        mc[6] = qxz
        mc[7] = qyy
        mc[8] = qyz
        mc[9] = oxxx
        mc[10] = oxxy
        mc[11] = oxxz
        mc[12] = oxyy
        mc[13] = oxyz
        mc[14] = oyyy
        mc[15] = oyyz


@njit
def target_groups(start, end, nxt, group_size):
    """Cells evaluated together: the largest cells with at most ``group_size`` tips, or leaves."""
    n_cells = start.shape[0]
    group = np.empty(n_cells, np.int64)
    ng = 0
    c = 0
    while c < n_cells:
        if end[c] - start[c] <= group_size or nxt[c] == c + 1:
            group[ng] = c
            ng += 1
            c = nxt[c]
        else:
            c += 1
    return group[:ng].copy()


# ----------------------------------------------------------- evaluation kernels


@inline_sum
def _field_quadrupole(dx, dy, dz, m, px, py, pz, qxx, qxy, qxz, qyy, qyz):
    """Field of a cell's moments up to quadrupole at offset d from its centre (module docstring)."""
    ir = 1.0 / math.sqrt(dx * dx + dy * dy + dz * dz)
    ir2 = ir * ir
    ir3 = ir * ir2
    ir5 = ir3 * ir2
    ir7 = ir5 * ir2
    ux = qxx * dx + qxy * dy + qxz * dz
    uy = qxy * dx + qyy * dy + qyz * dz
    uz = qxz * dx + qyz * dy - (qxx + qyy) * dz
    pd = px * dx + py * dy + pz * dz
    dqd = dx * ux + dy * uy + dz * uz
    radial = m * ir3 + 3.0 * pd * ir5 + 2.5 * dqd * ir7
    return (radial * dx - px * ir3 - ux * ir5, radial * dy - py * ir3 - uy * ir5, radial * dz - pz * ir3 - uz * ir5)


@inline_sum
def _field_octupole(dx, dy, dz, m, px, py, pz, qxx, qxy, qxz, qyy, qyz, oxxx, oxxy, oxxz, oxyy, oxyz, oyyy, oyyz):
    """Field of a cell's moments up to octupole at offset d from its centre (module docstring)."""
    ir = 1.0 / math.sqrt(dx * dx + dy * dy + dz * dz)
    ir2 = ir * ir
    ir3 = ir * ir2
    ir5 = ir3 * ir2
    ir7 = ir5 * ir2
    ir9 = ir7 * ir2
    ux = qxx * dx + qxy * dy + qxz * dz
    uy = qxy * dx + qyy * dy + qyz * dz
    uz = qxz * dx + qyz * dy - (qxx + qyy) * dz
    pd = px * dx + py * dy + pz * dz
    dqd = dx * ux + dy * uy + dz * uz
    oxzz = -(oxxx + oxyy)
    oyzz = -(oxxy + oyyy)
    ozzz = -(oxxz + oyyz)
    xx = dx * dx
    yy = dy * dy
    zz = dz * dz
    xy = 2.0 * dx * dy
    xz = 2.0 * dx * dz
    yz = 2.0 * dy * dz
    vx = oxxx * xx + oxyy * yy + oxzz * zz + oxxy * xy + oxxz * xz + oxyz * yz
    vy = oxxy * xx + oyyy * yy + oyzz * zz + oxyy * xy + oxyz * xz + oyyz * yz
    vz = oxxz * xx + oyyz * yy + ozzz * zz + oxyz * xy + oxzz * xz + oyzz * yz
    dvd = dx * vx + dy * vy + dz * vz
    radial = m * ir3 + 3.0 * pd * ir5 + 2.5 * dqd * ir7 + (7.0 / 6.0) * dvd * ir9
    return (
        radial * dx - px * ir3 - ux * ir5 - 0.5 * vx * ir7,
        radial * dy - py * ir3 - uy * ir5 - 0.5 * vy * ir7,
        radial * dz - pz * ir3 - uz * ir5 - 0.5 * vz * ir7,
    )


#: float32 constants of :func:`_field_octupole_f32` (a float64 literal would promote it to float64)
_F32_HALF = np.float32(0.5)
_F32_ONE = np.float32(1.0)
_F32_TWO = np.float32(2.0)
_F32_THREE = np.float32(3.0)
_F32_FIVE_HALVES = np.float32(2.5)
_F32_SEVEN_SIXTHS = np.float32(7.0 / 6.0)
#: the far field of a cell is taken in float32 (``precision="mixed"``) only while the offsets
#: from the group's box centre, in units of the cell's distance s from the box, stay below this
#: (and below 1e30 in absolute value, far inside the float32 range):
#: the float32 offset of a target from the cell centre is then off by at most about
#: ``6e-8 * SPAN32`` = 6e-5 of its length (a cell of radius b contributes a truncation error of
#: up to ``theta^4``, 0.026 at theta 0.4, of its own field). Cells beyond it (a target group
#: much larger than its distance to the cell, or offsets beyond the float32 range) take the
#: float64 loop.
SPAN32 = 1000.0


@inline_sum
def _field_octupole_f32(dx, dy, dz, m, px, py, pz, qxx, qxy, qxz, qyy, qyz, oxxx, oxxy, oxxz, oxyy, oxyz, oyyy, oyyz):
    """:func:`_field_octupole` in float32: every argument float32, every constant float32.

    Called with the offset and the moments in units of the cell's distance (the module
    docstring's formulas hold in any unit of length), so that every power of ``1/R`` stays
    near 1 and far from the float32 range. With ``arcp`` LLVM takes ``1/sqrt`` as a reciprocal
    square root estimate and one Newton step: no divider in the loop.
    """
    ir = _F32_ONE / math.sqrt(dx * dx + dy * dy + dz * dz)
    ir2 = ir * ir
    ir3 = ir * ir2
    ir5 = ir3 * ir2
    ir7 = ir5 * ir2
    ir9 = ir7 * ir2
    ux = qxx * dx + qxy * dy + qxz * dz
    uy = qxy * dx + qyy * dy + qyz * dz
    uz = qxz * dx + qyz * dy - (qxx + qyy) * dz
    pd = px * dx + py * dy + pz * dz
    dqd = dx * ux + dy * uy + dz * uz
    oxzz = -(oxxx + oxyy)
    oyzz = -(oxxy + oyyy)
    ozzz = -(oxxz + oyyz)
    xx = dx * dx
    yy = dy * dy
    zz = dz * dz
    xy = _F32_TWO * dx * dy
    xz = _F32_TWO * dx * dz
    yz = _F32_TWO * dy * dz
    vx = oxxx * xx + oxyy * yy + oxzz * zz + oxxy * xy + oxxz * xz + oxyz * yz
    vy = oxxy * xx + oyyy * yy + oyzz * zz + oxyy * xy + oxyz * xz + oyyz * yz
    vz = oxxz * xx + oyyz * yy + ozzz * zz + oxyz * xy + oxzz * xz + oyzz * yz
    dvd = dx * vx + dy * vy + dz * vz
    radial = m * ir3 + _F32_THREE * pd * ir5 + _F32_FIVE_HALVES * dqd * ir7 + _F32_SEVEN_SIXTHS * dvd * ir9
    return (
        radial * dx - px * ir3 - ux * ir5 - _F32_HALF * vx * ir7,
        radial * dy - py * ir3 - uy * ir5 - _F32_HALF * vy * ir7,
        radial * dz - pz * ir3 - uz * ir5 - _F32_HALF * vz * ir7,
    )


@njit
def _append(buf, n, value):
    """``buf[n] = value``, doubling the buffer when full; returns the buffer."""
    if n == buf.shape[0]:
        grown = np.empty(2 * n, buf.dtype)
        grown[:n] = buf
        buf = grown
    buf[n] = value
    return buf


@njit_parallel_sum
def evaluate_groups(
    x,
    y,
    z,
    charge,
    rod,
    index,
    rank,
    start,
    end,
    nxt,
    box,
    centre,
    radius,
    moment,
    group,
    order,
    theta,
    rstar,
    kappa,
    lo,
    hi,
    mixed,
    out,
):
    """Tip-tip force on the tips with original number in [lo, hi) by the tree.

    One walk per target group (module docstring): near leaves are summed exactly
    over a contiguous copy of their tips, accepted cells are applied to all the
    group's targets in a loop vectorised across targets.

    Parameters
    ----------
    x, y, z, charge : (n_tips,) float64
        Tips in Morton order; ``rod`` (n_tips,) int64 their rod numbers.
    index, rank : (n_tips,) int64
        Morton position -> original number and its inverse.
    start, end, nxt, box, centre, radius, moment, group :
        The tree (:class:`TipTree`).
    order : int
        2 or 3 (as the moments were built).
    theta, rstar, kappa : float
        Opening angle, transition radius r* and core stiffness.
    lo, hi : int
        Original tip numbers to evaluate; other rows of ``out`` are untouched.
    mixed : bool
        Sum the near pairs and take each accepted cell's field in float32
        (:func:`evaluate_tip_tree`); False: float64.
    out : (n_tips, 3) float64
        Rows ``lo:hi`` overwritten with the force on each tip (original order).
    """
    n_cells = start.shape[0]
    theta2 = theta * theta
    rstar32 = np.float32(rstar)
    kappa32 = np.float32(kappa)
    zero32 = np.float32(0.0)
    for gi in prange(group.shape[0]):
        g = group[gi]
        gs = start[g]
        ge = end[g]
        # the group's targets in [lo, hi), packed: the cost follows the rows asked for
        sel = np.empty(ge - gs, np.int64)
        n_w = 0
        for i in range(gs, ge):
            k = index[i]
            if k >= lo and k < hi:
                sel[n_w] = i
                n_w += 1
        if n_w == 0:
            continue
        xl = box[g, 0]
        yl = box[g, 1]
        zl = box[g, 2]
        xh = box[g, 3]
        yh = box[g, 4]
        zh = box[g, 5]
        # target coordinates padded with copies of the box centre (never on an
        # accepted cell's centre) to a whole number of vector blocks: every target
        # runs through the same vector code wherever it sits in the block, so its
        # force does not depend on which other rows are evaluated
        n_pad = -(-n_w // PAD) * PAD
        tx = np.full(n_pad, 0.5 * (xl + xh))
        ty = np.full(n_pad, 0.5 * (yl + yh))
        tz = np.full(n_pad, 0.5 * (zl + zh))
        partner = np.empty(n_w, np.int64)
        for w in range(n_w):
            i = sel[w]
            tx[w] = x[i]
            ty[w] = y[i]
            tz[w] = z[i]
            partner[w] = rank[index[i] ^ 1]
        partner_near = np.zeros(n_w, np.bool_)
        ex = np.zeros(n_pad)
        ey = np.zeros(n_pad)
        ez = np.zeros(n_pad)
        # mixed: the far field in float32, targets relative to the group's box centre
        gcx = 0.5 * (xl + xh)
        gcy = 0.5 * (yl + yh)
        gcz = 0.5 * (zl + zh)
        half = 0.5 * max(xh - xl, yh - yl, zh - zl)
        n_far32 = n_pad if mixed else 0
        tx32 = np.empty(n_far32, np.float32)
        ty32 = np.empty(n_far32, np.float32)
        tz32 = np.empty(n_far32, np.float32)
        fx32 = np.empty(n_far32, np.float32)
        fy32 = np.empty(n_far32, np.float32)
        fz32 = np.empty(n_far32, np.float32)
        for t in range(n_far32):
            tx32[t] = np.float32(tx[t] - gcx)
            ty32[t] = np.float32(ty[t] - gcy)
            tz32[t] = np.float32(tz[t] - gcz)
        near = np.empty(64, np.int64)
        n_near = 0
        n_near_tips = 0
        # one walk for the whole group (its box, not the packed targets, decides,
        # so the cells taken do not depend on lo and hi either)
        c = 0
        while c < n_cells:
            cx = centre[c, 0]
            cy = centre[c, 1]
            cz = centre[c, 2]
            wx = max(xl - cx, 0.0, cx - xh)
            wy = max(yl - cy, 0.0, cy - yh)
            wz = max(zl - cz, 0.0, cz - zh)
            d2 = wx * wx + wy * wy + wz * wz
            b = radius[c]
            if d2 * theta2 > b * b and d2 > (b + rstar) * (b + rstar):
                mc = moment[c]
                # d2 > 0 here: dist is the cell centre's distance from the group's box, which
                # every target is at least as far from
                dist = math.sqrt(d2)
                span = half + max(abs(cx - gcx), abs(cy - gcy), abs(cz - gcz))
                if mixed and span < SPAN32 * dist and span < 1e30:
                    # offsets and moments in units of dist (the field then in units of 1/dist^2):
                    # |offset| >= 1 and the moments' scale is cut by (b / dist)^order, so that the
                    # powers of 1/R stay far from the float32 range; the cell's field in float32,
                    # then added in float64 to the sum over cells
                    inv = 1.0 / dist
                    inv2 = inv * inv
                    inv3 = inv2 * inv
                    inv32 = np.float32(inv)
                    ccx = np.float32(cx - gcx)
                    ccy = np.float32(cy - gcy)
                    ccz = np.float32(cz - gcz)
                    m0 = np.float32(mc[0])
                    m1 = np.float32(mc[1] * inv)
                    m2 = np.float32(mc[2] * inv)
                    m3 = np.float32(mc[3] * inv)
                    m4 = np.float32(mc[4] * inv2)
                    m5 = np.float32(mc[5] * inv2)
                    m6 = np.float32(mc[6] * inv2)
                    m7 = np.float32(mc[7] * inv2)
                    m8 = np.float32(mc[8] * inv2)
                    m9 = np.float32(mc[9] * inv3)
                    m10 = np.float32(mc[10] * inv3)
                    m11 = np.float32(mc[11] * inv3)
                    m12 = np.float32(mc[12] * inv3)
                    m13 = np.float32(mc[13] * inv3)
                    m14 = np.float32(mc[14] * inv3)
                    m15 = np.float32(mc[15] * inv3)
                    # two loops: adding the float32 terms to float64 sums in the first kept LLVM
                    # from vectorising it well (measured slower than the float64 loop)
                    for t in range(n_pad):
                        e1, e2, e3 = _field_octupole_f32(
                            (tx32[t] - ccx) * inv32,
                            (ty32[t] - ccy) * inv32,
                            (tz32[t] - ccz) * inv32,
                            m0,
                            m1,
                            m2,
                            m3,
                            m4,
                            m5,
                            m6,
                            m7,
                            m8,
                            m9,
                            m10,
                            m11,
                            m12,
                            m13,
                            m14,
                            m15,
                        )
                        fx32[t] = e1
                        fy32[t] = e2
                        fz32[t] = e3
                    for t in range(n_pad):
                        ex[t] += np.float64(fx32[t]) * inv2
                        ey[t] += np.float64(fy32[t]) * inv2
                        ez[t] += np.float64(fz32[t]) * inv2
                elif order >= 3:
                    for t in range(n_pad):
                        e1, e2, e3 = _field_octupole(
                            tx[t] - cx,
                            ty[t] - cy,
                            tz[t] - cz,
                            mc[0],
                            mc[1],
                            mc[2],
                            mc[3],
                            mc[4],
                            mc[5],
                            mc[6],
                            mc[7],
                            mc[8],
                            mc[9],
                            mc[10],
                            mc[11],
                            mc[12],
                            mc[13],
                            mc[14],
                            mc[15],
                        )
                        ex[t] += e1
                        ey[t] += e2
                        ez[t] += e3
                else:
                    for t in range(n_pad):
                        e1, e2, e3 = _field_quadrupole(
                            tx[t] - cx,
                            ty[t] - cy,
                            tz[t] - cz,
                            mc[0],
                            mc[1],
                            mc[2],
                            mc[3],
                            mc[4],
                            mc[5],
                            mc[6],
                            mc[7],
                            mc[8],
                        )
                        ex[t] += e1
                        ey[t] += e2
                        ez[t] += e3
                c = nxt[c]
            elif nxt[c] == c + 1:
                near = _append(near, n_near, c)
                n_near += 1
                n_near_tips += end[c] - start[c]
                c += 1
            else:
                c += 1
        # near leaves: exact law, one long loop per target over a contiguous copy of
        # their tips (a reduction that vectorises like the direct sum)
        # mixed: float32 copies relative to the group's box centre (a scene far from
        # the origin loses nothing), each coordinate as a float32 pair hi + lo (lo the
        # float32 rounding of what hi misses), rods as int32 (8 lanes like the
        # coordinates); only the copies of the chosen precision are filled
        n32 = n_near_tips if mixed else 0
        n64 = 0 if mixed else n_near_tips
        fx = np.empty(n32, np.float32)
        fy = np.empty(n32, np.float32)
        fz = np.empty(n32, np.float32)
        lx = np.empty(n32, np.float32)
        ly = np.empty(n32, np.float32)
        lz = np.empty(n32, np.float32)
        fq = np.empty(n32, np.float32)
        frod = np.empty(n32, np.int32)
        nx = np.empty(n64)
        ny = np.empty(n64)
        nz = np.empty(n64)
        nq = np.empty(n64)
        nrod = np.empty(n64, np.int64)
        j = 0
        for a in range(n_near):
            s = start[near[a]]
            e = end[near[a]]
            for w in range(n_w):
                partner_near[w] |= (partner[w] >= s) & (partner[w] < e)
            if mixed:
                for i in range(s, e):
                    fx[j] = np.float32(x[i] - gcx)
                    fy[j] = np.float32(y[i] - gcy)
                    fz[j] = np.float32(z[i] - gcz)
                    lx[j] = np.float32((x[i] - gcx) - np.float64(fx[j]))
                    ly[j] = np.float32((y[i] - gcy) - np.float64(fy[j]))
                    lz[j] = np.float32((z[i] - gcz) - np.float64(fz[j]))
                    fq[j] = np.float32(charge[i])
                    frod[j] = np.int32(rod[i])
                    j += 1
            else:
                for i in range(s, e):
                    nx[j] = x[i]
                    ny[j] = y[i]
                    nz[j] = z[i]
                    nq[j] = charge[i]
                    nrod[j] = rod[i]
                    j += 1
        for w in range(n_w):
            i = sel[w]
            xk = tx[w]
            yk = ty[w]
            zk = tz[w]
            qk = charge[i]
            rk = rod[i]
            sx = 0.0
            sy = 0.0
            sz = 0.0
            if mixed:
                xk32 = np.float32(xk - gcx)
                yk32 = np.float32(yk - gcy)
                zk32 = np.float32(zk - gcz)
                xl32 = np.float32((xk - gcx) - np.float64(xk32))
                yl32 = np.float32((yk - gcy) - np.float64(yk32))
                zl32 = np.float32((zk - gcz) - np.float64(zk32))
                qk32 = np.float32(qk)
                rk32 = np.int32(rk)
                bx = zero32
                by = zero32
                bz = zero32
                for j in range(n_near_tips):
                    # names of their own: a name shared with the float64 code would be
                    # typed float64 and promote the loop
                    # hi - hi is exact for close tips (Sterbenz), so the difference
                    # keeps float32 precision relative to itself, not to |x - centre|
                    # (measured in aggregates: median error 4e-7 instead of 8e-6)
                    ux = (xk32 - fx[j]) + (xl32 - lx[j])
                    uy = (yk32 - fy[j]) + (yl32 - ly[j])
                    uz = (zk32 - fz[j]) + (zl32 - lz[j])
                    g32 = tip_force_over_r_f32(ux * ux + uy * uy + uz * uz, qk32 * fq[j], rstar32, kappa32)
                    g32 = zero32 if frod[j] == rk32 else g32
                    bx += g32 * ux
                    by += g32 * uy
                    bz += g32 * uz
                sx = np.float64(bx)
                sy = np.float64(by)
                sz = np.float64(bz)
            else:
                for j in range(n_near_tips):
                    dx = xk - nx[j]
                    dy = yk - ny[j]
                    dz = zk - nz[j]
                    gl = tip_force_over_r(dx * dx + dy * dy + dz * dz, qk * nq[j], rstar, kappa)
                    gl = 0.0 if nrod[j] == rk else gl
                    sx += gl * dx
                    sy += gl * dy
                    sz += gl * dz
            sx += qk * ex[w]
            sy += qk * ey[w]
            sz += qk * ez[w]
            if not partner_near[w]:
                # the partner's charge is in an accepted cell's moments: take its exact force out
                p = partner[w]
                dx = xk - x[p]
                dy = yk - y[p]
                dz = zk - z[p]
                gp = tip_force_over_r(dx * dx + dy * dy + dz * dz, qk * charge[p], rstar, kappa)
                sx -= gp * dx
                sy -= gp * dy
                sz -= gp * dz
            k = index[i]
            out[k, 0] = sx
            out[k, 1] = sy
            out[k, 2] = sz


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
        Multipole order: 2 (quadrupole) or 3 (octupole).

    Raises
    ------
    ValueError
        On shapes that disagree, an odd or zero number of tips, NaN or inf input,
        or knobs out of range.
    """
    x, y, z, charge = _coords(x, y, z, charge)
    if order not in (2, 3):
        raise ValueError(f"order must be 2 or 3, got {order}")
    if leaf_size < 1 or group_size < 1:
        raise ValueError(f"leaf_size and group_size must be >= 1, got {leaf_size}, {group_size}")
    key = np.empty(x.shape[0], np.int64)
    morton_keys(x, y, z, key)
    # numpy's quicksort of int64 (SIMD on x86) is deterministic and, measured at 2e5
    # tips, 3.5 ms against 20 ms for the stable sort; the order of equal keys is
    # irrelevant (they share a leaf)
    index = np.argsort(key)
    rank = np.empty_like(index)
    rank[index] = np.arange(index.shape[0])
    start, end, nxt = build_cells(key[index], int(leaf_size))
    xs, ys, zs, qs = x[index], y[index], z[index], charge[index]
    n_cells = start.shape[0]
    box = np.empty((n_cells, 6))
    centre = np.empty((n_cells, 3))
    radius = np.empty(n_cells)
    moment = np.empty((n_cells, N_MOMENT))
    cell_moments(xs, ys, zs, qs, start, end, int(order), box, centre, radius, moment)
    group = target_groups(start, end, nxt, int(group_size))
    return TipTree(
        index, rank, xs, ys, zs, qs, index // 2, start, end, nxt, box, centre, radius, moment, group, int(order)
    )


def evaluate_tip_tree(tree, rstar, kappa, theta, out, lo=0, hi=None, precision="float64"):
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
        sum. ``THETA`` (0.4) with the default knobs gives a median relative error
        of 3e-4 to 8e-4 in a uniform rod gas of 1e3 to 1e5 rods, 30 times less in
        aggregates (docs/performance.md).
    out : (n_tips, 3) float64, C-contiguous
        Rows ``lo:hi`` (original tip numbers) are overwritten; others untouched.
    lo, hi : int
        Target rows; ``hi=None`` means ``n_tips``.
    precision : str
        ``"float64"``: every sum in float64. ``"mixed"``: the exact near pairs are summed in
        float32: coordinates taken relative to the target group's box centre before the cast,
        each as two float32 numbers ``hi + lo`` so that the difference of two close tips keeps
        float32 precision relative to itself; the law in float32
        (:func:`.laws.tip_force_over_r_f32`); one float32 sum per target, then added in float64
        to the far field; the subtraction of the rod partner stays float64. The far field:
        each accepted cell's field in float32 (:func:`_field_octupole_f32`), with the offsets
        and the moments in units of the cell's distance from the group's box (every power of
        ``1/R`` then near 1), added in float64 to the sum over cells; a cell whose offsets
        exceed ``SPAN32`` times that distance keeps the float64 loop.
        AVX2 runs 8 float32 lanes per instruction against 4 float64, and LLVM replaces the
        float32 square root and division by a reciprocal square root estimate and one Newton
        step (``vrsqrtps``): no divider in the loop. Measured (docs/performance.md,
        tools/bench_tree.py ``--precision``): the difference from float64 is about 4e-7 of a
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
    if lo == hi:
        return out
    # groups differ in cost (dense clusters, the edge of the system): threads take
    # one group at a time. Measured on 2 threads: 428 against 469 ms for 1e5 uniform
    # rods, 192 against 227 ms for three clusters of chains with numba's static
    # blocks. Set here, not in the kernel, which could then not be cached.
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
            float(theta),
            float(rstar),
            float(kappa),
            lo,
            hi,
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
