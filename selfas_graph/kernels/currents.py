"""Kernels for the magnetic field of the rod currents: on the tips (term 9) and at any points, such
as term 10's quadrature points (the Lorentz force on the currents is :mod:`.lorentz`).

docs/model.md 'Term 9', 'Term 10', in reduced units (docs/model.md 'Reduced units'): the field
of an infinite straight current J at distance d is ``2 J / d``, the force on a current
element is ``J dl x B`` and the force on a magnetic tip is ``q B``.

Layout (docs/model.md 'Rods'): rod ``i`` has tip a at row ``2 i`` and tip b at row
``2 i + 1`` of ``position``; its axis is ``s_i = x_b - x_a`` and its current ``J_i``
is positive when it flows from tip a to tip b.

Only the rods listed in ``active_rod`` (the rods that carry a current after the last
circuit solve) are visited, so rods without current cost nothing. The loops over
sources read the active rods packed into contiguous arrays, and the segment law has
no branches, so that they vectorise with the ``reassoc``/``contract`` sums of
``njit_parallel_sum``: measured on one core with 640 of 1200 rods carrying current,
7.7 times faster than gathering tip rows with a branching law under strict IEEE sums
(12.1 -> 1.6 ms for the force on all tips), results within 2e-15 relative. The caller (model
layer) validates shapes and indices: numba does not bounds-check, and
``active_rod`` must hold distinct rod indices in ``[0, n_rods)``.

Glossary of the short symbols used inside the kernels:

=========  ==================================================================
``A, B``   segment ends (tip a and tip b of a rod)
``s``      segment vector ``B - A``
``a, b``   ``x - A`` and ``x - B`` for the field point ``x``
``c``      ``s x a``; ``|c| = |s| rho`` with rho the distance of x to the line
``w``      wire radius, ``D / 2`` (docs/model.md 'Term 9')
``t, wt``  Gauss-Legendre nodes and weights on ``[0, 1]``
``J``      rod current
=========  ==================================================================

Mixed precision (``rod_current_field_mixed``, ``current_force_on_tips_mixed``; the knob
``precision = "mixed"`` of ``[forces.current_field]`` and ``[forces.current_lorentz]``): the
same sums with the segment law in float32 on 8 AVX2 lanes, each coordinate relative to the
centre of the active rods' box as a float32 pair hi + lo, so that ``x - A`` keeps float32
precision relative to itself however far the scene is from the origin; the law is taken in a
form without cancellation beyond the segment's ends (``segment_field_f32``); float32 partial
sums over blocks of ``MIXED_BLOCK`` sources are added in float64. docs/performance.md 'Rod-current
kernels on AVX2' has the speed and the error against the float64 kernels.
"""

import numpy as np

from ._jit import inline, inline_sum, njit, njit_parallel_sum, prange

#: the arithmetic of the rod-current sums: float64, or mixed (float32 law, float64 sums)
PRECISIONS = ("float64", "mixed")

#: sources per float32 partial sum of the mixed kernels, each added in float64 (measured: 64 to
#: 4096 run within 10 % of each other; shorter blocks keep float32 rounding of the sums smaller)
MIXED_BLOCK = 128

# float32 constants of the mixed law (a float64 literal would promote it to float64)
_F32_ONE = np.float32(1.0)
_F32_ZERO = np.float32(0.0)
# |x - A|^2 below this (|x - A| < 1e-15) counts as on the end: the w > 0 field is zero there,
# and a smaller (subnormal) square could make the float32 reciprocal square root infinite
_F32_TINY = np.float32(1e-30)

