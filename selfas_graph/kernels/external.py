"""Fixed external objects of case (ii) (docs/model.md 'Term 11'): a straight current filament on
the z axis and a large magnetic dipole on it, with monopoles at its ends and a screened
line charge along it.

Derivation of the line-charge force. A line charge of density lambda on the z axis from
z1 to z2, seen from a rod centre P = (x, y, z_p) with rod charge Z, gives the screened
potential ``U = Z lambda int g(r) dz'`` with ``g(r) = exp(-r/R) / r``. The line is given the
radius w of the filament: ``r^2 = rho^2 + w^2 + (z' - z_p)^2`` (rho the distance of P to the
axis), which keeps U finite on the axis. With ``rho_e^2 = rho^2 + w^2`` and the substitution
``z' - z_p = rho_e sinh(u)``, ``dz' = rho_e cosh(u) du`` and ``r = rho_e cosh(u)``, so

    U = Z lambda int exp(-rho_e cosh(u) / R) du,
    F = -grad U = Z lambda int f(r) (x, y, -rho_e sinh(u)) du,   f(r) = exp(-r/R)(1/r^2 + 1/(R r)),

over ``u`` from ``asinh((z1 - z_p)/rho_e)`` to ``asinh((z2 - z_p)/rho_e)``. In u the integrand is
smooth and its peak at the foot of the perpendicular is resolved, so Gauss-Legendre with a
few tens of nodes converges fast (the number of nodes is an accuracy knob).
"""

import math

import numpy as np

from ._jit import inline, njit_parallel, njit_rows, prange
from .laws import tip_force_over_r, tip_potential


@inline
def filament_field_at(px, py, current, w):
    """Field of the straight filament on the z axis, current along +z (docs/model.md 'Term 11').

    ``B = 2 J rho / (rho^2 + w^2) phi_hat``; returns (Bx, By), Bz = 0.
    """
    c = 2.0 * current / (px * px + py * py + w * w)
    return -c * py, c * px


@njit_rows
def filament_field(point, current, w, out):
    """Filament field at points (m, 3); ``out`` (m, 3) overwritten."""
    for k in prange(point.shape[0]):
        bx, by = filament_field_at(point[k, 0], point[k, 1], current, w)
        out[k, 0] = bx
        out[k, 1] = by
        out[k, 2] = 0.0


@njit_rows
def filament_force_on_tips(position, charge, current, w, out):
    """``F_k = q_k B_fil(x_k)``; ``out`` (n_tips, 3) overwritten."""
    for k in prange(position.shape[0]):
        bx, by = filament_field_at(position[k, 0], position[k, 1], current, w)
        out[k, 0] = charge[k] * bx
        out[k, 1] = charge[k] * by
        out[k, 2] = 0.0


@njit_rows
def monopoles_on_tips(position, velocity, charge, source, source_charge, rstar, kappa, k_br, out_force, out_brake):
    """Fixed magnetic monopoles acting on tips with the tip law and brake of terms 1-2.

    Parameters
    ----------
    position, velocity : (n_tips, 3) float64
    charge : (n_tips,) float64
    source : (m, 3) float64
        Fixed monopole positions (velocity zero).
    source_charge : (m,) float64
    rstar, kappa, k_br : float
    out_force, out_brake : (n_tips, 3) float64
        Overwritten with the conservative part and the brake.
    """
    rs2 = rstar * rstar
    for k in prange(position.shape[0]):
        fx = 0.0
        fy = 0.0
        fz = 0.0
        touching = 0.0
        for j in range(source.shape[0]):
            dx = position[k, 0] - source[j, 0]
            dy = position[k, 1] - source[j, 1]
            dz = position[k, 2] - source[j, 2]
            r2 = dx * dx + dy * dy + dz * dz
            g = tip_force_over_r(r2, charge[k] * source_charge[j], rstar, kappa)
            fx += g * dx
            fy += g * dy
            fz += g * dz
            if r2 < rs2:
                touching += 1.0
        out_force[k, 0] = fx
        out_force[k, 1] = fy
        out_force[k, 2] = fz
        for d in range(3):
            out_brake[k, d] = -k_br * touching * velocity[k, d]


