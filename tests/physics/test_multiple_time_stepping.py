"""Multiple time stepping (``integrator.slow_every``, ``integrator.fast_range``).

The slow forces (tip pairs beyond the fast range, the Yukawa sum, the rod-current
terms) are evaluated on every K-th step and held in between; the stiff short-range
forces are fresh every step. These tests check the split itself (fast part against a
literal reference, fast + slow = the whole force), which evaluations skip the slow
kernels (by counting calls), that currents changing force a full evaluation, that the
error vanishes as K -> 1, and that a resumed run continues bit for bit.
"""

import numpy as np
import pytest

import reference as ref
from conftest import SMALL_CIRCUIT_SCENE, random_rods, simulation
from selfas_graph import NumericalFailure, Simulation
from selfas_graph.io.checkpoint import read_checkpoint, write_checkpoint
from selfas_graph.io.scenario import scenario_from_text
from selfas_graph.kernels import tips as kt
from selfas_graph.model.neighbours import NeighbourList

RSTAR, KAPPA = 0.06, 1.0

SCENE = """
[scenario]
seed = 5
[rods]
count = 80
[placement]
box = [[-2.0, 2.0], [-2.0, 2.0], [-1.5, 1.5]]
[forces.tip_magnetic]
[forces.tip_brake]
[forces.ambient_brake]
[forces.yukawa]
core_radius = 0.06
[forces.electrodes]
gap = 3.0
[integrator]
dt = 1e-3
brake = "split"
[run]
t_end = 0.3
"""


def _switch(r, r_in, r_out):
    """S(r) as documented: 1 inside r_in, 0 beyond r_out, smoothstep between."""
    if r <= r_in:
        return 1.0
    if r >= r_out:
        return 0.0
    s = (r - r_in) / (r_out - r_in)
    return 1.0 - s * s * (3.0 - 2.0 * s)


def test_switch_is_continuous_with_a_continuous_slope():
    r_in, r_out = 0.12, 0.18
    s = kt.fast_switch.py_func
    assert s(0.0, r_in, r_out) == 1.0 and s(r_in**2, r_in, r_out) == 1.0 and s(r_out**2, r_in, r_out) == 0.0
    # one-sided slopes at both ends vanish: (S(r +- h) - S(r)) / h = 3 h / (r_out - r_in)^2 at most,
    # 8e-4 for h = 1e-6, against the largest slope 1.5 / (r_out - r_in) = 25 in the middle. Measured
    # 8.33e-4 inside the range (the exact 3 h / d^2 - 2 h^2 / d^3, d = r_out - r_in, to 2.3e-12), 0 outside;
    # the round-off of S adds at most 1e-16 / h = 1e-10, so 1e-3 is the formula's value with a 1.2x margin,
    # and a kink at the ends fails it
    h = 1e-6
    for r in (r_in, r_out):
        for side in (-1.0, 1.0):
            assert abs(s((r + side * h) ** 2, r_in, r_out) - s(r * r, r_in, r_out)) / h < 1e-3
    mid = 0.5 * (r_in + r_out)
    # s = 1/2 up to the rounding of r_in + r_out and of the square root, about 1 ulp of 0.15 over
    # r_out - r_in = 0.06, times |dS/ds| = 1.5: below 1e-15. Measured: exactly 0.5
    assert s(mid * mid, r_in, r_out) == pytest.approx(0.5, abs=1e-15)


def test_fast_kernel_equals_the_literal_switched_sum(rng):
    """Every pair of tips of different rods within r_out, S(r) f(r) along the pair, summed literally."""
    s = random_rods(60, rng, box=1.2)
    # pairs in the core, in the switch zone and exactly on top of each other
    s.position[5] = s.position[40] + [0.02, 0.0, 0.01]
    s.position[7] = s.position[50] + [0.0, 0.15, 0.0]
    s.position[9] = s.position[60]
    r_in, r_out = 2 * RSTAR, 3 * RSTAR
    nl = NeighbourList(r_out, 0.1, exclude_same_rod=True)
    nl.build(s.position)
    got = np.zeros_like(s.position)
    kt.tip_tip_fast(s.position, s.tip_charge, nl.start, nl.index, RSTAR, KAPPA, r_in, r_out, got)
    want = np.zeros_like(s.position)
    n = s.n_tips
    for k in range(n):
        for l in range(n):
            if k // 2 == l // 2:
                continue
            d = s.position[k] - s.position[l]
            r = np.linalg.norm(d)
            if 0 < r < r_out:
                want[k] += (
                    ref.tip_law(r, s.tip_charge[k] * s.tip_charge[l], RSTAR, KAPPA) * _switch(r, r_in, r_out) * d / r
                )
    assert np.abs(want).max() > 1.0  # the core pairs are in
    # round-off of sums of a few terms of size up to ~1e4 (core pairs): 1e-12 relative to the largest
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12 * np.abs(want).max())
    # the compiled steps' kernel by blocks of tips (kernels/tips.py tip_tip_fast_rows), the same sum
    parts = np.full_like(s.position, np.nan)
    for t0, t1 in ((0, 40), (40, 41), (41, 41), (41, n)):
        kt.tip_tip_fast_rows(s.position, s.tip_charge, nl.start, nl.index, RSTAR, KAPPA, r_in, r_out, t0, t1, parts)
    np.testing.assert_allclose(parts, want, rtol=1e-12, atol=1e-12 * np.abs(want).max())


