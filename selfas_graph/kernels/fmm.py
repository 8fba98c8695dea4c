"""Tip-tip force (docs/model.md 'Term 1') by a fast multipole method: cell-cell expansions on the
tip tree, float64. Measured by ``selfas-graph bench fmm`` (docs/performance.md "A fast multipole
method, measured"); the model does not use it (its walk is :mod:`.treewalk`).

The walk of :mod:`.treewalk` applies every accepted cell's multipoles to every target of a group.
Here the targets are cells too, at every level (Dehnen's scheme, J. Comput. Phys. 179, 27, 2002):

1. **Moments** (P2M, M2M). For a cell of centre ``c`` (the tree's box centre), with ``s = x_l - c``
   and multi-indices ``a`` of degree ``|a| <= p``: ``M_a = sum q s^a / a!`` (full Cartesian
   tensors, not traceless), summed at the leaves and shifted up the tree,
   ``M_a(parent) += sum_{g <= a} M_g(child) d^(a - g) / (a - g)!`` with ``d = c_child - c_parent``.
2. **The dual walk.** From the pair (root, root): a pair of cells A, B is *well separated* when
   ``r_A + r_B < theta |c_A - c_B|`` and ``|c_A - c_B| > r_A + r_B + r*`` (no tip pair within the
   soft core, so every far pair obeys the Coulomb law); then it is one M2L pair, taken both ways.
   Otherwise two leaves are one near pair, a cell with itself splits into its child pairs, and a
   pair of different cells splits the larger one (by radius). Each pair of cells is met once.
3. **M2L.** With ``R = c_A - c_B`` and ``D_n = d^n (1/|R|)`` (the derivatives of ``1/r``, by the
   McMurchie-Davidson recursion ``R^m_{t+1,u,v} = t R^{m+1}_{t-1,u,v} + X R^{m+1}_{t,u,v}`` from
   ``R^m_000 = (-1)^m (2m - 1)!! / |R|^(2m + 1)``), the potential of B about ``c_A`` is
   ``phi(c_A + h) = sum_b L_b h^b`` with ``L_b = (1 / b!) sum_{|a| <= p - |b|} (-1)^|a| M_a(B) D_{a+b}``.
   Each cell takes the expansions of all its far cells (both cells of every far pair), its sources
   in batches of :data:`LANES` across which the derivatives and the rows of the sum run, so that
   every inner loop is vectorised (:func:`m2l_lanes`).
4. **L2L, L2P.** Local expansions are shifted down the tree,
   ``L_g(child) += sum_{b >= g} L_b binom(b, g) d^(b - g)``, and each leaf's gives the field
   ``E = -grad phi`` at its tips; the force is ``q E``.
5. **Near pairs (P2P)**: every tip of a leaf with every tip of the leaves it is near to (and its own
   leaf) by the exact law :func:`.laws.tip_force_over_r`, each pair from both sides, the pairs
   of a tip's own rod included; then every tip's force from its rod partner is taken off by the
   same law (when the partner was far, the expansion held it: the difference is of the
   expansion's error, as in :mod:`.treewalk`).

Each order multiplies the error by about a pair's ``(r_A + r_B) / |c_A - c_B|``, at most ``theta``
(tests/physics/test_fmm.py); ``theta`` must be in [0, 1); ``theta = 0`` takes every pair as near (the direct sum). Cells are the tip tree's
(:func:`.tree.build_tip_tree`); the tree's leaf size sets the near work.
"""

import math
from typing import NamedTuple

import numpy as np

from ._jit import njit, njit_parallel, njit_parallel_sum, njit_sum, prange
from .laws import tip_force_over_r


