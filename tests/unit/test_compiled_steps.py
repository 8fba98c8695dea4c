"""The fast steps in one compiled call (``Simulation.compiled``, model/compiled.py,
kernels/steps.py) against the Python step, their slow reference: the same state, bit for bit, after
every call, through contact events, list builds, slow evaluations and a short circuit; on one thread
and on a team of two (kernels/team.py) with the rods in as many blocks as threads or three times as
many (blocks of unequal sizes)."""

import platform

import numba
import numpy as np
import pytest

from conftest import SMALL_CIRCUIT_SCENE
from selfas_graph import load_scenario
from selfas_graph.io.scenario import scenario_from_text
from selfas_graph.model import compiled
from selfas_graph.model import operations as op
from selfas_graph.model.compiled import advance
from selfas_graph.model.simulation import Simulation


@pytest.fixture(params=["one thread", "team", "team, 3 blocks a thread"])
def team(request, monkeypatch):
    """The compiled steps on the calling thread only, or on two threads for every number of tips."""
    if request.param == "one thread":
        monkeypatch.setattr(compiled, "TEAM_TIPS", 2**62)
        return
    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("numba has one thread here (NUMBA_NUM_THREADS)")
    monkeypatch.setattr(compiled, "TEAM_TIPS", 0)
    monkeypatch.setattr(compiled, "TEAM_CHUNKS", 1 if request.param == "team" else 3)
    threads = numba.get_num_threads()
    numba.set_num_threads(2)
    request.addfinalizer(lambda: numba.set_num_threads(threads))


def pair(params, **integrator):
    """Two simulations of the same scene: every step in Python, and with the compiled steps."""
    params = params.replace(integrator=integrator) if integrator else params
    slow, fast = Simulation(params), Simulation(params)
    slow.compiled = None
    assert fast.compiled is not None
    return slow, fast


def same_snapshots(a, b):
    """Every entry of the two simulations' snapshots equal to the last bit (NaN where NaN)."""
    sa, sb = a.snapshot(), b.snapshot()
    assert sa.keys() == sb.keys()
    for k in sa:
        x, y = np.asarray(sa[k]), np.asarray(sb[k])
        assert x.shape == y.shape, k
        if x.dtype.kind == "f":
            np.testing.assert_array_equal(x.view(np.int64), y.view(np.int64), err_msg=k)
        else:
            assert np.array_equal(x, y), k


def step_for_step(slow, fast, n_steps):
    """Advance ``fast`` by calls of the compiled steps (as many steps as each call makes) and ``slow``
    by as many Python steps, comparing after each call; returns the number of calls that made more
    than one step."""
    runs = 0
    while fast.state.step < n_steps:
        k = advance(fast, n_steps - fast.state.step)
        runs += k > 1
        for _ in range(k):
            slow.python_step()
        same_snapshots(slow, fast)
        # the channels too (the force of every term at the last step, which the snapshot does not hold):
        # the compiled steps write a held force that is +0 throughout on the first step of a call only
        for name in ("channel_block", "total"):
            a, b = getattr(slow.force_field, name), getattr(fast.force_field, name)
            np.testing.assert_array_equal(a.view(np.int64), b.view(np.int64), err_msg=name)
        assert slow.force_field.calls == fast.force_field.calls
        assert slow.events == fast.events and slow.circuit_log == fast.circuit_log
    return runs


@pytest.mark.jit_off_ok
def test_compiled_steps_are_the_python_steps_early(team):
    """The first 160 steps of a small circuit scene under multiple time stepping (slow_every = 8): the
    RK4 start, tip-list builds and the first contacts, the state the same bit for bit after every call."""
    params = scenario_from_text(SMALL_CIRCUIT_SCENE).params.replace(rods={"count": 30})
    slow, fast = pair(params, slow_every=8)
    assert step_for_step(slow, fast, 160) > 5


@pytest.mark.jit_off_ok
@pytest.mark.skipif(
    platform.machine().lower() not in ("x86_64", "amd64"), reason="the cycle counter is read on x86-64 only"
)
def test_timed_phases_change_nothing(team):
    """With the phases timed (``FastStepArgs.phase_time``, ``bench profile --team --phases``) the steps are
    the same bit for bit; the call's ticks are counted, each phase's within them; a timing array of another
    length is refused."""
    params = scenario_from_text(SMALL_CIRCUIT_SCENE).params.replace(rods={"count": 30})
    slow, fast = pair(params, slow_every=8)
    fast.compiled.phase_time = np.zeros(9)
    assert step_for_step(slow, fast, 160) > 5
    t = fast.compiled.phase_time
    assert t[0] > 0 and t[2] > 0 and t[3] > 0 and t[1:].sum() <= t[0]
    fast.compiled.phase_time = np.zeros(8)
    with pytest.raises(ValueError, match="phase_time must be empty or"):
        fast.compiled.advance(8)


