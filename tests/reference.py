"""Slow, obviously-correct references for the engine kernels (pure numpy / Python loops).

Each follows docs/model.md 'Force terms' or 'Rigid rods and time integration' literally; the kernels must agree with them
to round-off.
"""
import math

import numpy as np


def tip_law(r, p, rstar, kappa):
    """f(r) of term 1 (positive = repulsive)."""
    if r >= rstar:
        return p / r**2
    return p * r / rstar**3 + kappa * (rstar - r) / rstar**3


def tip_law_potential(r, p, rstar, kappa):
    if r >= rstar:
        return p / r
    return p * (3 * rstar**2 - r**2) / (2 * rstar**3) + kappa * (rstar - r) ** 2 / (2 * rstar**3)


def tip_tip_force(position, charge, rstar, kappa):
    n = len(position)
    out = np.zeros((n, 3))
    for k in range(n):
        for l in range(n):
            if k // 2 == l // 2:
                continue
            d = position[k] - position[l]
            r = np.linalg.norm(d)
            if r > 0:
                out[k] += tip_law(r, charge[k] * charge[l], rstar, kappa) * d / r
    return out


def tip_tip_energy(position, charge, rstar, kappa):
    n = len(position)
    return sum(tip_law_potential(np.linalg.norm(position[k] - position[l]), charge[k] * charge[l], rstar, kappa)
               for k in range(n) for l in range(k + 1, n) if k // 2 != l // 2)


def tip_brake(position, velocity, rstar, k_br):
    n = len(position)
    out = np.zeros((n, 3))
    for k in range(n):
        for l in range(n):
            if k // 2 != l // 2 and np.linalg.norm(position[k] - position[l]) < rstar:
                out[k] -= k_br * (velocity[k] - velocity[l])
    return out


def _yukawa_f(r, zz, screening, core):
    """Term 6 magnitude; inside the core radius it falls linearly, f(r_c) r / r_c."""
    if r < core:
        return _yukawa_f(core, zz, screening, 0.0) * r / core
    return zz * math.exp(-r / screening) * (1 / r**2 + 1 / (screening * r))


def _yukawa_u(r, zz, screening, core):
    if r < core:
        return _yukawa_u(core, zz, screening, 0.0) + _yukawa_f(core, zz, screening, 0.0) * (core**2 - r**2) / (2 * core)
    return zz * math.exp(-r / screening) / r


def yukawa_force(centre, z, screening, cutoff, core=0.0):
    n = len(centre)
    out = np.zeros((n, 3))
    for i in range(n):
        for j in range(n):
            d = centre[i] - centre[j]
            r = np.linalg.norm(d)
            if i != j and r < cutoff:
                out[i] += _yukawa_f(r, z[i] * z[j], screening, core) * d / r
    return out


def yukawa_energy(centre, z, screening, cutoff, core=0.0):
    n = len(centre)
    total = 0.0
    for i in range(n):
        for j in range(i + 1, n):
            r = np.linalg.norm(centre[i] - centre[j])
            if r < cutoff:
                zz = z[i] * z[j]
                total += _yukawa_u(r, zz, screening, core) - _yukawa_u(cutoff, zz, screening, core)
    return total


def plasma_field(point, x0, y0, radius, current):
    out = np.zeros_like(point)
    for k, p in enumerate(point):
        dx, dy = p[0] - x0, p[1] - y0
        rho = math.hypot(dx, dy)
        mag = 2 * current * rho / radius**2 if rho <= radius else 2 * current / rho
        if rho > 0:
            out[k] = mag * np.array([-dy / rho, dx / rho, 0.0])
    return out


def electrode_walls(position, velocity, z_lo, z_hi, rstar, kappa, k_br):
    push = np.zeros_like(position)
    brake = np.zeros_like(position)
    for k, (p, v) in enumerate(zip(position, velocity)):
        for h, sign in ((p[2] - z_lo, +1.0), (z_hi - p[2], -1.0)):
            if h < rstar:
                push[k, 2] += sign * kappa * (rstar - h) / rstar**3
                brake[k] -= k_br * v
    return push, brake


def bond_acceleration(force, velocity, position, exact):
    """Paper Eqs. (5-6) with A from docs/model.md 'Rigid rods and time integration' (exact) or paper Eq. (9)."""
    out = np.empty_like(force)
    for i in range(len(position) // 2):
        a, b = 2 * i, 2 * i + 1
        r12 = position[a] - position[b]
        v12 = velocity[a] - velocity[b]
        G = force[a] - force[b]
        A = 0.5 * (G @ r12 + (v12 @ v12 if exact else 0.0)) / (r12 @ r12)
        out[a] = force[a] - A * r12
        out[b] = force[b] + A * r12
    return out


def constrain_bonds(position, velocity, project, correct_velocity, length=None):
    x, v = position.copy(), velocity.copy()
    for i in range(len(x) // 2):
        a, b = 2 * i, 2 * i + 1
        ell = 1.0 if length is None else length[i]
        if project:
            c = 0.5 * (x[a] + x[b])
            u = (x[a] - x[b]) / np.linalg.norm(x[a] - x[b])
            x[a], x[b] = c + 0.5 * ell * u, c - 0.5 * ell * u
        if correct_velocity:
            r12 = x[a] - x[b]
            vc = -((v[a] - v[b]) @ r12) / (2 * (r12 @ r12))  # solves paper Eq. (15)
            v[a], v[b] = v[a] + vc * r12, v[b] - vc * r12
    return x, v