class Tables(NamedTuple):
    """Index tables of the expansions of order ``p`` (:func:`tables`); ``K`` multi-indices in
    order of degree.

    ``degree, fact`` per index (``|a|`` and ``a!``); ``axis, lower1, lower2, t`` the recursion of
    monomials and derivatives (the first axis with a nonzero count, the index less one and two
    along it, -1 if none, and that count less one); ``m2l`` rows ``(b, a, a + b)`` with the
    weight ``w_fwd = (-1)^|a| / b!``; ``shift`` rows ``(a, g, a - g)``
    with ``w_m2m = 1 / (a - g)!`` and ``w_l2l = binom(a, g)``; ``grad`` rows ``(b, b + e_i, i)`` with
    ``w_grad = b_i + 1``.
    """

    p: int
    degree: np.ndarray
    fact: np.ndarray
    axis: np.ndarray
    lower1: np.ndarray
    lower2: np.ndarray
    t: np.ndarray
    m2l: np.ndarray
    w_fwd: np.ndarray
    shift: np.ndarray
    w_m2m: np.ndarray
    w_l2l: np.ndarray
    grad: np.ndarray
    w_grad: np.ndarray


def multi_indices(p):
    """The multi-indices ``(a_x, a_y, a_z)`` of degree at most ``p``, in order of degree."""
    return [(a, b, d - a - b) for d in range(p + 1) for a in range(d, -1, -1) for b in range(d - a, -1, -1)]


def tables(p):
    """The :class:`Tables` of order ``p`` (at least 1)."""
    if p < 1:
        raise ValueError(f"the expansion order must be at least 1, got {p}")
    idx = multi_indices(p)
    k_of = {a: k for k, a in enumerate(idx)}
    n = len(idx)
    degree = np.array([sum(a) for a in idx], np.int64)
    fact = np.array([math.factorial(a[0]) * math.factorial(a[1]) * math.factorial(a[2]) for a in idx])
    axis = np.full(n, -1, np.int64)
    lower1 = np.full(n, -1, np.int64)
    lower2 = np.full(n, -1, np.int64)
    t = np.zeros(n, np.int64)
    for k, a in enumerate(idx[1:], start=1):
        i = next(j for j in range(3) if a[j] > 0)
        axis[k] = i
        one = list(a)
        one[i] -= 1
        lower1[k] = k_of[tuple(one)]
        t[k] = a[i] - 1
        if a[i] >= 2:
            one[i] -= 1
            lower2[k] = k_of[tuple(one)]
    m2l, w_fwd = [], []
    for kb, b in enumerate(idx):
        for ka, a in enumerate(idx):
            if sum(a) + sum(b) <= p:
                m2l.append((kb, ka, k_of[tuple(u + v for u, v in zip(a, b))]))
                w_fwd.append((-1) ** sum(a) / fact[kb])
    shift, w_m2m, w_l2l = [], [], []
    for ka, a in enumerate(idx):
        for kg, g in enumerate(idx):
            if all(u <= v for u, v in zip(g, a)):
                k_d = k_of[tuple(v - u for u, v in zip(g, a))]
                shift.append((ka, kg, k_d))
                w_m2m.append(1.0 / fact[k_d])
                w_l2l.append(math.prod(math.comb(v, u) for u, v in zip(g, a)))
    grad, w_grad = [], []
    for kb, b in enumerate(idx):
        if sum(b) < p:
            for i in range(3):
                up = list(b)
                up[i] += 1
                grad.append((kb, k_of[tuple(up)], i))
                w_grad.append(b[i] + 1.0)
    f64 = np.float64
    return Tables(
        p, degree, fact.astype(f64), axis, lower1, lower2, t,
        np.array(m2l, np.int64), np.array(w_fwd, f64),
        np.array(shift, np.int64), np.array(w_m2m, f64), np.array(w_l2l, f64),
        np.array(grad, np.int64), np.array(w_grad, f64),
    )  # fmt: skip


@njit
def monomials(vx, vy, vz, axis, lower1, out):
    """``out[k] = v^a_k`` for every multi-index (``out[0] = 1``)."""
    out[0] = 1.0
    for k in range(1, out.shape[0]):
        i = axis[k]
        v = vx if i == 0 else (vy if i == 1 else vz)
        out[k] = out[lower1[k]] * v


