"""The accuracy each knob is measured to reach, and the settings of a scene that fall short of it.

Every knob that trades speed for accuracy defaults to the setting that meets the accuracy
docs/performance.md states for it; a faster setting is a choice a scene makes and names (the
shipped scenario files carry ``[accuracy knob: ...]`` with the error it costs on the line that
sets it, which ``tests/unit/test_accuracy_defaults.py`` checks). :func:`short_of_accuracy` lists the
settings of a parameter set that are below their stated accuracy; ``selfas-graph simulate
--dry-run`` prints them.
"""

from __future__ import annotations

import dataclasses
from typing import Callable

__all__ = ["ACCURACY_RULES", "AccuracyRule", "null_model_notes", "short_of_accuracy"]


@dataclasses.dataclass(frozen=True)
class AccuracyRule:
    """One accuracy knob: its dotted key, the setting that meets its stated accuracy, and a test of it.

    ``applies(params)`` says whether the knob matters in the scene (its term is on); ``meets(params)``
    whether the scene's setting reaches the stated accuracy.
    """

    key: str
    stated: str
    applies: Callable
    meets: Callable

    def value(self, params):
        """The scene's setting of :attr:`key` (``params.integrator.slow_every`` for "integrator.slow_every")."""
        obj = params
        for part in self.key.split("."):
            obj = getattr(obj, part)
        return obj


def _term(name):
    return lambda p: getattr(p.forces, name) is not None


def _always(p):
    return True


def _tree(p):
    """Whether the scene may sum the tip-tip force by the tree."""
    return p.forces.tip_magnetic is not None and p.forces.tip_magnetic.method != "direct"


#: what the tree of the rod currents reaches at its default opening angle
CURRENT_TREE_STATED = (
    "<= 0.5 with the tree (median error 1.4e-4 of the rod currents' field on the tips at t = 100 of a Fig. 6 "
    "run with 3150 rods carrying current; docs/performance.md 'A tree of the rod currents')"
)

