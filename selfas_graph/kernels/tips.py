"""Tip-tip magnetic force (docs/model.md 'Term 1') as a direct sum over all tip pairs.

Tips are numbered ``2 i`` and ``2 i + 1`` for rod ``i``; the two tips of one
rod do not interact (their bond is rigid). Positions come as three separate
coordinate arrays (structure of arrays) so that the inner loop vectorises;
the "same rod" pair is removed by a select, not a branch.
"""

import math

import numpy as np

from ._jit import inline, inline_sum, njit, njit_parallel_sum, njit_rows, prange
from .laws import tip_force_over_r, tip_force_over_r_f32, tip_potential


@inline_sum
def _force_on_tip(k, x, y, z, charge, rstar, kappa):
    """Force on tip k from every tip of the other rods (the loop of the direct sums)."""
    n = x.shape[0]
    rod = k // 2
    xk = x[k]
    yk = y[k]
    zk = z[k]
    qk = charge[k]
    fx = 0.0
    fy = 0.0
    fz = 0.0
    for l in range(n):
        dx = xk - x[l]
        dy = yk - y[l]
        dz = zk - z[l]
        g = tip_force_over_r(dx * dx + dy * dy + dz * dz, qk * charge[l], rstar, kappa)
        g = 0.0 if (l >> 1) == rod else g  # l >= 0: a shift, cheaper than the floor division of signed ints
        fx += g * dx
        fy += g * dy
        fz += g * dz
    return fx, fy, fz


@njit_parallel_sum
def tip_tip_direct(x, y, z, charge, rstar, kappa, lo, hi, out):
    """Force of all other rods' tips on the tips ``lo <= k < hi``, by direct summation.

    Parameters
    ----------
    x, y, z : (n_tips,) float64
        Tip coordinates.
    charge : (n_tips,) float64
        Magnetic charge of each tip (+q_i for tip a, -q_i for tip b).
    rstar, kappa : float
        Transition radius r* and core stiffness of the tip law.
    lo, hi : int
        Target rows, ``0 <= lo <= hi <= n_tips``. Each row's sum runs over all tips in the
        same order whatever the range, so a row does not depend on ``lo, hi`` (bit for bit).
    out : (n_tips, 3) float64
        Rows ``lo:hi`` overwritten with the force on those tips; other rows untouched.
        Parallel over tips (gather).
    """
    for k in prange(lo, hi):
        fx, fy, fz = _force_on_tip(k, x, y, z, charge, rstar, kappa)
        out[k, 0] = fx
        out[k, 1] = fy
        out[k, 2] = fz


#: tips per float32 partial sum of :func:`tip_tip_direct_mixed`, each added in float64
MIXED_BLOCK = 128

#: the mixed sum falls back to float64 when a coordinate lies farther than this from the tips'
#: box centre or a charge is outside [MIXED_CHARGE_MIN, MIXED_CHARGE_MAX] in magnitude (float32
#: products of charges and powers of 1/r would over- or underflow; reduced units keep all O(1))
MIXED_SPAN = 1e15
MIXED_CHARGE_MIN = 1e-15
MIXED_CHARGE_MAX = 1e15


@njit
def _tips_mixed(x, y, z, charge):
    """Tips packed for the mixed sum: ``(ok, pk, rod)``.

    ``pk`` (7, n) float32: rows 0-2 the hi and 3-5 the lo parts of ``x - origin`` (the centre of
    the tips' box), ``hi = float32(u)``, ``lo = float32(u - hi)``, which hold u to about 1e-14 of
    itself; row 6 the charge. ``rod`` (n,) int32, ``k >> 1``. ``ok`` False when a coordinate or a
    charge is outside what float32 holds here (:data:`MIXED_SPAN`, :data:`MIXED_CHARGE_MIN`,
    :data:`MIXED_CHARGE_MAX`), or not finite: then the caller sums in float64.
    """
    n = x.shape[0]
    pk = np.empty((7, n), np.float32)
    rod = np.empty(n, np.int32)
    ok = True
    origin = np.zeros(3)
    for d, c in enumerate((x, y, z)):
        lo = np.inf
        hi = -np.inf
        for k in range(n):
            lo = min(lo, c[k])
            hi = max(hi, c[k])
            ok = ok and math.isfinite(c[k])
        origin[d] = 0.5 * (lo + hi)
        ok = ok and (hi - lo) < 2.0 * MIXED_SPAN  # False for NaN and inf too
    for k in range(n):
        q = abs(charge[k])
        ok = ok and (q == 0.0 or (MIXED_CHARGE_MIN <= q <= MIXED_CHARGE_MAX))
    if not ok:
        return ok, pk, rod
    for k in range(n):
        for d, c in enumerate((x, y, z)):
            u = c[k] - origin[d]
            h = np.float32(u)
            pk[d, k] = h
            pk[3 + d, k] = np.float32(u - np.float64(h))
        pk[6, k] = np.float32(charge[k])
        rod[k] = np.int32(k >> 1)
    return ok, pk, rod