# --------------------------------------------------------------------------------------
# scalar law
# --------------------------------------------------------------------------------------
#
# Derivation of the segment field (docs/model.md 'Term 9').
#
# Biot-Savart in reduced units: dB = J dl x r / |r|^3, with r = x - x' (this is the
# normalisation that gives 2 J / d for an infinite wire). Along the segment
# x' = A + u s_hat, u in [0, |s|], dl = s_hat du, so dl x r = s_hat x a for every u:
# the direction is fixed, c_hat = (s x a) / |s x a|. With rho the distance of x to the
# line and u0 = s_hat . a the position of the foot of the perpendicular,
#     |B| = J rho int_0^|s| du / (rho^2 + (u0 - u)^2)^(3/2)
#         = (J / rho) [ (u0 - u) / sqrt(rho^2 + (u0 - u)^2) ]_{u=|s|}^{u=0}
#         = (J / rho) (s_hat . a / |a| - s_hat . b / |b|)      (cos(theta_1) - cos(theta_2)).
# Using |c| = |s| rho to remove rho and s_hat:
#     B = J c (s.a/|a| - s.b/|b|) / |c|^2.
# An infinite wire has bracket -> 2 and gives |B| = 2 J / rho, as required.
#
# Regularisation: |c|^2 = |s|^2 rho^2 is replaced by |s|^2 (rho^2 + w^2). The field then
# behaves as 2 J rho / (rho^2 + w^2) near the wire (at most J / w, reached at rho = w)
# instead of diverging as 2 J / rho; far away it is the w = 0 field times
# rho^2 / (rho^2 + w^2), i.e. a relative change w^2 / (rho^2 + w^2) ~ (w / rho)^2.
#
# Degenerate points: on a segment end (|a| = 0 or |b| = 0) the bracket is 0/0 while
# c = 0 exactly; the w > 0 field tends to zero there (c -> 0, denominator -> w^2 |s|^2),
# so the law returns exactly zero. With w = 0 a point on the segment's line has
# denominator 0: outside the segment the true Biot-Savart field is zero (dl x r = 0),
# on the segment itself it is undefined; the law returns zero in both cases, so the
# result is always finite. A zero-length segment also gives zero.


@inline
def segment_field(px, py, pz, ax, ay, az, bx, by, bz, current, wire_radius):
    """Magnetic field at point x of a straight finite segment A -> B carrying ``current``.

    docs/model.md 'Term 9' (regularised Biot-Savart law of a finite wire)::

        s = B - A,  a = x - A,  b = x - B,
        B_seg = J (s x a) (s.a/|a| - s.b/|b|) / (|s x a|^2 + w^2 |s|^2)

    See the derivation in the comment above this function. Returns exactly zero when
    x is on an end of the segment (|a| = 0 or |b| = 0: the limit of the w > 0 field)
    or when the denominator vanishes (w = 0 and x on the segment's line, or a
    zero-length segment), so the result is always finite.

    Parameters
    ----------
    px, py, pz : float
        Field point x.
    ax, ay, az : float
        Start A of the segment (tip a of a rod).
    bx, by, bz : float
        End B of the segment (tip b of a rod).
    current : float
        Current J, positive when it flows from A to B (reduced units, J0).
    wire_radius : float
        Wire radius w >= 0 (D / 2 in docs/model.md 'Term 9') that keeps the field finite
        near the wire; w = 0 gives the bare line-current field.

    Returns
    -------
    (Bx, By, Bz) : tuple of float
        Field at x, in reduced units (B0).
    """
    sx = bx - ax
    sy = by - ay
    sz = bz - az
    a_x = px - ax
    a_y = py - ay
    a_z = pz - az
    b_x = px - bx
    b_y = py - by
    b_z = pz - bz
    na = np.sqrt(a_x * a_x + a_y * a_y + a_z * a_z)
    nb = np.sqrt(b_x * b_x + b_y * b_y + b_z * b_z)
    # c = s x a
    cx = sy * a_z - sz * a_y
    cy = sz * a_x - sx * a_z
    cz = sx * a_y - sy * a_x
    ss = sx * sx + sy * sy + sz * sz
    den = cx * cx + cy * cy + cz * cz + wire_radius * wire_radius * ss
    # degenerate cases by selects, not branches, so that the loops over sources vectorise;
    # a NaN coordinate compares unequal to 0 and passes through to the result
    degenerate = (na == 0.0) | (nb == 0.0) | (den == 0.0)
    na = 1.0 if na == 0.0 else na
    nb = 1.0 if nb == 0.0 else nb
    den = 1.0 if den == 0.0 else den
    bracket = (sx * a_x + sy * a_y + sz * a_z) / na - (sx * b_x + sy * b_y + sz * b_z) / nb
    f = current * bracket / den
    f = 0.0 if degenerate else f
    return f * cx, f * cy, f * cz