def _sim(slow_every, **extra):
    text = SCENE.replace('brake = "split"', f'brake = "split"\nslow_every = {slow_every}')
    sc = scenario_from_text(text, overrides=[f"{k}={v}" for k, v in extra.items()])
    return Simulation.from_scenario(sc)


def test_full_and_fast_evaluations_give_the_whole_force():
    """Right after a full evaluation, held slow part + fresh fast part is the whole force (round-off)."""
    plain, mts = _sim(1), _sim(4)
    x, v = plain.state.position, plain.state.velocity
    want = plain.force_field.evaluate(x, v).copy()
    full = mts.force_field.evaluate(x, v, full=True).copy()
    fast = mts.force_field.evaluate(x, v, full=False).copy()
    np.testing.assert_array_equal(full, want)  # a full evaluation is the plain one
    # far part + fast part, rounded separately: 1e-12 of the largest force
    np.testing.assert_allclose(fast, want, rtol=0, atol=1e-12 * np.abs(want).max())


def test_slow_kernels_run_only_on_every_kth_step():
    """Counted, not timed: 3 RK4 start steps (4 evaluations each, all full), then one full evaluation
    per K steps, counted from step 0."""
    k, steps = 4, 40
    sim = _sim(k)
    sim.step(steps)
    full = 12 + sum(1 for s in range(3, steps) if s % k == 0)
    calls = sim.force_field.calls
    assert calls["tip_magnetic"] == full and calls["yukawa"] == full
    assert calls["electrodes"] == 12 + steps - 3  # a fast term: every evaluation


@pytest.mark.parametrize("extrapolate", ["false", "true"])
def test_new_currents_refresh_the_current_terms_at_the_next_step(rng, extrapolate):
    """After a circuit solve the current terms are recomputed at the next step, full or not, and
    only they: the tip-tip and Yukawa sums keep their cycle."""
    s = random_rods(6, rng, box=3.0)
    sim = simulation(
        s,
        forces={"tip_magnetic": {}, "electrodes": {"gap": 20.0}, "current_field": {}, "current_lorentz": {}},
        circuit={"delta_J0": 1.0},
        integrator={"slow_every": 5, "dt": 1e-3, "slow_extrapolation": extrapolate == "true"},
    )
    sim.step(5)  # RK4 start, steps 3 and 4 fast
    ff = sim.force_field
    before = ff.calls["tip_magnetic"]
    sim.step(1)  # step 5: full anyway
    sim.step(1)  # step 6: fast
    assert ff.calls["tip_magnetic"] == before + 1
    ff.set_currents(np.linspace(0.5, 1.0, s.n_rods))
    sim.step(1)  # step 7: fast, but the currents changed
    assert ff.calls["tip_magnetic"] == before + 1
    assert ff.calls["current_field"] == 1 and ff.calls["current_lorentz"] == 1
    held = ff.out["current_field"].copy()
    assert np.abs(held).max() > 0
    sim.step(1)  # step 8: fast; the current force is held (no trend across a jump of the currents)
    assert ff.calls["current_field"] == 1
    np.testing.assert_array_equal(ff.out["current_field"], held)
    sim.step(2)  # step 10: full
    assert ff.calls["current_field"] == 2 and ff.calls["tip_magnetic"] == before + 2


