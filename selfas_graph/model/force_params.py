"""Parameters of the force terms (docs/model.md 'Force terms'): one frozen dataclass per scenario
table ``[forces.NAME]``, and :class:`ForceParams`, the set of them; a term whose table is absent
is off. Part of the schema of :mod:`selfas_graph.model.params` (which re-exports every name here).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import TYPE_CHECKING, Optional

from .schema import spec

if TYPE_CHECKING:
    from .params import Parameters


@dataclass(frozen=True)
class TipMagnetic:
    """Term 1: tip-tip magnetic Coulomb force with a soft core, summed directly or by a multipole tree."""

    method: str = spec(
        "auto",
        "how the force is summed: direct (all tip pairs, exact), tree (multipole octree; pairs "
        "within r* always exact; error set by opening_angle and order), auto (the tree above tree_above rods)",
        choices=("auto", "direct", "tree"),
    )
    opening_angle: float = spec(
        0.55,
        "tree: a cell acts as a multipole when its radius is below this times its distance from the "
        "target group's box; an accuracy knob (0.55 with order 4 and groups of up to 1024 tips: median "
        "relative force error 2e-4 to 9.6e-4 in a uniform rod gas and the Fig. 2 slab of 3000 to 10^5 "
        "rods, docs/performance.md 'Tip-tip force by a multipole tree')",
        gt=0.0,
        lt=1.0,
    )
    group_size: int = spec(
        1024,
        "tree: targets walk the tree together in groups, the largest cells of at most this many tips; "
        "an accuracy and speed knob (a cell is accepted for the whole group by its distance from the "
        "group's box, so larger groups err less at a given opening_angle and share one walk; 1024 at "
        "opening_angle 0.55 evaluates 1.05 to 2.2 times faster than groups of 128 at 0.475, with a median "
        "error as small or smaller but for a uniform gas of 10^5 rods (7.9e-4 against 7.4e-4), docs/performance.md 'Tip-tip force by a multipole tree')",
        ge=1,
    )
    leaf_size: int = spec(
        64,
        "tree: a cell is split until it holds at most this many tips (a leaf's tips are taken as near pairs "
        "when it is opened); with groups of 1024 tips from 16 to 256 cost within 13 % of each other and larger "
        "leaves err slightly less (128: 3 % less in the median than 64), docs/performance.md 'Leaves of the two trees'",
        ge=1,
        le=100000,
    )
    order: int = spec(
        4,
        "tree: the highest multipole moment of a cell, 2 (quadrupole), 3 (octupole) or 4 (hexadecapole); an "
        "accuracy knob (the error falls about as opening_angle^(order + 1); with 4 the tree reaches the error "
        "of order 3 at opening angle 0.4 1.06 to 1.25 times faster, docs/performance.md)",
        ge=2,
        le=4,
    )
    precision: str = spec(
        "float64",
        "arithmetic of the sum: float64, or mixed (direct: a float32 pair law on coordinates "
        "relative to the tips' box centre as float32 hi + lo pairs, sums of 128 pairs added in float64; "
        "tree: float32 near pairs on coordinates relative to the root cell's centre as float32 hi + lo "
        "pairs and float32 multipole fields, each summed per target in float32 and added in float64; "
        "both differ from float64 by about 1e-7 of the largest pair force in a tip's sum, docs/model.md "
        "'Term 1', docs/performance.md 'Mixed precision')",
        choices=("float64", "mixed"),
    )
    tree_above: int = spec(
        2000,
        "auto: use the tree from this many rods on (measured: at 2000 rods an evaluation with the mixed near "
        "field the scenes take costs 3.2-3.7 times less than the float64 direct sum; a Fig. 2 step of 1200 rods "
        "costs the same with the tree as with the mixed direct sum; docs/performance.md 'Tip-tip force by a "
        "multipole tree')",
        ge=1,
    )
    energy_tree_above: int = spec(
        20000,
        "the energy of a frame (and the energy balance's reference) by the tree, with opening_angle, "
        "group_size and order, from this many rods on, whatever method says; below, by the direct sum over all tip pairs, "
        "exact (measured on 2 "
        "threads: the direct sum 0.8 s a frame at 24 000 rods and 14 s at 10^5, the tree 0.08 s and 0.4 s; "
        "late in Fig. 6 the tree errs 9e-8 of the tip-tip energy, 10^5 times below the run's energy "
        "balance, docs/performance.md)",
        ge=1,
    )


@dataclass(frozen=True)
class TipBrake:
    coefficient: float = spec(100.0, "k_br, friction between tips closer than r* (units m/t0)", ge=0.0)


@dataclass(frozen=True)
class AmbientBrake:
    coefficient: float = spec(1.5, "M_br, friction of every tip with the ambient medium (units m/t0)", ge=0.0)


@dataclass(frozen=True)
class UniformField:
    B: tuple = spec(None, "uniform magnetic field (Bx, By, Bz) in units B0", length=3, factory=lambda: (0.0, 0.0, 0.5))


@dataclass(frozen=True)
class PlasmaFilament:
    radius: float = spec(6.0, "R_plas, radius of the uniform current channel", gt=0.0)
    current: float = spec(
        -7.5,
        "I_plas, total current, signed along +z (units J0): negative runs from the anode (z = +dZ/2) to "
        "the cathode, parallel to the current of a rod filament spanning the gap, as the paper's discharge "
        "(docs/model.md 'Term 5')",
    )
    axis: tuple = spec(None, "(x0, y0) of the channel axis", length=2, factory=lambda: (0.0, 0.0))


def plasma_current_text(p: "Parameters"):
    """One line saying which way the plasma current of ``p`` flows, or None without term 5.

    Case (i) names the electrodes and whether the current is parallel to that of a rod
    filament spanning the gap (which flows from the anode at z = +dZ/2 to the cathode
    when the bias is positive, docs/model.md 'Circuit').
    """
    pf = p.forces.plasma_filament
    if pf is None:
        return None
    size = f"{abs(pf.current):g} J0"
    if pf.current == 0.0:
        return "plasma current 0 (the plasma filament has no field)"
    el = p.forces.electrodes
    if el is None:
        return f"plasma current {size} along {'-' if pf.current < 0 else '+'}z (I_plas = {pf.current:g})"
    half = 0.5 * el.gap
    anode, cathode = f"the anode (z = +{half:g})", f"the cathode (z = -{half:g})"
    text = (
        f"plasma current {size} from {anode} to {cathode}"
        if pf.current < 0
        else f"plasma current {size} from {cathode} to {anode}"
    )
    if p.circuit is not None and p.circuit.delta_J0 > 0:
        text += (
            ", parallel to the current of a spanning filament"
            if pf.current < 0
            else ", antiparallel to the current of a spanning filament"
        )
    return text + f" (I_plas = {pf.current:g})"


@dataclass(frozen=True)
class Yukawa:
    screening_length: float = spec(1.0, "R_D, screening length of the rod charges", gt=0.0)
    tolerance: float = spec(
        1e-4,
        "the force is cut off where Z_max^2 times its magnitude falls below this (units F_M0); an accuracy knob",
        gt=0.0,
        lt=1.0,
    )
    core_radius: float = spec(
        0.0,
        "a: inside this centre distance the force falls linearly to zero (a point charge "
        "inside a charged ball; rods of diameter D cannot bring their centres much closer than D); 0 = the bare law of "
        "docs/model.md 'Term 6', unbounded for crossing rods",
        ge=0.0,
    )
    precision: str = spec(
        "float64",
        "arithmetic of the force: float64, or mixed (the pair law in float32 on separations taken in float64, "
        "float32 sums per rod, float64 where charges or lengths leave what float32 holds; about 1.6-1.9 "
        "times faster on one AVX2 core at 1200-24 000 rods of the Fig. 2 scene, differs from float64 by "
        "at most 3.3e-7 of the largest force there, docs/performance.md); the energy stays float64",
        choices=("float64", "mixed"),
    )


@dataclass(frozen=True)
class ElectricField:
    E: tuple = spec(
        None, "uniform electric field (Ex, Ey, Ez) acting on rod charges", length=3, factory=lambda: (0.0, 0.0, 0.0)
    )


@dataclass(frozen=True)
class Electrodes:
    gap: float = spec(17.9, "distance dZ between the cathode plane z = -dZ/2 and the anode plane z = +dZ/2", gt=0.0)

    @property
    def planes(self) -> tuple:
        """``(z_cathode, z_anode) = (-gap/2, +gap/2)``, the planes of term 7 and of the contact search."""
        return (-0.5 * self.gap, 0.5 * self.gap)


_CURRENT_PRECISION_HELP = (
    "arithmetic of the rod currents' field {where}: float64, or mixed (the segment law in float32 "
    "with coordinates as float32 hi + lo pairs relative to the active rods' centre, float64 sums; "
    "about 1.6-1.9 times faster on AVX2, differs from float64 by a median of 1e-7 of a force, at most 2e-5, "
    "docs/performance.md)"
)

_CURRENT_METHOD_HELP = (
    "how the rod currents' field {where} is summed: direct (every current-carrying rod by the segment law, "
    "O(N_points N_current)) or tree (a multipole tree of the rods' vector potential, docs/model.md 'The rod "
    "currents by a tree'; with 3150 rods carrying current 2.5 to 2.7 times faster than the direct sum of the same "
    "precision at a median error of 1.4e-4 of the field, 16 to 21 times with 5 x 10^4, no faster with 1000; "
    "docs/performance.md 'A tree of the rod currents'); a speed knob for large networks"
)
_CURRENT_LEAF_HELP = (
    "tree: a cell of rods is split until it holds at most this many (a leaf's rods are summed by the segment "
    "law when it is opened); a speed and accuracy knob: in a sparse network larger leaves make most rods near "
    "and exact, in a gas they cost more (docs/performance.md 'Leaves of the two trees'). With both current "
    "terms on the tree, one tree serves both where their leaf_size and order agree; a value set for one term "
    "only builds a second tree"
)
_CURRENT_GROUP_HELP = (
    "tree: field points walk the tree in runs of this many in Morton order, a cell accepted for the run by "
    "its distance from the run's box; an accuracy and speed knob (docs/performance.md 'A tree of the rod currents')"
)
_CURRENT_ORDER_HELP = (
    "tree: the highest moment of a cell's vector potential, 2 (quadrupole) or 3 (octupole); an accuracy knob "
    "(docs/model.md 'The rod currents by a tree')"
)
_CURRENT_THETA_HELP = (
    "tree: a cell of rods acts through its moments when its radius is below this times its distance from the "
    "group of points; an accuracy and speed knob (in [0, 1): the own rod of a point is then always summed "
    "exactly, and left out; 0 sums every rod by the segment law)"
)


@dataclass(frozen=True)
class CurrentField:
    """Term 9: the Biot-Savart field of rod currents on tips (wire radius D/2, docs/model.md 'Term 9')."""

    precision: str = spec("float64", _CURRENT_PRECISION_HELP.format(where="on the tips"), choices=("float64", "mixed"))
    method: str = spec("direct", _CURRENT_METHOD_HELP.format(where="on the tips"), choices=("direct", "tree"))
    opening_angle: float = spec(0.5, _CURRENT_THETA_HELP, ge=0.0, lt=1.0)
    leaf_size: int = spec(64, _CURRENT_LEAF_HELP, ge=1, le=100000)
    group_size: int = spec(128, _CURRENT_GROUP_HELP, ge=1, le=1000000)
    order: int = spec(3, _CURRENT_ORDER_HELP, ge=2, le=3)


@dataclass(frozen=True)
class CurrentLorentz:
    quadrature_points: int = spec(
        2,
        "Gauss-Legendre points along each rod for the Lorentz force on its current, for the rods whose centres "
        "are at least near_range apart and for the other fields; an accuracy knob (with near_range = 1.5, late "
        "in Fig. 2 the term errs 2.8e-3 of its rms force at the 99th percentile; 4 points and near_range = 0 "
        "err 0.65, docs/performance.md 'Term 10 near pairs')",
        ge=1,
        le=1000,
    )
    precision: str = spec(
        "float64",
        _CURRENT_PRECISION_HELP.format(where="at the quadrature points (the other fields stay float64)"),
        choices=("float64", "mixed"),
    )
    near_range: float = spec(
        1.5,
        "centre distance (units L) within which another rod's field is integrated along a rod by "
        "panels adapted to the pair (from the point where the two come closest) instead of the "
        "quadrature_points rule; 0: off. An accuracy knob (docs/model.md 'Term 10')",
        ge=0.0,
        le=1e6,
    )
    method: str = spec(
        "direct", _CURRENT_METHOD_HELP.format(where="at the quadrature points"), choices=("direct", "tree")
    )
    opening_angle: float = spec(0.5, _CURRENT_THETA_HELP, ge=0.0, lt=1.0)
    leaf_size: int = spec(64, _CURRENT_LEAF_HELP, ge=1, le=100000)
    group_size: int = spec(128, _CURRENT_GROUP_HELP, ge=1, le=1000000)
    order: int = spec(3, _CURRENT_ORDER_HELP, ge=2, le=3)


@dataclass(frozen=True)
class ExternalFilament:
    """Term 11, case (ii): a fixed straight current filament on the z axis, also a conductor."""

    current: float = spec(10.0, "J_ext, current along +z (units J0)")
    diameter: float = spec(
        0.18,
        "D_ext; its field is 2 J rho / (rho^2 + (D_ext/2)^2) and tips touch it within r* + D_ext/2 of the axis",
        gt=0.0,
    )

    @property
    def radius(self) -> float:
        """D_ext/2, the filament's radius: in its field (term 11) and in the contact search."""
        return 0.5 * self.diameter


