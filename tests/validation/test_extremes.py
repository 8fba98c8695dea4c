"""Numerical stability at the extremes: every case runs cleanly or stops with a diagnosis, never NaN."""

from pathlib import Path

import numpy as np
import pytest

from conftest import random_rods, simulation
from selfas_graph.model import events as ev
from selfas_graph.model.graph import FILAMENT
from selfas_graph.model.simulation import NumericalFailure, Simulation
from selfas_graph.model.state import State

ALL_PAIR_TERMS = {"tip_magnetic": {}, "tip_brake": {}, "ambient_brake": {}, "yukawa": {}}


def _finite(sim):
    return np.isfinite(sim.state.position).all() and np.isfinite(sim.state.velocity).all()


def test_coincident_tips_give_finite_forces():
    """Two tips of different rods exactly on top of each other: the core law gives 0 there, no NaN."""
    state = State.from_rods([[0.0, 0.0, 0.5], [0.0, 0.0, -0.5]], [[0, 0, -1.0], [0, 0, 1.0]], [1.0, 1.0], [1.0, 1.0])
    assert np.array_equal(state.position[1], state.position[3])  # tip b of rod 0 on tip b of rod 1, at 0
    sim = simulation(state, forces=ALL_PAIR_TERMS, integrator={"dt": 1e-4})
    force = sim.force_field.evaluate(state.position, state.velocity)
    assert np.isfinite(force).all()
    sim.run(t_end=0.05)
    assert _finite(sim)


def test_overlapping_start_is_resolved_by_the_core(rng):
    """Rods placed with tips inside each other's cores (min_tip_distance = 0) are pushed apart, no NaN.

    Random placement never does this by default (placement.min_tip_distance = 4 r*); a hand-made
    state may, and the soft core resolves it.
    """
    state = random_rods(20, rng, box=1.5)
    sim = simulation(state, forces=ALL_PAIR_TERMS, integrator={"dt": 2e-4})
    sim.run(t_end=0.1)
    # the projection restores each bond to round-off (a few ulp of 1); a failed one would leave 1e-3 or more
    assert _finite(sim) and sim.max_bond_error < 1e-12


@pytest.mark.parametrize("q, runs", [(1e-6, True), (40.0, False)])
def test_tiny_and_huge_charges(rng, q, runs):
    """Tiny charges run with a tiny energy balance; huge ones (p = q^2 = 1600 in the core) stop with a diagnosis."""
    state = random_rods(30, rng, box=3.0, q=(q, q))
    sim = simulation(state, forces=ALL_PAIR_TERMS, integrator={"dt": 5e-4})
    if runs:
        sim.run(t_end=0.2)
        # every force scales with q^2 = 1e-12: the energies, and so their balance, are 1e-12 of those of
        # unit charges, whose balance over 400 steps is well below 1
        assert _finite(sim) and abs(sim.observables()["energy_balance"]) < 1e-12
    else:
        with pytest.raises(NumericalFailure, match="integrator.dt"):
            sim.run(t_end=1.0)
        assert sim.state.step > 0


@pytest.mark.parametrize("screening", [1e-3, 1e3])
def test_extreme_screening_lengths(rng, screening):
    """R_D from 1e-3 (cut-off below the rod spacing: no neighbours) to 1e3 (cut-off beyond the box: all pairs)."""
    state = random_rods(20, rng, box=3.0, q=(0.5, 0.6))
    sim = simulation(
        state, forces={"yukawa": {"screening_length": screening, "tolerance": 1e-6}}, integrator={"dt": 5e-4}
    )
    sim.run(t_end=0.1)
    # AB4 over 200 steps of a smooth, weak force (charges 0.5, a Yukawa term alone): an integration error
    # many decades below 1e-9; a term that jumped at its cut-off would break it
    assert _finite(sim) and abs(sim.observables()["energy_balance"]) < 1e-9