def test_the_same_currents_again_refresh_nothing(rng):
    """A solve that gives the currents already in use (an event in a structure that carries none)
    leaves the held current forces as they are: nothing is recomputed off the cycle."""
    s = random_rods(6, rng, box=3.0)
    sim = simulation(
        s,
        forces={"tip_magnetic": {}, "electrodes": {"gap": 20.0}, "current_field": {}, "current_lorentz": {}},
        circuit={"delta_J0": 1.0},
        integrator={"slow_every": 5, "dt": 1e-3},
    )
    sim.step(6)  # RK4 start, step 5 full, now at step 6
    ff = sim.force_field
    current = np.linspace(0.5, 1.0, s.n_rods)
    ff.set_currents(current)
    sim.step(1)  # step 6: fast, the new currents computed
    assert ff.calls["current_field"] == 1
    ff.set_currents(current.copy())  # the same values, another array
    assert not ff.mts.stale
    sim.step(1)  # step 7: fast, nothing recomputed
    assert ff.calls["current_field"] == 1 and ff.calls["current_lorentz"] == 1
    ff.set_currents(current * 1.5)  # different values: refreshed at the next step
    sim.step(1)
    assert ff.calls["current_field"] == 2


def test_error_vanishes_as_the_slow_interval_shrinks():
    """Position difference from K = 1 after 0.05 t0 (the violent start of a random scene, before
    contacts amplify every difference), with the default fast range. Held forces err to first
    order in K dt (measured for K = 2, 4, 8, 16: 2.8e-5, 8.3e-5, 1.8e-4, 3.4e-4), below the
    difference that halving the time step makes (1.7e-4) at K = 2; extrapolated ones to second
    order (2.4e-6, 1.4e-5, 6.9e-5, 2.7e-4)."""
    t = 0.05
    base = _sim(1)
    base.run(t_end=t)
    err = {}
    for extrapolate in ("false", "true"):
        for k in (2, 4, 8):
            sim = _sim(k, **{"integrator.slow_extrapolation": extrapolate})
            sim.run(t_end=t)
            err[extrapolate, k] = float(np.abs(sim.state.position - base.state.position).max())
    half = _sim(1, **{"integrator.dt": 5e-4})
    half.run(t_end=t)
    for mode in ("false", "true"):
        assert err[mode, 2] < err[mode, 4] < err[mode, 8]
    assert err["false", 2] < float(np.abs(half.state.position - base.state.position).max()), err
    for k in (2, 4, 8):
        assert err["true", k] < err["false", k], err
    assert err["true", 4] > 3 * err["true", 2], err  # second order: 4x expected, 6x measured


@pytest.mark.parametrize("extrapolate", ["false", "true"])
def test_checkpoint_between_full_evaluations_resumes_bit_for_bit(tmp_path, extrapolate):
    """Interrupted at a step that is not a multiple of K, the held forces (and the extrapolation's
    bases and rates) travel in the checkpoint."""
    n1, n2 = 23, 30
    extra = {"integrator.slow_extrapolation": extrapolate}
    whole = _sim(4, **extra)
    whole.step(n1 + n2)
    first = _sim(4, **extra)
    first.step(n1)
    path = tmp_path / "c.h5"
    write_checkpoint(path, first.snapshot(), {"scenario_text": "", "overrides": "[]", "run_file": "x", "version": "t"})
    snap, _ = read_checkpoint(path)
    assert any(key.startswith("mts_held_") for key in snap)
    second = Simulation.from_snapshot(first.params, snap)
    second.step(n2)
    np.testing.assert_array_equal(second.state.position, whole.state.position)
    np.testing.assert_array_equal(second.state.velocity, whole.state.velocity)


@pytest.mark.parametrize("current_every", [0, 8])
def test_resume_with_currents_flowing_is_bit_for_bit(tmp_path, current_every):
    """The small circuit scene (contacts, a short circuit, currents re-solved at events) with K = 4, and
    with the current terms every M = 8 steps: interrupted after the short circuit at a step that is a
    multiple of neither K nor M, resumed from a checkpoint file, it ends where the uninterrupted run ends."""
    text = SMALL_CIRCUIT_SCENE.replace("dt = 5e-4", f"dt = 5e-4\nslow_every = 4\ncurrent_every = {current_every}")
    sc = scenario_from_text(text)
    whole = Simulation.from_scenario(sc)
    whole.step(1200)
    # the circuit closes before the interruption at step 901 (t = 0.4505): currents flow across it
    assert whole.short_circuit_time is not None and whole.short_circuit_time < 0.4
    first = Simulation.from_scenario(sc)
    first.step(901)
    path = tmp_path / "c.h5"
    write_checkpoint(
        path, first.snapshot(), {"scenario_text": text, "overrides": "[]", "run_file": "x", "version": "t"}
    )
    second = Simulation.from_snapshot(sc.params, read_checkpoint(path)[0])
    second.step(299)
    np.testing.assert_array_equal(second.state.position, whole.state.position)
    np.testing.assert_array_equal(second.force_field.current, whole.force_field.current)
    assert second.events == whole.events


