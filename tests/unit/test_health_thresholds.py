"""The thresholds of the health checks (docs/model.md 'Health checks'): a bond off by more than 0.05
before the corrections, or a tip moving more than 0.25 rod lengths along a coordinate in one step, stops the run with
a diagnosis; just below each threshold the run goes on.

The scene: 8 parallel rods 3 L apart with no force on them (no term, or the tip term with zero
charges), dt = 0.01, brought to step 5 and then set by hand. Without a force and with zero
velocities a step moves no tip, so a rod stretched by hand keeps its stretch into the bond error
of the step (the projection restores it after); a rod given one velocity on both tips keeps its
length and that speed. The states sit 1e-6 (relative) inside or outside a threshold: far beyond
the round-off of a bond length or a speed times dt (1e-16 relative), far within any physical
difference. Each threshold is checked on the two paths that carry the check: the Python step
(``HealthChecks.after_step``) and the compiled steps (``kernels/steps.py``, which hand a failed
step to ``after_step`` for its diagnosis).
"""

import numpy as np
import pytest

from conftest import simulation
from selfas_graph.kernels.steps import NEEDS_HEALTH
from selfas_graph.model.compiled import advance
from selfas_graph.model.health import NumericalFailure
from selfas_graph.model.state import State

#: the thresholds as docs/model.md 'Health checks' states them (not the constants of health.py)
BOND_LIMIT = 0.05
MOVE_LIMIT = 0.25
DT = 0.01
ROD = 6  # the rod set by hand
MARGIN = 1e-6  # relative distance of the hand-set states from the threshold (module docstring)


def scene(path):
    """The simulation at step 5 and a log of the compiled calls' (steps made, reason).

    ``path="python"``: no force term, so every step is a Python step (no compiled steps without
    multiple time stepping). ``path="compiled"``: the tip term on zero charges with
    ``integrator.slow_every = 4``, so that step 5 -> 6 is a compiled step (not a slow step, past
    the RK4 start)."""
    centre = np.array([[3.0 * i, 0.0, 0.0] for i in range(8)])
    state = State.from_rods(centre, np.tile([0.0, 0.0, 1.0], (8, 1)), np.zeros(8), np.zeros(8))
    if path == "python":
        sim = simulation(state, integrator={"dt": DT})
        assert sim.compiled is None
    else:
        sim = simulation(state, forces={"tip_magnetic": {}}, integrator={"dt": DT, "slow_every": 4})
        assert sim.compiled is not None
    calls = []
    if sim.compiled is not None:
        compiled_advance = sim.compiled.advance

        def logged(n):
            result = compiled_advance(n)
            calls.append(result)
            return result

        sim.compiled.advance = logged
    sim.step(5)
    sim.health.keep_last_good(sim.snapshot())  # as Simulation.run does at its start and each frame
    calls.clear()
    return sim, calls


def steps_with_errors(sim, n):
    """``n`` steps as ``Simulation.step`` makes them; returns the bond error before the constraint of each."""
    errors = []
    done = 0
    while done < n:
        done += advance(sim, n - done, rows=lambda first, e: errors.extend(float(v) for v in e))
    return errors


def stretch(sim, amount):
    """Lengthen rod ROD by ``amount`` along its axis (tip b moved), velocities untouched (zero)."""
    sim.state.position[2 * ROD + 1, 2] += amount


def move(sim, speed):
    """Give both tips of rod ROD the velocity ``speed`` along x (the rod keeps its length)."""
    sim.state.velocity[2 * ROD : 2 * ROD + 2] = [speed, 0.0, 0.0]


@pytest.mark.parametrize("path", ["python", "compiled"])
def test_a_bond_just_below_the_limit_passes(path):
    """A bond off by 0.05 (1 - 1e-6) before the corrections passes the check: the run makes its steps,
    and the step's bond error is that value (the state was the one meant), the projection then
    restoring the length."""
    sim, calls = scene(path)
    stretch(sim, BOND_LIMIT * (1 - MARGIN))
    errors = steps_with_errors(sim, 3)
    assert sim.state.step == 8
    assert errors[0] == pytest.approx(BOND_LIMIT * (1 - MARGIN), rel=1e-12)  # a length's round-off
    assert max(errors[1:]) < 1e-12 and sim.max_bond_error < 1e-12
    if path == "compiled":
        assert calls and calls[0][0] >= 1  # the step with the error was a compiled one


@pytest.mark.parametrize("path", ["python", "compiled"])
def test_a_bond_just_above_the_limit_stops_with_a_broken_bond_diagnosis(path):
    """A bond off by 0.05 (1 + 1e-6) stops the run at that step with NumericalFailure naming a broken
    rigid bond and its error, the step, the time step and the stretched rod, not a runaway step or
    a non-finite value."""
    sim, calls = scene(path)
    stretch(sim, BOND_LIMIT * (1 + MARGIN))
    with pytest.raises(NumericalFailure) as info:
        steps_with_errors(sim, 3)
    msg = str(info.value)
    assert info.value.step == 6 and "at step 6 " in msg
    assert f"a broken rigid bond (length error 0.05 >= {BOND_LIMIT})" in msg
    assert "runaway" not in msg and "non-finite" not in msg and f"integrator.dt = {DT:g}" in msg
    # the projection has given the bond its length again: the rods named are those whose tips moved most
    # since the last state that passed (the stretched rod, the others at rest)
    assert ROD in info.value.rods
    if path == "compiled":
        assert calls == [(1, NEEDS_HEALTH)]  # found by the compiled steps' own check


@pytest.mark.parametrize("path", ["python", "compiled"])
def test_a_step_just_below_the_move_limit_passes(path):
    """A tip whose velocity carries it 0.25 (1 - 1e-6) rod lengths in a step passes the check: the run
    makes its steps at that speed (no force changes it)."""
    sim, calls = scene(path)
    move(sim, MOVE_LIMIT * (1 - MARGIN) / DT)
    steps_with_errors(sim, 3)
    assert sim.state.step == 8
    assert sim.integrator.speed_max * DT == pytest.approx(MOVE_LIMIT * (1 - MARGIN), rel=1e-12)
    if path == "compiled":
        assert calls and calls[0][0] >= 1


@pytest.mark.parametrize("path", ["python", "compiled"])
def test_a_step_just_above_the_move_limit_stops_with_a_runaway_diagnosis(path):
    """A tip carried 0.25 (1 + 1e-6) rod lengths in a step stops the run at that step with NumericalFailure
    naming a runaway step and the distance, the step, the time step and the moving rod (the rods are
    ranked by speed), not a broken bond."""
    sim, calls = scene(path)
    move(sim, MOVE_LIMIT * (1 + MARGIN) / DT)
    with pytest.raises(NumericalFailure) as info:
        steps_with_errors(sim, 3)
    msg = str(info.value)
    assert info.value.step == 6 and "at step 6 " in msg
    assert f"a runaway step (a tip moved {MOVE_LIMIT} rod lengths along one axis in one step)" in msg
    assert "broken" not in msg and f"integrator.dt = {DT:g}" in msg and ROD in info.value.rods
    # no force acts (no term, or the tip term on zero charges): no term is named as the largest
    assert "no force acts on them" in msg and "'tip_magnetic'" not in msg
    if path == "compiled":
        assert calls == [(1, NEEDS_HEALTH)]