@pytest.mark.parametrize("brake, runs", [("explicit", False), ("split", True)])
def test_huge_brake_coefficient(rng, brake, runs):
    """k_br = 1e5: the explicit brake stops with a diagnosis naming a brake; the split brake runs."""
    state = random_rods(20, rng, box=1.2)
    sim = simulation(
        state, forces={"tip_magnetic": {}, "tip_brake": {"coefficient": 1e5}}, integrator={"dt": 5e-4, "brake": brake}
    )
    if runs:
        sim.run(t_end=0.1)
        assert _finite(sim) and sim.observables()["work/tip_brake"] < 0
    else:
        with pytest.raises(NumericalFailure, match="brake"):
            sim.run(t_end=0.1)


def test_a_stiff_ambient_brake_is_named_in_either_brake_mode(rng):
    """The ambient brake is in the Adams-Bashforth step whatever integrator.brake says: at M_br dt = 10
    (far past AB4's 0.3) the run stops naming it and the dt it needs, not a term it happened to push."""
    state = random_rods(20, rng, box=1.2)
    for brake in ("split", "explicit"):
        sim = simulation(
            state.copy(),
            forces={"tip_magnetic": {}, "ambient_brake": {"coefficient": 1e4}},
            integrator={"dt": 1e-3, "brake": brake},
        )
        with pytest.raises(NumericalFailure, match=r"'ambient_brake' term is too stiff .* a dt below 3e-05"):
            sim.run(t_end=0.1)


def test_a_coarse_split_tip_brake_is_named_when_the_energy_check_stops(tmp_path, capsys):
    """The split tip brake is stable at any step, but at k_br dt = 10 its splitting from the step is
    coarse and the energy balance goes 35 % off (the quick scene, 150 rods, by t = 0.5): the failure
    names the brake and the dt it needs, not the stability limit of a dt already far below it."""
    from selfas_graph.cli.main import main

    quick = Path(__file__).resolve().parents[2] / "scenarios" / "quick.toml"
    argv = ["simulate", str(quick), "-o", str(tmp_path / "r.h5"), "--t-end", "1", "--progress", "none"]
    assert main([*argv, "--set", "rods.count=150", "--set", "forces.tip_brake.coefficient=1e4"]) == 3
    err = capsys.readouterr().err
    assert "the energy balance is off" in err and "The split tip brake is stable at any step" in err
    assert "a dt below 3e-05" in err


def test_a_tip_core_too_small_for_the_step_is_named(tmp_path, capsys):
    """At r* = 0.01 two tips falling together cross the core in about 3.5e-4 (charges up to 2): the
    quick scene at dt = 1e-3 goes 62 % off by t = 0.05, and the failure gives the crossing time and a
    dt that follows it (measured: 7e-5 and below run, 2 % off at 1e-4); at r* = 1e-30 no dt would."""
    from selfas_graph.cli.main import main

    quick = Path(__file__).resolve().parents[2] / "scenarios" / "quick.toml"
    argv = ["simulate", str(quick), "-o", str(tmp_path / "r.h5"), "--t-end", "0.5", "--progress", "none"]
    assert main([*argv, "--set", "rods.transition_radius=0.01", "--set", "output.interval=0.05"]) == 3
    err = capsys.readouterr().err
    assert "at the core r* = 0.01 (rods.transition_radius, or rods.diameter) and cross it in about 0.000354" in err
    assert "dt below about 7.1e-05" in err


def test_slow_forces_held_far_too_long_are_named_before_the_step(tmp_path, capsys):
    """slow_every = 1000 at dt = 1e-3 holds the slow forces for 1 t0 (the shipped scenes: 0.008-0.024):
    the quick scene goes 53 % off at dt = 1e-3 and 5e-4 alike, so the failure names slow_every, not dt."""
    from selfas_graph.cli.main import main

    quick = Path(__file__).resolve().parents[2] / "scenarios" / "quick.toml"
    argv = ["simulate", str(quick), "-o", str(tmp_path / "r.h5"), "--t-end", "1", "--progress", "none"]
    assert main([*argv, "--set", "rods.count=150", "--set", "integrator.slow_every=1000"]) == 3
    err = capsys.readouterr().err
    assert "The slow forces are evaluated every integrator.slow_every = 1000 steps (1 t0)" in err
    assert "try slow_every = 16 or less" in err and "try half of it" not in err


