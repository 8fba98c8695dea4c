"""The field of the rod currents by a multipole tree (docs/model.md 'Term 9', 'The rod currents by a
tree'): what ``method = "tree"`` of ``[forces.current_field]`` and ``[forces.current_lorentz]`` runs
instead of the all-pairs sums of :mod:`.currents`.

The field of a straight current is the curl of its vector potential: with the rod ``x' = A + t s``,
t in [0, 1], carrying J, ``A(x) = J s int_0^1 dt / |x - x'(t)|`` (reduced units; ``curl A`` is the
Biot-Savart law of :func:`.currents.segment_field` with ``w = 0``). Each component ``A_d`` is the
Coulomb potential of a line charge of density ``J s_d`` along the rod, so that a cell of rods
carries three sets of Cartesian multipole moments, one per channel d = x, y, z, in the layout of
:mod:`.multipole` (M, P, Q, O: up to octupoles), and a far cell acts through
``B = curl A``: with ``E_d = -grad A_d`` the field of channel d's moments,
``B = (E_y,z - E_z,y, E_z,x - E_x,z, E_x,y - E_y,x)`` (``E_d,c`` the c component of ``E_d``).

Moments. A channel's moment of order n is the integral along the rod of a polynomial of degree n
in t: the 3-point Gauss-Legendre rule (:data:`GL_T`, :data:`GL_W`, exact to degree 5) gives the
moments of a straight rod exactly up to octupoles. A cell's box, centre and radius are those of
its rods' ends, so that the whole of every rod lies within the cell's radius of its centre.

Walk. Targets (tips, or term 10's quadrature points) are sorted by the Morton key of their
position and taken in groups of :data:`GROUP_SIZE` (:func:`sort_targets`). A group walks the tree
once, alone (processes may share the groups out by runs, :func:`target_runs`): a cell acts
through its moments on all the group's targets when its radius is below ``opening_angle`` times
the distance of its centre from the group's box; a leaf that is not accepted is near, and its
rods act by the regularised segment law, as in the direct sum. ``mixed``: the near rods by
``segment_field_f32`` relative to the group's box centre, summed in float32 per target; each
accepted cell's field in float32 in units of its distance d from the group's box (offsets and
moments scaled by powers of 1/d, as the tip tree's, :mod:`.treewalk`; float64 where the group's
span exceeds ``SPAN32`` d), added in float64. A target's own rod (``exclude_rod``) is
within the radius of every cell that holds it, so for opening angles below 1 that cell is never
accepted: the own rod is always near and is left out exactly. The regularisation by the wire
radius changes a rod's field by about ``(w / d)^2`` at distance d; an accepted cell is at least
its radius over the opening angle away, half a rod length for a single rod at 1.
"""

from typing import NamedTuple

import numpy as np

from ._jit import inline_sum, njit, njit_parallel, njit_parallel_sum, njit_sum, prange
from .currents import packed_segments, segment_field, segment_field_f32
from .multipole import field_octupole, field_octupole_f32, field_quadrupole
from .treebuild import add_moments, argsort_keys, bounding_box, build_cells, morton_keys
from .treewalk import SPAN32, accepts, append_grown

#: rods per leaf and targets per walk: leaves of 16 to 128 rods and groups of 32 to 256 points ran
#: within 10 % of each other at a given median error at t = 100 of a Fig. 6 run with 3150 rods
#: carrying current, 64 and 128 among the fastest (docs/performance.md 'A tree of the rod currents')
LEAF_SIZE = 64
GROUP_SIZE = 128
#: moments per channel: M, P (3), Q (5 independent), O (7 independent)
N_CHANNEL = 16
#: the highest moment (3: octupoles; 2 stops at quadrupoles)
ORDER = 3

_S = np.sqrt(0.6)
#: the 3-point Gauss-Legendre rule on [0, 1]: exact for the moments up to octupoles
GL_T = np.array([0.5 - 0.5 * _S, 0.5, 0.5 + 0.5 * _S])
GL_W = np.array([5.0 / 18.0, 8.0 / 18.0, 5.0 / 18.0])


