"""Kernels of the Lorentz force on the rod currents (docs/model.md 'Term 10').

The force on rod i is ``J_i int_0^1 s_i x B_tot(x_a + t s_i) dt``, taken by a Gauss-Legendre rule
(:func:`gauss_legendre_01`) at the points of :func:`quadrature_points` and shared between the tips
(:func:`lorentz_force_on_rods`); the field of a neighbouring rod's current, peaked where the two
segments come closest, is integrated for the near pairs by a rule adapted to each pair
(:func:`near_rule`, :func:`lorentz_near_correction`). The field of the rod currents at the
quadrature points is :func:`.currents.rod_current_field`; layout and glossary as in :mod:`.currents`.
"""

import operator

import numpy as np

from ._jit import inline, njit, njit_parallel, njit_parallel_sum, prange
from .currents import segment_field


@njit_parallel
def quadrature_points(position, active_rod, gl_t, out):
    """Gauss-Legendre points ``x_a + t s`` along each active rod (docs/model.md 'Term 10').

    Row order is rod-major: ``out[r * n_gl + g]`` is node ``gl_t[g]`` of rod
    ``active_rod[r]``. Parallel over active rods; each writes its own ``n_gl`` rows.

    Parameters
    ----------
    position : ndarray, shape (n_tips, 3), float64
        Tip positions (rod i: rows 2 i and 2 i + 1).
    active_rod : ndarray, shape (n_active,), int64
        Indices of the rods carrying a current. May be empty.
    gl_t : ndarray, shape (n_gl,), float64
        Quadrature nodes on [0, 1] (see ``gauss_legendre_01``).
    out : ndarray, shape (n_active * n_gl, 3), float64
        Overwritten with the quadrature points.
    """
    n_gl = gl_t.shape[0]
    for r in prange(active_rod.shape[0]):
        j = active_rod[r]
        ia = 2 * j
        ib = 2 * j + 1
        for g in range(n_gl):
            t = gl_t[g]
            row = r * n_gl + g
            for d in range(3):
                out[row, d] = position[ia, d] + t * (position[ib, d] - position[ia, d])


@njit_parallel
def lorentz_force_on_rods(position, active_rod, current, field, gl_t, gl_w, out):
    """Lorentz force on the rod currents, shared between the tips, ADDED to ``out``.

    docs/model.md 'Term 10'::

        F_i = J_i int_0^1 s_i x B_tot(x_a + t s_i) dt
            ~ sum_g J_i w_g (s_i x B_g)

    The element ``dF_g = J_i w_g (s_i x B_g)`` goes ``(1 - t_g)`` to tip a and ``t_g``
    to tip b. This keeps the total force, and also the torque: about the rod centre
    x_c, ``(x_a - x_c) x (1 - t) dF + (x_b - x_c) x t dF = (t - 1/2) s x dF``, which is
    the torque of dF applied at ``x_a + t s``. Parallel over active rods; each rod
    writes only its own two tips (``active_rod`` entries must be distinct).

    Parameters
    ----------
    position : ndarray, shape (n_tips, 3), float64
        Tip positions (rod i: rows 2 i and 2 i + 1).
    active_rod : ndarray, shape (n_active,), int64
        Distinct indices of the rods carrying a current. May be empty.
    current : ndarray, shape (n_rods,), float64
        Rod currents J, positive from tip a to tip b.
    field : ndarray, shape (n_active * n_gl, 3), float64
        Total field B_tot at the quadrature points, rod-major as produced by
        ``quadrature_points`` (uniform + plasma + external objects + other rods'
        currents, summed by the caller).
    gl_t : ndarray, shape (n_gl,), float64
        Quadrature nodes on [0, 1].
    gl_w : ndarray, shape (n_gl,), float64
        Quadrature weights on [0, 1] (sum to 1).
    out : ndarray, shape (n_tips, 3), float64
        Tip forces; the term-10 force is added to it (reduced units, F_M0).
    """
    n_gl = gl_t.shape[0]
    for r in prange(active_rod.shape[0]):
        j = active_rod[r]
        ia = 2 * j
        ib = 2 * j + 1
        sx = position[ib, 0] - position[ia, 0]
        sy = position[ib, 1] - position[ia, 1]
        sz = position[ib, 2] - position[ia, 2]
        cur = current[j]
        fax = 0.0
        fay = 0.0
        faz = 0.0
        fbx = 0.0
        fby = 0.0
        fbz = 0.0
        for g in range(n_gl):
            row = r * n_gl + g
            f_x = field[row, 0]
            f_y = field[row, 1]
            f_z = field[row, 2]
            cw = cur * gl_w[g]
            # dF = J w (s x B)
            dx = cw * (sy * f_z - sz * f_y)
            dy = cw * (sz * f_x - sx * f_z)
            dz = cw * (sx * f_y - sy * f_x)
            t = gl_t[g]
            u = 1.0 - t
            fax += u * dx
            fay += u * dy
            faz += u * dz
            fbx += t * dx
            fby += t * dy
            fbz += t * dz
        out[ia, 0] += fax
        out[ia, 1] += fay
        out[ia, 2] += faz
        out[ib, 0] += fbx
        out[ib, 1] += fby
        out[ib, 2] += fbz