@pytest.mark.parametrize("brake", ["split", "explicit"])
def test_compiled_steps_are_the_python_steps_through_a_short_circuit(brake, team):
    """The whole small circuit scene (contacts from step 91, a short circuit at step 567 whose currents
    make the held current forces stale): bit for bit with the split and the explicit brakes."""
    params = scenario_from_text(SMALL_CIRCUIT_SCENE).params
    slow, fast = pair(params, slow_every=8, brake=brake)
    runs = step_for_step(slow, fast, 1200)
    assert runs > 50
    assert fast.short_circuit_time is not None and np.count_nonzero(fast.force_field.current)


#: the small circuit scene with term 5 (its axis off the z axis, its radius inside the placement box, so
#: that tips lie inside and outside the channel) and term 7 on
PLASMA_AND_E_SCENE = (
    SMALL_CIRCUIT_SCENE
    + """
[forces.plasma_filament]
radius = 1.5
current = -3.0
axis = [0.3, -0.2]
[forces.electric_field]
E = [0.1, -0.2, 0.3]
"""
)


def test_compiled_steps_are_the_python_steps_with_plasma_filament_and_electric_field(team):
    """The small circuit scene with the plasma filament (docs/model.md 'Term 5') and the uniform electric
    field ('Term 7') on, both fast terms of the compiled steps (``FAST_TERMS``): the plasma force on tips
    evaluated at every compiled step, the electric field's constant channel kept, bit for bit with the
    Python step through the contacts and the short circuit. The other scenes of this file switch neither
    term on."""
    params = scenario_from_text(PLASMA_AND_E_SCENE).params
    assert params.forces.plasma_filament is not None and params.forces.electric_field is not None
    slow, fast = pair(params, slow_every=8)
    assert step_for_step(slow, fast, 1200) > 50
    assert fast.short_circuit_time is not None  # the plasma field then acts on rod currents too (term 10)
    out = fast.force_field.out
    assert np.abs(out["plasma_filament"]).max() > 0 and np.abs(out["electric_field"]).max() > 0
    x = fast.state.position
    rho = np.hypot(x[:, 0] - 0.3, x[:, 1] + 0.2)
    assert rho.min() < 1.5 < rho.max()  # both branches of the field, inside and outside the channel