@dataclass(frozen=True)
class ExternalDipole:
    """Term 11, case (ii): a fixed large dipole centred on the z axis at z = 0."""

    magnetic_charge: float = spec(
        10.0, "Z_Mext: +Z_Mext at z = +length/2 and -Z_Mext at z = -length/2 (moment along +z, co-directed with B_ext)"
    )
    length: float = spec(20.0, "L_ext", gt=0.0)
    line_charge: float = spec(3.2, "lambda_ext, electric charge per unit length along the dipole")
    screening_length: float = spec(2.4, "R_Dext, screening length of the line charge", gt=0.0)
    radius: float = spec(
        0.09, "radius of the line charge (softens it on the axis; D_ext/2 in the paper's scene)", gt=0.0
    )
    quadrature_points: int = spec(
        32, "Gauss-Legendre points of the line-charge integral; an accuracy knob", ge=1, le=1000
    )
    line_charge_slow: bool = spec(
        False,
        "with multiple time stepping (integrator.slow_every > 1), the line charge with the slow sums, "
        "extrapolated between them, instead of at every step; an accuracy knob (docs/performance.md "
        '"The line charge\'s quadrature (Fig. 8)")',
    )


@dataclass(frozen=True)
class ForceParams:
    """The force terms of docs/model.md 'Force terms'; a term whose table is absent is off."""

    tip_magnetic: Optional[TipMagnetic] = spec(None, "term 1: tip-tip magnetic force")
    tip_brake: Optional[TipBrake] = spec(None, "term 2: brake between touching tips")
    ambient_brake: Optional[AmbientBrake] = spec(None, "term 3: brake in the ambient medium")
    uniform_field: Optional[UniformField] = spec(None, "term 4: uniform external magnetic field")
    plasma_filament: Optional[PlasmaFilament] = spec(None, "term 5: field of a plasma current filament")
    yukawa: Optional[Yukawa] = spec(None, "term 6: screened electric repulsion of rod charges")
    electric_field: Optional[ElectricField] = spec(None, "term 7: uniform electric field on rod charges")
    electrodes: Optional[Electrodes] = spec(None, "term 8: electrode walls (case (i))")
    external_filament: Optional[ExternalFilament] = spec(
        None, "term 11: fixed current filament on the z axis (case (ii))"
    )
    external_dipole: Optional[ExternalDipole] = spec(
        None, "term 11: fixed large dipole with a screened line charge (case (ii))"
    )
    current_field: Optional[CurrentField] = spec(None, "term 9: field of rod currents on tips (needs [circuit])")
    current_lorentz: Optional[CurrentLorentz] = spec(
        None, "term 10: Lorentz force on rod currents from all fields (needs [circuit])"
    )

    def active(self):
        """Names of the terms that are on, in the order they are computed and summed: 1-8, 11, 9, 10 (this
        class's fields; docs/model.md 'Force terms')."""
        return [f.name for f in dataclasses.fields(self) if getattr(self, f.name) is not None]


#: every table, :class:`ForceParams` and :func:`plasma_current_text`: what :mod:`.params` re-exports (a new
#: table is in it without a line more)
__all__ = [n for n, v in list(globals().items()) if dataclasses.is_dataclass(v) and v.__module__ == __name__]
__all__ += ["plasma_current_text"]
