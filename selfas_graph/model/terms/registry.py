"""The force terms by scenario name: ``[forces.<name>]`` turns on ``TERM_CLASSES[name]``."""

from __future__ import annotations

from .currents import CurrentFieldForce, CurrentLorentzForce
from .external import ExternalDipoleForce, ExternalFilamentForce
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
