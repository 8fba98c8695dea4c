"""Rigid massless bond between the two tips of each rod (paper Eqs. 5-9, 14-15; docs/model.md 'Rigid rods and time integration').

Derivation of the exact bond force. With ``r12 = x_a - x_b``, ``v12 = v_a - v_b``,
equal tip masses m, and external forces F_a, F_b, the tips move as
``m a_a = F_a - A r12`` and ``m a_b = F_b + A r12`` (paper Eqs. 5-6). Then
``d2 r12/dt2 = G - (2 A / m) r12`` with ``G = (F_a - F_b) / m``. Keeping
``|r12|`` constant needs ``(r12, v12) = 0`` at all times, whose time derivative is
``(d2 r12/dt2, r12) + |v12|^2 = 0``. Solving for A:

    A = mu ((G, r12) + |v12|^2) / |r12|^2,   mu = m / 2.

The paper's Eq. (9) drops ``|v12|^2`` (it imposes ``(d2 r12/dt2, r12) = 0``);
that variant is kept as ``exact=False`` for comparison. Masses are 1 (reduced units).
The bond force holds whatever length the bond has, so it serves rods of any length.

Rod lengths. ``length`` is an ``(n_rods,)`` array of the lengths l_i the bonds keep
(units L, docs/model.md 'Rods'), or an empty array when every rod has length 1:
then the kernels compute exactly what they did before per-rod lengths existed
(``1.0 / sqrt(r2)`` and ``l_i / sqrt(r2)`` with l_i = 1 are the same float).
"""

import math

from ._jit import inline, njit_rows, prange


@njit_rows
def bond_acceleration(force, velocity, position, exact, out):
    """Tip accelerations with the rigid-bond force added.

    Parameters
    ----------
    force : (n_tips, 3) float64
        Total external force on each tip (centre forces already shared by mass).
    velocity, position : (n_tips, 3) float64
    exact : bool
        True for the exact bond force, False for the paper's Eq. (9).
    out : (n_tips, 3) float64
        Overwritten with the accelerations (unit masses).
    """
    n_rods = position.shape[0] // 2
    for i in prange(n_rods):
        a = 2 * i
        b = a + 1
        g_r = 0.0
        v2 = 0.0
        r2 = 0.0
        for d in range(3):
            r = position[a, d] - position[b, d]
            v = velocity[a, d] - velocity[b, d]
            g_r += (force[a, d] - force[b, d]) * r
            v2 += v * v
            r2 += r * r
        if not exact:
            v2 = 0.0
        lam = 0.5 * (g_r + v2) / r2
        for d in range(3):
            r = position[a, d] - position[b, d]
            out[a, d] = force[a, d] - lam * r
            out[b, d] = force[b, d] + lam * r


@njit_rows
def bond_length_error(position, length):
    """Largest ``| |x_a - x_b| - l_i |`` over all rods (``length`` empty: l_i = 1)."""
    n_rods = position.shape[0] // 2
    return worst_bond_error(position[: 2 * n_rods].reshape(n_rods, 6), length)


@inline
def worst_bond_error(rods, length):
    """:func:`bond_length_error` of rods given as rows of six (tip a's x, y, z, then tip b's): a loop
    from 0 with constant columns, which a loop over each rod's two tip rows is not."""
    unit = length.shape[0] == 0
    worst = 0.0
    for i in prange(rods.shape[0]):
        r2 = 0.0
        for d in range(3):
            r = rods[i, d] - rods[i, d + 3]
            r2 += r * r
        ell = 1.0 if unit else length[i]
        worst = max(worst, abs(math.sqrt(r2) - ell))
    return worst


@njit_rows
def constrain_bonds(position, velocity, project, correct_velocity, length):
    """Restore the rigid bonds after an integration step, in place.

    ``project``: move both tips along the axis, about the rod centre, so that
    ``|r12| = l_i`` (the paper leaves positions uncorrected). ``correct_velocity``:
    paper Eqs. (14-15), ``v_a += c r12``, ``v_b -= c r12`` with c chosen so that
    ``(v12, r12) = 0``; equal masses share it, so momentum is unchanged.

    Parameters
    ----------
    position, velocity : (n_tips, 3) float64, modified in place
    project, correct_velocity : bool
    length : (n_rods,) float64, or empty for rods of length 1
    """
    n_rods = position.shape[0] // 2
    unit = length.shape[0] == 0
    p = position.reshape(n_rods, 6)
    w = velocity.reshape(n_rods, 6)
    for i in prange(n_rods):
        _constrain_row(p[i], w[i], project, correct_velocity, 1.0 if unit else length[i])


