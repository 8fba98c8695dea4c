"""Evaluation of the tip tree (:mod:`.tree`, docs/model.md 'Term 1'): one walk per group of targets.

:func:`evaluate_groups` runs, for each target group (in parallel over groups, a group writing only
the rows of its own tips), the stages of the evaluation, each a function of its own inlined into it:

1. :func:`_targets` -- the group's targets in the asked rows, their coordinates padded to a whole
   number of vector blocks, and their rod partners;
2. :func:`_interaction_lists` -- the walk: the cells accepted as multipoles (the far list) and the
   near leaves, as runs of sorted tips;
3. :func:`_far_field` -- each accepted cell's field, applied to all the group's targets in float64
   (:func:`_cell_on_targets`, one variant per multipole order) or, in mixed precision, recorded in
   float32 (:func:`_record_far32`, :func:`_pad_far32`) for the targets to sum;
4. :func:`_near_copies` -- the near leaves' tips copied into one contiguous buffer (float64, or the
   tree's float32 copies);
5. per target, the near field (:func:`_near_on_target`, or :func:`_near_on_target_f32` and the
   recorded cells summed over by :func:`_far32_on_target`, one variant per order), the far field,
   and the exact pair force of the rod partner taken out when the partner's charge was in an
   accepted cell's moments.

The loops of a multipole order or a float type are built once, by the factories
:func:`_make_cell_on_targets` and :func:`_make_far32_on_target` over the fields of
:mod:`.multipole`. The tree's docstring gives the acceptance test, the layout of the recorded cells
and the measurements behind the choices.
"""

import math

import numpy as np

from ._jit import inline, inline_sum, njit, njit_parallel_sum, prange
from .laws import tip_force_over_r, tip_force_over_r_f32
from .multipole import (
    field_hexadecapole,
    field_hexadecapole_f32,
    field_octupole,
    field_octupole_f32,
    field_quadrupole,
)
from .treebuild import N_MOMENT

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
#: the far field of a cell is taken in float32 (``precision="mixed"``) only while the offsets
#: from the group's box centre, in units of the cell's distance s from the box, stay below this
#: (and below 1e30 in absolute value, far inside the float32 range):
#: the float32 offset of a target from the cell centre is then off by at most about
#: ``6e-8 * SPAN32`` = 6e-5 of its length (a cell of radius b contributes a truncation error of
#: up to ``theta^4``, 0.026 at theta 0.4, of its own field). Cells beyond it (a target group
#: much larger than its distance to the cell, or offsets beyond the float32 range) take the
#: float64 loop.
SPAN32 = 1000.0

_ZERO32 = np.float32(0.0)


@njit
def _append(buf, n, value):
    """``buf[n] = value``, doubling the buffer when full; returns the buffer."""
    if n == buf.shape[0]:
        grown = np.empty(2 * n, buf.dtype)
        grown[:n] = buf
        buf = grown
    buf[n] = value
    return buf