@inline_sum
def _force_on_tip_mixed(k, pk, rod, rstar, kappa):
    """:func:`_force_on_tip` with the law in float32 (:func:`~.laws.tip_force_over_r_f32`) on the
    packed tips of :func:`_tips_mixed`: float32 sums over blocks of :data:`MIXED_BLOCK` tips,
    each added in float64."""
    n = rod.shape[0]
    xh = pk[0, k]
    yh = pk[1, k]
    zh = pk[2, k]
    xl = pk[3, k]
    yl = pk[4, k]
    zl = pk[5, k]
    qk = pk[6, k]
    mine = rod[k]
    zero = np.float32(0.0)
    fx = 0.0
    fy = 0.0
    fz = 0.0
    # [perf] unsigned indices: numba checks a signed index for wraparound, and on AVX-512 targets
    # LLVM then loads the packed rows with gathers, 2.4 times slower than the AVX2 build's plain
    # loads (docs/performance.md 'Unsigned loop indices on AVX-512'); the same sums bit for bit
    block = np.uint64(MIXED_BLOCK)
    n_u = np.uint64(n)
    for l0 in range(np.uint64(0), n_u, block):
        gx = zero
        gy = zero
        gz = zero
        for l in range(l0, min(l0 + block, n_u)):
            # hi differences first: exact for close tips (Sterbenz), so dx keeps float32
            # precision relative to itself
            dx = (xh - pk[0, l]) + (xl - pk[3, l])
            dy = (yh - pk[1, l]) + (yl - pk[4, l])
            dz = (zh - pk[2, l]) + (zl - pk[5, l])
            g = tip_force_over_r_f32(dx * dx + dy * dy + dz * dz, qk * pk[6, l], rstar, kappa)
            g = zero if rod[l] == mine else g  # the tips of one rod: a select, so that the loop vectorises
            gx += g * dx
            gy += g * dy
            gz += g * dz
        fx += np.float64(gx)
        fy += np.float64(gy)
        fz += np.float64(gz)
    return fx, fy, fz


@njit_parallel_sum
def tip_tip_direct_mixed(x, y, z, charge, rstar, kappa, lo, hi, out):
    """:func:`tip_tip_direct` with the pair law in float32 (``forces.tip_magnetic.precision = "mixed"``).

    The same arguments and rows (a row does not depend on ``lo, hi``). Each tip's coordinates
    relative to the centre of the tips' box are float32 pairs hi + lo, so that the separations of
    close tips keep float32 precision relative to themselves wherever the scene is; the law runs
    on 8 float32 lanes and its sums over blocks of :data:`MIXED_BLOCK` tips are added in float64.
    Each force differs from the float64 sum by about 1e-7 of the largest pair force in it
    (docs/performance.md 'Mixed-precision direct tip-tip sum'). Falls back to the float64 sum,
    bit for bit, when coordinates or charges are outside what float32 holds (:func:`_tips_mixed`).
    """
    ok, pk, rod = _tips_mixed(x, y, z, charge)
    r32 = np.float32(rstar)
    k32 = np.float32(kappa)
    for k in prange(lo, hi):
        if ok:
            fx, fy, fz = _force_on_tip_mixed(k, pk, rod, r32, k32)
        else:
            fx, fy, fz = _force_on_tip(k, x, y, z, charge, rstar, kappa)
        out[k, 0] = fx
        out[k, 1] = fy
        out[k, 2] = fz


@njit_parallel_sum
def tip_tip_energy(x, y, z, charge, rstar, kappa, lo, hi, out):
    """Tip-tip potential energy by rows: ``out[k]`` sums the pairs of tip k with the tips of later rods.

    Summed over all rows, ``out`` gives the total energy with each pair of tips of different
    rods counted once. Parameters as :func:`tip_tip_direct`; ``out`` is (n_tips,) float64,
    rows ``lo:hi`` overwritten. One value per row (no reduction across rows) keeps the
    total independent of how rows are split over threads or ranks.
    """
    n = x.shape[0]
    m = hi - lo
    for t in prange(m):
        # row k has n - k pairs: rows taken from both ends in turn, so that equal blocks of t (the
        # threads' shares) hold equal work (2 threads at 12 000 tips: 1.31 times one, before, as rows
        # in order give one thread three quarters of the pairs)
        k = lo + t // 2 if t % 2 == 0 else hi - 1 - t // 2
        acc = 0.0
        for l in range(k - (k % 2) + 2, n):
            dx = x[k] - x[l]
            dy = y[k] - y[l]
            dz = z[k] - z[l]
            acc += tip_potential(dx * dx + dy * dy + dz * dz, charge[k] * charge[l], rstar, kappa)
        out[k] = acc


