"""Tip-tip magnetic force (docs/model.md 'Term 1') as a direct sum over all tip pairs.

Tips are numbered ``2 i`` and ``2 i + 1`` for rod ``i``; the two tips of one
rod do not interact (their bond is rigid). Positions come as three separate
coordinate arrays (structure of arrays) so that the inner loop vectorises;
the "same rod" pair is removed by a select, not a branch.
"""

import math

from ._jit import inline, inline_sum, njit_parallel_sum, njit_rows, prange
from .laws import tip_force_over_r, tip_potential


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


@njit_parallel_sum
def tip_tip_energy(x, y, z, charge, rstar, kappa, lo, hi, out):
    """Tip-tip potential energy by rows: ``out[k]`` sums the pairs of tip k with the tips of later rods.

    Summed over all rows, ``out`` gives the total energy with each pair of tips of different
    rods counted once. Parameters as :func:`tip_tip_direct`; ``out`` is (n_tips,) float64,
    rows ``lo:hi`` overwritten. One value per row (no reduction across rows) keeps the
    total independent of how rows are split over threads or ranks.
    """
    n = x.shape[0]
    for k in prange(lo, hi):
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
    start, index : int64 arrays
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
        fx = 0.0
        fy = 0.0
        fz = 0.0
        for j in range(start[k], start[k + 1]):
            l = index[j]
            dx = position[k, 0] - position[l, 0]
            dy = position[k, 1] - position[l, 1]
            dz = position[k, 2] - position[l, 2]
            r2 = dx * dx + dy * dy + dz * dz
            if r2 < r_out * r_out:
                g = tip_force_over_r(r2, charge[k] * charge[l], rstar, kappa) * fast_switch(r2, r_in, r_out)
                fx += g * dx
                fy += g * dy
                fz += g * dz
        out[k, 0] = fx
        out[k, 1] = fy
        out[k, 2] = fz