class CurrentTree(NamedTuple):
    """A tree of the rods that carry current (:func:`build_current_tree`).

    Attributes
    ----------
    seg : (7, n) float64
        The rods in Morton order of their centres: rows tip a x y z, tip b x y z, current J.
    rod : (n,) int64
        The rod index of each column of ``seg``.
    start, end, nxt : (n_cells,) int64
        Each cell's range of columns and the cell after its subtree (depth-first preorder).
    centre : (n_cells, 3) float64
        The centre of the box of the cell's rod ends (the expansion centre).
    radius : (n_cells,) float64
        The largest distance of a rod end from the centre.
    moment : (n_cells, 3 N_CHANNEL) float64
        Channel d's moments (of the line charge ``J s_d``) in columns ``N_CHANNEL d`` onward.
    order : int
        The highest moment (2 or 3).
    """

    seg: np.ndarray
    rod: np.ndarray
    start: np.ndarray
    end: np.ndarray
    nxt: np.ndarray
    centre: np.ndarray
    radius: np.ndarray
    moment: np.ndarray
    order: int


@njit_parallel
def _cell_moments(seg, start, end, order, gl_t, gl_w, centre, radius, moment, c0, c1):
    """Centre, radius and the three channels' moments of cells ``c0`` to ``c1 - 1`` (the module
    docstring); each cell from its own rods, so that a cell is the same whichever run fills it."""
    for c in prange(c0, c1):
        s = start[c]
        e = end[c]
        lo = np.empty(3)
        hi = np.empty(3)
        for d in range(3):
            lo[d] = min(seg[d, s], seg[3 + d, s])
            hi[d] = max(seg[d, s], seg[3 + d, s])
        for r in range(s + 1, e):
            for d in range(3):
                lo[d] = min(lo[d], seg[d, r], seg[3 + d, r])
                hi[d] = max(hi[d], seg[d, r], seg[3 + d, r])
        cx = 0.5 * (lo[0] + hi[0])
        cy = 0.5 * (lo[1] + hi[1])
        cz = 0.5 * (lo[2] + hi[2])
        centre[c, 0] = cx
        centre[c, 1] = cy
        centre[c, 2] = cz
        b2 = 0.0
        row = moment[c]
        row[:] = 0.0
        for r in range(s, e):
            ax = seg[0, r] - cx
            ay = seg[1, r] - cy
            az = seg[2, r] - cz
            bx = seg[3, r] - cx
            by = seg[4, r] - cy
            bz = seg[5, r] - cz
            b2 = max(b2, ax * ax + ay * ay + az * az, bx * bx + by * by + bz * bz)
            sx = bx - ax
            sy = by - ay
            sz = bz - az
            for g in range(gl_t.shape[0]):
                t = gl_t[g]
                px = ax + t * sx
                py = ay + t * sy
                pz = az + t * sz
                jw = seg[6, r] * gl_w[g]
                add_moments(row, 0, jw * sx, px, py, pz, order)
                add_moments(row, N_CHANNEL, jw * sy, px, py, pz, order)
                add_moments(row, 2 * N_CHANNEL, jw * sz, px, py, pz, order)
        radius[c] = np.sqrt(b2)


def build_current_tree(position, active_rod, current, leaf_size=LEAF_SIZE, order=ORDER):
    """The tree of the rods ``active_rod`` (distinct, at least one) with their ``current``
    (:func:`plan_current_tree`, then :func:`fill_current_cells` of every cell).

    Parameters
    ----------
    position : (n_tips, 3) float64
        Tip positions (rod i: rows 2 i and 2 i + 1), finite.
    active_rod : (n_active,) int64
        Distinct indices of the rods carrying a current, n_active >= 1.
    current : (n_rods,) float64
        Rod currents, positive from tip a to tip b.
    leaf_size : int
        Rods per leaf.
    order : int
        2 (quadrupoles) or 3 (octupoles).

    Returns
    -------
    CurrentTree
    """
    tree = plan_current_tree(position, active_rod, current, leaf_size, order)
    fill_current_cells(tree, 0, tree.start.shape[0])
    return tree