def test_slow_interval_far_past_its_limit_stops_with_a_diagnosis_naming_it():
    """K = 1000 (the largest accepted): the slow forces, held through the violent start of the
    small scene, leave the energy balance off by most of the energy turned over; the run stops
    on the energy check at t = 1 with a message naming slow_every, its state still finite."""
    sim = _sim(1000)
    with pytest.raises(NumericalFailure) as info:
        sim.run(t_end=3.0)
    msg = str(info.value)
    assert "integrator.slow_every = 1000" in msg and f"step {info.value.step}" in msg
    assert np.isfinite(sim.state.position).all() and np.isfinite(sim.state.velocity).all()


def _current_sim(rng, slow_every, current_every, extrapolate=True):
    s = random_rods(6, rng, box=3.0)
    return s, simulation(
        s,
        forces={"tip_magnetic": {}, "electrodes": {"gap": 20.0}, "current_field": {}, "current_lorentz": {}},
        circuit={"delta_J0": 1.0},
        integrator={
            "slow_every": slow_every,
            "current_every": current_every,
            "dt": 1e-3,
            "slow_extrapolation": extrapolate,
        },
    )


def test_current_every_evaluates_the_current_terms_every_mth_step(rng):
    """Counted, not timed: with K = 4 and M = 12 the current terms run on the step after new currents,
    on the next full evaluation (their first rate after the change), then on the full evaluations of
    the multiples of 12 only, the tip-tip sum on every 4th; in between the current forces are
    extrapolated from their last two evaluations, the same numbers as the held base plus rate times
    the steps since."""
    s, sim = _current_sim(rng, 4, 12)
    sim.step(4)  # RK4 start (steps 0-2), step 3 fast
    ff, mts = sim.force_field, sim.force_field.mts
    ff.set_currents(np.linspace(0.5, 1.0, s.n_rods))
    sim.step(1)  # step 4: full, and the currents are new: computed, no rate (a jump)
    calls = dict(ff.calls)
    assert not mts._rated["current_field"]
    sim.step(4)  # steps 5-8: full at 8, not a multiple of 12, but the current terms have no rate yet
    assert ff.calls["current_field"] == calls["current_field"] + 1 and mts._rated["current_field"]
    sim.step(4)  # steps 9-12: full at 12, everything
    assert ff.calls["current_field"] == calls["current_field"] + 2
    sim.step(12)  # steps 13-24: full at 16 and 20 (tip-tip only), 24 (everything)
    assert ff.calls["current_field"] == calls["current_field"] + 3
    assert ff.calls["current_lorentz"] == calls["current_lorentz"] + 3
    assert ff.calls["tip_magnetic"] == calls["tip_magnetic"] + 5
    sim.step(4)  # steps 25-28, full at 28 for the tip-tip sum: the current force extrapolated from 12 and 24
    assert ff.calls["current_field"] == calls["current_field"] + 3
    assert mts.base_step["current_field"] == 24
    want = mts._rate["current_field"] * 4.0 + mts._base["current_field"]
    np.testing.assert_array_equal(ff.out["current_field"], want)
    assert not np.array_equal(want, mts._base["current_field"])


def test_current_every_new_currents_before_a_fast_step(rng):
    """K = 4, M = 16: currents changed before a fast step are computed there with no rate, again at the
    next full evaluation (the first rate after the change), and then only on the multiples of 16."""
    s, sim = _current_sim(rng, 4, 16)
    sim.step(17)  # RK4 start, steps up to 16, now at step 17
    ff, mts = sim.force_field, sim.force_field.mts
    ff.set_currents(np.linspace(0.5, 1.0, s.n_rods))
    sim.step(1)  # step 17: fast, the new currents
    assert ff.calls["current_field"] == 1 and mts.base_step["current_field"] is None
    sim.step(3)  # steps 18-20: full at 20, the current terms too (no base at a step start yet)
    assert ff.calls["current_field"] == 2 and not mts._rated["current_field"]
    sim.step(4)  # step 24: again (a rate needs two evaluations at step starts)
    assert ff.calls["current_field"] == 3 and mts._rated["current_field"]
    sim.step(8)  # steps 25-32: full at 28 (skipped) and 32 (computed)
    assert ff.calls["current_field"] == 4