NEAR_PANEL_POINTS = 4

#: shortest first panel of the near rule, in units of the rod's length (bounds the number of
#: panels to 2 x 11 when the segments touch and w = 0)
NEAR_MIN_PANEL = 2.0**-10

#: the most panels on one side of the closest point; the last NEAR_DOUBLING_PANELS of them double
#: (2^-10 (2^11 - 1) > 1: eleven doublings from the shortest panel reach any end)
NEAR_MAX_PANELS = 64
NEAR_DOUBLING_PANELS = 11


@inline
def closest_parameter(ax, ay, az, sx, sy, sz, cx, cy, cz, ux, uy, uz):
    """``(t, d)``: the parameter t in [0, 1] of the point of segment ``A + t s`` closest to segment
    ``C + v u`` (v in [0, 1]), and the distance d between the two segments.

    The closest points of two segments (clamp the infinite lines' solution to the first
    segment, project onto the second and clamp, then project back onto the first and clamp);
    parallel segments (``|s x u|^2`` below ``1e-12 |s|^2 |u|^2``) take ``t = 0``'s partner.
    Zero-length segments give ``t = 0``. Finite in, finite out.
    """
    rx = ax - cx
    ry = ay - cy
    rz = az - cz
    a = sx * sx + sy * sy + sz * sz
    b = sx * ux + sy * uy + sz * uz
    c = ux * ux + uy * uy + uz * uz
    d = sx * rx + sy * ry + sz * rz
    e = ux * rx + uy * ry + uz * rz
    den = a * c - b * b
    t = 0.0
    if den > 1e-12 * a * c:
        t = min(max((b * e - c * d) / den, 0.0), 1.0)
    v = 0.0
    if c > 0.0:
        v = (b * t + e) / c
        if v < 0.0:
            v = 0.0
            t = min(max(-d / a, 0.0), 1.0) if a > 0.0 else 0.0
        elif v > 1.0:
            v = 1.0
            t = min(max((b - d) / a, 0.0), 1.0) if a > 0.0 else 0.0
    elif a > 0.0:
        t = min(max(-d / a, 0.0), 1.0)
    qx = rx + t * sx - v * ux
    qy = ry + t * sy - v * uy
    qz = rz + t * sz - v * uz
    return t, np.sqrt(qx * qx + qy * qy + qz * qz)


@inline
def _distance2_to_segment(px, py, pz, cx, cy, cz, ux, uy, uz, inv_uu):
    """Squared distance from the point p to the segment ``C + v u``, v in [0, 1]
    (``inv_uu = 1 / |u|^2``, 0 for a zero-length segment)."""
    rx = px - cx
    ry = py - cy
    rz = pz - cz
    v = min(max((rx * ux + ry * uy + rz * uz) * inv_uu, 0.0), 1.0)
    qx = rx - v * ux
    qy = ry - v * uy
    qz = rz - v * uz
    return qx * qx + qy * qy + qz * qz