def plan_current_tree(position, active_rod, current, leaf_size=LEAF_SIZE, order=ORDER):
    """The tree of :func:`build_current_tree` with its rods sorted and its cells cut, their centres,
    radii and moments not yet computed (:func:`fill_current_cells`; processes may share the cells
    out by runs, :func:`.tree.cell_bounds`, and gather them)."""
    if order not in (2, 3):
        raise ValueError(f"the current tree's order must be 2 or 3, got {order}")
    packed = packed_segments(position, active_rod, current)
    middle = 0.5 * (packed[0:3] + packed[3:6])  # the rods' centres, rows x, y, z
    key = np.empty(active_rod.shape[0], np.int64)
    morton_keys(middle[0], middle[1], middle[2], key)
    perm = argsort_keys(key)
    start, end, nxt = build_cells(key[perm], leaf_size)
    seg = packed[:, perm]
    rod = active_rod[perm]
    nc = start.shape[0]
    centre = np.empty((nc, 3))
    radius = np.empty(nc)
    moment = np.empty((nc, 3 * N_CHANNEL))
    return CurrentTree(seg, rod, start, end, nxt, centre, radius, moment, order)


def fill_current_cells(tree, c0, c1):
    """Compute the centre, radius and moments of cells ``c0`` to ``c1 - 1`` of a planned tree, in place."""
    t = tree
    _cell_moments(t.seg, t.start, t.end, t.order, GL_T, GL_W, t.centre, t.radius, t.moment, int(c0), int(c1))


@inline_sum
def _cell_field(dx, dy, dz, row, base, order):
    """The field ``E = -grad phi`` at offset ``d`` of one channel's moments ``row[base:]``."""
    if order >= 3:
        return field_octupole(
            dx, dy, dz, row[base], row[base + 1], row[base + 2], row[base + 3], row[base + 4],
            row[base + 5], row[base + 6], row[base + 7], row[base + 8], row[base + 9], row[base + 10],
            row[base + 11], row[base + 12], row[base + 13], row[base + 14], row[base + 15],
        )  # fmt: skip
    return field_quadrupole(
        dx, dy, dz, row[base], row[base + 1], row[base + 2], row[base + 3], row[base + 4],
        row[base + 5], row[base + 6], row[base + 7], row[base + 8],
    )  # fmt: skip


@inline_sum
def _cell_field_f32(dx, dy, dz, row, base):
    """:func:`_cell_field` in float32 at octupole order (a quadrupole tree's octupoles are zero)."""
    return field_octupole_f32(
        dx, dy, dz, row[base], row[base + 1], row[base + 2], row[base + 3], row[base + 4],
        row[base + 5], row[base + 6], row[base + 7], row[base + 8], row[base + 9], row[base + 10],
        row[base + 11], row[base + 12], row[base + 13], row[base + 14], row[base + 15],
    )  # fmt: skip


def _make_far_cell_f64(order):
    """The float64 loop of an accepted cell at multipole ``order`` (2 or 3), frozen into the loop.

    [perf] The order a constant and the loop a function of its own: with the order a run-time
    argument (and the loop inlined into the walk beside the float32 one) the AVX2 build took 1.6 to
    2.1 times longer (Zen 4, 2 threads, opening angle 0.5, the gas of 24 000 rods of ``selfas-graph
    bench current_tree``: 209-262 against 128 ms)."""

    @njit_sum
    def far_cell(cx, cy, cz, row, tx, ty, tz, g0, m, bx, by, bz):
        """Add the field of an accepted cell (centre ``c``, moments ``row``) to the ``m`` targets from ``g0``."""
        for k in range(m):
            dx = tx[g0 + k] - cx
            dy = ty[g0 + k] - cy
            dz = tz[g0 + k] - cz
            exx, exy, exz = _cell_field(dx, dy, dz, row, 0, order)
            eyx, eyy, eyz = _cell_field(dx, dy, dz, row, N_CHANNEL, order)
            ezx, ezy, ezz = _cell_field(dx, dy, dz, row, 2 * N_CHANNEL, order)
            bx[k] += eyz - ezy
            by[k] += ezx - exz
            bz[k] += exy - eyx

    return far_cell