def test_a_balance_at_round_off_is_not_given_as_a_ratio(tmp_path, capsys):
    """At dt = 1e-30 no energy is turned over: the balance is the energies' round-off, and its ratio to
    the energy turned over read -1.4e+38 in the summary."""
    from selfas_graph.cli.main import main

    quick = Path(__file__).resolve().parents[2] / "scenarios" / "quick.toml"
    argv = ["simulate", str(quick), "-o", str(tmp_path / "r.h5"), "--t-end", "1e-28", "--progress", "none"]
    assert main([*argv, "--set", "integrator.dt=1e-30", "--set", "output.interval=2e-29"]) == 0
    assert "(round-off of the energies: almost no energy turned over)" in capsys.readouterr().out


def _chain(n, gap_margin=0.02):
    """n rods stacked tip to tip along z, touching, spanning electrodes just outside the chain ends."""
    z = np.arange(n) * 1.0 - (n - 1) / 2
    centre = np.column_stack([np.zeros(n), np.zeros(n), z])
    state = State.from_rods(centre, [[0, 0, 1.0]] * n, np.ones(n), np.zeros(n))
    return state, n + gap_margin


@pytest.mark.parametrize("delta", [0.0, 1e4])
def test_all_rods_in_one_chain_with_zero_and_huge_bias(delta):
    """50 rods in one chain between the electrodes: every rod is FILAMENT and carries delta gap / 50.

    delta_J0 = 0: a short circuit (topology) with zero current everywhere, so no current kernel
    runs; the effective resistance is the chain's, 50 R0, at either bias. delta_J0 = 1e4: currents of 2e2 J0; the run goes on or stops with a diagnosis, never NaN:
    either way every position and velocity left in the state is finite (measured: the run stops at
    step 13 on a runaway step, a tip moved 0.73 rod lengths, the largest force from the Lorentz term).
    """
    state, gap = _chain(50)
    forces = {
        "tip_magnetic": {},
        "tip_brake": {},
        "electrodes": {"gap": gap},
        "current_field": {},
        "current_lorentz": {},
        "uniform_field": {"B": [0.3, 0.0, 0.5]},
    }
    sim = simulation(state, forces=forces, circuit={"delta_J0": delta}, integrator={"dt": 2e-4, "brake": "split"})
    kinds = [r[2] for r in sim.events]
    assert kinds.count(ev.SHORT_CIRCUIT) == 1
    assert (sim.graph.topology().role == FILAMENT).all()
    # 50 unit rods in series, whatever the bias (without one, from the probe at a unit bias: it was
    # reported open, infinite, with the electrodes joined)
    assert sim.solution.effective_resistance == pytest.approx(50.0, rel=1e-12)
    # and after a restart from a snapshot (the contacts' heights kept for the probe)
    again = Simulation.from_snapshot(sim.params, sim.snapshot())
    assert again.solution.effective_resistance == pytest.approx(50.0, rel=1e-12)
    if delta == 0.0:
        assert sim.solution is not None and np.array_equal(sim.solution.current, np.zeros(50))
        assert len(sim.force_field.active_rod) == 0
        sim.run(t_end=0.02)
        assert sim.force_field.calls["current_lorentz"] == 0
    else:
        # tip a is the lower end and the cathode is below: current flows b -> a, i.e. negative
        np.testing.assert_allclose(sim.solution.current, -delta * gap / 50, rtol=1e-10)
        try:
            sim.run(t_end=0.02)
        except NumericalFailure as exc:
            assert "integrator.dt" in str(exc)  # the diagnosis names the knob to turn
    assert _finite(sim)  # whether the run went on or stopped: not a single NaN or inf