@njit
def near_rule(ax, ay, az, sx, sy, sz, cx, cy, cz, ux, uy, uz, h_min, panel_t, panel_w, gl_t, gl_w, node, weight):
    """The nodes of one near pair (rod ``A + t s`` in the field of rod ``C + v u``): the adapted
    panels, then the plain rule ``gl_t, gl_w`` with negative weights.

    Panels start at the point of the rod closest to the other (:func:`closest_parameter`) and go
    to each end; each is as long as the distance from its inner edge to the other rod, but at
    least ``h_min`` (in units of the rod's length) and at most twice the one before, so that the
    field, peaked within that distance, is resolved where it varies; after
    ``NEAR_MAX_PANELS - NEAR_DOUBLING_PANELS`` panels on one side (rods lying along each other
    for a long stretch) each next one is twice the one before. ``panel_t, panel_w`` on each
    panel. Writes ``node[:m], weight[:m]`` and returns m; ``node`` and ``weight`` must hold
    ``2 NEAR_MAX_PANELS len(panel_t) + len(gl_t)`` entries.
    """
    t_star, dist = closest_parameter(ax, ay, az, sx, sy, sz, cx, cy, cz, ux, uy, uz)
    ss = sx * sx + sy * sy + sz * sz
    uu = ux * ux + uy * uy + uz * uz
    inv_uu = 1.0 / uu if uu > 0.0 else 0.0
    scale = 1.0 / np.sqrt(ss) if ss > 0.0 else 1.0
    m = 0
    n_p = panel_t.shape[0]
    for side in range(2):
        edge = t_star
        h = max(dist * scale, h_min)
        count = 0
        while (edge < 1.0) if side == 0 else (edge > 0.0):
            if side == 0:
                p_lo = edge
                p_hi = min(edge + h, 1.0)
                edge = p_hi
            else:
                p_lo = max(edge - h, 0.0)
                p_hi = edge
                edge = p_lo
            width = p_hi - p_lo
            for g in range(n_p):
                node[m] = p_lo + width * panel_t[g]
                weight[m] = width * panel_w[g]
                m += 1
            count += 1
            if count < NEAR_MAX_PANELS - NEAR_DOUBLING_PANELS:
                # h = min(2 h, max(far, h_min)) with far the distance at the edge (in rod lengths);
                # the square root only when far lies between the two
                far2 = _distance2_to_segment(
                    ax + edge * sx, ay + edge * sy, az + edge * sz, cx, cy, cz, ux, uy, uz, inv_uu
                ) * (scale * scale)
                if far2 < 4.0 * h * h:
                    h = max(np.sqrt(far2), h_min) if far2 > h_min * h_min else h_min
                else:
                    h = 2.0 * h
            else:
                h = 2.0 * h
    for g in range(gl_t.shape[0]):
        node[m] = gl_t[g]
        weight[m] = -gl_w[g]
        m += 1
    return m