#: the accuracy knobs, each with the setting that meets the accuracy docs/performance.md states for it
ACCURACY_RULES = (
    AccuracyRule(
        "integrator.dt",
        "dt <= 1e-3 with the split brake, <= 5e-4 with the explicit one (half the largest step that "
        "survives the start of Fig. 2; docs/performance.md 'The largest stable time step, and the brake')",
        _always,
        lambda p: p.integrator.dt <= (1e-3 if p.integrator.brake == "split" else 5e-4) * (1 + 1e-12),
    ),
    AccuracyRule(
        "integrator.slow_every",
        "1: every force every step (every K steps, the slow sums add an error as large as the time step's own "
        "at K = 8-16, and at 24 in the Fig. 6 scene; docs/performance.md 'Multiple time stepping: the slow "
        "sums every K steps')",
        _always,
        lambda p: p.integrator.slow_every == 1,
    ),
    AccuracyRule(
        "integrator.current_every",
        "0: the rod-current terms with the other slow sums (docs/performance.md 'Multiple time stepping: "
        "the slow sums every K steps')",
        lambda p: (
            p.integrator.slow_every > 1 and (p.forces.current_field is not None or p.forces.current_lorentz is not None)
        ),
        lambda p: p.integrator.current_every in (0, p.integrator.slow_every),
    ),
    AccuracyRule(
        "forces.tip_magnetic.opening_angle",
        "<= 0.55 with order 4 (with groups of 1024 tips: median relative force error 2e-4 to 9.6e-4; "
        "docs/performance.md 'Tip-tip force by a multipole tree')",
        _tree,
        lambda p: p.forces.tip_magnetic.opening_angle <= 0.55 and p.forces.tip_magnetic.order >= 4,
    ),
    AccuracyRule(
        "forces.tip_magnetic.group_size",
        ">= 1024 at opening angles above 0.475 (smaller groups err more at a given angle: at 0.55 groups of "
        "128 err 1.0e-3 in a gas of 24 000 rods; groups of 128 at 0.475 err 5e-4 to 9.7e-4; docs/performance.md 'Groups of "
        "1024 tips at opening angle 0.55')",
        _tree,
        lambda p: p.forces.tip_magnetic.group_size >= 1024 or p.forces.tip_magnetic.opening_angle <= 0.475,
    ),
    AccuracyRule(
        "forces.tip_magnetic.precision",
        "float64",
        _term("tip_magnetic"),
        lambda p: p.forces.tip_magnetic.precision == "float64",
    ),
    AccuracyRule(
        "forces.yukawa.tolerance",
        "<= 1e-3 (its error sits below the time step's; docs/performance.md 'Speed-accuracy trade of every knob')",
        _term("yukawa"),
        lambda p: p.forces.yukawa.tolerance <= 1e-3,
    ),
    AccuracyRule(
        "forces.yukawa.precision", "float64", _term("yukawa"), lambda p: p.forces.yukawa.precision == "float64"
    ),
    AccuracyRule(
        "forces.current_field.precision",
        "float64",
        _term("current_field"),
        lambda p: p.forces.current_field.precision == "float64",
    ),
    AccuracyRule(
        "forces.current_field.opening_angle",
        CURRENT_TREE_STATED,
        lambda p: p.forces.current_field is not None and p.forces.current_field.method == "tree",
        lambda p: p.forces.current_field.opening_angle <= 0.5,
    ),
    AccuracyRule(
        "forces.current_lorentz.opening_angle",
        CURRENT_TREE_STATED,
        lambda p: p.forces.current_lorentz is not None and p.forces.current_lorentz.method == "tree",
        lambda p: p.forces.current_lorentz.opening_angle <= 0.5,
    ),
    *(
        AccuracyRule(
            f"forces.{term}.order",
            "3 with the tree (quadrupoles err 3-4 times more in the median at 2-7 % less cost; "
            "docs/performance.md 'Leaves of the two trees')",
            lambda p, term=term: getattr(p.forces, term) is not None and getattr(p.forces, term).method == "tree",
            lambda p, term=term: getattr(p.forces, term).order >= 3,
        )
        for term in ("current_field", "current_lorentz")
    ),
    AccuracyRule(
        "forces.current_lorentz.near_range",
        "near_range >= 1.5 with quadrature_points >= 2 (2.8e-3 of the term's rms force at the 99th "
        "percentile late in Fig. 2; docs/performance.md 'Term 10 near pairs')",
        _term("current_lorentz"),
        lambda p: p.forces.current_lorentz.near_range >= 1.5 and p.forces.current_lorentz.quadrature_points >= 2,
    ),
    AccuracyRule(
        "forces.current_lorentz.precision",
        "float64",
        _term("current_lorentz"),
        lambda p: p.forces.current_lorentz.precision == "float64",
    ),
    AccuracyRule(
        "forces.external_dipole.quadrature_points",
        ">= 32 (1.9e-13 of the term's rms force at worst late in Fig. 8, 1.9e-10 nearer the line; "
        'docs/performance.md "The line charge\'s quadrature (Fig. 8)")',
        _term("external_dipole"),
        lambda p: p.forces.external_dipole.quadrature_points >= 32,
    ),
    AccuracyRule(
        "forces.external_dipole.line_charge_slow",
        "false: the line charge at every step (held between the slow sums it errs as they do; "
        'docs/performance.md "The line charge\'s quadrature (Fig. 8)")',
        lambda p: p.forces.external_dipole is not None and p.integrator.slow_every > 1,
        lambda p: not p.forces.external_dipole.line_charge_slow,
    ),
    AccuracyRule(
        "circuit.height_tolerance",
        "<= 0.01 L (the median tip 20 times under the time step's error late in Fig. 8 quick; "
        'docs/performance.md "The case (ii) filament contacts: when to solve the circuit again")',
        lambda p: p.forces.external_filament is not None,
        lambda p: p.circuit.height_tolerance <= 0.01,
    ),
)


def short_of_accuracy(params) -> list[AccuracyRule]:
    """The rules of :data:`ACCURACY_RULES` that apply to ``params`` and that its settings do not meet."""
    return [r for r in ACCURACY_RULES if r.applies(params) and not r.meets(params)]


def null_model_notes(params) -> list[str]:
    """What a scene that switches a mechanism off still keeps, for a null model stated with
    ``--set forces.TERM=false`` (docs/results.md, "Null models"): sticking comes from the forces,
    so removing only the bookkeeping does not remove aggregation."""
    f, notes = params.forces, []
    if not params.contacts.enabled and (f.tip_magnetic is not None or f.tip_brake is not None):
        notes.append(
            "contacts.enabled = false removes the contact bookkeeping (events, structures, the circuit), not "
            "aggregation: the tips still attract (forces.tip_magnetic) and stick (forces.tip_brake); for rods "
            "that never stick also set forces.tip_magnetic=false and forces.tip_brake=false"
        )
    if f.tip_magnetic is None and f.tip_brake is not None:
        notes.append(
            "forces.tip_magnetic is off but forces.tip_brake is on: tips that meet by chance still stick; "
            "set forces.tip_brake=false as well for rods that never stick"
        )
    if params.circuit is None and f.electrodes is not None and f.tip_magnetic is not None:
        notes.append("no circuit: filaments may still span the electrodes, but no current flows and none acts back")
    return notes
