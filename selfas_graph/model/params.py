"""Frozen parameter objects of a simulation, and the schema of scenario files.

Each dataclass field carries its documentation and its admissible range in
``metadata``; :mod:`selfas_graph.io.scenario` walks these classes to validate a
TOML scenario, so defaults, types, ranges and docs are written once, here.
All values are in the reduced units of docs/model.md 'Reduced units'.

Optional sections (the force terms, the circuit) default to ``None``: a term
whose table is absent from the scenario is not computed at all.
"""

from __future__ import annotations

import dataclasses
import math
import threading
from dataclasses import dataclass
from typing import Optional

from .force_params import *  # noqa: F403 - the force tables (force_params.__all__) are part of this schema
from .force_params import ForceParams
from .schema import spec

#: set while the scenario loader builds a Parameters it validates itself (no second check)
_unchecked = threading.local()


@dataclass(frozen=True)
class ChargeDistribution:
    """How a per-rod charge is drawn (docs/model.md 'Rods')."""

    distribution: str = spec(
        "constant",
        "constant (every rod gets `value`), uniform (uniform in (low, high)), "
        "two_level (`high` for a fraction `high_fraction` of the rods, `low` for the rest), "
        "magnetic (electric charge only: Z_i equals the rod's magnetic charge)",
        choices=("constant", "uniform", "two_level", "magnetic"),
    )
    value: float = spec(1.0, "charge of every rod when distribution = constant", ge=0.0)
    low: float = spec(2.0 / 3.0, "lower bound (uniform) or common value (two_level)", ge=0.0)
    high: float = spec(2.0, "upper bound (uniform) or rare value (two_level)", ge=0.0)
    high_fraction: float = spec(1.0 / 3.0, "fraction of rods with the `high` value (two_level)", ge=0.0, le=1.0)


@dataclass(frozen=True)
class LengthDistribution:
    """Per-rod length l_i in units of the mean rod length L (docs/model.md 'Rods')."""

    distribution: str = spec(
        "constant",
        "constant (every rod has `value`), uniform (uniform in (low, high)), "
        "two_level (`high` for a fraction `high_fraction` of the rods, `low` for the rest); "
        "the law's mean must be 1, since L is the mean length",
        choices=("constant", "uniform", "two_level"),
    )
    value: float = spec(1.0, "length of every rod when distribution = constant (then 1)", gt=0.0)
    low: float = spec(0.5, "lower bound (uniform) or common value (two_level)", gt=0.0)
    high: float = spec(1.5, "upper bound (uniform) or rare value (two_level)", gt=0.0)
    high_fraction: float = spec(0.5, "fraction of rods with the `high` value (two_level)", ge=0.0, le=1.0)

    def mean(self) -> float:
        """Mean of the law (1 for a valid scene)."""
        if self.distribution == "constant":
            return self.value
        if self.distribution == "uniform":
            return 0.5 * (self.low + self.high)
        return (1.0 - self.high_fraction) * self.low + self.high_fraction * self.high

    def bounds(self) -> tuple:
        """(shortest, longest) length the law can give."""
        if self.distribution == "constant":
            return self.value, self.value
        return min(self.low, self.high), max(self.low, self.high)


@dataclass(frozen=True)
class ResistanceDistribution:
    """Per-rod resistance R_i in units of R0 (docs/model.md 'Circuit')."""

    distribution: str = spec(
        "constant",
        "constant (every rod gets `value`), uniform (uniform in (low, high)), "
        "two_level (`high` for a fraction `high_fraction` of the rods, `low` for the rest)",
        choices=("constant", "uniform", "two_level"),
    )
    value: float = spec(1.0, "resistance of every rod when distribution = constant", gt=0.0)
    low: float = spec(0.5, "lower bound (uniform) or common value (two_level)", gt=0.0)
    high: float = spec(1.5, "upper bound (uniform) or rare value (two_level)", gt=0.0)
    high_fraction: float = spec(0.5, "fraction of rods with the `high` value (two_level)", ge=0.0, le=1.0)
    per_length: bool = spec(
        False, "the drawn value is a resistance per unit length: R_i = value * l_i (l_i from rods.length)"
    )