def test_one_rod_runs():
    """A single rod with every one-body term on: nothing to pair with, energy balance at the AB4 error."""
    state = State.from_rods([[0.3, -0.2, 0.1]], [[1.0, 0.5, 0.2]], [1.2], [0.7])
    state.velocity[:] = [[0.1, 0.0, 0.0], [0.0, 0.2, 0.0]]
    forces = dict(
        ALL_PAIR_TERMS,
        uniform_field={"B": [0, 0, 0.5]},
        plasma_filament={"radius": 2.0, "current": 1.0},
        electric_field={"E": [0, 0, 0.1]},
        electrodes={"gap": 4.0},
    )
    sim = simulation(state, forces=forces, integrator={"dt": 1e-3})
    sim.run(t_end=1.0)
    obs = sim.observables()
    # the AB4 error of the brake's and the plasma field's work (docs/model.md 'Work bookkeeping and the
    # energy balance'), not round-off: measured -7.4e-12 at dt = 1e-3, 16x less per halving of dt; 1e-10 leaves 13x
    assert _finite(sim) and abs(obs["energy_balance"]) < 1e-10 * max(1.0, sim.energy_scale(obs))


def test_one_rod_in_a_tight_box_is_placed_or_named_by_the_box():
    """The least tip distance is between tips of different rods, so one rod fits any box it is shorter
    than (the packing rule said "use fewer rods" to one rod); a box that leaves a random orientation
    almost no room is named as the box, not the rod count."""
    from selfas_graph.io.scenario import load_scenario
    from selfas_graph.model.placement import PlacementError

    quick = Path(__file__).resolve().parents[2] / "scenarios" / "quick.toml"
    one = [
        "rods.count=1",
        "forces.electrodes.gap=1.2",
        "placement.min_tip_distance=0.9",
    ]  # an exclusion fraction of 0.64
    sim = Simulation.from_scenario(
        load_scenario(quick, overrides=[*one, "placement.box=[[-0.5,0.5],[-0.5,0.5],[-0.6,0.6]]"])
    )
    assert sim.state.n_rods == 1
    tight = load_scenario(quick, overrides=[*one, "placement.box=[[-0.1,0.1],[-0.1,0.1],[-0.5,0.5]]"])
    with pytest.raises(PlacementError, match=r"placed no rod in 2000 draws .* make placement.box larger"):
        Simulation.from_scenario(tight)


def test_dead_end_rods_get_exactly_zero_current():
    """A dangling rod on a current-carrying chain gets exactly 0 (not round-off) and stays out of the kernels."""
    state, gap = _chain(4)
    # a fifth rod hanging sideways from the top tip of the second rod (tip 3, at z = 0)
    junction = state.position[3].copy()
    extra = State.from_rods([junction + [0.5 + 0.01, 0.0, 0.0]], [[1.0, 0.0, 0.0]], [1.0], [0.0])
    both = State(
        np.vstack([state.position, extra.position]),
        np.zeros((10, 3)),
        np.concatenate([state.tip_charge, extra.tip_charge]),
        np.zeros(5),
    )
    sim = simulation(
        both, forces={"tip_magnetic": {}, "electrodes": {"gap": gap}, "current_field": {}}, circuit={"delta_J0": 2.0}
    )
    role = sim.graph.topology().role
    assert list(role) == [FILAMENT] * 4 + [2]  # the dangling rod is a dead end
    assert sim.force_field.current[4] == 0.0
    assert 4 not in sim.force_field.active_rod and len(sim.force_field.active_rod) == 4


@pytest.mark.parametrize("dt", [1e-3, 1e-4])
def test_bonds_that_drift_with_both_corrections_off_are_named_not_the_step(dt):
    """With the position projection and the velocity correction both off, the split brakes' velocity
    along the rods makes the bonds drift whatever the step (the quick scene breaks one at t = 0.042 with
    dt = 1e-3, 1e-4 and 1e-5): the diagnosis names the two switches, and no longer blames dt."""
    from selfas_graph import Simulation, load_scenario

    scene = load_scenario(
        Path(__file__).resolve().parents[2] / "scenarios" / "quick.toml",
        overrides=[
            "integrator.position_projection=false",
            "integrator.velocity_correction=false",
            f"integrator.dt={dt}",
        ],
    )
    sim = Simulation.from_scenario(scene)
    with pytest.raises(NumericalFailure, match="broken rigid bond") as failure:
        sim.run(t_end=0.06)
    message = str(failure.value)
    assert "integrator.position_projection and integrator.velocity_correction are both off" in message
    assert "is the likely cause" not in message