@njit
def _offset_monomials(centre, c, ch, axis, lower1, out):
    """:func:`monomials` of the offset ``d = c_child - c_parent`` of child ``ch`` from cell ``c``."""
    monomials(
        centre[ch, 0] - centre[c, 0], centre[ch, 1] - centre[c, 1], centre[ch, 2] - centre[c, 2], axis, lower1, out
    )


@njit
def children(nxt, c):
    """The children of cell ``c`` (empty for a leaf)."""
    out = []
    ch = c + 1
    while ch < nxt[c]:
        out.append(ch)
        ch = nxt[ch]
    return out


@njit
def dual_walk(nxt, centre, radius, theta, rstar):
    """The interaction lists of the dual walk (module docstring, step 2): ``(far, near)``, arrays of
    cell pairs ``(A, B)``; ``near`` holds each pair of different leaves once and every leaf with
    itself."""
    far = []
    near = []
    stack = [(0, 0)]
    while len(stack) > 0:
        a, b = stack.pop()
        if a == b:
            if nxt[a] == a + 1:
                near.append((a, a))
            else:
                ch = children(nxt, a)
                for i in range(len(ch)):
                    for j in range(i, len(ch)):
                        stack.append((ch[i], ch[j]))
            continue
        dx = centre[a, 0] - centre[b, 0]
        dy = centre[a, 1] - centre[b, 1]
        dz = centre[a, 2] - centre[b, 2]
        d = math.sqrt(dx * dx + dy * dy + dz * dz)
        rab = radius[a] + radius[b]
        if rab < theta * d and d > rab + rstar:
            far.append((a, b))
            continue
        leaf_a = nxt[a] == a + 1
        leaf_b = nxt[b] == b + 1
        if leaf_a and leaf_b:
            near.append((a, b))
        elif leaf_b or (not leaf_a and radius[a] >= radius[b]):
            for ch in children(nxt, a):
                stack.append((ch, b))
        else:
            for ch in children(nxt, b):
                stack.append((a, ch))
    far_arr = np.empty((len(far), 2), np.int64)
    for k in range(len(far)):
        far_arr[k, 0], far_arr[k, 1] = far[k]
    near_arr = np.empty((len(near), 2), np.int64)
    for k in range(len(near)):
        near_arr[k, 0], near_arr[k, 1] = near[k]
    return far_arr, near_arr


@njit_parallel
def leaf_moments(x, y, z, charge, start, end, nxt, centre, fact, axis, lower1, moment):
    """P2M: ``moment[c]`` of every leaf (other rows left as they are)."""
    k_n = moment.shape[1]
    for c in prange(start.shape[0]):
        if nxt[c] != c + 1:
            continue
        mono = np.empty(k_n)
        for k in range(k_n):
            moment[c, k] = 0.0
        for i in range(start[c], end[c]):
            monomials(x[i] - centre[c, 0], y[i] - centre[c, 1], z[i] - centre[c, 2], axis, lower1, mono)
            for k in range(k_n):
                moment[c, k] += charge[i] * mono[k] / fact[k]


@njit
def upward(nxt, centre, shift, w_m2m, axis, lower1, moment):
    """M2M: the moments of every inner cell from its children's (children follow their parent in
    preorder, so a reverse sweep meets them first)."""
    n_cells, k_n = moment.shape
    mono = np.empty(k_n)
    for c in range(n_cells - 1, -1, -1):
        if nxt[c] == c + 1:
            continue
        moment[c, :] = 0.0
        for ch in children(nxt, c):
            _offset_monomials(centre, c, ch, axis, lower1, mono)
            for r in range(shift.shape[0]):
                moment[c, shift[r, 0]] += moment[ch, shift[r, 1]] * mono[shift[r, 2]] * w_m2m[r]


