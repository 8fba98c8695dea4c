"""The force terms by scenario name: ``[forces.<name>]`` turns on ``TERM_CLASSES[name]`` and, right
after it, the terms of ``FOLLOWING_TERMS[name]`` (a table that sets up more than one term)."""

from __future__ import annotations

from .currents import CurrentFieldForce, CurrentLorentzForce
from .external import ExternalDipoleForce, ExternalFilamentForce, ExternalLineChargeForce
from .fields import AmbientBrakeForce, ElectricFieldForce, ElectrodesForce, PlasmaFilamentForce, UniformFieldForce
from .pairs import TipBrakeForce, TipMagneticForce, YukawaForce

#: scenario name (a field of ForceParams) -> term class; the field order of ForceParams, not
#: this table's, is the order the terms are computed and summed in
TERM_CLASSES = {
    cls.name: cls
    for cls in (
        TipMagneticForce,
        TipBrakeForce,
        AmbientBrakeForce,
        UniformFieldForce,
        PlasmaFilamentForce,
        YukawaForce,
        ElectricFieldForce,
        ElectrodesForce,
        ExternalFilamentForce,
        ExternalDipoleForce,
        CurrentFieldForce,
        CurrentLorentzForce,
    )
}

#: scenario name -> the terms its table also turns on, built and summed right after TERM_CLASSES[name]
FOLLOWING_TERMS = {"external_dipole": (ExternalLineChargeForce,)}


def term_classes(name) -> tuple:
    """The term classes ``[forces.<name>]`` turns on, in the order they are computed and summed."""
    return (TERM_CLASSES[name], *FOLLOWING_TERMS.get(name, ()))