@pytest.mark.parametrize("line_slow", [False, True])
def test_compiled_steps_are_the_python_steps_in_case_ii(line_slow, team):
    """Case (ii), the quick Fig. 8 scene with fewer rods: external filament, the dipole's monopoles with
    their split brake and its screened line charge (at every step, or held with the slow forces:
    ``forces.external_dipole.line_charge_slow``), the filament's contact heights."""
    params = load_scenario("scenarios/fig8_quick.toml").params.replace(rods={"count": 60})
    params = params.replace(forces={"external_dipole": {"line_charge_slow": line_slow}})
    slow, fast = pair(params)
    assert step_for_step(slow, fast, 600) > 20
    evaluations = fast.force_field.calls["external_line_charge"]
    # at every evaluation (600 steps, and the RK4 start's stages), or only on the full ones: one in
    # slow_every, plus the RK4 start (3 steps x 4 stages); 20 is more than that and far below 600
    assert (evaluations < 600 // params.integrator.slow_every + 20) == line_slow


def test_compiled_steps_are_the_python_steps_with_tips_in_the_poles_cores(team):
    """Case (ii) with a tip of rod 0 inside the core of the dipole's upper pole and one of rod 1 inside the
    lower one from the start: the monopoles' split brake acts at every step, in the compiled steps as in
    Python, bit for bit (the scene of the test above never brings a tip within r* of a pole)."""
    from selfas_graph.model.placement import random_state

    params = load_scenario("scenarios/fig8_quick.toml").params.replace(rods={"count": 60})
    state = random_state(params)
    top = np.array([0.0, 0.0, 0.5 * params.forces.external_dipole.length])
    axis = np.array([0.0, 0.6, 0.8])
    state.position[1] = top + [0.01, 0.02, -0.03]  # tip b of rod 0 (charge -q), drawn to the +Q pole
    state.position[0] = state.position[1] - axis
    state.position[2] = -top + [0.02, -0.01, 0.03]  # tip a of rod 1 (+q), drawn to the -Q pole
    state.position[3] = state.position[2] + axis
    state.velocity[:4] = 0.5
    slow, fast = Simulation(params, state.copy()), Simulation(params, state.copy())
    slow.compiled = None
    brake = []
    column = slow.force_field.nonconservative.index("external_monopole_brake")
    for _ in range(200):
        slow.python_step()
        brake.append(slow.integrator.work[column])
    assert np.count_nonzero(np.diff(brake)) > 150  # the brake works at (nearly) every step
    slow = Simulation(params, state.copy())
    slow.compiled = None
    assert step_for_step(slow, fast, 600) > 20


@pytest.mark.parametrize("brake", ["split", "explicit"])
@pytest.mark.parametrize("fault", ["speed", "nan"])
def test_compiled_steps_stop_at_a_failing_step_with_the_python_diagnosis(fault, brake, team):
    """A tip thrown far in one step (its velocity 1e6) or made NaN: the compiled steps stop after that
    step with the Python step's diagnosis (the same message, step and rods), the state the same bit for
    bit. With the explicit brake the compiled step fails the health check; with the split brake the
    tip's move calls for a list build first, so the step is undone and made in Python."""
    from selfas_graph.model.health import NumericalFailure

    params = scenario_from_text(SMALL_CIRCUIT_SCENE).params
    slow, fast = pair(params, slow_every=8, brake=brake)
    step_for_step(slow, fast, 41)  # past the RK4 start; the next step is a fast one (slow_every = 8)
    for sim in (slow, fast):
        sim.state.velocity[7] = (1e6, 0.0, 0.0) if fault == "speed" else (np.nan, 0.0, 0.0)
    with pytest.raises(NumericalFailure) as python:
        while True:
            slow.python_step()
    reasons = []
    make = compiled.CompiledSteps.advance

    def spy(self, n_max):
        reasons.append(make(self, n_max))
        return reasons[-1]

    with pytest.MonkeyPatch.context() as m:
        m.setattr(compiled.CompiledSteps, "advance", spy)
        with pytest.raises(NumericalFailure) as comp:
            while True:
                advance(fast, 64)
    assert reasons[-1] == ((1, compiled.NEEDS_HEALTH) if brake == "explicit" else (0, compiled.NEEDS_STEP))
    assert str(comp.value) == str(python.value) and comp.value.step == python.value.step
    assert tuple(comp.value.rods) == tuple(python.value.rods)
    same_snapshots(slow, fast)


class Recorder:
    """A writer that records what a run hands it (per-step rows, frames)."""

    n_frames = 0

    def __init__(self):
        self.rows, self.frames = [], []

    def reserve_per_step(self, n):
        pass

    def buffer_per_step(self, step, err):
        self.rows.append((step, err))

    def flush_pending(self, events, circuit_log):
        pass

    def write_frame(self, step, time, position, velocity, obs):
        self.n_frames += 1
        self.frames.append((step, time, position.copy(), float(obs["energy_balance"])))

    def write_graph(self, *args):
        pass

    def flush(self):
        pass


def test_run_hands_the_same_rows_and_frames():
    """``run`` with the compiled steps: the same per-step rows, frames and observables as with every
    step in Python; the stop check, asked every 8 steps, stops after the first such step it is true."""
    params = scenario_from_text(SMALL_CIRCUIT_SCENE).params.replace(output={"interval": 0.02})
    slow, fast = pair(params, slow_every=8)
    ws, wf = Recorder(), Recorder()
    slow.run(t_end=0.3, writer=ws)
    fast.run(t_end=0.3, writer=wf)
    assert ws.rows == wf.rows and len(ws.rows) == 600
    assert [f[:2] + f[3:] for f in ws.frames] == [f[:2] + f[3:] for f in wf.frames]
    for a, b in zip(ws.frames, wf.frames):
        np.testing.assert_array_equal(a[2], b[2])
    same_snapshots(slow, fast)
    with pytest.raises(op.RunInterrupted) as exc:
        fast.run(t_end=0.4, stop=lambda: fast.state.step >= 603, check_every=8)
    assert exc.value.step == 608


def test_steps_to_next_act_counts_to_the_next_trigger():
    """The run's horizon: the next step of a Periodic trigger (with its phase), of a When trigger's
    period, 1 for an Always trigger; operations that take per-step rows do not count."""

    class Every(op.Operation):
        def __init__(self, trigger):
            self.trigger = trigger

    assert op.steps_to_next_act([Every(op.Periodic(10))], 0, 100) == 10
    assert op.steps_to_next_act([Every(op.Periodic(10, phase=3))], 3, 100) == 10
    assert op.steps_to_next_act([Every(op.Periodic(10, phase=3))], 4, 100) == 9
    assert op.steps_to_next_act([Every(op.When(lambda: True, 16))], 17, 100) == 15
    assert op.steps_to_next_act([Every(op.Periodic(10))], 0, 4) == 4
    assert op.steps_to_next_act([Every(op.Always())], 0, 100) == 1
    assert op.steps_to_next_act([op.PerStepRows(None, 5)], 0, 100) == 100
    assert op.When(lambda: True, 4)(8) and not op.When(lambda: True, 4)(9)


def test_all_plus_zero_tells_plus_zero_from_minus_zero_and_nan():
    """The test that lets the compiled steps skip a held force whose rate and base are +0 throughout: only
    +0 counts (rate * s + base is then +0; with a -0 in the base it would be +0 where the base holds -0)."""
    from selfas_graph.kernels.steps import _all_plus_zero

    assert _all_plus_zero(np.zeros((5, 3))) and _all_plus_zero(np.zeros((0, 3)))
    for bad in (-0.0, np.nan, 1e-300, np.inf):
        a = np.zeros((5, 3))
        a[4, 2] = bad
        assert not _all_plus_zero(a)


def test_the_reason_a_run_takes_every_step_in_python_is_named(tmp_path, capsys):
    """python_steps_reason names why no step is compiled (no multiple time stepping, timing, a fast term the
    compiled steps do not know) and is None exactly when the simulation has compiled steps; the dry run's
    plan says which (``fast_steps``)."""
    import json

    from selfas_graph.cli.main import main

    base = scenario_from_text(SMALL_CIRCUIT_SCENE).params
    mts = base.replace(integrator={"slow_every": 4})
    sim = Simulation(mts)
    assert sim.compiled is not None and compiled.python_steps_reason(sim) is None
    assert "slow_every = 1" in compiled.python_steps_reason(Simulation(base))
    timed = Simulation(mts)
    timed.force_field.clock.on = True
    assert compiled.python_steps_reason(timed) == "per-term timing is on"
    unknown = Simulation(mts)
    term = next(t for t in unknown.force_field.terms if t.name == "tip_brake")
    term.name = "a_new_term"
    assert compiled.python_steps_reason(unknown) == "fast terms the compiled steps do not know: a_new_term"
    scene = tmp_path / "s.toml"
    scene.write_text(SMALL_CIRCUIT_SCENE)
    for every, says in ((4, "compiled"), (1, "in Python: no multiple time stepping")):
        capsys.readouterr()
        assert main(["simulate", str(scene), "--dry-run", "--set", f"integrator.slow_every={every}"]) == 0
        out = capsys.readouterr().out
        assert json.loads(out[out.index("{") :])["fast_steps"].startswith(says)


@pytest.mark.jit_off_ok
@pytest.mark.parametrize("field", ["uniform_field", "electric_field"])
def test_a_simulation_from_a_snapshot_keeps_the_constant_fields_in_its_compiled_steps(field):
    """The compiled steps leave the channels of the uniform magnetic and electric fields as a Python step
    filled them. A simulation rebuilt from a snapshot at a step off the slow pattern starts with them at
    zero, and its compiled steps went on without the fields until a step ran in Python (scenes without
    electrodes, whose brake sends the first step to Python: 7.7e-3 in position after 400 steps of the
    Fig. 8 quick scene). Its first step now runs in Python: the run is the uninterrupted one, bit for bit."""
    import copy

    params = scenario_from_text(SMALL_CIRCUIT_SCENE).params.replace(rods={"count": 30}, integrator={"slow_every": 8})
    off = ("forces.electrodes", "circuit", "forces.current_field", "forces.current_lorentz")
    params = params.replace({k: False for k in off})
    if field == "electric_field":
        params = params.replace({"forces.uniform_field": False, "forces.electric_field": {"E": [0.0, 0.0, 0.5]}})
    whole = Simulation(params)
    assert whole.compiled is not None
    whole.step(203)  # off the pattern of slow_every = 8
    resumed = Simulation.from_snapshot(params, copy.deepcopy(whole.snapshot()))
    assert np.abs(whole.force_field.out[field]).max() > 0.1
    whole.step(100)
    resumed.step(100)
    same_snapshots(whole, resumed)


@pytest.mark.jit_off_ok
def test_where_a_run_stops_off_the_frame_grid_does_not_change_its_trajectory():
    """The energies of a frame at a run's end off the frame grid rebuilt the rod-centre list there, and
    the steps after it summed the Yukawa force over that list: ``sim.run(t1); sim.run(t2)`` differed from
    ``sim.run(t2)`` (3.6e-14 in position in the quick scene), and so did a resume after an end off the
    grid. Off the grid the energies now read the lists without moving their rebuilds (the same values);
    on it they update them as they always have."""
    params = scenario_from_text(SMALL_CIRCUIT_SCENE).params.replace(
        rods={"count": 30}, integrator={"slow_every": 8}, neighbours={"centre_skin": 1e-4}, output={"interval": 0.05}
    )
    whole, chunked = Simulation(params), Simulation(params)
    whole.run(0.2)
    chunked.run(0.1025)  # 205 steps: off the frame grid (100 steps) and off the slow pattern
    energies = chunked.energies()
    chunked.run(0.2)
    same_snapshots(whole, chunked)
    assert np.isfinite(list(energies.values())).all()