@njit
def packed_segments(position, active_rod, current):
    """The active rods as packed segment arrays (ends A, B, current, rod index), so that
    the loops over sources read contiguous memory instead of gathering tip rows."""
    n = active_rod.shape[0]
    seg = np.empty((7, n))
    for r in range(n):
        ia = 2 * active_rod[r]
        for d in range(3):
            seg[d, r] = position[ia, d]
            seg[3 + d, r] = position[ia + 1, d]
        seg[6, r] = current[active_rod[r]]
    return seg


@inline
def _active_rod_field(px, py, pz, skip_rod, seg, active_rod, wire_radius):
    """Sum of ``segment_field`` over the packed active rods at point x, skipping one rod.

    The one loop over sources shared by ``rod_current_field`` and
    ``current_force_on_tips`` (docs/model.md 'Term 9'); the skipped rod is removed by a select,
    so that the loop vectorises.

    Parameters
    ----------
    px, py, pz : float
        Field point x.
    skip_rod : int
        Rod whose own segment is left out (-1: none).
    seg : ndarray, shape (7, n_active), float64
        From :func:`packed_segments`: rows A (3), B (3) and the current of each active rod.
    active_rod : ndarray, shape (n_active,), int64
        Rods that carry a current, in the order of ``seg``.
    wire_radius : float
        Wire radius w (docs/model.md 'Term 9').

    Returns
    -------
    (Bx, By, Bz) : tuple of float
        Total field of the active rods' currents at x.
    """
    fx = 0.0
    fy = 0.0
    fz = 0.0
    for r in range(active_rod.shape[0]):
        gx, gy, gz = segment_field(
            px,
            py,
            pz,
            seg[0, r],
            seg[1, r],
            seg[2, r],
            seg[3, r],
            seg[4, r],
            seg[5, r],
            seg[6, r],
            wire_radius,
        )
        keep = 0.0 if active_rod[r] == skip_rod else 1.0
        fx += keep * gx
        fy += keep * gy
        fz += keep * gz
    return fx, fy, fz


@inline_sum
def segment_field_f32(a_x, a_y, a_z, b_x, b_y, b_z, sx, sy, sz, w2ss, current):
    """:func:`segment_field` in float32 from the separations, for the mixed kernels.

    Every argument float32: ``a = x - A``, ``b = x - B``, ``s = B - A``, ``w2ss = w^2 |s|^2``
    and the current J. The same law (docs/model.md 'Term 9')::

        B_seg = J (s x a) (s.a/|a| - s.b/|b|) / (|s x a|^2 + w^2 |s|^2)

    with one change of form: beyond an end of the segment (``s.a`` and ``s.b`` of one sign)
    the bracket ``cos t1 - cos t2`` is a difference of nearly equal numbers far away, which
    float32 would lose (relative error 1e-7 / bracket, 1e-4 at a thousand rod lengths). With
    ``|s x a|^2 = |s|^2 |a|^2 - (s.a)^2 = |s|^2 |b|^2 - (s.b)^2`` and ``|a|^2 - |b|^2 = s.a + s.b``,

        s.a/|a| - s.b/|b| = |s x a|^2 (s.a + s.b) / (|a|^2 |b|^2 (s.a/|a| + s.b/|b|)),

    a sum of terms of one sign. Beside the segment (``s.a s.b <= 0``) the two cosines have
    opposite signs and the plain form has no cancellation. One division and two reciprocal
    square roots per pair, which LLVM takes as ``vrsqrtps`` and a Newton step on 8 lanes.
    Returns zero on an end (``|a|^2`` or ``|b|^2`` below ``1e-30``) and where the denominator
    vanishes, like :func:`segment_field`; relative rounding about 1e-7 of the field.
    """
    cx = sy * a_z - sz * a_y
    cy = sz * a_x - sx * a_z
    cz = sx * a_y - sy * a_x
    c2 = cx * cx + cy * cy + cz * cz
    den = c2 + w2ss
    a2 = a_x * a_x + a_y * a_y + a_z * a_z
    b2 = b_x * b_x + b_y * b_y + b_z * b_z
    sa = sx * a_x + sy * a_y + sz * a_z
    sb = sx * b_x + sy * b_y + sz * b_z
    degenerate = (a2 < _F32_TINY) | (b2 < _F32_TINY) | (den == _F32_ZERO)
    a2 = _F32_ONE if degenerate else a2
    b2 = _F32_ONE if degenerate else b2
    ra = _F32_ONE / np.sqrt(a2)
    rb = _F32_ONE / np.sqrt(b2)
    far = sa * sb > _F32_ZERO
    rab = ra * rb
    num = c2 * (sa + sb) * rab * rab if far else sa * ra - sb * rb
    div = (sa * ra + sb * rb) * den if far else den
    div = _F32_ONE if degenerate else div
    f = current * num / div
    f = _F32_ZERO if degenerate else f
    return f * cx, f * cy, f * cz


