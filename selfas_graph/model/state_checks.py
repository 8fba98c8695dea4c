"""Whether a state given to a simulation fits its parameters (:func:`check_against`): the rules a scene
file's placement obeys (``io/scenario.py``), for a state built by hand."""

from __future__ import annotations

import numpy as np

from ..kernels.rigid import bond_length_error
from .health import BOND_BREAK
from .params import Parameters
from .state import State, StateError
from .validate import MAX_RESISTANCE_SPREAD


def check_against(params: Parameters, state: State, values: bool = True) -> None:
    """StateError where a state given to a simulation does not fit ``params``: another rod count, and with
    ``values`` what a scene file may not hold: lengths of mean off 1 or under the diameter, resistances or
    lengths the parameters set but the state lacks (its rods would take 1 and the run file state the
    other), resistances spanning more than :data:`~.validate.MAX_RESISTANCE_SPREAD`, a tip beyond an electrode
    by more than r* (docs/model.md 'Term 8: electrode walls (case (i))': the walls' range)."""
    rods, n = params.rods, state.n_rods
    if n != rods.count:
        raise StateError(
            f"the state has {n} rods but rods.count = {rods.count}; make them agree, e.g. "
            f"params.replace(rods={{'count': {n}}})"
        )
    if not values:
        return
    for name, key in (("rod_length", "length"), ("rod_resistance", "resistance")):
        if getattr(rods, key) is not None and getattr(state, name) is None:
            raise StateError(
                f"State.{name}: rods.{key} is set in the parameters, but the state has none (its rods would "
                f"take 1); give them (State.from_rods(..., {key}=...)) or leave rods.{key} out"
            )
    if state.rod_length is not None:
        shortest, mean = float(state.rod_length.min()), float(state.rod_length.mean())
        if shortest < rods.diameter or abs(mean - 1.0) > 1e-9:
            raise StateError(
                f"State.rod_length: the rods' mean length is {mean:.12g} and the shortest {shortest:g}; lengths are "
                f"in units of the mean rod length (mean 1, docs/model.md 'Reduced units'), none shorter than "
                f"rods.diameter = {rods.diameter:g}"
            )
    r = state.rod_resistance if state.rod_resistance is not None else np.ones(n)
    c = params.contacts.resistance
    lo, hi = min(r.min(), c if c > 0 else np.inf), max(r.max(), c)
    if params.circuit is not None and hi > MAX_RESISTANCE_SPREAD * lo:
        raise StateError(
            f"State.rod_resistance: the circuit's resistances span {lo:.3g} to {hi:.3g} R0, a factor above "
            f"{MAX_RESISTANCE_SPREAD:.0e}: the Kirchhoff solve's round-off grows with it and its currents would be "
            f"wrong without a sign; keep them within that factor"
        )
    el = params.forces.electrodes
    if el is not None:
        beyond = np.flatnonzero(np.abs(state.position[:, 2]) > 0.5 * el.gap + rods.rstar)
        if len(beyond):
            tip = int(beyond[0])
            raise StateError(
                f"State.position: tip {tip} (rod {tip // 2}) is at z = {state.position[tip, 2]:.6g}, beyond the "
                f"electrodes at z = +-{0.5 * el.gap:g} (forces.electrodes.gap = {el.gap:g}) by more than r* = "
                f"{rods.rstar:g}; rods start between them"
                + (f" ({len(beyond)} tips are beyond)" if len(beyond) > 1 else "")
            )


def check_live(state: State) -> None:
    """StateError where the live state, between two steps, is not one the steps leave: a NaN or inf,
    or a rod whose tips are not its length apart (past the health checks' bond limit). A run that
    breaks down stops with a diagnosis before either; so they come from changes made from outside, to
    the arrays ``sim.state.position`` and ``.velocity`` the simulation steps in place, and the message
    says so rather than blaming the time step or a force (``Simulation.step`` and ``run`` check this)."""
    for name in ("position", "velocity"):
        a = getattr(state, name)
        if not np.isfinite(a).all():
            tip = int(np.flatnonzero(~np.isfinite(a).all(axis=1))[0])
            raise StateError(
                f"sim.state.{name} holds NaN or inf at tip {tip} (rod {tip // 2}) before the step: the state was "
                f"changed from outside since the last step (its arrays are the simulation's own); give finite values"
            )
    length = state.rod_length if state.rod_length is not None else np.zeros(0)
    err = bond_length_error(state.position, length)
    if err >= BOND_BREAK:
        ell = np.ones(state.n_rods) if state.rod_length is None else state.rod_length
        gap = np.linalg.norm(state.position[1::2] - state.position[0::2], axis=1)
        rod = int(np.argmax(np.abs(gap - ell)))
        raise StateError(
            f"sim.state.position: the tips of rod {rod} are {gap[rod]:.6g} apart, not its length {ell[rod]:.6g}, "
            f"before the step: the positions were changed from outside since the last step; move a rod's two "
            f"tips together (the bonds are rigid)"
        )
