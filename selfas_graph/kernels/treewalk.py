"""Evaluation of the tip tree (:mod:`.tree`, docs/model.md 'Term 1'): one walk per group of targets.

:func:`evaluate_groups` runs, for each target group (in parallel over groups, a group writing only
the rows of its own tips), the stages of the evaluation, each a function inlined into it:

1. :func:`_targets` -- the group's targets in the asked rows, their coordinates padded to a whole
   number of vector blocks, and their rod partners;
2. :func:`_walk` -- the interaction lists and the far field in one walk of the tree: each cell
   accepted as a multipole is applied at once to all the group's targets in float64 (the loop of
   the tree's order, :func:`_make_cell_on_targets`) or, in mixed precision, recorded in float32
   for the targets to sum; the near leaves are listed as runs of sorted tips;
3. :func:`_near_copies` -- the near leaves' tips copied into one contiguous buffer (float64, or the
   tree's float32 copies), and whether each target's rod partner is among them;
4. per target: the near field (:func:`_near_on_target`, :func:`_near_on_target_f32`), the recorded
   cells summed in float32 (the loop of the order, :func:`_make_far32_on_target`), the far field,
   and the exact pair force of the rod partner taken out when the partner's charge was in an
   accepted cell's moments.

The loops of a multipole order are built once per order by the two factories, over the fields
of :mod:`.multipole` (one definition for float64 and float32). [perf] The walk applies or records
each accepted cell as it finds it: a walk that returned the list of accepted cells, applied after
it (with the near sums taken per group), made the evaluation 3 to 20 % slower (6000 rods of the
Fig. 2 slab, one thread, interleaved with the code before: 0.97 at theta 0 and 0.81 at 0.475 in
float64, 0.93 and 0.79 mixed); the stages as they are measured 0.99-1.02 of the one-body code
before them. The tree's docstring gives the acceptance test, the layout of the recorded cells and
the measurements behind the choices.
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
def append_grown(buf, n, value):
    """``buf[n] = value``, doubling the buffer when full; returns the buffer."""
    if n == buf.shape[0]:
        grown = np.empty(2 * n, buf.dtype)
        grown[:n] = buf
        buf = grown
    buf[n] = value
    return buf


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
def _targets(x, y, z, index, rank, gs, ge, lo, hi, gcx, gcy, gcz):
    """Stage 1: the targets of a group (sorted tips ``gs:ge``) with original number in ``[lo, hi)``,
    ``(sel, n_w, tx, ty, tz, partner)``: ``sel[:n_w]`` their sorted positions (packed: the cost
    follows the rows asked for), ``partner`` the sorted position of each one's rod partner, ``tx,
    ty, tz`` their coordinates padded with copies of the group's box centre (never on an accepted
    cell's centre) to a whole number of vector blocks (:data:`PAD`): every target runs through the
    same vector code wherever it sits in the block, so its force does not depend on which other
    rows are evaluated."""
    sel = np.empty(ge - gs, np.int64)
    n_w = 0
    for i in range(gs, ge):
        k = index[i]
        if k >= lo and k < hi:
            sel[n_w] = i
            n_w += 1
    n_pad = -(-n_w // PAD) * PAD
    tx = np.full(n_pad, gcx)
    ty = np.full(n_pad, gcy)
    tz = np.full(n_pad, gcz)
    partner = np.empty(n_w, np.int64)
    for w in range(n_w):
        i = sel[w]
        tx[w] = x[i]
        ty[w] = y[i]
        tz[w] = z[i]
        partner[w] = rank[index[i] ^ 1]
    return sel, n_w, tx, ty, tz, partner


@inline
def _near_copies(
    near_start, near_end, n_near, n_near_tips, partner, mixed, x, y, z, charge, rod, near32, charge32, rod32
):
    """Stage 3: the near leaves' tips (runs ``near_start[a]:near_end[a]``) copied into one contiguous
    buffer per quantity, so that each target runs one long branch-free reduction over them, like
    the direct sum; mixed: copies of the tree's float32 hi + lo coordinates (relative to the root
    cell's centre), charges and int32 rods (8 lanes like the coordinates); only the copies of the
    chosen precision are filled. Returns whether each target's rod partner is among them, the
    float32 copies (x, y, z hi, x, y, z lo, charge, rod) and the float64 ones (x, y, z, charge, rod)."""
    n_w = partner.shape[0]
    partner_near = np.zeros(n_w, np.bool_)
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
    return partner_near, fx, fy, fz, lx, ly, lz, fq, frod, nx, ny, nz, nq, nrod


@inline_sum
def _near_on_target(xk, yk, zk, qk, rk, nx, ny, nz, nq, nrod, n, rstar, kappa):
    """Stage 4, near field in float64: the exact force on one target (coordinates, charge, rod)
    from the ``n`` near tips copied by :func:`_near_copies`, the law of
    :func:`.laws.tip_force_over_r`, the pairs of its own rod left out by a select (so that the
    loop vectorises)."""
    sx = 0.0
    sy = 0.0
    sz = 0.0
    for j in range(n):
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
def _near_on_target_f32(i, near32, charge32, rod32, fx, fy, fz, lx, ly, lz, fq, frod, n, rstar32, kappa32):
    """Stage 4, near field in float32: :func:`_near_on_target` for the target at sorted position
    ``i``, the law of :func:`.laws.tip_force_over_r_f32` on the tree's hi + lo coordinates (the near
    tips' hi ``fx, fy, fz`` and lo ``lx, ly, lz``), one float32 sum."""
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
    for j in range(n):
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