@njit
def _segments_mixed(position, active_rod, current, wire_radius):
    """The active rods packed for the mixed kernels, and the origin of their coordinates.

    Returns ``seg`` (17, n_active) float32: rows 0-2 and 3-5 the hi and lo parts of
    ``A - origin``, rows 6-8 and 9-11 those of ``B - origin``, rows 12-14 ``s = B - A``
    (taken in float64, then rounded), row 15 ``w^2 |s|^2``, row 16 the current; ``rod``
    (n_active,) int32, the rod indices (8 lanes like the float32 rows); ``origin`` (3,)
    float64, the centre of the box of the active rods' tips. ``hi = float32(u)`` and
    ``lo = float32(u - hi)`` hold u to about 1e-14 of itself.
    """
    n = active_rod.shape[0]
    seg = np.empty((17, n), np.float32)
    rod = np.empty(n, np.int32)
    origin = np.zeros(3)
    if n == 0:
        return seg, rod, origin
    for d in range(3):
        lo_d = np.inf
        hi_d = -np.inf
        for r in range(n):
            ia = 2 * active_rod[r]
            lo_d = min(lo_d, position[ia, d], position[ia + 1, d])
            hi_d = max(hi_d, position[ia, d], position[ia + 1, d])
        origin[d] = 0.5 * (lo_d + hi_d)
    for r in range(n):
        ia = 2 * active_rod[r]
        ss = 0.0
        for d in range(3):
            a = position[ia, d] - origin[d]
            b = position[ia + 1, d] - origin[d]
            seg[d, r] = np.float32(a)
            seg[3 + d, r] = np.float32(a - np.float64(seg[d, r]))
            seg[6 + d, r] = np.float32(b)
            seg[9 + d, r] = np.float32(b - np.float64(seg[6 + d, r]))
            sd = position[ia + 1, d] - position[ia, d]
            seg[12 + d, r] = np.float32(sd)
            ss += sd * sd
        seg[15, r] = np.float32(wire_radius * wire_radius * ss)
        seg[16, r] = np.float32(current[active_rod[r]])
        rod[r] = np.int32(active_rod[r])
    return seg, rod, origin


