"""Exact restart: a simulation's :func:`snapshot` and a simulation rebuilt from one (:func:`from_snapshot`),
the union of the components' states (the bodies of :meth:`Simulation.snapshot
<.simulation.Simulation.snapshot>` and :meth:`Simulation.from_snapshot <.simulation.Simulation.from_snapshot>`)."""

from __future__ import annotations

import math

import numpy as np

from . import events as ev
from .circuitlog import circuit_log_array
from .integrator import same_time_step
from .state import State


def snapshot(sim) -> dict:
    """Everything the next step of ``sim`` depends on, as a flat dict of numpy arrays and scalars."""
    snap = sim.state.state_dict()
    snap.update(sim.integrator.state_dict())
    snap.update(
        max_bond_error=sim.health.max_bond_error,
        energy0=np.nan if sim.observe.energy0 is None else sim.observe.energy0,
        events=ev.event_array(sim.events),
        circuit_log=circuit_log_array(sim.circuit_log),
        short_circuit_time=np.nan if sim.short_circuit_time is None else sim.short_circuit_time,
    )
    if sim.network is not None:
        snap.update(sim.network.state_dict())  # contacts, flags, filament heights, the rod currents
    snap.update(sim.force_field.state_dict())  # neighbour lists, held slow forces
    return snap


def from_snapshot(cls, params, snap: dict, timing=False, comm=None, new_dt=False):
    """A ``cls`` (a :class:`~.simulation.Simulation`) of ``params`` continuing from ``snap``; with ``new_dt``
    at another time step than the snapshot's, its derivative history forgotten (the next three steps RK4)."""
    state = State.from_state_dict(snap)
    sim = cls(params, state=state, timing=timing, comm=comm, check_state=False)
    _check_time_step(sim.integrator, snap, new_dt)
    sim.integrator.load_state_dict(snap)
    if new_dt:
        sim.integrator.reset_history()
    sim.health.max_bond_error = float(snap["max_bond_error"])
    e0 = float(snap["energy0"])
    sim.observe.energy0 = None if math.isnan(e0) else e0
    sct = float(snap["short_circuit_time"])
    sim.short_circuit_time = None if math.isnan(sct) else sct
    sim.events = [tuple(r.item()) for r in np.asarray(snap["events"])]
    sim.circuit_log = [tuple(r.item()) for r in snap.get("circuit_log", ())]  # older checkpoints: none
    if sim.network is not None:
        sim.network.load_state_dict(snap)
    ff = sim.force_field
    ff.bind(state.position, state.velocity)
    ff.load_state_dict(snap)  # neighbour lists, held slow forces (missing ones: rebuilt)
    return sim


def snapshot_dt(snap: dict) -> float | None:
    """The time step ``snap`` was made with, from its step and time and the run's time origin
    (``time = origin_time + (step - origin_step) dt``); None at the origin itself, where no step was made."""
    steps = int(snap["step"]) - int(snap["time_origin_step"])
    return (float(snap["time"]) - float(snap["time_origin_time"])) / steps if steps else None


def _check_time_step(integrator, snap, new_dt) -> None:
    """ValueError when ``snap`` was made at another time step than ``integrator``'s and ``new_dt`` is not
    given: the Adams-Bashforth history it holds is of derivatives at the old step's spacing, which the new
    step would extrapolate as if they were at its own."""
    if new_dt or int(snap["count"]) == 0 or same_time_step(snap, integrator.dt):
        return
    raise ValueError(
        f"Simulation.from_snapshot: the snapshot was made with integrator.dt = {snapshot_dt(snap)!r}, the "
        f"parameters have {integrator.dt!r}; its Adams-Bashforth history holds derivatives at the old time "
        f"step. Continue with the snapshot's dt, or start a new run from its state "
        f"(Simulation(params, state=State.from_state_dict(snap))); new_dt=True continues it with the "
        f"history forgotten (RK4 again)"
    )