@njit
def downward(nxt, centre, shift, w_l2l, axis, lower1, local):
    """L2L: every cell's local expansion handed down to its children, in preorder."""
    n_cells, k_n = local.shape
    mono = np.empty(k_n)
    for c in range(n_cells):
        if nxt[c] == c + 1:
            continue
        for ch in children(nxt, c):
            _offset_monomials(centre, c, ch, axis, lower1, mono)
            # L_g(child) += sum_{b >= g} L_b binom(b, g) d^(b - g): the shift rows are (b, g, b - g)
            for r in range(shift.shape[0]):
                local[ch, shift[r, 1]] += local[c, shift[r, 0]] * w_l2l[r] * mono[shift[r, 2]]


@njit_parallel
def leaf_fields(x, y, z, charge, start, end, nxt, centre, local, axis, lower1, grad, w_grad, out):
    """L2P: ``out[i] = q_i E(x_i)`` from its leaf's local expansion (sorted tips)."""
    k_n = local.shape[1]
    for c in prange(start.shape[0]):
        if nxt[c] != c + 1:
            continue
        mono = np.empty(k_n)
        for i in range(start[c], end[c]):
            monomials(x[i] - centre[c, 0], y[i] - centre[c, 1], z[i] - centre[c, 2], axis, lower1, mono)
            e = np.zeros(3)
            for r in range(grad.shape[0]):
                e[grad[r, 2]] -= w_grad[r] * local[c, grad[r, 1]] * mono[grad[r, 0]]
            out[i, 0] = charge[i] * e[0]
            out[i, 1] = charge[i] * e[1]
            out[i, 2] = charge[i] * e[2]


@njit
def pair_rows(pairs, n_cells):
    """Pairs of cells as rows per cell, both ways (a cell with itself once): ``(row_start, row_cell)``
    (CSR)."""
    count = np.zeros(n_cells + 1, np.int64)
    for k in range(pairs.shape[0]):
        count[pairs[k, 0] + 1] += 1
        if pairs[k, 1] != pairs[k, 0]:
            count[pairs[k, 1] + 1] += 1
    row_start = np.cumsum(count)
    fill = row_start[:-1].copy()
    row_cell = np.empty(row_start[-1], np.int64)
    for k in range(pairs.shape[0]):
        a = pairs[k, 0]
        b = pairs[k, 1]
        row_cell[fill[a]] = b
        fill[a] += 1
        if b != a:
            row_cell[fill[b]] = a
            fill[b] += 1
    return row_start, row_cell


@njit_parallel
def near_forces(x, y, z, charge, start, end, nxt, row_start, row_cell, rstar, kappa, out):
    """P2P: add to ``out[i]`` the force of every tip of the leaves near tip i's leaf (its own
    included, its own rod too; the pair of a tip with itself gives 0)."""
    for c in prange(start.shape[0]):
        if nxt[c] != c + 1:
            continue
        for i in range(start[c], end[c]):
            sx = 0.0
            sy = 0.0
            sz = 0.0
            for r in range(row_start[c], row_start[c + 1]):
                b = row_cell[r]
                for j in range(start[b], end[b]):
                    dx = x[i] - x[j]
                    dy = y[i] - y[j]
                    dz = z[i] - z[j]
                    g = tip_force_over_r(dx * dx + dy * dy + dz * dz, charge[i] * charge[j], rstar, kappa)
                    sx += g * dx
                    sy += g * dy
                    sz += g * dz
            out[i, 0] += sx
            out[i, 1] += sy
            out[i, 2] += sz


@njit_parallel
def without_partner(x, y, z, charge, rank, index, rstar, kappa, out):
    """Take off every tip's force from its rod partner (tips ``2k`` and ``2k + 1`` of rod k), by
    the law of the near pairs (sorted tips; ``index``/``rank`` the tree's)."""
    for i in prange(x.shape[0]):
        j = rank[index[i] ^ 1]
        dx = x[i] - x[j]
        dy = y[i] - y[j]
        dz = z[i] - z[j]
        g = tip_force_over_r(dx * dx + dy * dy + dz * dz, charge[i] * charge[j], rstar, kappa)
        out[i, 0] -= g * dx
        out[i, 1] -= g * dy
        out[i, 2] -= g * dz