@dataclass(frozen=True)
class RodParams:
    # 10^7 rods hold about 2 GB per float64 array of tips: the practical ceiling of one machine
    count: int = spec(300, "number of rods (a scene needs at least one)", ge=1, le=10_000_000)
    magnetic_charge: ChargeDistribution = spec(
        None, "tip magnetic charge q_i (units Z_M0 e)", factory=ChargeDistribution
    )
    electric_charge: ChargeDistribution = spec(
        None,
        "electric charge Z_i of the rod centre (units Z_M0 e)",
        factory=lambda: ChargeDistribution(distribution="magnetic"),
    )
    diameter: float = spec(0.06, "rod diameter D (inverse aspect ratio D/L)", gt=0.0, lt=0.5)
    transition_radius: Optional[float] = spec(
        None, "r*, below which the tip law has its soft core (default: the diameter)", gt=0.0, lt=0.5
    )
    tip_stiffness: float = spec(1.0, "kappa, elastic stiffness of the tip core and of the electrode walls", ge=0.0)
    length: Optional[LengthDistribution] = spec(
        None,
        "length l_i of each rod in units of the mean length L, a number or a distribution table "
        "(absent: every rod has length 1)",
    )
    resistance: Optional[ResistanceDistribution] = spec(
        None,
        "resistance R_i of each rod in units of R0, a number or a distribution table (absent: every rod has R0 = 1)",
    )

    @property
    def rstar(self) -> float:
        return self.diameter if self.transition_radius is None else self.transition_radius


@dataclass(frozen=True)
class PlacementParams:
    box: tuple = spec(
        None,
        "[[xmin, xmax], [ymin, ymax], [zmin, zmax]] holding both tips of every rod at t = 0",
        factory=lambda: ((-5.0, 5.0), (-5.0, 5.0), (-5.0, 5.0)),
    )
    min_tip_distance: Optional[float] = spec(
        None, "no two tips of different rods start closer than this (default 4 r*)", ge=0.0, le=100.0
    )
    max_attempts: int = spec(2000, "random draws tried per rod before placement gives up", ge=1, le=10**9)


@dataclass(frozen=True)
class IntegratorParams:
    dt: float = spec(1e-3, "time step (units t0); an accuracy knob", gt=0.0)
    bond_force: str = spec(
        "exact",
        "rigid-bond force: exact (docs/model.md 'Rigid rods and time integration') or paper (Eq. 9 as printed)",
        choices=("exact", "paper"),
    )
    velocity_correction: bool = spec(True, "apply the paper's velocity correction, Eqs. (14-15), after each step")
    position_projection: bool = spec(
        True, "restore each bond length to the rod's length l_i about the rod centre after each step"
    )
    brake: str = spec(
        "split",
        "how the stiff contact brakes (tip brake, electrode and monopole brakes) are integrated: "
        "explicit (a force in the Adams-Bashforth step) or split (solved exactly pair by pair after each step, "
        "stable for any dt; first order in dt for the brakes' effect)",
        choices=("explicit", "split"),
    )
    energy_tolerance: float = spec(
        0.1,
        "stop the run when the energy balance |E - E0 - W| exceeds this fraction of the energy turned over "
        "(kinetic energy + |work| of every non-conservative term), checked every output interval; the usual "
        "sign of a time step past the stability limit of the brakes (at most 1: a balance off by the whole "
        "energy turned over is no result)",
        gt=0.0,
        le=1.0,
    )
    restart_on_events: bool = spec(
        False,
        "restart the Adams-Bashforth history (three RK4 steps) after a contact event or a new circuit "
        "solution, when forces jump",
    )
    slow_every: int = spec(
        1,
        "multiple time stepping: evaluate the slow forces (the far part of the tip-tip pairs, switched on from "
        "(fast_range - 1) r* to fast_range r*, the Yukawa sum, the rod-current terms 9 and 10) every this many steps and "
        "extrapolate them in between (slow_extrapolation), while the stiff short-range forces are evaluated every "
        "step; 1 evaluates everything every step; an accuracy knob",
        ge=1,
        le=1000,
    )
    current_every: int = spec(
        0,
        "with slow_every > 1: evaluate the rod-current terms 9 and 10 every this many steps (a multiple of "
        "slow_every; still on the first step after the currents change) and extrapolate them in between like "
        "the other slow forces; 0 evaluates them with the other slow forces, every slow_every steps; no "
        "effect with slow_every = 1 (every force every step); an accuracy knob (docs/model.md 'Multiple time stepping (`integrator.slow_every`)')",
        ge=0,
        le=100000,
    )
    slow_extrapolation: bool = spec(
        True,
        "with slow_every > 1: extrapolate the slow forces linearly in time from the last two full "
        "evaluations (second order in slow_every dt) instead of holding them constant (first order)",
    )
    fast_range: float = spec(
        8.0,
        "with slow_every > 1: tip pairs closer than (fast_range - 1) r* count as fast, pairs beyond "
        "fast_range r* as slow, with a smooth switch in between; an accuracy knob",
        ge=2.0,
        le=100.0,
    )