@njit_parallel
def monopoles_energy(position, charge, source, source_charge, rstar, kappa):
    """Potential energy of tips in the field of fixed monopoles (tip law of term 1); summed in tip
    order after the parallel loop, so the total does not depend on the thread count."""
    n = position.shape[0]
    per_tip = np.empty(n)
    for k in prange(n):
        acc = 0.0
        for j in range(source.shape[0]):
            dx = position[k, 0] - source[j, 0]
            dy = position[k, 1] - source[j, 1]
            dz = position[k, 2] - source[j, 2]
            acc += tip_potential(dx * dx + dy * dy + dz * dz, charge[k] * source_charge[j], rstar, kappa)
        per_tip[k] = acc
    total = 0.0
    for k in range(n):
        total += per_tip[k]
    return total


@njit_rows
def monopole_field(point, source, source_charge, rstar, out):
    """Magnetic field of fixed monopoles at points: ``Q d / r^3``, ``Q d / r*^3`` inside r* (a smeared charge)."""
    for k in prange(point.shape[0]):
        bx = 0.0
        by = 0.0
        bz = 0.0
        for j in range(source.shape[0]):
            dx = point[k, 0] - source[j, 0]
            dy = point[k, 1] - source[j, 1]
            dz = point[k, 2] - source[j, 2]
            g = tip_force_over_r(dx * dx + dy * dy + dz * dz, source_charge[j], rstar, 0.0)
            bx += g * dx
            by += g * dy
            bz += g * dz
        out[k, 0] = bx
        out[k, 1] = by
        out[k, 2] = bz


@njit_rows
def line_yukawa_on_centres(centre, rod_charge, z1, z2, lam, screening, w, nodes, weights, out):
    """Screened repulsion of a line charge on the z axis from z1 to z2 on rod centres (see module docstring).

    Parameters
    ----------
    centre : (n_rods, 3) float64
    rod_charge : (n_rods,) float64
    z1, z2, lam, screening, w : float
        Line ends, charge density, screening length R_Dext and filament radius.
    nodes, weights : (n,) float64
        Gauss-Legendre nodes and weights on [0, 1].
    out : (n_rods, 3) float64
        Overwritten with the force on each rod centre.
    """
    for i in prange(centre.shape[0]):
        x = centre[i, 0]
        y = centre[i, 1]
        zp = centre[i, 2]
        rho_e = math.sqrt(x * x + y * y + w * w)
        u1 = math.asinh((z1 - zp) / rho_e)
        u2 = math.asinh((z2 - zp) / rho_e)
        span = u2 - u1
        sx = 0.0
        sz = 0.0
        for g in range(nodes.shape[0]):
            u = u1 + span * nodes[g]
            r = rho_e * math.cosh(u)
            f = math.exp(-r / screening) * (1.0 / (r * r) + 1.0 / (screening * r))
            sx += weights[g] * f
            sz -= weights[g] * f * rho_e * math.sinh(u)
        c = rod_charge[i] * lam * span
        out[i, 0] = c * sx * x
        out[i, 1] = c * sx * y
        out[i, 2] = c * sz


@njit_parallel
def line_yukawa_energy(centre, rod_charge, z1, z2, lam, screening, w, nodes, weights):
    """Potential energy of the rod charges in the screened line charge (see module docstring); summed
    in rod order after the parallel loop, so the total does not depend on the thread count."""
    n = centre.shape[0]
    per_rod = np.empty(n)
    for i in prange(n):
        x = centre[i, 0]
        y = centre[i, 1]
        zp = centre[i, 2]
        rho_e = math.sqrt(x * x + y * y + w * w)
        u1 = math.asinh((z1 - zp) / rho_e)
        u2 = math.asinh((z2 - zp) / rho_e)
        acc = 0.0
        for g in range(nodes.shape[0]):
            u = u1 + (u2 - u1) * nodes[g]
            acc += weights[g] * math.exp(-rho_e * math.cosh(u) / screening)
        per_rod[i] = rod_charge[i] * lam * (u2 - u1) * acc
    total = 0.0
    for i in range(n):
        total += per_rod[i]
    return total