class Lists(NamedTuple):
    """The dual walk's lists (:func:`dual_walk`) and, per cell, its far cells and (per leaf) its near
    leaves, both ways (:func:`pair_rows`)."""

    far: np.ndarray
    near: np.ndarray
    far_start: np.ndarray
    far_cell: np.ndarray
    near_start: np.ndarray
    near_leaf: np.ndarray


def interaction_lists(tree, theta, rstar):
    """The :class:`Lists` of the tip tree ``tree`` (:func:`.tree.build_tip_tree`) at opening angle
    ``theta`` (in [0, 1): at 1 and above the expansions need not converge; ValueError)."""
    if not 0.0 <= theta < 1.0:
        raise ValueError(f"the opening angle theta must be in [0, 1), got {theta}")
    far, near = dual_walk(tree.next, tree.centre, tree.radius, float(theta), float(rstar))
    n_cells = tree.start.shape[0]
    return Lists(far, near, *pair_rows(far, n_cells), *pair_rows(near, n_cells))


def moments(tree, tab):
    """P2M and M2M: ``(n_cells, K)`` moments of every cell."""
    moment = np.zeros((tree.start.shape[0], tab.degree.shape[0]))
    leaf_moments(tree.x, tree.y, tree.z, tree.charge, tree.start, tree.end, tree.next, tree.centre,
                 tab.fact, tab.axis, tab.lower1, moment)  # fmt: skip
    upward(tree.next, tree.centre, tab.shift, tab.w_m2m, tab.axis, tab.lower1, moment)
    return moment


def locals_of(tree, tab, lists, moment):
    """M2L: ``(n_cells, K)`` local expansions of every cell from its far cells (not yet handed down)."""
    local = np.empty_like(moment)
    m2l_lanes(lists.far_start, lists.far_cell, tree.centre, np.ascontiguousarray(moment.T), tab.p, tab.degree,
              tab.axis, tab.lower1, tab.lower2, tab.t, tab.m2l, tab.w_fwd, local)  # fmt: skip
    return local


def fields(tree, tab, local):
    """L2L and L2P: ``q E`` of the far field at every tip, sorted (n_tips, 3); ``local`` is handed
    down in place."""
    downward(tree.next, tree.centre, tab.shift, tab.w_l2l, tab.axis, tab.lower1, local)
    out = np.empty((tree.x.shape[0], 3))
    leaf_fields(tree.x, tree.y, tree.z, tree.charge, tree.start, tree.end, tree.next, tree.centre, local,
                tab.axis, tab.lower1, tab.grad, tab.w_grad, out)  # fmt: skip
    return out


def near_and_partners(tree, lists, rstar, kappa, out):
    """P2P, and the rod partners taken off: added to ``out`` (sorted tips)."""
    near_forces(tree.x, tree.y, tree.z, tree.charge, tree.start, tree.end, tree.next, lists.near_start,
                lists.near_leaf, float(rstar), float(kappa), out)  # fmt: skip
    without_partner(tree.x, tree.y, tree.z, tree.charge, tree.rank, tree.index, float(rstar), float(kappa), out)


def fmm_forces(tree, tab, theta, rstar, kappa):
    """The tip-tip force on every tip, in the tips' own order (n_tips, 3): far field, near pairs,
    the rod partners taken off (module docstring)."""
    lists = interaction_lists(tree, theta, rstar)
    f = fields(tree, tab, locals_of(tree, tab, lists, moments(tree, tab)))
    near_and_partners(tree, lists, rstar, kappa, f)
    return f[tree.rank]


#: sources taken together by :func:`m2l_lanes`: the loops over them are the vector lanes
LANES = 64