@dataclass(frozen=True)
class ContactParams:
    enabled: bool = spec(True, "detect tip-tip and tip-conductor contacts (electrodes, external filament) as events")
    release_factor: float = spec(
        1.5, "a contact is released when the tips are farther apart than release_factor * r* (hysteresis)", ge=1.0
    )
    resistance: float = spec(
        0.0,
        "resistance r of every tip-tip and tip-conductor contact in the circuit (units R0); 0 = ideal "
        "contacts, tips in contact are one electrical node",
        ge=0.0,
    )


@dataclass(frozen=True)
class CircuitParams:
    delta_J0: float = spec(
        2.23,
        "bias parameter delta_J0 = U L / (R0 J0 dZ) (paper Eq. 1); electrode potentials +-delta_J0 dZ / 2, "
        "filament potential -delta_J0 z",
        ge=0.0,
    )
    solver: str = spec(
        "auto",
        "linear solver of the nodal equations: direct (sparse LU), cg (conjugate gradients to round-off, "
        "falls back to direct), auto (direct up to 50000 unknowns, cg above; measured in docs/performance.md)",
        choices=("auto", "direct", "cg"),
    )
    height_tolerance: float = spec(
        0.01,
        "case (ii): re-solve the circuit when a tip touching the filament has moved this far along z since its "
        "potential -delta_J0 z was set; an accuracy knob",
        gt=0.0,
    )


@dataclass(frozen=True)
class NeighbourParams:
    skin: float = spec(
        0.3, "Verlet skin of the neighbour lists; rebuilt when a point moved more than skin/2", gt=0.0, le=100.0
    )
    centre_skin: Optional[float] = spec(
        None,
        "Verlet skin of the rod-centre list of the Yukawa sum (default: skin); a longer one means fewer builds "
        'and longer rows; the same forces, summed in another order (docs/performance.md "The rod-centre '
        "list's own skin\")",
        gt=0.0,
        le=100.0,
    )


@dataclass(frozen=True)
class RunParams:
    t_end: float = spec(
        10.0,
        "simulated time at which the run stops (units t0); a whole number of steps integrator.dt from the start",
        gt=0.0,
    )


@dataclass(frozen=True)
class OutputParams:
    interval: float = spec(1.0, "simulated time between saved frames, in whole steps; data are flushed at each", gt=0.0)
    file: Optional[str] = spec(
        None, "output HDF5 path (default: the scenario file name with .h5, in the working directory)"
    )
    velocities: bool = spec(True, "save tip velocities with every frame")
    checkpoint_interval: float = spec(
        900.0,
        "wall-clock seconds between checkpoints (RUN.checkpoint.h5), the first before the first step; "
        "one is also written at the end and on SIGTERM/SIGINT; 0 writes only those",
        ge=0.0,
    )


@dataclass(frozen=True)
class ScenarioInfo:
    name: str = spec("unnamed", "short name of the scene")
    description: str = spec("", "what the scene is and where its parameters come from")
    seed: int = spec(1, "seed of every random draw (charges, placement)", ge=0, le=2**63 - 1)


