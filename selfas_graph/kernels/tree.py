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
box, :data:`FAR_ROWS` numbers); each target then sums the recorded cells in one
loop over them, vectorised across cells, in float32 (:func:`_field_octupole_f32`,
:func:`_field_hexadecapole_f32`), like the near pairs. Both float32 sums are added
in float64. The float64 path is unchanged by it, bit for bit.

The defaults (hexadecapoles, leaves of at most 64 tips, groups of at most 128,
theta 0.475) reach the median error of octupoles at theta 0.4 (5e-4 to 8e-4 in a
uniform rod gas and the Fig. 2 slab of 6000 to 10^5 rods) 1.0 to 1.25 times
faster on AVX2 (docs/performance.md, selfas_graph/bench/tree.py). On one AVX2 core of a
Zen 4 (mixed) a near pair costs about 0.67 ns, an accepted cell about 4 ns per
target; at the defaults and 24 000 rods of the Fig. 2 slab a target sees about
1650 near tips and 160 cells, and the near pairs are about 55 % of the evaluation,
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
"""

import math
from typing import NamedTuple

import numpy as np

from ._jit import inline_sum, njit, njit_parallel, njit_parallel_sum, prange, set_parallel_chunksize
from .laws import tip_force_over_r, tip_force_over_r_f32

#: bits of the Morton key per axis; also the depth cap of the tree
KEY_BITS = 21
#: stored moments per cell: M, P (3), Q (5 independent), O (7 independent), H (9 independent)
N_MOMENT = 25

# Defaults from selfas_graph/bench/tree.py (docs/performance.md): the fastest setting
# with median relative error <= 1e-3 in a uniform rod gas at 1e4 and 1e5 rods,
# the hardest of the measured configurations (in aggregates the contact forces
# dominate and the relative error is 30 times smaller). Octupoles reach that
# error 1.2 (1e4 rods) to 2 (1e5) times faster than quadrupoles.
LEAF_SIZE = 64
GROUP_SIZE = 128
ORDER = 4
THETA = 0.475
#: far-field targets are padded to a multiple of this (one AVX-512 vector of
#: doubles, two AVX2 vectors: whole vectors on both); measured at 1e5 rods on an
#: AVX-512 machine: 1.13 to 1.28 times faster than no padding, padding to 16 or 32
#: gained less (1.08) or lost (0.88)
PAD = 16
#: rows of a recorded far cell in the mixed evaluation: offset of its centre from the group's box
#: centre (3), 1 / distance and its square, the moments in units of the distance
FAR_ROWS = 5 + N_MOMENT
#: recorded far cells are stored and summed in chunks of this many (a whole number of vectors on
#: every target; the last chunk padded with cells of zero moments): with a constant trip count the
#: loop addresses all rows from one pointer
FAR_CHUNK = 64
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


#: bits per digit of :func:`argsort_keys` (6 passes over 63-bit keys, counts of 2048 fit in L1)
RADIX_BITS = 11


@njit
def argsort_keys(key):
    """Stable argsort of non-negative int64 keys below 2**63 (Morton keys): ``np.argsort(key, kind="stable")``.

    Least-significant-digit radix sort, :data:`RADIX_BITS` bits a pass, all digit counts taken in
    one pass over the keys, and a pass skipped where every key has the same digit (the high bits of
    a flat scene's keys). Ties keep the order of the tips, so that the result is one permutation
    whatever the platform. Measured on a Zen 4 (numpy 2.4, whose quicksort there is not the SIMD
    one): 2.6 against 11 ms for numpy's argsort at 2e5 Morton keys, 0.6 against 2.1 ms at 48 000.
    """
    n = key.shape[0]
    passes = -(-63 // RADIX_BITS)
    size = 1 << RADIX_BITS
    mask = size - 1
    count = np.zeros((passes, size), np.int64)
    for i in range(n):
        k = key[i]
        for p in range(passes):
            count[p, (k >> (RADIX_BITS * p)) & mask] += 1
    index = np.arange(n)
    cur = key.copy()
    spare_index = np.empty(n, np.int64)
    spare_key = np.empty(n, np.int64)
    for p in range(passes):
        shift = RADIX_BITS * p
        if n == 0 or count[p, (cur[0] >> shift) & mask] == n:
            continue  # one digit for all: the pass would not move a key
        total = 0
        for d in range(size):  # exclusive prefix sums: the first place of each digit
            c = count[p, d]
            count[p, d] = total
            total += c
        for i in range(n):
            d = (cur[i] >> shift) & mask
            j = count[p, d]
            count[p, d] = j + 1
            spare_key[j] = cur[i]
            spare_index[j] = index[i]
        cur, spare_key = spare_key, cur
        index, spare_index = spare_index, index
    return index


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
        hxxxx = hxxxy = hxxxz = hxxyy = hxxyz = hxyyy = hxyyz = hyyyy = hyyyz = 0.0
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
            if order >= 4:
                u = 15.0 * q * s2
                v = 3.0 * q * s2 * s2
                xx = sx * sx
                yy = sy * sy
                hxxxx += 105.0 * q * xx * xx - 6.0 * u * xx + 3.0 * v
                hxxxy += 105.0 * q * xx * sx * sy - 3.0 * u * sx * sy
                hxxxz += 105.0 * q * xx * sx * sz - 3.0 * u * sx * sz
                hxxyy += 105.0 * q * xx * yy - u * (xx + yy) + v
                hxxyz += 105.0 * q * xx * sy * sz - u * sy * sz
                hxyyy += 105.0 * q * sx * yy * sy - 3.0 * u * sx * sy
                hxyyz += 105.0 * q * sx * yy * sz - u * sx * sz
                hyyyy += 105.0 * q * yy * yy - 6.0 * u * yy + 3.0 * v
                hyyyz += 105.0 * q * yy * sy * sz - 3.0 * u * sy * sz
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
        mc[16] = hxxxx
        mc[17] = hxxxy
        mc[18] = hxxxz
        mc[19] = hxxyy
        mc[20] = hxxyz
        mc[21] = hxyyy
        mc[22] = hxyyz
        mc[23] = hyyyy
        mc[24] = hyyyz


@njit_parallel
def split_hi_lo(x, y, z, origin, near32):
    """Coordinates relative to ``origin`` as float32 pairs hi + lo (rows of ``near32``, :class:`TipTree`).

    hi is the float32 rounding of ``x - origin``, lo the float32 rounding of the rest: together
    they hold about 48 bits, so that ``(hi_k - hi_l) + (lo_k - lo_l)`` keeps float32 precision
    relative to the distance of two tips, not to their distance from the origin.
    """
    for i in prange(x.shape[0]):
        u = x[i] - origin[0]
        v = y[i] - origin[1]
        w = z[i] - origin[2]
        near32[0, i] = np.float32(u)
        near32[1, i] = np.float32(v)
        near32[2, i] = np.float32(w)
        near32[3, i] = np.float32(u - np.float64(near32[0, i]))
        near32[4, i] = np.float32(v - np.float64(near32[1, i]))
        near32[5, i] = np.float32(w - np.float64(near32[2, i]))


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


@inline_sum
def _hexadecapole_contraction(dx, dy, dz, h0, h1, h2, h3, h4, h5, h6, h7, h8, three, six):
    """``w_i = H_ijkl d_j d_k d_l`` of a traceless hexadecapole from its 9 stored components.

    ``h0..h8`` are H_xxxx, H_xxxy, H_xxxz, H_xxyy, H_xxyz, H_xyyy, H_xyyz, H_yyyy, H_yyyz; the six
    others follow from the vanishing traces. ``three`` and ``six`` carry the precision (float32 or
    float64 constants), so that one body serves both far-field loops.
    """
    hxxzz = -(h0 + h3)
    hxyzz = -(h1 + h5)
    hxzzz = -(h2 + h6)
    hyyzz = -(h3 + h7)
    hyzzz = -(h4 + h8)
    hzzzz = -(hxxzz + hyyzz)
    xxx = dx * dx * dx
    xxy = three * dx * dx * dy
    xxz = three * dx * dx * dz
    xyy = three * dx * dy * dy
    xyz = six * dx * dy * dz
    xzz = three * dx * dz * dz
    yyy = dy * dy * dy
    yyz = three * dy * dy * dz
    yzz = three * dy * dz * dz
    zzz = dz * dz * dz
    wx = h0 * xxx + h1 * xxy + h2 * xxz + h3 * xyy + h4 * xyz + hxxzz * xzz + h5 * yyy + h6 * yyz + hxyzz * yzz
    wx += hxzzz * zzz
    wy = h1 * xxx + h3 * xxy + h4 * xxz + h5 * xyy + h6 * xyz + hxyzz * xzz + h7 * yyy + h8 * yyz + hyyzz * yzz
    wy += hyzzz * zzz
    wz = h2 * xxx + h4 * xxy + hxxzz * xxz + h6 * xyy + hxyzz * xyz + hxzzz * xzz + h8 * yyy + hyyzz * yyz
    wz += hyzzz * yzz + hzzzz * zzz
    return wx, wy, wz


@inline_sum
def _field_hexadecapole(dx, dy, dz, mc):
    """Field of a cell's moments up to hexadecapole (``mc``, the cell's row of ``moment``) at
    offset d from its centre: the octupole field plus, with ``w = H(ddd.)``,
    ``3/8 d (d.w) / R^11 - w / (6 R^9)`` (module docstring)."""
    ex, ey, ez = _field_octupole(
        dx, dy, dz, mc[0], mc[1], mc[2], mc[3], mc[4], mc[5], mc[6], mc[7], mc[8],
        mc[9], mc[10], mc[11], mc[12], mc[13], mc[14], mc[15],
    )  # fmt: skip
    wx, wy, wz = _hexadecapole_contraction(
        dx, dy, dz, mc[16], mc[17], mc[18], mc[19], mc[20], mc[21], mc[22], mc[23], mc[24], 3.0, 6.0
    )
    ir = 1.0 / math.sqrt(dx * dx + dy * dy + dz * dz)
    ir2 = ir * ir
    ir9 = ir * ir2 * ir2 * ir2 * ir2
    radial = 0.375 * (dx * wx + dy * wy + dz * wz) * ir9 * ir2
    return (
        ex + radial * dx - (1.0 / 6.0) * wx * ir9,
        ey + radial * dy - (1.0 / 6.0) * wy * ir9,
        ez + radial * dz - (1.0 / 6.0) * wz * ir9,
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


_F32_SIX = np.float32(6.0)
_F32_SIXTH = np.float32(1.0 / 6.0)
_F32_THREE_EIGHTHS = np.float32(0.375)


@inline_sum
def _field_hexadecapole_f32(
    dx, dy, dz, m, px, py, pz, qxx, qxy, qxz, qyy, qyz, oxxx, oxxy, oxxz, oxyy, oxyz, oyyy, oyyz,
    h0, h1, h2, h3, h4, h5, h6, h7, h8,
):  # fmt: skip
    """:func:`_field_hexadecapole` in float32, as :func:`_field_octupole_f32` (every argument
    float32, the offset and the moments in units of the cell's distance)."""
    ex, ey, ez = _field_octupole_f32(
        dx, dy, dz, m, px, py, pz, qxx, qxy, qxz, qyy, qyz, oxxx, oxxy, oxxz, oxyy, oxyz, oyyy, oyyz
    )  # fmt: skip
    wx, wy, wz = _hexadecapole_contraction(dx, dy, dz, h0, h1, h2, h3, h4, h5, h6, h7, h8, _F32_THREE, _F32_SIX)
    ir = _F32_ONE / math.sqrt(dx * dx + dy * dy + dz * dz)
    ir2 = ir * ir
    ir9 = ir * ir2 * ir2 * ir2 * ir2
    radial = _F32_THREE_EIGHTHS * (dx * wx + dy * wy + dz * wz) * ir9 * ir2
    return (
        ex + radial * dx - _F32_SIXTH * wx * ir9,
        ey + radial * dy - _F32_SIXTH * wy * ir9,
        ez + radial * dz - _F32_SIXTH * wz * ir9,
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
    near32,
    charge32,
    rod32,
    theta,
    rstar,
    kappa,
    lo,
    hi,
    g_lo,
    g_hi,
    mixed,
    out,
):
    """Tip-tip force on the tips with original number in [lo, hi) of groups g_lo..g_hi-1 by the tree.

    One walk per target group (module docstring): near leaves are summed exactly
    over a contiguous copy of their tips, accepted cells are applied to all the
    group's targets in a loop vectorised across targets.

    Parameters
    ----------
    x, y, z, charge : (n_tips,) float64
        Tips in Morton order; ``rod`` (n_tips,) int64 their rod numbers.
    index, rank : (n_tips,) int64
        Morton position -> original number and its inverse.
    start, end, nxt, box, centre, radius, moment, group, near32, charge32, rod32 :
        The tree (:class:`TipTree`).
    order : int
        2, 3 or 4 (as the moments were built).
    theta, rstar, kappa : float
        Opening angle, transition radius r* and core stiffness.
    lo, hi : int
        Original tip numbers to evaluate; other rows of ``out`` are untouched.
    g_lo, g_hi : int
        The groups (indices into ``group``) whose targets are evaluated.
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
    for gi in prange(g_lo, g_hi):
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
        # mixed: the far field in float32, targets relative to the group's box centre; each
        # accepted cell is recorded (a column of far32: offset, scale, moments, all float32) and
        # every target sums the recorded cells in one loop
        gcx = 0.5 * (xl + xh)
        gcy = 0.5 * (yl + yh)
        gcz = 0.5 * (zl + zh)
        half = 0.5 * max(xh - xl, yh - yl, zh - zl)
        far32 = np.empty((1 if mixed else 0, FAR_ROWS, FAR_CHUNK), np.float32)
        n_far = 0
        # near leaves as runs of consecutive sorted tips (leaves next to each other in Morton
        # order merge): near_start[a]:near_end[a]
        near_start = np.empty(64, np.int64)
        near_end = np.empty(64, np.int64)
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
                    # powers of 1/R stay far from the float32 range
                    k = n_far // FAR_CHUNK
                    f = n_far % FAR_CHUNK
                    if k == far32.shape[0]:
                        grown = np.empty((2 * k, FAR_ROWS, FAR_CHUNK), np.float32)
                        grown[:k] = far32
                        far32 = grown
                    inv = 1.0 / dist
                    inv2 = inv * inv
                    inv3 = inv2 * inv
                    inv4 = inv2 * inv2
                    far32[k, 0, f] = np.float32(cx - gcx)
                    far32[k, 1, f] = np.float32(cy - gcy)
                    far32[k, 2, f] = np.float32(cz - gcz)
                    far32[k, 3, f] = np.float32(inv)
                    far32[k, 4, f] = np.float32(inv2)
                    far32[k, 5, f] = np.float32(mc[0])
                    for r in range(1, 4):
                        far32[k, 5 + r, f] = np.float32(mc[r] * inv)
                    for r in range(4, 9):
                        far32[k, 5 + r, f] = np.float32(mc[r] * inv2)
                    for r in range(9, 16):
                        far32[k, 5 + r, f] = np.float32(mc[r] * inv3)
                    for r in range(16, N_MOMENT):
                        far32[k, 5 + r, f] = np.float32(mc[r] * inv4)
                    n_far += 1
                elif order >= 4:
                    for t in range(n_pad):
                        e1, e2, e3 = _field_hexadecapole(tx[t] - cx, ty[t] - cy, tz[t] - cz, mc)
                        ex[t] += e1
                        ey[t] += e2
                        ez[t] += e3
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
                if n_near > 0 and near_end[n_near - 1] == start[c]:
                    near_end[n_near - 1] = end[c]
                else:
                    near_start = _append(near_start, n_near, start[c])
                    near_end = _append(near_end, n_near, end[c])
                    n_near += 1
                n_near_tips += end[c] - start[c]
                c += 1
            else:
                c += 1
        # pad the last chunk of far cells with cells of zero moments at a point outside the group's
        # box (offsets of 0.5 to 1.5 in its units): each adds exactly zero
        n_chunks = -(-n_far // FAR_CHUNK)
        if mixed and n_far % FAR_CHUNK:
            k = n_far // FAR_CHUNK
            away = 2.0 * half + 1.0
            for f in range(n_far % FAR_CHUNK, FAR_CHUNK):
                far32[k, 0, f] = np.float32(away)
                far32[k, 1, f] = np.float32(0.0)
                far32[k, 2, f] = np.float32(0.0)
                far32[k, 3, f] = np.float32(1.0 / away)
                for r in range(4, FAR_ROWS):
                    far32[k, r, f] = np.float32(0.0)
        # near leaves: exact law, one long loop per target over a contiguous copy of
        # their tips (a reduction that vectorises like the direct sum); mixed: copies of the
        # tree's float32 hi + lo coordinates (relative to the root cell's centre), charges and
        # int32 rods (8 lanes like the coordinates); only the copies of the chosen precision
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
            s = near_start[a]
            e = near_end[a]
            for w in range(n_w):
                partner_near[w] |= (partner[w] >= s) & (partner[w] < e)
            m = e - s
            if mixed:
                fx[j : j + m] = near32[0, s:e]
                fy[j : j + m] = near32[1, s:e]
                fz[j : j + m] = near32[2, s:e]
                lx[j : j + m] = near32[3, s:e]
                ly[j : j + m] = near32[4, s:e]
                lz[j : j + m] = near32[5, s:e]
                fq[j : j + m] = charge32[s:e]
                frod[j : j + m] = rod32[s:e]
            else:
                nx[j : j + m] = x[s:e]
                ny[j : j + m] = y[s:e]
                nz[j : j + m] = z[s:e]
                nq[j : j + m] = charge[s:e]
                nrod[j : j + m] = rod[s:e]
            j += m
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
                xk32 = near32[0, i]
                yk32 = near32[1, i]
                zk32 = near32[2, i]
                xl32 = near32[3, i]
                yl32 = near32[4, i]
                zl32 = near32[5, i]
                qk32 = charge32[i]
                rk32 = rod32[i]
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
                # the recorded far cells, summed in float32 over cells like the near pairs
                gx32 = np.float32(xk - gcx)
                gy32 = np.float32(yk - gcy)
                gz32 = np.float32(zk - gcz)
                cx32 = zero32
                cy32 = zero32
                cz32 = zero32
                # [perf] one loop per order: one loop with the hexadecapole term behind a test of the
                # order inside it was 1.17 times slower for octupoles on the host build (Zen 4, 24 000 rods)
                if order >= 4:
                    for k in range(n_chunks):
                        fc = far32[k]
                        for j in range(FAR_CHUNK):
                            s32 = fc[3, j]
                            e1, e2, e3 = _field_hexadecapole_f32(
                                (gx32 - fc[0, j]) * s32,
                                (gy32 - fc[1, j]) * s32,
                                (gz32 - fc[2, j]) * s32,
                                fc[5, j], fc[6, j], fc[7, j], fc[8, j], fc[9, j], fc[10, j], fc[11, j],
                                fc[12, j], fc[13, j], fc[14, j], fc[15, j], fc[16, j], fc[17, j], fc[18, j],
                                fc[19, j], fc[20, j], fc[21, j], fc[22, j], fc[23, j], fc[24, j], fc[25, j],
                                fc[26, j], fc[27, j], fc[28, j], fc[29, j],
                            )  # fmt: skip
                            w32 = fc[4, j]
                            cx32 += e1 * w32
                            cy32 += e2 * w32
                            cz32 += e3 * w32
                else:
                    for k in range(n_chunks):
                        fc = far32[k]
                        for j in range(FAR_CHUNK):
                            s32 = fc[3, j]
                            e1, e2, e3 = _field_octupole_f32(
                                (gx32 - fc[0, j]) * s32,
                                (gy32 - fc[1, j]) * s32,
                                (gz32 - fc[2, j]) * s32,
                                fc[5, j], fc[6, j], fc[7, j], fc[8, j], fc[9, j], fc[10, j], fc[11, j],
                                fc[12, j], fc[13, j], fc[14, j], fc[15, j], fc[16, j], fc[17, j], fc[18, j],
                                fc[19, j], fc[20, j],
                            )  # fmt: skip
                            w32 = fc[4, j]
                            cx32 += e1 * w32
                            cy32 += e2 * w32
                            cz32 += e3 * w32
                sx = np.float64(bx) + qk * np.float64(cx32)
                sy = np.float64(by) + qk * np.float64(cy32)
                sz = np.float64(bz) + qk * np.float64(cz32)
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
        sum. ``THETA`` (0.475) with the default knobs (hexadecapoles) gives a median
        relative error of 5e-4 to 8e-4 in a uniform rod gas and in the Fig. 2 slab of
        6000 to 1e5 rods, 30 to 100 times less in aggregates (docs/performance.md).
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
        (:func:`_field_octupole_f32`, :func:`_field_hexadecapole_f32`), with the offsets and the
        moments in units of the cell's distance from the group's box (every power of ``1/R``
        then near 1), summed over the cells in float32 per target and added in float64; a cell
        whose offsets exceed ``SPAN32`` times that distance takes the float64 loop.
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