def test_current_every_new_currents_on_a_full_step_start_without_a_rate(rng):
    """With current_every, currents changed right before a full evaluation start a base with no rate
    as without it, and the next full evaluation takes the rate."""
    s, sim = _current_sim(rng, 4, 16)
    sim.step(5)
    ff, mts = sim.force_field, sim.force_field.mts
    ff.set_currents(np.linspace(0.5, 1.0, s.n_rods))
    sim.step(12)  # steps 5-16: a rate from 12 and 16
    assert mts._rated["current_field"] and np.abs(mts._rate["current_field"]).max() > 0.0
    sim.step(3)  # to step 20
    ff.set_currents(3.0 * np.linspace(0.5, 1.0, s.n_rods))
    sim.step(1)  # step 20: full (not a multiple of 16), and the currents are new
    assert np.abs(mts._rate["current_field"]).max() == 0.0 and not mts._rated["current_field"]
    n = ff.calls["current_field"]
    sim.step(4)  # step 24: full, computed for its rate
    assert ff.calls["current_field"] == n + 1 and mts._rated["current_field"]


def test_current_every_computes_the_current_terms_in_the_rk4_start(rng):
    """The RK4 start (steps 0-2, four evaluations each) computes every slow term at every evaluation,
    whatever M: the first stage of steps 1 and 2 as well as the others."""
    s, sim = _current_sim(rng, 4, 12)
    sim.force_field.set_currents(np.linspace(0.5, 1.0, s.n_rods))
    sim.step(3)
    assert sim.force_field.calls["current_field"] == 12


def test_current_every_compiled_and_python_steps_agree(rng):
    """The fast steps in one compiled call and the Python step give the same run with M = 8."""
    runs = []
    for compiled in (True, False):
        s, sim = _current_sim(np.random.default_rng(4), 4, 8)
        if not compiled:
            sim.compiled = None
        sim.step(6)
        sim.force_field.set_currents(np.linspace(0.5, 1.0, s.n_rods))
        sim.step(60)
        runs.append(sim.state.position.copy())
    np.testing.assert_array_equal(runs[0], runs[1])


def test_current_every_of_slow_every_is_the_default_bit_for_bit(rng):
    """current_every = K is current_every = 0: the same run."""
    runs = []
    for m in (0, 4):
        s, sim = _current_sim(np.random.default_rng(3), 4, m)
        sim.step(4)
        sim.force_field.set_currents(np.linspace(0.5, 1.0, s.n_rods))
        sim.step(30)
        runs.append(sim.state.position.copy())
    np.testing.assert_array_equal(runs[0], runs[1])


def test_current_every_has_no_effect_without_multiple_time_stepping(rng):
    """slow_every = 1 turns multiple time stepping off whatever current_every says (a scene that sets
    both, as Fig. 2 does, runs every force every step with slow_every = 1 alone): the same run bit for
    bit as with current_every = 0."""
    runs = []
    for m in (0, 8):
        s, sim = _current_sim(np.random.default_rng(4), 1, m)
        assert sim.force_field.mts is None
        sim.step(3)
        sim.force_field.set_currents(np.linspace(0.5, 1.0, s.n_rods))
        sim.step(12)
        runs.append(sim.state.position.copy())
    np.testing.assert_array_equal(runs[0], runs[1])


def test_a_scene_with_current_every_and_slow_every_1_is_accepted():
    """slow_every = 1 alone turns multiple time stepping off in a scene that sets current_every (as
    the Fig. 2 scene does): accepted, current_every kept and without effect."""
    text = SCENE.replace('brake = "split"', 'brake = "split"\nslow_every = 1\ncurrent_every = 8')
    assert scenario_from_text(text).params.integrator.current_every == 8


@pytest.mark.parametrize(("slow_every", "current_every"), [(4, 6), (16, 40)])
def test_current_every_off_the_slow_pattern_is_refused_naming_both_keys(slow_every, current_every):
    from selfas_graph.io.scenario import ScenarioError

    text = SCENE.replace(
        'brake = "split"', f'brake = "split"\nslow_every = {slow_every}\ncurrent_every = {current_every}'
    )
    with pytest.raises(ScenarioError) as info:
        scenario_from_text(text)
    msg = str(info.value)
    assert "integrator.current_every" in msg and "integrator.slow_every" in msg and "multiple" in msg


def test_new_currents_on_a_full_step_start_without_a_rate(rng):
    """Currents changed right before a full evaluation: the current forces computed there start a new
    base with no rate (a jump, not a trend), as after a change before a fast step."""
    s, sim = _current_sim(rng, 5, 0)
    sim.step(5)
    ff = sim.force_field
    ff.set_currents(np.linspace(0.5, 1.0, s.n_rods))
    sim.step(10)  # steps 5-14: full at 5 (new currents) and 10, a rate from the two
    assert np.abs(ff.mts._rate["current_field"]).max() > 0.0
    ff.set_currents(3.0 * np.linspace(0.5, 1.0, s.n_rods))
    sim.step(1)  # step 15: full, and the currents are new
    assert np.abs(ff.mts._rate["current_field"]).max() == 0.0