@njit_parallel_sum
def lorentz_near_correction(
    position, active_rod, current, start, index, r_lo, r_hi, gl_t, gl_w, panel_t, panel_w, wire_radius, out
):
    """The near-pair correction of term 10, ADDED to ``out`` (see the comment above).

    For each active rod ``i = active_rod[r]``, ``r_lo <= r < r_hi``, and each of its near rods
    ``j = active_rod[index[q]]``, ``start[r] <= q < start[r + 1]``: the force of rod j's field on
    rod i's current by the adapted panels (:func:`near_rule`), less the same by the plain rule
    ``gl_t, gl_w``, shared between rod i's tips as :func:`lorentz_force_on_rods` shares it.
    Float64 segment law (:func:`segment_field`), the nodes of a pair summed in one branch-free
    loop that vectorises. Parallel over rods; each rod writes only its own two tips, and a rod's
    result does not depend on ``r_lo, r_hi`` or the thread count.

    Parameters
    ----------
    position : (n_tips, 3) float64
    active_rod : (n_active,) int64
        Distinct indices of the current-carrying rods.
    current : (n_rods,) float64
    start, index : int64 offsets and int32 or int64 entries (``cells.list_dtype``)
        Compressed rows over ``active_rod`` (``start`` has ``n_active + 1`` entries): the near
        rods of each active rod, as places in ``active_rod``, never the rod itself.
    r_lo, r_hi : int
        The active rods (places in ``active_rod``) whose tips this call corrects.
    gl_t, gl_w : (n_gl,) float64
        The plain rule on [0, 1] (``forces.current_lorentz.quadrature_points``).
    panel_t, panel_w : (NEAR_PANEL_POINTS,) float64
        The rule on each panel, on [0, 1].
    wire_radius : float
        w = D / 2 (docs/model.md 'Term 9').
    out : (n_tips, 3) float64
        Tip forces; the correction is added to the tips of rods ``active_rod[r_lo:r_hi]``.
    """
    size = 2 * NEAR_MAX_PANELS * panel_t.shape[0] + gl_t.shape[0]
    for r in prange(r_lo, r_hi):
        i = active_rod[r]
        ia = 2 * i
        ib = ia + 1
        ax = position[ia, 0]
        ay = position[ia, 1]
        az = position[ia, 2]
        sx = position[ib, 0] - ax
        sy = position[ib, 1] - ay
        sz = position[ib, 2] - az
        length = np.sqrt(sx * sx + sy * sy + sz * sz)
        # the shortest panel: half the wire radius, the width of the field's peak (docs/model.md 'Term 9')
        h_min = max(0.5 * wire_radius / length, NEAR_MIN_PANEL) if length > 0.0 else 1.0
        cur = current[i]
        node = np.empty(size)
        weight = np.empty(size)
        fax = 0.0
        fay = 0.0
        faz = 0.0
        fbx = 0.0
        fby = 0.0
        fbz = 0.0
        for q in range(start[r], start[r + 1]):
            j = active_rod[index[q]]
            ja = 2 * j
            jb = ja + 1
            cx = position[ja, 0]
            cy = position[ja, 1]
            cz = position[ja, 2]
            ex = position[jb, 0]
            ey = position[jb, 1]
            ez = position[jb, 2]
            cj = current[j]
            m = near_rule(
                ax, ay, az, sx, sy, sz, cx, cy, cz, ex - cx, ey - cy, ez - cz, h_min,
                panel_t, panel_w, gl_t, gl_w, node, weight,
            )  # fmt: skip
            # branch-free over the nodes of the pair: the loop vectorises
            for g in range(m):
                t = node[g]
                bx, by, bz = segment_field(
                    ax + t * sx, ay + t * sy, az + t * sz, cx, cy, cz, ex, ey, ez, cj, wire_radius
                )
                cw = cur * weight[g]
                dx = cw * (sy * bz - sz * by)
                dy = cw * (sz * bx - sx * bz)
                dz = cw * (sx * by - sy * bx)
                u = 1.0 - t
                fax += u * dx
                fay += u * dy
                faz += u * dz
                fbx += t * dx
                fby += t * dy
                fbz += t * dz
        out[ia, 0] += fax
        out[ia, 1] += fay
        out[ia, 2] += faz
        out[ib, 0] += fbx
        out[ib, 1] += fby
        out[ib, 2] += fbz


# --------------------------------------------------------------------------------------
# plain Python helper
# --------------------------------------------------------------------------------------


def gauss_legendre_01(n):
    """Nodes and weights of the n-point Gauss-Legendre rule on [0, 1].

    The rule integrates polynomials of degree <= 2 n - 1 exactly (term 10's
    accuracy knob, docs/model.md 'Force terms').

    Parameters
    ----------
    n : int
        Number of nodes, >= 1.

    Returns
    -------
    t : ndarray, shape (n,), float64
        Nodes in (0, 1), increasing.
    w : ndarray, shape (n,), float64
        Weights, positive, summing to 1.

    Raises
    ------
    ValueError
        If ``n < 1``.
    """
    n = operator.index(n)
    if n < 1:
        raise ValueError(f"Gauss-Legendre quadrature needs at least 1 node, got n = {n}")
    x, w = np.polynomial.legendre.leggauss(n)
    t = np.ascontiguousarray(0.5 * (x + 1.0), dtype=np.float64)
    w = np.ascontiguousarray(0.5 * w, dtype=np.float64)
    return t, w