@inline
def accepts(centre, radius, c, xl, yl, zl, xh, yh, zh, theta2, rstar):
    """The acceptance test of the walk (the tree's docstring): whether cell ``c`` acts on a group of
    box ``xl, yl, zl``-``xh, yh, zh`` through its moments (its radius below the opening angle times the
    distance d of its centre from the box, ``theta2`` the angle squared, and no tip of it within r* of
    the box), and d^2."""
    cx = centre[c, 0]
    cy = centre[c, 1]
    cz = centre[c, 2]
    wx = max(xl - cx, 0.0, cx - xh)
    wy = max(yl - cy, 0.0, cy - yh)
    wz = max(zl - cz, 0.0, cz - zh)
    d2 = wx * wx + wy * wy + wz * wz
    b = radius[c]
    return d2 * theta2 > b * b and d2 > (b + rstar) * (b + rstar), d2


@inline_sum
def _walk(start, end, nxt, centre, radius, moment, order, mixed, theta2, rstar, xl, yl, zl, xh, yh, zh, tx, ty, tz):
    """Stage 2, the interaction lists and the far field: one walk of the tree for a group (its box,
    low ``xl, yl, zl``, high ``xh, yh, zh``; the box, not the packed targets, decides, so the cells
    taken do not depend on the rows asked for). A cell accepted as a multipole is applied at once
    to all the group's padded targets ``tx, ty, tz`` in float64 (``ex, ey, ez``, the loop of the
    tree's order) or, with ``mixed``, recorded in float32 (``far32``, ``n_far`` cells in
    ``n_chunks`` chunks, the last padded) for the targets to sum; leaves not accepted are near,
    listed as runs of sorted tips ``near_start[a]:near_end[a]`` (``n_near`` runs, ``n_near_tips``
    tips). Returns ``(ex, ey, ez, far32, n_chunks, near_start, near_end, n_near, n_near_tips)``."""
    n_cells = start.shape[0]
    n_pad = tx.shape[0]
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
    # stage 2, interaction lists and far field: one walk for the whole group (its box, not the
    # packed targets, decides,
    # so the cells taken do not depend on lo and hi either)
    c = 0
    while c < n_cells:
        cx = centre[c, 0]
        cy = centre[c, 1]
        cz = centre[c, 2]
        take, d2 = accepts(centre, radius, c, xl, yl, zl, xh, yh, zh, theta2, rstar)
        if take:
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
                _cell_on_targets_4(cx, cy, cz, mc, tx, ty, tz, ex, ey, ez)
            elif order >= 3:
                _cell_on_targets_3(cx, cy, cz, mc, tx, ty, tz, ex, ey, ez)
            else:
                _cell_on_targets_2(cx, cy, cz, mc, tx, ty, tz, ex, ey, ez)
            c = nxt[c]
        elif nxt[c] == c + 1:
            if n_near > 0 and near_end[n_near - 1] == start[c]:
                near_end[n_near - 1] = end[c]
            else:
                near_start = append_grown(near_start, n_near, start[c])
                near_end = append_grown(near_end, n_near, end[c])
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
    return ex, ey, ez, far32, n_chunks, near_start, near_end, n_near, n_near_tips


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
    theta2 = theta * theta
    rstar32 = np.float32(rstar)
    kappa32 = np.float32(kappa)
    for gi in prange(g_lo, g_hi):
        g = group[gi]
        gs = start[g]
        ge = end[g]
        xl = box[g, 0]
        yl = box[g, 1]
        zl = box[g, 2]
        xh = box[g, 3]
        yh = box[g, 4]
        zh = box[g, 5]
        # stage 1, targets
        sel, n_w, tx, ty, tz, partner = _targets(
            x, y, z, index, rank, gs, ge, lo, hi, 0.5 * (xl + xh), 0.5 * (yl + yh), 0.5 * (zl + zh)
        )
        if n_w == 0:
            continue
        gcx = 0.5 * (xl + xh)
        gcy = 0.5 * (yl + yh)
        gcz = 0.5 * (zl + zh)
        # stage 2, interaction lists and far field
        ex, ey, ez, far32, n_chunks, near_start, near_end, n_near, n_near_tips = _walk(
            start, end, nxt, centre, radius, moment, order, mixed, theta2, rstar, xl, yl, zl, xh, yh, zh, tx, ty, tz
        )
        # stage 3, near copies
        partner_near, fx, fy, fz, lx, ly, lz, fq, frod, nx, ny, nz, nq, nrod = _near_copies(
            near_start, near_end, n_near, n_near_tips, partner, mixed, x, y, z, charge, rod, near32, charge32, rod32
        )
        # stage 4, per target: the near field, the recorded far cells (mixed), the far field, the rod partner
        for w in range(n_w):
            i = sel[w]
            xk = tx[w]
            yk = ty[w]
            zk = tz[w]
            qk = charge[i]
            if mixed:
                bx, by, bz = _near_on_target_f32(
                    i, near32, charge32, rod32, fx, fy, fz, lx, ly, lz, fq, frod, n_near_tips, rstar32, kappa32
                )
                # the recorded far cells, summed in float32 over cells like the near pairs
                gx32 = np.float32(xk - gcx)
                gy32 = np.float32(yk - gcy)
                gz32 = np.float32(zk - gcz)
                if order >= 4:
                    cx32, cy32, cz32 = _far32_on_target_4(far32, n_chunks, gx32, gy32, gz32)
                else:
                    cx32, cy32, cz32 = _far32_on_target_3(far32, n_chunks, gx32, gy32, gz32)
                sx = np.float64(bx) + qk * np.float64(cx32)
                sy = np.float64(by) + qk * np.float64(cy32)
                sz = np.float64(bz) + qk * np.float64(cz32)
            else:
                sx, sy, sz = _near_on_target(xk, yk, zk, qk, rod[i], nx, ny, nz, nq, nrod, n_near_tips, rstar, kappa)
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