_far_cell_f64_2 = _make_far_cell_f64(2)
_far_cell_f64_3 = _make_far_cell_f64(3)


@njit_sum
def _far_cell_f32(cx, cy, cz, row, dist, m32, tx, ty, tz, g0, m, bx, by, bz):
    """:func:`_make_far_cell_f64`'s loop in float32, in units of the cell's distance ``dist`` from the group's box
    (offsets >= 1, moments cut by (b / dist)^n, the field in units of 1 / dist^2), each cell's field on
    a target added in float64; ``m32`` is scratch for the scaled moments."""
    inv = 1.0 / dist
    for ch in range(3):
        base = N_CHANNEL * ch
        m32[base] = np.float32(row[base])
        for r in range(1, 4):
            m32[base + r] = np.float32(row[base + r] * inv)
        for r in range(4, 9):
            m32[base + r] = np.float32(row[base + r] * (inv * inv))
        for r in range(9, 16):
            m32[base + r] = np.float32(row[base + r] * (inv * inv * inv))
    unit = inv * inv
    for k in range(m):
        dx = np.float32((tx[g0 + k] - cx) * inv)
        dy = np.float32((ty[g0 + k] - cy) * inv)
        dz = np.float32((tz[g0 + k] - cz) * inv)
        exx, exy, exz = _cell_field_f32(dx, dy, dz, m32, 0)
        eyx, eyy, eyz = _cell_field_f32(dx, dy, dz, m32, N_CHANNEL)
        ezx, ezy, ezz = _cell_field_f32(dx, dy, dz, m32, 2 * N_CHANNEL)
        bx[k] += unit * np.float64(eyz - ezy)
        by[k] += unit * np.float64(ezx - exz)
        bz[k] += unit * np.float64(exy - eyx)