@njit_rows
def constrain_bonds_checked(position, velocity, project, correct_velocity, length):
    """:func:`constrain_bonds`, then :func:`bond_length_error`, and the largest velocity component
    ``max |v_k,d|`` (what the run's health check reads), in one pass, bit for bit as the separate calls.

    Parameters as :func:`constrain_bonds` (both flags False: only the two maxima).

    Returns
    -------
    (float, float)
        The largest bond-length error after the constraint, and the largest ``|v_k,d|`` after it
        (NaN if any velocity component is NaN, as numpy's ``np.abs(v).max()``; 0 without rods).
    """
    n_rods = position.shape[0] // 2
    unit = length.shape[0] == 0
    # a rod as a row of six (tip a's x, y, z, then tip b's), each loop from 0 with constant columns,
    # and the largest velocity over the flat array in a loop of its own (the same maxima: a maximum
    # does not depend on the order it is taken in): `bench kernels --kernels constraint`, 6000 rods, one
    # thread, Zen 5: 79 against 102 us for the loop over the tips of each rod, the AVX2 build alike
    p = position.reshape(n_rods, 6)
    w = velocity.reshape(n_rods, 6)
    worst = 0.0
    for i in prange(n_rods):
        ell = 1.0 if unit else length[i]
        # r2 is that of the positions as they leave: the sum bond_length_error forms
        r2 = _constrain_row(p[i], w[i], project, correct_velocity, ell)
        worst = max(worst, abs(math.sqrt(r2) - ell))
    flat = velocity.reshape(-1)
    fastest = 0.0
    n_nan = 0
    for k in prange(6 * n_rods):
        u = abs(flat[k])
        if u != u:
            n_nan += 1
        else:
            fastest = max(fastest, u)
    if n_nan:
        return worst, math.nan
    return worst, fastest


@inline
def _constrain_row(p, w, project, correct_velocity, ell):
    """The constraint of one rod (:func:`constrain_bonds`), a row of six positions ``p`` and
    velocities ``w`` (tip a's x, y, z, then tip b's), in place; returns ``|r12|^2`` of the positions as they leave."""
    r2 = 0.0
    for d in range(3):
        r = p[d] - p[d + 3]
        r2 += r * r
    if project:
        s = 0.5 * (ell / math.sqrt(r2) - 1.0)
        for d in range(3):
            r = p[d] - p[d + 3]
            p[d] += s * r
            p[d + 3] -= s * r
        r2 = 0.0
        for d in range(3):
            r = p[d] - p[d + 3]
            r2 += r * r
    if correct_velocity:
        vr = 0.0
        for d in range(3):
            vr += (w[d] - w[d + 3]) * (p[d] - p[d + 3])
        c = -0.5 * vr / r2
        for d in range(3):
            r = p[d] - p[d + 3]
            w[d] += c * r
            w[d + 3] -= c * r
    return r2


@njit_rows
def rod_centres(position, out):
    """Rod centres, the mean of each rod's two tips: ``out[i] = 0.5 (x_2i + x_2i+1)``.

    The same numbers as numpy's ``0.5 * (position[0::2] + position[1::2])``, bit for bit, about a
    tenth of its time at 24 000 rods (numpy's strided views: 374 against 31 us, Zen 4).

    Parameters
    ----------
    position : (n_tips,) rows of 3 float64 (rod i's tips are rows 2 i and 2 i + 1)
    out : (n_tips // 2, 3) float64, overwritten
    """
    for i in prange(out.shape[0]):
        for d in range(3):
            out[i, d] = 0.5 * (position[2 * i, d] + position[2 * i + 1, d])


@njit_rows
def share_by_mass(centre_force, tip_out):
    """A force on a rod centre goes half to each of its tips (equal masses; paper Eqs. 5-6):
    ``tip_out[2 i] = tip_out[2 i + 1] = 0.5 centre_force[i]``, the numbers of numpy's two strided
    assignments, bit for bit, in a tenth of their time at 24 000 rods (430 against 41 us, Zen 4).

    Parameters
    ----------
    centre_force : (n_rods, 3) float64
    tip_out : (2 n_rods, 3) float64, overwritten
    """
    for i in prange(centre_force.shape[0]):
        for d in range(3):
            half = 0.5 * centre_force[i, d]
            tip_out[2 * i, d] = half
            tip_out[2 * i + 1, d] = half
