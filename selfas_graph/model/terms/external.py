"""The fixed external objects of case (ii) (docs/model.md 'Term 11'): a current filament on the
z axis and a large dipole on it. Both are also sources of the field that the Lorentz force on
rod currents feels (:class:`~selfas_graph.model.terms.base.FieldSource`).
"""

from __future__ import annotations

import numpy as np

from ...kernels import external as kx
from ...kernels import lorentz as kl
from .base import FieldSource, Term, kinetic, share_by_mass


def external_monopoles(d):
    """Positions (2, 3) and charges (2,) of the external dipole's end monopoles (moment along +z)."""
    source = np.array([[0.0, 0.0, 0.5 * d.length], [0.0, 0.0, -0.5 * d.length]])
    return source, np.array([d.magnetic_charge, -d.magnetic_charge])


class ExternalFilamentForce(Term, FieldSource):
    """Term 11: q_k B of the fixed filament on the z axis (not conservative: the field circles the axis)."""

    name = "external_filament"
    channels = [("external_filament", False)]
    keys = {"external_filament": ("forces.external_filament.current", "forces.external_filament.diameter")}

    def __init__(self, p, state):
        f = p.forces.external_filament
        self.current, self.w = f.current, f.radius

    def compute(self, ctx, out):
        kx.filament_force_on_tips(ctx.position, ctx.tip_charge, self.current, self.w, out["external_filament"])

    def field_at(self, points, out):
        kx.filament_field(points, self.current, self.w, out)


class ExternalDipoleForce(Term, FieldSource):
    """Term 11: the dipole's end monopoles on tips (tip law and brake). Its field (:meth:`field_at`) is
    that of the two monopoles, smeared inside r*. Its screened line charge is the term that follows it,
    :class:`ExternalLineChargeForce`, built from the same scenario table."""

    name = "external_dipole"
    channels = [("external_monopoles", True), ("external_monopole_brake", False)]
    keys = {
        "external_monopoles": (
            "forces.external_dipole.magnetic_charge",
            "forces.external_dipole.length",
            "rods.magnetic_charge",
            "rods.tip_stiffness",
        ),
        "external_monopole_brake": ("forces.tip_brake.coefficient", "forces.external_dipole.length"),
    }

    def __init__(self, p, state):
        d = p.forces.external_dipole
        self.source, self.source_charge = external_monopoles(d)
        self.rstar, self.kappa = p.rods.rstar, p.rods.tip_stiffness
        self.k = p.forces.tip_brake.coefficient if p.forces.tip_brake is not None else 0.0
        self.split_mode = p.integrator.brake == "split"

    def compute(self, ctx, out):
        k = 0.0 if self.split_mode else self.k
        kx.monopoles_on_tips(
            ctx.position,
            ctx.velocity,
            ctx.tip_charge,
            self.source,
            self.source_charge,
            self.rstar,
            self.kappa,
            k,
            out["external_monopoles"],
            out["external_monopole_brake"],
        )

    def field_at(self, points, out):
        kx.monopole_field(points, self.source, self.source_charge, self.rstar, out)

    def split(self, ctx, dt):
        d2 = ((ctx.position[:, None, :] - self.source[None, :, :]) ** 2).sum(axis=-1)
        touching = (d2 < self.rstar**2).sum(axis=1).astype(np.float64)
        tips = np.flatnonzero(touching)
        if not len(tips) or self.k == 0.0:
            return {}
        before = kinetic(ctx.velocity, tips)
        ctx.velocity[tips] *= np.exp(-self.k * touching[tips] * dt)[:, None]
        return {"external_monopole_brake": kinetic(ctx.velocity, tips) - before}

    def energy(self, ctx):
        return {
            "external_monopoles": kx.monopoles_energy(
                ctx.position, ctx.tip_charge, self.source, self.source_charge, self.rstar, self.kappa
            )
        }


class ExternalLineChargeForce(Term):
    """Term 11: the external dipole's screened line charge on rod charges, shared half to each tip
    (``[forces.external_dipole]``, built after :class:`ExternalDipoleForce`). A slow term when
    ``forces.external_dipole.line_charge_slow`` is set (with ``integrator.slow_every > 1``)."""

    name = "external_line_charge"
    channels = [("external_line_charge", True)]
    keys = {
        "external_line_charge": (
            "forces.external_dipole.line_charge",
            "forces.external_dipole.screening_length",
            "forces.external_dipole.radius",
            "rods.electric_charge",
        )
    }

    def __init__(self, p, state):
        d = p.forces.external_dipole
        self.line = (-0.5 * d.length, 0.5 * d.length, d.line_charge, d.screening_length, d.radius)
        self.nodes, self.weights = kl.gauss_legendre_01(d.quadrature_points)
        self.slow = bool(d.line_charge_slow)

    def compute(self, ctx, out):
        f = ctx.buffer("line_centre", ctx.n_rods)
        kx.line_yukawa_on_centres(ctx.centre(), ctx.rod_charge, *self.line, self.nodes, self.weights, f)
        share_by_mass(f, out["external_line_charge"])

    def energy(self, ctx):
        return {
            "external_line_charge": kx.line_yukawa_energy(
                ctx.centre(), ctx.rod_charge, *self.line, self.nodes, self.weights
            )
        }