@inline_sum
def _active_rod_field_mixed(px, py, pz, skip_rod, seg, rod, origin):
    """:func:`_active_rod_field` of the mixed kernels: ``segment_field_f32`` over the packed
    rods of :func:`_segments_mixed`, float32 sums over blocks of ``MIXED_BLOCK`` rods, each
    added in float64. Returns the float64 field at x, skipping rod ``skip_rod`` (-1: none)."""
    ux = px - origin[0]
    uy = py - origin[1]
    uz = pz - origin[2]
    xh = np.float32(ux)
    yh = np.float32(uy)
    zh = np.float32(uz)
    xl = np.float32(ux - np.float64(xh))
    yl = np.float32(uy - np.float64(yh))
    zl = np.float32(uz - np.float64(zh))
    skip = np.int32(skip_rod)
    n = rod.shape[0]
    fx = 0.0
    fy = 0.0
    fz = 0.0
    # [perf] unsigned indices, as in kernels/tips.py::_force_on_tip_mixed: with signed ones LLVM
    # loads the rows with gathers on AVX-512 targets (docs/performance.md 'Unsigned loop indices
    # on AVX-512'); the same sums bit for bit
    block = np.uint64(MIXED_BLOCK)
    n_u = np.uint64(n)
    for r0 in range(np.uint64(0), n_u, block):
        gx = _F32_ZERO
        gy = _F32_ZERO
        gz = _F32_ZERO
        for r in range(r0, min(r0 + block, n_u)):
            # hi differences first: exact when x and the end are close (Sterbenz), so that
            # a = x - A keeps float32 precision relative to |a|
            hx, hy, hz = segment_field_f32(
                (xh - seg[0, r]) + (xl - seg[3, r]),
                (yh - seg[1, r]) + (yl - seg[4, r]),
                (zh - seg[2, r]) + (zl - seg[5, r]),
                (xh - seg[6, r]) + (xl - seg[9, r]),
                (yh - seg[7, r]) + (yl - seg[10, r]),
                (zh - seg[8, r]) + (zl - seg[11, r]),
                seg[12, r],
                seg[13, r],
                seg[14, r],
                seg[15, r],
                seg[16, r],
            )
            # the skipped rod by a select, not a branch, so that the loop vectorises
            keep = rod[r] != skip
            gx += hx if keep else _F32_ZERO
            gy += hy if keep else _F32_ZERO
            gz += hz if keep else _F32_ZERO
        fx += np.float64(gx)
        fy += np.float64(gy)
        fz += np.float64(gz)
    return fx, fy, fz


# --------------------------------------------------------------------------------------
# loops
# --------------------------------------------------------------------------------------


@njit_parallel_sum
def rod_current_field(point, exclude_rod, position, active_rod, current, wire_radius, out):
    """Field of the active rods' currents at arbitrary points (docs/model.md 'Term 9', 'Term 10').

    ``out[p] = sum over active rods j != exclude_rod[p] of B_seg(point[p]; j)``.
    Used for the field at the Lorentz quadrature points (excluding the rod the point
    belongs to) and for diagnostics (B_z of the rod currents, docs/model.md 'Figure diagnostics').
    Parallel over points; each point writes only its own row.

    Parameters
    ----------
    point : ndarray, shape (m, 3), float64
        Field points.
    exclude_rod : ndarray, shape (m,), int64
        For each point, the rod whose own segment is skipped (-1: none).
    position : ndarray, shape (n_tips, 3), float64
        Tip positions (rod i: rows 2 i and 2 i + 1).
    active_rod : ndarray, shape (n_active,), int64
        Distinct indices of the rods with nonzero current; only these are summed.
        May be empty.
    current : ndarray, shape (n_rods,), float64
        Rod currents J, positive from tip a to tip b.
    wire_radius : float
        Wire radius w = D / 2 (docs/model.md 'Term 9').
    out : ndarray, shape (m, 3), float64
        Overwritten with the total field at each point (reduced units, B0).
    """
    seg = packed_segments(position, active_rod, current)
    for p in prange(point.shape[0]):
        fx, fy, fz = _active_rod_field(
            point[p, 0],
            point[p, 1],
            point[p, 2],
            exclude_rod[p],
            seg,
            active_rod,
            wire_radius,
        )
        out[p, 0] = fx
        out[p, 1] = fy
        out[p, 2] = fz


