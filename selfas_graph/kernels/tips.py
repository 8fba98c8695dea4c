"""Tip-tip magnetic force (MODEL.md term 1) as a direct sum over all tip pairs.

Tips are numbered ``2 i`` and ``2 i + 1`` for rod ``i``; the two tips of one
rod do not interact (their bond is rigid). Positions come as three separate
coordinate arrays (structure of arrays) so that the inner loop vectorises;
the "same rod" pair is removed by a select, not a branch.
"""
from ._jit import njit_parallel_sum, prange
from .laws import tip_force_over_r, tip_potential


@njit_parallel_sum
def tip_tip_direct(x, y, z, charge, rstar, kappa, out):
    """Force of all other rods' tips on every tip, by direct summation.

    Parameters
    ----------
    x, y, z : (n_tips,) float64
        Tip coordinates.
    charge : (n_tips,) float64
        Magnetic charge of each tip (+q_i for tip a, -q_i for tip b).
    rstar, kappa : float
        Transition radius r* and core stiffness of the tip law.
    out : (n_tips, 3) float64
        Overwritten with the force on each tip. Parallel over tips (gather).
    """
    n = x.shape[0]
    for k in prange(n):
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
            g = 0.0 if l // 2 == rod else g
            fx += g * dx
            fy += g * dy
            fz += g * dz
        out[k, 0] = fx
        out[k, 1] = fy
        out[k, 2] = fz


@njit_parallel_sum
def tip_tip_energy(x, y, z, charge, rstar, kappa):
    """Total tip-tip potential energy, each pair of tips of different rods once.

    Parameters as :func:`tip_tip_direct`. Returns a float.
    """
    n = x.shape[0]
    total = 0.0
    for k in prange(n):
        acc = 0.0
        for l in range(k - (k % 2) + 2, n):
            dx = x[k] - x[l]
            dy = y[k] - y[l]
            dz = z[k] - z[l]
            acc += tip_potential(dx * dx + dy * dy + dz * dz, charge[k] * charge[l], rstar, kappa)
        total += acc
    return total


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
    n = x.shape[0]
    for j in prange(row.shape[0]):
        k = row[j]
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
            g = 0.0 if l // 2 == rod else g
            fx += g * dx
            fy += g * dy
            fz += g * dz
        out[j, 0] = fx
        out[j, 1] = fy
        out[j, 2] = fz