@njit_parallel_sum
def _evaluate(
    seg, rod, start, end, nxt, centre, radius, moment, order, tx, ty, tz, texcl, index, group, theta2, w, mixed, out
):
    """The walk of every target group (the module docstring); writes ``out[index[k]]``."""
    n_cells = start.shape[0]
    w2 = w * w
    for g in prange(group.shape[0] - 1):
        g0 = group[g]
        g1 = group[g + 1]
        m = g1 - g0
        xl, yl, zl, xh, yh, zh = bounding_box(tx, ty, tz, g0, g1)
        ox = 0.5 * (xl + xh)
        oy = 0.5 * (yl + yh)
        oz = 0.5 * (zl + zh)
        half = 0.5 * max(xh - xl, yh - yl, zh - zl)
        m32 = np.zeros(3 * N_CHANNEL, np.float32)
        bx = np.zeros(m)
        by = np.zeros(m)
        bz = np.zeros(m)
        near = np.empty(16, np.int64)
        n_near = 0
        n_seg = 0
        c = 0
        while c < n_cells:
            # the tip tree's test without its core (r* = 0): the radius below theta times the distance
            take, d2 = accepts(centre, radius, c, xl, yl, zl, xh, yh, zh, theta2, 0.0)
            if take:
                cx = centre[c, 0]
                cy = centre[c, 1]
                cz = centre[c, 2]
                row = moment[c]
                dist = np.sqrt(d2)
                span = half + max(abs(cx - ox), abs(cy - oy), abs(cz - oz))
                if mixed and span < SPAN32 * dist:
                    _far_cell_f32(cx, cy, cz, row, dist, m32, tx, ty, tz, g0, m, bx, by, bz)
                elif order >= 3:
                    _far_cell_f64_3(cx, cy, cz, row, tx, ty, tz, g0, m, bx, by, bz)
                else:
                    _far_cell_f64_2(cx, cy, cz, row, tx, ty, tz, g0, m, bx, by, bz)
                c = nxt[c]
            elif nxt[c] == c + 1:
                near = append_grown(near, n_near, c)
                n_near += 1
                n_seg += end[c] - start[c]
                c += 1
            else:
                c += 1
        # the near rods, copied into one contiguous block (relative to the group's box centre)
        ns = np.empty((7, n_seg))
        nrod = np.empty(n_seg, np.int64)
        q = 0
        for i in range(n_near):
            for r in range(start[near[i]], end[near[i]]):
                ns[0, q] = seg[0, r] - ox
                ns[1, q] = seg[1, r] - oy
                ns[2, q] = seg[2, r] - oz
                ns[3, q] = seg[3, r] - ox
                ns[4, q] = seg[4, r] - oy
                ns[5, q] = seg[5, r] - oz
                ns[6, q] = seg[6, r]
                nrod[q] = rod[r]
                q += 1
        if mixed:
            n32 = np.empty((11, n_seg), np.float32)
            # int32 rod indices: a comparison as wide as the float32 lanes (int64 halves them on AVX2)
            rod32 = np.empty(n_seg, np.int32)
            for r in range(n_seg):
                rod32[r] = nrod[r]
                for d in range(6):
                    n32[d, r] = np.float32(ns[d, r])
                sx = ns[3, r] - ns[0, r]
                sy = ns[4, r] - ns[1, r]
                sz = ns[5, r] - ns[2, r]
                n32[6, r] = np.float32(sx)
                n32[7, r] = np.float32(sy)
                n32[8, r] = np.float32(sz)
                n32[9, r] = np.float32(w2 * (sx * sx + sy * sy + sz * sz))
                n32[10, r] = np.float32(ns[6, r])
            for k in range(m):
                px = np.float32(tx[g0 + k] - ox)
                py = np.float32(ty[g0 + k] - oy)
                pz = np.float32(tz[g0 + k] - oz)
                skip = np.int32(texcl[g0 + k])
                hx = np.float32(0.0)
                hy = np.float32(0.0)
                hz = np.float32(0.0)
                for r in range(n_seg):
                    fx, fy, fz = segment_field_f32(
                        px - n32[0, r], py - n32[1, r], pz - n32[2, r], px - n32[3, r], py - n32[4, r],
                        pz - n32[5, r], n32[6, r], n32[7, r], n32[8, r], n32[9, r], n32[10, r],
                    )  # fmt: skip
                    keep = rod32[r] != skip
                    hx += fx if keep else np.float32(0.0)
                    hy += fy if keep else np.float32(0.0)
                    hz += fz if keep else np.float32(0.0)
                bx[k] += np.float64(hx)
                by[k] += np.float64(hy)
                bz[k] += np.float64(hz)
        else:
            for k in range(m):
                px = tx[g0 + k] - ox
                py = ty[g0 + k] - oy
                pz = tz[g0 + k] - oz
                skip = texcl[g0 + k]
                hx = 0.0
                hy = 0.0
                hz = 0.0
                for r in range(n_seg):
                    fx, fy, fz = segment_field(
                        px, py, pz, ns[0, r], ns[1, r], ns[2, r], ns[3, r], ns[4, r], ns[5, r], ns[6, r], w
                    )
                    keep = 0.0 if nrod[r] == skip else 1.0
                    hx += keep * fx
                    hy += keep * fy
                    hz += keep * fz
                bx[k] += hx
                by[k] += hy
                bz[k] += hz
        for k in range(m):
            i = index[g0 + k]
            out[i, 0] = bx[k]
            out[i, 1] = by[k]
            out[i, 2] = bz[k]


class CurrentTargets(NamedTuple):
    """Field points sorted for the walk (:func:`sort_targets`).

    Attributes
    ----------
    index : (m,) int64
        The points in Morton order of their positions: sorted point k is ``point[index[k]]``.
    tx, ty, tz : (m,) float64
        The sorted points' coordinates.
    exclude : (m,) int64
        The rod each sorted point leaves out (-1: none).
    group : (n_groups + 1,) int64
        Group g is sorted points ``group[g]:group[g + 1]``.
    """

    index: np.ndarray
    tx: np.ndarray
    ty: np.ndarray
    tz: np.ndarray
    exclude: np.ndarray
    group: np.ndarray