@njit_parallel_sum
def current_force_on_tips(position, charge, active_rod, current, wire_radius, lo, hi, out):
    """Force of the rod currents' field on the magnetic tips ``lo <= k < hi``, ADDED to ``out`` (term 9).

    ``out[k] += charge[k] * sum over active rods j != k // 2 of B_seg(x_k; j)``:
    a tip feels every current-carrying rod except its own. ``out`` is accumulated into,
    not overwritten, so that the force field can sum its terms in one array. Parallel
    over tips; each tip writes only its own row.

    Parameters
    ----------
    position : ndarray, shape (n_tips, 3), float64
        Tip positions (rod i: rows 2 i and 2 i + 1).
    charge : ndarray, shape (n_tips,), float64
        Magnetic charge of each tip (+q_i on tip a, -q_i on tip b).
    active_rod : ndarray, shape (n_active,), int64
        Distinct indices of the rods with nonzero current; only these are summed.
        May be empty (then ``out`` is unchanged).
    current : ndarray, shape (n_rods,), float64
        Rod currents J, positive from tip a to tip b.
    wire_radius : float
        Wire radius w = D / 2 (docs/model.md 'Term 9').
    lo, hi : int
        Target tips, ``0 <= lo <= hi <= n_tips``; a row does not depend on the range.
    out : ndarray, shape (n_tips, 3), float64
        Tip forces; the term-9 force is added to rows ``lo:hi`` (reduced units, F_M0).
    """
    if active_rod.shape[0] == 0:
        return
    seg = packed_segments(position, active_rod, current)
    for k in prange(lo, hi):
        q = charge[k]
        if q == 0.0:
            continue
        fx, fy, fz = _active_rod_field(
            position[k, 0],
            position[k, 1],
            position[k, 2],
            k // 2,
            seg,
            active_rod,
            wire_radius,
        )
        out[k, 0] += q * fx
        out[k, 1] += q * fy
        out[k, 2] += q * fz


@njit_parallel_sum
def rod_current_field_mixed(point, exclude_rod, position, active_rod, current, wire_radius, out):
    """:func:`rod_current_field` with the segment law in float32 (the mixed precision above).

    Same arguments and result, to float32 rounding of each segment's field (about 1e-7 of
    it); 1.6-1.9 times as fast on AVX2 (docs/performance.md 'Rod-current kernels on AVX2').
    """
    seg, rod, origin = _segments_mixed(position, active_rod, current, wire_radius)
    for p in prange(point.shape[0]):
        fx, fy, fz = _active_rod_field_mixed(point[p, 0], point[p, 1], point[p, 2], exclude_rod[p], seg, rod, origin)
        out[p, 0] = fx
        out[p, 1] = fy
        out[p, 2] = fz


@njit_parallel_sum
def current_force_on_tips_mixed(position, charge, active_rod, current, wire_radius, lo, hi, out):
    """:func:`current_force_on_tips` with the segment law in float32 (the mixed precision above).

    Same arguments and result (ADDED to ``out``), to float32 rounding of each segment's field.
    """
    if active_rod.shape[0] == 0:
        return
    seg, rod, origin = _segments_mixed(position, active_rod, current, wire_radius)
    for k in prange(lo, hi):
        q = charge[k]
        if q == 0.0:
            continue
        fx, fy, fz = _active_rod_field_mixed(position[k, 0], position[k, 1], position[k, 2], k // 2, seg, rod, origin)
        out[k, 0] += q * fx
        out[k, 1] += q * fy
        out[k, 2] += q * fz


# --------------------------------------------------------------------------------------
# near pairs of term 10: a quadrature adapted to each pair
# --------------------------------------------------------------------------------------
#
# The field of a neighbouring rod's current along a rod is peaked where the two segments come
# closest (within a few wire radii at a joint or a crossing), so a fixed Gauss-Legendre rule
# converges only slowly there (docs/performance.md 'Term 10 near pairs'). For the pairs of rods
# whose centres are closer than ``forces.current_lorentz.near_range`` the field of rod j along
# rod i is integrated instead by panels placed from the point of rod i closest to rod j: the
# first panel on each side as long as the distance between the segments (at least the wire
# radius w, and 2^-10 of the rod), each next one twice as long, up to the rod's ends, with
# ``NEAR_PANEL_POINTS`` Gauss-Legendre points per panel; what the plain rule gave for the pair
# is subtracted, so that the plain sum over all rods plus this correction is the adapted rule
# for near pairs and the plain one for the rest.
