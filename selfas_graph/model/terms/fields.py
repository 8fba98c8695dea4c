"""One-body terms of the apparatus: each tip or rod alone in a given field or medium
(docs/model.md 'Term 3', 'Term 4', 'Term 5', 'Term 7', 'Term 8').

The uniform magnetic field and the plasma filament are also sources of the field that the
Lorentz force on rod currents feels (:class:`~selfas_graph.model.terms.base.FieldSource`).
"""

from __future__ import annotations

import numpy as np

from ...kernels import fields as kf
from .base import FieldSource, Term, share_by_mass


class AmbientBrakeForce(Term):
    """Term 3: the ambient medium brakes every tip, ``-M_br v``."""

    name = "ambient_brake"
    channels = [("ambient_brake", False)]
    keys = {"ambient_brake": ("forces.ambient_brake.coefficient",)}

    def __init__(self, p, state):
        self.k = p.forces.ambient_brake.coefficient

    def compute(self, ctx, out):
        np.multiply(ctx.velocity, -self.k, out=out["ambient_brake"])


class UniformFieldForce(Term, FieldSource):
    """Term 4: ``q_k B`` of the uniform magnetic field; conservative."""

    name = "uniform_field"
    channels = [("uniform_field", True)]
    keys = {"uniform_field": ("forces.uniform_field.B", "rods.magnetic_charge")}

    def __init__(self, p, state):
        self.B = np.array(p.forces.uniform_field.B, dtype=np.float64)

    def compute(self, ctx, out):
        kf.uniform_force_on_tips(ctx.tip_charge, self.B, out["uniform_field"])

    def energy(self, ctx):
        return {"uniform_field": -float(ctx.tip_charge @ (ctx.position @ self.B))}

    def field_at(self, points, out):
        out[:] = self.B


class PlasmaFilamentForce(Term, FieldSource):
    """Term 5: ``q_k B_plas(x_k)`` of the plasma current filament along z."""

    name = "plasma_filament"
    channels = [("plasma_filament", False)]
    keys = {
        "plasma_filament": ("forces.plasma_filament.current", "forces.plasma_filament.radius", "rods.magnetic_charge")
    }

    def __init__(self, p, state):
        pf = p.forces.plasma_filament
        self.args = (float(pf.axis[0]), float(pf.axis[1]), pf.radius, pf.current)

    def compute(self, ctx, out):
        kf.plasma_force_on_tips(ctx.position, ctx.tip_charge, *self.args, out["plasma_filament"])

    def field_at(self, points, out):
        kf.plasma_field(points, *self.args, out)


class ElectricFieldForce(Term):
    """Term 7: ``Z_i E`` on each rod centre, shared by its tips; conservative."""

    name = "electric_field"
    channels = [("electric_field", True)]
    keys = {"electric_field": ("forces.electric_field.E", "rods.electric_charge")}

    def __init__(self, p, state):
        self.E = np.array(p.forces.electric_field.E, dtype=np.float64)

    def compute(self, ctx, out):
        share_by_mass(ctx.rod_charge[:, None] * self.E[None, :], out["electric_field"])

    def energy(self, ctx):
        return {"electric_field": -float(ctx.rod_charge @ (ctx.centre() @ self.E))}


class ElectrodesForce(Term):
    """Term 8: the electrode planes push tips back into the gap and brake them (split or explicit)."""

    name = "electrodes"
    channels = [("electrodes", True), ("electrode_brake", False)]
    keys = {
        "electrodes": ("forces.electrodes.gap", "rods.tip_stiffness"),
        "electrode_brake": ("forces.electrodes.gap", "forces.tip_brake.coefficient"),
    }

    def __init__(self, p, state):
        self.z = p.forces.electrodes.planes
        self.rstar = p.rods.rstar
        self.kappa = p.rods.tip_stiffness
        self.k = p.forces.tip_brake.coefficient if p.forces.tip_brake is not None else 0.0
        self.split_mode = p.integrator.brake == "split"
        #: exp(-n k_br dt) for n = 0, 1, 2 planes touched, and the dt it was computed for (the compiled steps
        #: take it from here, model/compiled.py)
        self.decay, self.decay_dt = None, None

    def compute(self, ctx, out):
        k = 0.0 if self.split_mode else self.k
        kf.electrode_walls(
            ctx.position,
            ctx.velocity,
            self.z[0],
            self.z[1],
            self.rstar,
            self.kappa,
            k,
            out["electrodes"],
            out["electrode_brake"],
        )

    def split(self, ctx, dt):
        if self.k == 0.0:
            return {}
        if self.decay_dt != dt:
            # dv/dt = -n k v, exactly, for a tip touching n planes
            self.decay = np.exp(-self.k * np.array([0.0, 1.0, 2.0]) * dt)
            self.decay_dt = dt
        before, after = ctx.buffer("electrode_before", ctx.n_tips), ctx.buffer("electrode_after", ctx.n_tips)
        # the work: the change of kinetic energy of the touched tips, as kinetic_of sums it
        work, m = kf.electrode_brake_exact(ctx.position, ctx.velocity, *self.z, self.rstar, self.decay, before, after)
        return {"electrode_brake": work} if m else {}

    def energy(self, ctx):
        return {"electrodes": kf.electrode_energy(ctx.position, self.z[0], self.z[1], self.rstar, self.kappa)}