@njit
def _sorted_targets(point, exclude_rod, index, tx, ty, tz, texcl, group_size):
    """The targets in the order ``index`` into ``tx, ty, tz, texcl``; returns the group bounds."""
    m = point.shape[0]
    for k in range(m):
        i = index[k]
        tx[k] = point[i, 0]
        ty[k] = point[i, 1]
        tz[k] = point[i, 2]
        texcl[k] = exclude_rod[i]
    n_group = (m + group_size - 1) // group_size
    group = np.empty(n_group + 1, np.int64)
    for g in range(n_group):
        group[g] = g * group_size
    group[n_group] = m
    return group


def sort_targets(point, exclude_rod, group_size=GROUP_SIZE):
    """The field points ``point`` ((m, 3) float64, finite, m >= 1), each leaving out the rod
    ``exclude_rod[p]`` ((m,) int64, -1: none), sorted by their Morton keys into groups of ``group_size``
    for :func:`evaluate_current_tree`. Returns a :class:`CurrentTargets`."""
    m = point.shape[0]
    key = np.empty(m, np.int64)
    morton_keys(
        np.ascontiguousarray(point[:, 0]), np.ascontiguousarray(point[:, 1]), np.ascontiguousarray(point[:, 2]), key
    )
    index = argsort_keys(key)
    tx, ty, tz = np.empty(m), np.empty(m), np.empty(m)
    texcl = np.empty(m, np.int64)
    group = _sorted_targets(point, exclude_rod, index, tx, ty, tz, texcl, group_size)
    return CurrentTargets(index, tx, ty, tz, texcl, group)


def target_runs(targets, parts):
    """Cut the groups of ``targets`` into ``parts`` runs of about equal numbers of points, for
    :func:`evaluate_current_tree`'s ``groups`` (the work of ``parts`` processes): run r is groups
    ``bounds[r]:bounds[r + 1]``, sorted points ``rows[r]:rows[r + 1]``.

    Returns
    -------
    bounds, rows : (parts + 1,) int64
    """
    n_group = targets.group.shape[0] - 1
    bounds = (n_group * np.arange(parts + 1, dtype=np.int64)) // parts
    return bounds, targets.group[bounds]


def evaluate_current_tree(tree, targets, opening_angle, wire_radius, out, mixed=False, groups=None):
    """Overwrite the rows ``out[targets.index[k]]`` with the field of the tree's currents at the sorted
    points k of the groups ``groups`` (``(g0, g1)``: groups g0 to g1 - 1; None: every group). Each
    group is walked alone, so that the field at a point is the same bit for bit whichever run of
    groups it is evaluated in (:func:`target_runs` shares the walks out). The arguments as
    :func:`current_tree_field`'s."""
    g0, g1 = (0, targets.group.shape[0] - 1) if groups is None else (int(groups[0]), int(groups[1]))
    if g1 <= g0:
        return
    t = tree
    _evaluate(
        t.seg, t.rod, t.start, t.end, t.nxt, t.centre, t.radius, t.moment, t.order,
        targets.tx, targets.ty, targets.tz, targets.exclude, targets.index, targets.group[g0 : g1 + 1],
        opening_angle * opening_angle, wire_radius, mixed, out,
    )  # fmt: skip


def current_tree_field(tree, point, exclude_rod, opening_angle, wire_radius, out, mixed=False, group_size=GROUP_SIZE):
    """Overwrite ``out`` with the field of the tree's currents at ``point``, leaving out at each point
    the rod ``exclude_rod[p]`` (-1: none); :func:`.currents.rod_current_field` by the tree.
    (:func:`sort_targets` and :func:`evaluate_current_tree` of every group.)

    Parameters
    ----------
    tree : CurrentTree
    point : (m, 3) float64
        Finite field points.
    exclude_rod : (m,) int64
    opening_angle : float
        In [0, 1): a cell acts through its moments when its radius is below this times its
        distance from the target group's box; 0: every rod by the segment law (the direct sum).
    wire_radius : float
        w = D / 2 (docs/model.md 'Term 9'), for the near rods.
    out : (m, 3) float64
    mixed : bool
        The near rods by the float32 law (float32 sums per group, added in float64).
    group_size : int
        Targets per walk.
    """
    if point.shape[0] == 0:
        return
    targets = sort_targets(point, exclude_rod, group_size)
    evaluate_current_tree(tree, targets, opening_angle, wire_radius, out, mixed)