@njit_sum
def derivatives(rx, ry, rz, p, degree, axis, lower1, lower2, t, work):
    """``work[0, k, ln] = d^a_k (1/|R|)`` at ``R = (rx[ln], ry[ln], rz[ln])`` for every lane, by the
    McMurchie-Davidson recursion (module docstring; ``work`` is ``(p + 1, K, lanes)``, its rows
    ``m > 0`` scratch). Each loop runs over the lanes (a trip count known only at run time: a loop of
    a known 16 is unrolled into scalars, which are then not vectorised for fear of aliasing)."""
    n_lanes = rx.shape[0]
    for ln in range(n_lanes):
        inv_r2 = 1.0 / (rx[ln] * rx[ln] + ry[ln] * ry[ln] + rz[ln] * rz[ln])
        g = math.sqrt(inv_r2)
        for m in range(p + 1):
            work[m, 0, ln] = g
            g *= -(2 * m + 1) * inv_r2
    for k in range(1, work.shape[1]):
        i = axis[k]
        v = rx if i == 0 else (ry if i == 1 else rz)
        k1 = lower1[k]
        k2 = lower2[k]
        tk = float(t[k])
        for m in range(p + 1 - degree[k]):
            w0 = work[m, k]
            w1 = work[m + 1, k1]
            if k2 >= 0:
                w2 = work[m + 1, k2]
                for ln in range(n_lanes):
                    w0[ln] = v[ln] * w1[ln] + tk * w2[ln]
            else:
                for ln in range(n_lanes):
                    w0[ln] = v[ln] * w1[ln]


@njit_sum
def _rows_on_lanes(acc, mom, d, rows, w):
    """``acc[b] += w mom[a] d[a + b]`` over the rows of the expansion, each row a loop over the lanes
    (views from 0: no check of negative indices, so that it vectorises; the trip count as in
    :func:`derivatives`)."""
    n_lanes = acc.shape[1]
    for j in range(rows.shape[0]):
        acc_b = acc[rows[j, 0]]
        mom_a = mom[rows[j, 1]]
        d_ab = d[rows[j, 2]]
        wj = w[j]
        for ln in range(n_lanes):
            acc_b[ln] += wj * mom_a[ln] * d_ab[ln]


@njit_parallel_sum
def m2l_lanes(row_start, row_source, centre, moment_t, p, degree, axis, lower1, lower2, t, m2l_rows, w_fwd, local):
    """M2L one way per target cell (``local[a]`` overwritten): its sources in batches of
    :data:`LANES`, the derivatives and the rows of the expansion computed across the batch, so that
    every inner loop runs over the lanes (vectorised). ``moment_t`` is ``(K, n_cells)``. Empty lanes
    of the last batch get a far offset and no moments."""
    k_n = local.shape[1]
    for a in prange(local.shape[0]):
        local[a, :] = 0.0
        n_src = row_start[a + 1] - row_start[a]
        if n_src == 0:
            continue
        work = np.empty((p + 1, k_n, LANES))
        mom = np.empty((k_n, LANES))
        acc = np.zeros((k_n, LANES))
        rx = np.empty(LANES)
        ry = np.empty(LANES)
        rz = np.empty(LANES)
        for b0 in range(row_start[a], row_start[a + 1], LANES):
            for ln in range(LANES):
                r = b0 + ln
                if r < row_start[a + 1]:
                    b = row_source[r]
                    rx[ln] = centre[a, 0] - centre[b, 0]
                    ry[ln] = centre[a, 1] - centre[b, 1]
                    rz[ln] = centre[a, 2] - centre[b, 2]
                    for k in range(k_n):
                        mom[k, ln] = moment_t[k, b]
                else:
                    rx[ln] = 1.0
                    ry[ln] = 0.0
                    rz[ln] = 0.0
                    for k in range(k_n):
                        mom[k, ln] = 0.0
            derivatives(rx, ry, rz, p, degree, axis, lower1, lower2, t, work)
            _rows_on_lanes(acc, mom, work[0], m2l_rows, w_fwd)
        for k in range(k_n):
            s = 0.0
            for ln in range(LANES):
                s += acc[k, ln]
            local[a, k] = s
