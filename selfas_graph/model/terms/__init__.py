"""The force terms of docs/model.md 'Force terms', one class per term, and their container.

=====================  =====================================================================
module                 contents
=====================  =====================================================================
``base``               :class:`Term` (the interface), :class:`FieldSource`, shared helpers
``context``            :class:`EvalContext`: what the terms read and write in one evaluation;
                       :class:`PairLists`, the neighbour lists it hands out
``pairs``              forces between rods: terms 1, 2, 6 (tip-tip magnetic, tip brake, Yukawa)
``fields``             one-body terms of the apparatus: 3, 4, 5, 7, 8
``external``           the fixed objects of case (ii): term 11
``currents``           terms 9, 10 (the currents they read are the network's ``RodCurrents``)
``registry``           ``TERM_CLASSES``: scenario name -> term class (``term_classes``: and the
                       terms its table also turns on)
``forcefield``         :class:`ForceField`, the container (channels, sums, gather over ranks, state)
``mts``                :class:`MultipleTimeStepping`: the held slow forces
``timing``             :class:`TermClock`: wall time per term, for the benchmarks
=====================  =====================================================================

The term classes end in ``Force`` (``TipMagneticForce``); their parameters are the classes of
:mod:`selfas_graph.model.params` without the suffix (``TipMagnetic``).
"""

from .base import FieldSource, Term, share_by_mass
from .context import EvalContext, PairLists
from .currents import CurrentFieldForce, CurrentLorentzForce
from .external import ExternalDipoleForce, ExternalFilamentForce, ExternalLineChargeForce, external_monopoles
from .fields import AmbientBrakeForce, ElectricFieldForce, ElectrodesForce, PlasmaFilamentForce, UniformFieldForce
from .forcefield import ForceField
from .mts import MultipleTimeStepping
from .pairs import TipBrakeForce, TipMagneticForce, YukawaForce, yukawa_cutoff
from .registry import FOLLOWING_TERMS, TERM_CLASSES, term_classes
from .timing import TermClock

__all__ = [
    "AmbientBrakeForce",
    "CurrentFieldForce",
    "CurrentLorentzForce",
    "ElectricFieldForce",
    "ElectrodesForce",
    "EvalContext",
    "ExternalDipoleForce",
    "ExternalFilamentForce",
    "ExternalLineChargeForce",
    "FOLLOWING_TERMS",
    "FieldSource",
    "ForceField",
    "MultipleTimeStepping",
    "PairLists",
    "PlasmaFilamentForce",
    "TERM_CLASSES",
    "Term",
    "TermClock",
    "term_classes",
    "TipBrakeForce",
    "TipMagneticForce",
    "UniformFieldForce",
    "YukawaForce",
    "external_monopoles",
    "share_by_mass",
    "yukawa_cutoff",
]