@dataclass(frozen=True)
class Parameters:
    """Everything a run needs, resolved, validated and frozen.

    Every way of making one is validated as a scenario file is (same messages, naming the
    key and what is valid; :class:`selfas_graph.ScenarioError` lists every problem):
    ``Parameters()`` (the defaults), :meth:`from_dict` (nested dict as from TOML),
    :meth:`replace` (changes to an existing one), and even ``dataclasses.replace``.
    """

    scenario: ScenarioInfo = spec(None, "name, description and seed", factory=ScenarioInfo)
    rods: RodParams = spec(None, "the rods", factory=RodParams)
    placement: PlacementParams = spec(None, "initial placement", factory=PlacementParams)
    forces: ForceParams = spec(None, "force terms (a term not listed is not computed)", factory=ForceParams)
    integrator: IntegratorParams = spec(None, "time integration", factory=IntegratorParams)
    neighbours: NeighbourParams = spec(None, "neighbour lists", factory=NeighbourParams)
    contacts: ContactParams = spec(None, "contact detection and events", factory=ContactParams)
    circuit: Optional[CircuitParams] = spec(
        None, "circuit solve between the conductors: the electrodes, or the external filament (off when absent)"
    )
    run: RunParams = spec(None, "run length", factory=RunParams)
    output: OutputParams = spec(None, "output file", factory=OutputParams)

    @property
    def min_tip_distance(self) -> float:
        d = self.placement.min_tip_distance
        return 4.0 * self.rods.rstar if d is None else d

    def to_dict(self) -> dict:
        """Plain nested dict (tuples as lists), e.g. for JSON provenance."""
        return _plain(dataclasses.asdict(self))

    def __post_init__(self):
        if getattr(_unchecked, "on", False):
            return
        from ..io.scenario import check_parameters  # the schema walk lives with the scenario files

        check_parameters(self)

    def to_raw(self) -> dict:
        """The nested dict a scenario file would hold for these parameters (absent sections and
        unset optional values left out): ``Parameters.from_dict(p.to_raw()) == p``."""
        return _raw(dataclasses.asdict(self))

    @classmethod
    def from_dict(cls, raw: dict) -> "Parameters":
        """Validate a nested dict as from TOML, e.g. ``{"rods": {"count": 50}, "forces": {"tip_magnetic": {}}}``.

        Raises :class:`selfas_graph.ScenarioError` naming every invalid key.
        """
        from ..io.scenario import parameters_from_dict

        return parameters_from_dict(raw)

    def replace(self, changes: dict | None = None, /, **sections) -> "Parameters":
        """A validated copy with changes, by dotted key or by section::

            p.replace({"integrator.dt": 5e-4, "forces.yukawa": False})   # False: the term off
            p.replace(integrator={"dt": 5e-4}, rods={"count": 50})      # merged into the section
            p.replace({"forces.electrodes": True}, circuit={"delta_J0": 2.0})   # True or {} switches a table on
            p.replace(integrator=dataclasses.replace(p.integrator, dt=5e-4))    # a section object: the whole section
            p.replace({"rods.transition_radius": None})                 # None: the key unset, to its default

        Raises :class:`selfas_graph.ScenarioError` with the messages of a scenario file.
        """
        if changes is not None and not isinstance(changes, dict):
            raise TypeError(
                f"Parameters.replace: changes by dotted key in a dict, e.g. {{'integrator.dt': 5e-4}}, got {changes!r}"
            )
        raw = self.to_raw()
        for key, value in list((changes or {}).items()) + list(sections.items()):
            node, parts = raw, key.split(".")
            for name in parts[:-1]:
                if not isinstance(node.get(name), dict):
                    node[name] = {}
                node = node[name]
            if dataclasses.is_dataclass(value) and not isinstance(value, type):
                node[parts[-1]] = _raw(dataclasses.asdict(value))  # replaces the section, unset values too
                continue
            old = node.get(parts[-1])
            if value is None:
                node.pop(parts[-1], None)
            elif not (value is True and isinstance(old, dict)):  # True keeps a table already on as it is
                node[parts[-1]] = _merge(old, value) if isinstance(old, dict) and isinstance(value, dict) else value
        return self.from_dict(raw)


def _raw(obj):
    if isinstance(obj, dict):
        return {k: _raw(v) for k, v in obj.items() if v is not None}
    if isinstance(obj, (list, tuple)):
        return [_raw(v) for v in obj]
    return obj


def _merge(old: dict, new: dict) -> dict:
    out = dict(old)
    for k, v in new.items():
        if v is None:  # unset: the default
            out.pop(k, None)
        else:
            out[k] = _merge(out[k], v) if isinstance(out.get(k), dict) and isinstance(v, dict) else v
    return out


def _plain(obj):
    if isinstance(obj, dict):
        return {k: _plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_plain(v) for v in obj]
    if isinstance(obj, float) and not math.isfinite(obj):
        return repr(obj)
    return obj