@njit_parallel_sum
def tip_tip_direct_rows(x, y, z, charge, rstar, kappa, row, out):
    """Force of all other rods' tips on the tips listed in ``row``, by direct summation.

    The same sum as :func:`tip_tip_direct` restricted to some targets: an oracle
    for large systems, where the full direct sum is too slow.

    Parameters
    ----------
    x, y, z, charge, rstar, kappa :
        As :func:`tip_tip_direct`.
    row : (n_rows,) int64
        Target tip numbers, each in ``[0, n_tips)`` (checked by the caller).
    out : (n_rows, 3) float64
        Overwritten: ``out[j]`` is the force on tip ``row[j]``.
    """
    for j in prange(row.shape[0]):
        fx, fy, fz = _force_on_tip(row[j], x, y, z, charge, rstar, kappa)
        out[j, 0] = fx
        out[j, 1] = fy
        out[j, 2] = fz


@inline
def fast_switch(r2, r_in, r_out):
    """Share of a tip pair's force counted as fast in multiple time stepping (``integrator.slow_every``).

    ``S = 1`` for ``r <= r_in``, ``S = 0`` for ``r >= r_out``, and the smoothstep
    ``1 - s^2 (3 - 2 s)``, ``s = (r - r_in) / (r_out - r_in)``, in between: S and dS/dr are
    continuous, so neither the fast nor the slow part jumps when a pair crosses the range.
    """
    if r2 <= r_in * r_in:
        return 1.0
    if r2 >= r_out * r_out:
        return 0.0
    s = (math.sqrt(r2) - r_in) / (r_out - r_in)
    return 1.0 - s * s * (3.0 - 2.0 * s)


@njit_rows
def tip_tip_fast(position, charge, start, index, rstar, kappa, r_in, r_out, out):
    """Fast part ``S(r) f(r)`` of the tip-tip force (docs/model.md 'Term 1') over a tip neighbour list.

    Multiple time stepping splits each pair's force as ``S f + (1 - S) f`` with the switch
    :func:`fast_switch`; this kernel sums the first part, which holds the stiff core and the
    steep Coulomb attraction of tips about to touch, and is evaluated every step.

    Parameters
    ----------
    position : (n_tips, 3) float64
    charge : (n_tips,) float64
    start, index : int64 offsets and int32 or int64 entries (``cells.list_dtype``)
        Compressed-row tip neighbour list (both directions, tips of one rod excluded,
        covering at least ``r_out``).
    rstar, kappa : float
        Transition radius and core stiffness of the tip law.
    r_in, r_out : float
        Range of the switch, ``r_in < r_out``.
    out : (n_tips, 3) float64
        Overwritten with the fast force on each tip.
    """
    n = position.shape[0]
    for k in prange(n):
        _tip_fast_row(position, charge, start, index, rstar, kappa, r_in, r_out, position[k], charge[k], k, out[k])


@inline
def _tip_fast_row(position, charge, start, index, rstar, kappa, r_in, r_out, p, q, k, out):
    """Row ``k`` of :func:`tip_tip_fast` (``p`` its position, ``q`` its charge, ``out`` its output row)."""
    fx = 0.0
    fy = 0.0
    fz = 0.0
    for j in range(start[k], start[k + 1]):
        l = index[j]
        dx = p[0] - position[l, 0]
        dy = p[1] - position[l, 1]
        dz = p[2] - position[l, 2]
        r2 = dx * dx + dy * dy + dz * dz
        if r2 < r_out * r_out:
            g = tip_force_over_r(r2, q * charge[l], rstar, kappa) * fast_switch(r2, r_in, r_out)
            fx += g * dx
            fy += g * dy
            fz += g * dz
    out[0] = fx
    out[1] = fy
    out[2] = fz


@njit
def tip_tip_fast_rows(position, charge, start, index, rstar, kappa, r_in, r_out, lo, hi, out):
    """:func:`tip_tip_fast` of the tips ``lo`` to ``hi`` only (rows of ``out`` past them untouched), serial.

    The rows are read through slices from ``lo`` (a loop from 0): a loop over ``range(lo, hi)`` was
    1.13 times slower (75 against 66 us for the 12 000 tips of the Fig. 6 scene at t = 100, Zen 5)."""
    own, q, s, o = position[lo:hi], charge[lo:hi], start[lo : hi + 1], out[lo:hi]
    for i in range(hi - lo):
        _tip_fast_row(position, charge, s, index, rstar, kappa, r_in, r_out, own[i], q[i], i, o[i])