@inline
def _targets(x, y, z, index, rank, gs, ge, lo, hi, gc):
    """The targets of a group (sorted tips ``gs:ge``) with original number in ``[lo, hi)``:
    ``(sel, n_w, tx, ty, tz, partner)``.

    ``sel[:n_w]`` are their sorted positions (packed: the cost follows the rows asked for),
    ``partner`` the sorted position of each one's rod partner. ``tx, ty, tz`` their coordinates,
    padded with copies of the group's box centre ``gc`` (never on an accepted cell's centre) to a
    whole number of vector blocks (:data:`PAD`): every target runs through the same vector code
    wherever it sits in the block, so its force does not depend on which other rows are evaluated.
    """
    sel = np.empty(ge - gs, np.int64)
    n_w = 0
    for i in range(gs, ge):
        k = index[i]
        if k >= lo and k < hi:
            sel[n_w] = i
            n_w += 1
    n_pad = -(-n_w // PAD) * PAD
    tx = np.full(n_pad, gc[0])
    ty = np.full(n_pad, gc[1])
    tz = np.full(n_pad, gc[2])
    partner = np.empty(n_w, np.int64)
    for w in range(n_w):
        i = sel[w]
        tx[w] = x[i]
        ty[w] = y[i]
        tz[w] = z[i]
        partner[w] = rank[index[i] ^ 1]
    return sel, n_w, tx, ty, tz, partner


@inline
def _interaction_lists(bx, start, end, nxt, centre, radius, theta2, rstar):
    """The walk of one group (its box ``bx``, low x y z then high x y z): ``(far, far_d2, n_far,
    near_start, near_end, n_near, n_near_tips)``.

    A cell is accepted when, with ``d2`` the squared distance of its centre from the group's box,
    ``b^2 < theta^2 d2`` and ``d2 > (b + r*)^2`` (``b`` its radius): ``far[:n_far]`` lists the
    accepted cells in the order of the walk, ``far_d2`` their ``d2``. Leaves not accepted are near:
    runs of consecutive sorted tips ``near_start[a]:near_end[a]`` (leaves next to each other in
    Morton order merge), ``n_near_tips`` tips in all. The group's box, not its packed targets,
    decides, so the cells taken do not depend on the rows asked for.
    """
    n_cells = start.shape[0]
    xl = bx[0]
    yl = bx[1]
    zl = bx[2]
    xh = bx[3]
    yh = bx[4]
    zh = bx[5]
    far = np.empty(64, np.int64)
    far_d2 = np.empty(64)
    n_far = 0
    near_start = np.empty(64, np.int64)
    near_end = np.empty(64, np.int64)
    n_near = 0
    n_near_tips = 0
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
            far = _append(far, n_far, c)
            far_d2 = _append(far_d2, n_far, d2)
            n_far += 1
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
    return far, far_d2, n_far, near_start, near_end, n_near, n_near_tips


def _make_cell_on_targets(order):
    """The float64 far-field loop of multipole order ``order`` (2, 3 or 4): one accepted cell
    (centre ``cx, cy, cz``, moments ``mc``) applied to all the group's padded targets, its field
    added to ``ex, ey, ez`` (a loop vectorised across targets; the cell's moments are read once)."""

    @inline_sum
    def cell_on_targets(cx, cy, cz, mc, tx, ty, tz, ex, ey, ez):
        for t in range(tx.shape[0]):
            dx = tx[t] - cx
            dy = ty[t] - cy
            dz = tz[t] - cz
            if order >= 4:
                e1, e2, e3 = field_hexadecapole(
                    dx, dy, dz, mc[0], mc[1], mc[2], mc[3], mc[4], mc[5], mc[6], mc[7], mc[8],
                    mc[9], mc[10], mc[11], mc[12], mc[13], mc[14], mc[15],
                    mc[16], mc[17], mc[18], mc[19], mc[20], mc[21], mc[22], mc[23], mc[24],
                )  # fmt: skip
            elif order >= 3:
                e1, e2, e3 = field_octupole(
                    dx, dy, dz, mc[0], mc[1], mc[2], mc[3], mc[4], mc[5], mc[6], mc[7], mc[8],
                    mc[9], mc[10], mc[11], mc[12], mc[13], mc[14], mc[15],
                )  # fmt: skip
            else:
                e1, e2, e3 = field_quadrupole(dx, dy, dz, mc[0], mc[1], mc[2], mc[3], mc[4], mc[5], mc[6], mc[7], mc[8])
            ex[t] += e1
            ey[t] += e2
            ez[t] += e3

    return cell_on_targets


_cell_on_targets_2 = _make_cell_on_targets(2)
_cell_on_targets_3 = _make_cell_on_targets(3)
_cell_on_targets_4 = _make_cell_on_targets(4)


def _make_far32_on_target(order):
    """The float32 far-field loop of multipole order ``order`` (3 or 4; order 2 takes 3, its
    octupoles being zero): one target (its offset ``gx, gy, gz`` from the group's box centre, float32)
    summing the field of every recorded cell (:func:`_record_far32`), in float32, in one loop over
    the cells vectorised across them; returns the sum ``(cx, cy, cz)`` in units of the group's
    field scale as recorded.

    [perf] one loop per order: one loop with the hexadecapole term behind a test of the order
    inside it was 1.17 times slower for octupoles on the host build (Zen 4, 24 000 rods).
    """

    @inline_sum
    def far32_on_target(far32, n_chunks, gx, gy, gz):
        cx = _ZERO32
        cy = _ZERO32
        cz = _ZERO32
        for k in range(n_chunks):
            fc = far32[k]
            for j in range(FAR_CHUNK):
                s32 = fc[3, j]
                dx = (gx - fc[0, j]) * s32
                dy = (gy - fc[1, j]) * s32
                dz = (gz - fc[2, j]) * s32
                if order >= 4:
                    e1, e2, e3 = field_hexadecapole_f32(
                        dx, dy, dz,
                        fc[5, j], fc[6, j], fc[7, j], fc[8, j], fc[9, j], fc[10, j], fc[11, j],
                        fc[12, j], fc[13, j], fc[14, j], fc[15, j], fc[16, j], fc[17, j], fc[18, j],
                        fc[19, j], fc[20, j], fc[21, j], fc[22, j], fc[23, j], fc[24, j], fc[25, j],
                        fc[26, j], fc[27, j], fc[28, j], fc[29, j],
                    )  # fmt: skip
                else:
                    e1, e2, e3 = field_octupole_f32(
                        dx, dy, dz,
                        fc[5, j], fc[6, j], fc[7, j], fc[8, j], fc[9, j], fc[10, j], fc[11, j],
                        fc[12, j], fc[13, j], fc[14, j], fc[15, j], fc[16, j], fc[17, j], fc[18, j],
                        fc[19, j], fc[20, j],
                    )  # fmt: skip
                w32 = fc[4, j]
                cx += e1 * w32
                cy += e2 * w32
                cz += e3 * w32
        return cx, cy, cz

    return far32_on_target


_far32_on_target_3 = _make_far32_on_target(3)
_far32_on_target_4 = _make_far32_on_target(4)


@inline
def _record_far32(far32, n_far32, cx, cy, cz, gc, dist, mc):
    """Record an accepted cell for the float32 far field as column ``n_far32`` of ``far32`` (grown
    by chunks of :data:`FAR_CHUNK`): its offset from the group's box centre ``gc``, ``1 / dist`` and
    its square, and its moments, all in units of ``dist`` (the field then in units of
    ``1/dist^2``): ``|offset| >= 1`` and the moments' scale is cut by ``(b / dist)^order``, so that
    the powers of ``1/R`` stay far from the float32 range. Returns ``far32``."""
    k = n_far32 // FAR_CHUNK
    f = n_far32 % FAR_CHUNK
    if k == far32.shape[0]:
        grown = np.empty((2 * k, FAR_ROWS, FAR_CHUNK), np.float32)
        grown[:k] = far32
        far32 = grown
    inv = 1.0 / dist
    inv2 = inv * inv
    inv3 = inv2 * inv
    inv4 = inv2 * inv2
    far32[k, 0, f] = np.float32(cx - gc[0])
    far32[k, 1, f] = np.float32(cy - gc[1])
    far32[k, 2, f] = np.float32(cz - gc[2])
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
    return far32


@inline
def _pad_far32(far32, n_far32, half):
    """Pad the last chunk of recorded cells with cells of zero moments at a point outside the
    group's box (``half`` its half side; offsets of 0.5 to 1.5 in its units): each adds exactly zero."""
    if n_far32 % FAR_CHUNK:
        k = n_far32 // FAR_CHUNK
        away = 2.0 * half + 1.0
        for f in range(n_far32 % FAR_CHUNK, FAR_CHUNK):
            far32[k, 0, f] = np.float32(away)
            far32[k, 1, f] = np.float32(0.0)
            far32[k, 2, f] = np.float32(0.0)
            far32[k, 3, f] = np.float32(1.0 / away)
            for r in range(4, FAR_ROWS):
                far32[k, r, f] = np.float32(0.0)


@inline
def _far_field(far, far_d2, n_far, centre, moment, order, mixed, gc, half, tx, ty, tz):
    """The accepted cells' fields, in the order of the walk: ``(ex, ey, ez, far32, n_far32)``.

    In float64 each cell is applied to all targets at once (``ex, ey, ez``, padded like ``tx``);
    with ``mixed`` a cell whose offsets from the group's box centre ``gc`` stay within
    :data:`SPAN32` times its distance (and below 1e30) is recorded in ``far32`` instead (``n_far32``
    cells, the last chunk padded), the others take the float64 loop. ``half`` is the half side of
    the group's box.
    """
    n_pad = tx.shape[0]
    ex = np.zeros(n_pad)
    ey = np.zeros(n_pad)
    ez = np.zeros(n_pad)
    far32 = np.empty((1 if mixed else 0, FAR_ROWS, FAR_CHUNK), np.float32)
    n_far32 = 0
    for a in range(n_far):
        c = far[a]
        cx = centre[c, 0]
        cy = centre[c, 1]
        cz = centre[c, 2]
        mc = moment[c]
        # d2 > 0 here: dist is the cell centre's distance from the group's box, which every target
        # is at least as far from
        dist = math.sqrt(far_d2[a])
        span = half + max(abs(cx - gc[0]), abs(cy - gc[1]), abs(cz - gc[2]))
        if mixed and span < SPAN32 * dist and span < 1e30:
            far32 = _record_far32(far32, n_far32, cx, cy, cz, gc, dist, mc)
            n_far32 += 1
        elif order >= 4:
            _cell_on_targets_4(cx, cy, cz, mc, tx, ty, tz, ex, ey, ez)
        elif order >= 3:
            _cell_on_targets_3(cx, cy, cz, mc, tx, ty, tz, ex, ey, ez)
        else:
            _cell_on_targets_2(cx, cy, cz, mc, tx, ty, tz, ex, ey, ez)
    if mixed:
        _pad_far32(far32, n_far32, half)
    return ex, ey, ez, far32, n_far32


@inline
def _partner_near(near_start, near_end, n_near, partner):
    """True for each target whose rod partner (``partner``, sorted positions) is among the near tips."""
    n_w = partner.shape[0]
    partner_near = np.zeros(n_w, np.bool_)
    for a in range(n_near):
        s = near_start[a]
        e = near_end[a]
        for w in range(n_w):
            partner_near[w] |= (partner[w] >= s) & (partner[w] < e)
    return partner_near


@inline
def _near_copies(near_start, near_end, n_near, n, x, y, z, charge, rod):
    """The near tips (runs ``near_start[a]:near_end[a]``, ``n`` tips in all; 0 for none) copied
    into one contiguous buffer per quantity, so that each target runs one long branch-free
    reduction over them, like the direct sum: ``(x, y, z, charge, rod)`` of the near tips. Used for
    the float64 copies and for the float32 ones (the tree's hi + lo coordinates, charges and int32
    rods, 8 lanes like the coordinates), whatever the arrays' types."""
    nx = np.empty(n, x.dtype)
    ny = np.empty(n, y.dtype)
    nz = np.empty(n, z.dtype)
    nq = np.empty(n, charge.dtype)
    nrod = np.empty(n, rod.dtype)
    j = 0
    for a in range(n_near if n > 0 else 0):
        s = near_start[a]
        e = near_end[a]
        m = e - s
        nx[j : j + m] = x[s:e]
        ny[j : j + m] = y[s:e]
        nz[j : j + m] = z[s:e]
        nq[j : j + m] = charge[s:e]
        nrod[j : j + m] = rod[s:e]
        j += m
    return nx, ny, nz, nq, nrod


@inline_sum
def _near_on_target(xk, yk, zk, qk, rk, nx, ny, nz, nq, nrod, rstar, kappa):
    """The exact force on one target (float64 coordinates, charge, rod) from the near tips
    (:func:`_near_copies`), the law of :func:`.laws.tip_force_over_r`, the pairs of its own rod left
    out by a select; float64 sums."""
    sx = 0.0
    sy = 0.0
    sz = 0.0
    for j in range(nx.shape[0]):
        dx = xk - nx[j]
        dy = yk - ny[j]
        dz = zk - nz[j]
        gl = tip_force_over_r(dx * dx + dy * dy + dz * dz, qk * nq[j], rstar, kappa)
        gl = 0.0 if nrod[j] == rk else gl
        sx += gl * dx
        sy += gl * dy
        sz += gl * dz
    return sx, sy, sz


@inline_sum
def _near_on_target_f32(i, near32, charge32, rod32, fx, fy, fz, lx, ly, lz, fq, frod, rstar32, kappa32):
    """:func:`_near_on_target` in float32 for the target at sorted position ``i``: the law of
    :func:`.laws.tip_force_over_r_f32` on the tree's hi + lo coordinates (hi ``fx, fy, fz``, lo
    ``lx, ly, lz``, copies of :func:`_near_copies`), one float32 sum."""
    xk32 = near32[0, i]
    yk32 = near32[1, i]
    zk32 = near32[2, i]
    xl32 = near32[3, i]
    yl32 = near32[4, i]
    zl32 = near32[5, i]
    qk32 = charge32[i]
    rk32 = rod32[i]
    bx = _ZERO32
    by = _ZERO32
    bz = _ZERO32
    for j in range(fx.shape[0]):
        # hi - hi is exact for close tips (Sterbenz), so the difference keeps float32 precision
        # relative to itself, not to |x - centre| (measured in aggregates: median error 4e-7
        # instead of 8e-6)
        ux = (xk32 - fx[j]) + (xl32 - lx[j])
        uy = (yk32 - fy[j]) + (yl32 - ly[j])
        uz = (zk32 - fz[j]) + (zl32 - lz[j])
        g32 = tip_force_over_r_f32(ux * ux + uy * uy + uz * uz, qk32 * fq[j], rstar32, kappa32)
        g32 = _ZERO32 if frod[j] == rk32 else g32
        bx += g32 * ux
        by += g32 * uy
        bz += g32 * uz
    return bx, by, bz


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

    One walk per target group, in the stages of the module docstring: near leaves are summed
    exactly over a contiguous copy of their tips, accepted cells are applied to all the group's
    targets in a loop vectorised across targets (float64) or recorded and summed by each target in
    a loop vectorised across cells (mixed).

    Parameters
    ----------
    x, y, z, charge : (n_tips,) float64
        Tips in Morton order; ``rod`` (n_tips,) int64 their rod numbers.
    index, rank : (n_tips,) int64
        Morton position -> original number and its inverse.
    start, end, nxt, box, centre, radius, moment, group, near32, charge32, rod32 :
        The tree (:class:`.tree.TipTree`).
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
        (:func:`.tree.evaluate_tip_tree`); False: float64.
    out : (n_tips, 3) float64
        Rows ``lo:hi`` overwritten with the force on each tip (original order).
    """
    theta2 = theta * theta
    rstar32 = np.float32(rstar)
    kappa32 = np.float32(kappa)
    for gi in prange(g_lo, g_hi):
        g = group[gi]
        bx = box[g]
        gc = (0.5 * (bx[0] + bx[3]), 0.5 * (bx[1] + bx[4]), 0.5 * (bx[2] + bx[5]))
        half = 0.5 * max(bx[3] - bx[0], bx[4] - bx[1], bx[5] - bx[2])
        sel, n_w, tx, ty, tz, partner = _targets(x, y, z, index, rank, start[g], end[g], lo, hi, gc)
        if n_w == 0:
            continue
        far, far_d2, n_far, near_start, near_end, n_near, n_near_tips = _interaction_lists(
            bx, start, end, nxt, centre, radius, theta2, rstar
        )
        ex, ey, ez, far32, n_far32 = _far_field(far, far_d2, n_far, centre, moment, order, mixed, gc, half, tx, ty, tz)
        n_chunks = -(-n_far32 // FAR_CHUNK)
        partner_near = _partner_near(near_start, near_end, n_near, partner)
        # only the copies of the chosen precision are filled (the others are empty)
        n32 = n_near_tips if mixed else 0
        n64 = 0 if mixed else n_near_tips
        nx, ny, nz, nq, nrod = _near_copies(near_start, near_end, n_near, n64, x, y, z, charge, rod)
        fx, fy, fz, fq, frod = _near_copies(
            near_start, near_end, n_near, n32, near32[0], near32[1], near32[2], charge32, rod32
        )
        lx, ly, lz, _, _ = _near_copies(
            near_start, near_end, n_near, n32, near32[3], near32[4], near32[5], charge32, rod32
        )
        for w in range(n_w):
            i = sel[w]
            xk = tx[w]
            yk = ty[w]
            zk = tz[w]
            qk = charge[i]
            if mixed:
                bx32, by32, bz32 = _near_on_target_f32(
                    i, near32, charge32, rod32, fx, fy, fz, lx, ly, lz, fq, frod, rstar32, kappa32
                )
                # the recorded far cells, summed in float32 over cells like the near pairs
                gx32 = np.float32(xk - gc[0])
                gy32 = np.float32(yk - gc[1])
                gz32 = np.float32(zk - gc[2])
                if order >= 4:
                    cx32, cy32, cz32 = _far32_on_target_4(far32, n_chunks, gx32, gy32, gz32)
                else:
                    cx32, cy32, cz32 = _far32_on_target_3(far32, n_chunks, gx32, gy32, gz32)
                sx = np.float64(bx32) + qk * np.float64(cx32)
                sy = np.float64(by32) + qk * np.float64(cy32)
                sz = np.float64(bz32) + qk * np.float64(cz32)
            else:
                sx, sy, sz = _near_on_target(xk, yk, zk, qk, rod[i], nx, ny, nz, nq, nrod, rstar, kappa)
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
