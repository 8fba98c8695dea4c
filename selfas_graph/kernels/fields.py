"""One-body terms: fields of fixed sources acting on tips (docs/model.md 'Term 4', 'Term 5', 'Term 8')."""

import numpy as np

from ._jit import inline, njit, njit_parallel, njit_rows, prange
from .integrate import dot_as_numpy
from .laws import wall_potential, wall_push


@inline
def plasma_field_at(px, py, x0, y0, radius, current):
    """Field of a straight plasma current along +z through (x0, y0) (docs/model.md 'Term 5').

    Uniform current density inside ``radius``: ``B = 2 I rho / R^2 phi_hat``
    inside and ``2 I / rho phi_hat`` outside, with ``phi_hat = (-y', x', 0) / rho``.
    Returns (Bx, By); Bz = 0. Finite on the axis (B = 0 there).
    """
    dx = px - x0
    dy = py - y0
    rho2 = dx * dx + dy * dy
    r2 = radius * radius
    if rho2 <= r2:
        c = 2.0 * current / r2
    else:
        c = 2.0 * current / rho2
    return -c * dy, c * dx


@njit_rows
def plasma_field(point, x0, y0, radius, current, out):
    """Plasma-filament field at points.

    Parameters
    ----------
    point : (m, 3) float64
    x0, y0, radius, current : float
        Axis position, radius R_plas and total current I_plas along +z.
    out : (m, 3) float64
        Overwritten with B at each point.
    """
    for k in prange(point.shape[0]):
        bx, by = plasma_field_at(point[k, 0], point[k, 1], x0, y0, radius, current)
        out[k, 0] = bx
        out[k, 1] = by
        out[k, 2] = 0.0


@njit_rows
def plasma_force_on_tips(position, charge, x0, y0, radius, current, out):
    """``F_k = q_k B_plas(x_k)`` (docs/model.md 'Term 5' on tips); ``out`` (n_tips, 3) overwritten."""
    for k in prange(position.shape[0]):
        bx, by = plasma_field_at(position[k, 0], position[k, 1], x0, y0, radius, current)
        out[k, 0] = charge[k] * bx
        out[k, 1] = charge[k] * by
        out[k, 2] = 0.0


@njit_rows
def uniform_force_on_tips(charge, B, out):
    """``F_k = q_k B`` of a uniform field (docs/model.md 'Term 4'); ``out`` (n_tips, 3) overwritten.

    One product per element, as numpy's broadcast ``charge[:, None] * B[None, :]`` (bit for bit).
    """
    for k in prange(charge.shape[0]):
        for d in range(3):
            out[k, d] = charge[k] * B[d]


@njit_rows
def electrode_walls(position, velocity, z_cathode, z_anode, rstar, kappa, k_br, out_push, out_brake):
    """Electrode planes at ``z_cathode < z_anode`` acting on tips (docs/model.md 'Term 8').

    A tip at distance ``h < r*`` from a plane (measured towards the gap, so h < 0
    beyond the plane) is pushed back into the gap with ``kappa (r* - h) / r*^3``
    and braked with ``-k_br v`` (once per plane it touches).

    Parameters
    ----------
    position, velocity : (n_tips, 3) float64
    z_cathode, z_anode : float
    rstar, kappa, k_br : float
    out_push, out_brake : (n_tips, 3) float64
        Overwritten with the elastic and the friction parts.
    """
    for k in prange(position.shape[0]):
        z = position[k, 2]
        h_low = z - z_cathode
        h_high = z_anode - z
        push = wall_push(h_low, rstar, kappa) - wall_push(h_high, rstar, kappa)
        touching = (1.0 if h_low < rstar else 0.0) + (1.0 if h_high < rstar else 0.0)
        out_push[k, 0] = 0.0
        out_push[k, 1] = 0.0
        out_push[k, 2] = push
        for d in range(3):
            out_brake[k, d] = -k_br * touching * velocity[k, d]


@njit_parallel
def electrode_energy(position, z_cathode, z_anode, rstar, kappa):
    """Elastic energy of the electrode walls (potential of the push in :func:`electrode_walls`).

    One value per tip, summed in tip order afterwards: the total does not depend on the thread
    count (a ``prange`` reduction adds per-thread partial sums, whose order does).
    """
    n = position.shape[0]
    per_tip = np.empty(n)
    for k in prange(n):
        z = position[k, 2]
        per_tip[k] = wall_potential(z - z_cathode, rstar, kappa) + wall_potential(z_anode - z, rstar, kappa)
    total = 0.0
    for k in range(n):
        total += per_tip[k]
    return total


@njit
def electrode_brake_exact(position, velocity, z_cathode, z_anode, rstar, decay, before, after):
    """The exact electrode brake over one step (``integrator.brake = "split"``, docs/model.md 'Term 8').

    A tip within r* of ``n`` planes (n = 1 or 2; ``h < r*`` as in :func:`electrode_walls`) has its
    velocity multiplied by ``decay[n]``, which the caller computes once as ``exp(-n k_br dt)``.
    The work done is the change of the kinetic energy of the touched tips: their velocities, in tip
    order, are copied to the first m rows of ``before`` and ``after``, whose kinetic energies are
    summed as numpy's ``0.5 * np.einsum("ij,ij->", u, u)`` of those rows sums them
    (:func:`~.integrate.dot_as_numpy`), bit for bit.

    Parameters
    ----------
    position : (n_tips, 3) float64
    velocity : (n_tips, 3) float64, modified in place
    z_cathode, z_anode, rstar : float
    decay : (3,) float64
        Factor per number of planes touched (entry 0 unused).
    before, after : (n_tips, 3) float64
        Scratch rows, overwritten.

    Returns
    -------
    (float, int)
        The work done (0.0 when m = 0) and m, the number of tips touching a plane.
    """
    m = 0
    for k in range(position.shape[0]):
        z = position[k, 2]
        n = (1 if z - z_cathode < rstar else 0) + (1 if z_anode - z < rstar else 0)
        if n:
            f = decay[n]
            for d in range(3):
                before[m, d] = velocity[k, d]
                velocity[k, d] = velocity[k, d] * f
                after[m, d] = velocity[k, d]
            m += 1
    if not m:
        return 0.0, 0
    flat_before, flat_after = before.reshape(-1), after.reshape(-1)
    kinetic_after = 0.5 * dot_as_numpy(flat_after, flat_after, 3 * m)
    kinetic_before = 0.5 * dot_as_numpy(flat_before, flat_before, 3 * m)
    return kinetic_after - kinetic_before, m
