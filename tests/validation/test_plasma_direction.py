"""The direction of the plasma current in the shipped case (i) scenes (docs/model.md, term 5).

The plasma filament of case (i) is the discharge between the same biased electrodes, so its
current runs from the anode (z = +dZ/2) to the cathode: parallel to the current that a rod
filament carries once it spans the gap. These tests compute both fields with the project's own
kernels and circuit, so a sign slip in a scene, in the circuit's electrode potentials or in
either field kernel shows here.
"""

from pathlib import Path

import numpy as np
import pytest

from selfas_graph.io.scenario import load_scenario
from selfas_graph.kernels.currents import rod_current_field
from selfas_graph.kernels.fields import plasma_field
from selfas_graph.model.params import plasma_current_text
from selfas_graph.model.simulation import Simulation
from selfas_graph.model.state import State

SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"

#: every shipped scene with a plasma filament between electrodes with a circuit
CASE_I_PLASMA = sorted(
    p.name
    for p in SCENARIOS.glob("*.toml")
    if (lambda f: f.plasma_filament is not None and f.electrodes is not None)(load_scenario(p).params.forces)
    and load_scenario(p).params.circuit is not None
)


def spanning_chain(params):
    """State of a straight chain of rods along the z axis from the cathode to the anode.

    n rods of length 1 and resistance R0 with neighbouring tips |s| < r*/2 apart (s < 0: they overlap
    along the axis) and the end tips h = r*/2 from the electrode planes, so that every contact closes.
    Their lengths and resistances are given where the scene draws them (a scene with a length law).
    """
    gap, rstar = params.forces.electrodes.gap, params.rods.rstar
    h = 0.5 * rstar
    n = int(round(gap - 2 * h))
    s = (gap - 2 * h - n) / (n - 1)
    assert abs(s) < 0.5 * rstar, "the chain's tips would not touch"
    z0 = -0.5 * gap + h + 0.5
    centre = np.zeros((n, 3))
    centre[:, 2] = z0 + np.arange(n) * (1.0 + s)
    axis = np.tile([0.0, 0.0, 1.0], (n, 1))
    given = {key: 1.0 for key in ("length", "resistance") if getattr(params.rods, key) is not None}
    return State.from_rods(centre, axis, np.ones(n), np.zeros(n), **given)


def azimuthal(point, field):
    """phi_hat . B at points in a plane z = const (phi_hat = (-y, x, 0) / rho)."""
    rho = np.hypot(point[:, 0], point[:, 1])
    return (-point[:, 1] * field[:, 0] + point[:, 0] * field[:, 1]) / rho


def test_the_shipped_case_i_scenes_with_a_plasma_filament_are_the_expected_ones():
    # Fig. 2 and Fig. 6 and their quick variants; a new scene joins the check below by itself
    assert {"fig2.toml", "fig6.toml", "fig6_quick.toml", "quick.toml"} <= set(CASE_I_PLASMA)


@pytest.mark.parametrize("name", CASE_I_PLASMA)
def test_plasma_current_is_parallel_to_the_current_of_a_spanning_chain(name):
    params = load_scenario(SCENARIOS / name).params
    chain = spanning_chain(params)
    sim = Simulation(params.replace(rods={"count": chain.n_rods}), state=chain)
    assert sim.graph.has_short_circuit and sim.solution is not None
    current = sim.solution.current
    # every rod of a series chain carries one current, from the anode (top) to the cathode:
    # from tip b (top) to tip a, i.e. negative; its size is the bias delta_J0 dZ over the
    # chain's resistance: n rods of R0 (length 1) and, with resistive contacts of r, the
    # n - 1 junctions and the 2 electrode contacts in series
    n = current.shape[0]
    bias = params.circuit.delta_J0 * params.forces.electrodes.gap
    series = n + (n + 1) * params.contacts.resistance
    np.testing.assert_allclose(current, -bias / series, rtol=1e-12)  # the circuit's round-off
    # field of the chain and of the plasma on a ring around the axis in the mid-plane
    phi = np.linspace(0.0, 2 * np.pi, 8, endpoint=False)
    point = np.column_stack([3.0 * np.cos(phi), 3.0 * np.sin(phi), np.zeros_like(phi)])
    b_chain = np.zeros_like(point)
    rod_current_field(
        point,
        np.full(len(point), -1),
        sim.state.position,
        np.flatnonzero(current),
        current,
        0.5 * params.rods.diameter,
        b_chain,
    )
    pf = params.forces.plasma_filament
    b_plasma = np.zeros_like(point)
    plasma_field(point, pf.axis[0], pf.axis[1], pf.radius, pf.current, b_plasma)
    chain_phi, plasma_phi = azimuthal(point, b_chain), azimuthal(point, b_plasma)
    # a current along -z circles clockwise seen from +z: both azimuthal fields negative
    assert np.all(chain_phi < 0) and np.all(plasma_phi < 0)
    assert pf.current < 0


def test_the_direction_is_said_in_words():
    params = load_scenario(SCENARIOS / "fig2.toml").params
    assert plasma_current_text(params) == (
        "plasma current 7.5 J0 from the anode (z = +8.95) to the cathode (z = -8.95), "
        "parallel to the current of a spanning filament (I_plas = -7.5)"
    )
    reversed_ = load_scenario(SCENARIOS / "fig2.toml", overrides=["forces.plasma_filament.current=7.5"]).params
    assert "from the cathode (z = -8.95) to the anode (z = +8.95), antiparallel" in plasma_current_text(reversed_)
    assert plasma_current_text(load_scenario(SCENARIOS / "fig8.toml").params) is None


def test_a_plasma_filament_of_no_current_is_no_filament_bit_for_bit():
    """The plasma-current sweep takes the null model without the plasma filament as its point I_plas
    = 0 (docs/studies.toml): the two runs must be the same bits. The quick scene, to t = 1."""
    base = SCENARIOS / "quick.toml"
    runs = []
    for override in ("forces.plasma_filament.current=0", "forces.plasma_filament=false"):
        sim = Simulation.from_scenario(load_scenario(base, overrides=[override]))
        sim.run(1.0)
        runs.append(sim)
    a, b = runs
    assert a.state.step == b.state.step > 0
    np.testing.assert_array_equal(a.state.position, b.state.position)
    np.testing.assert_array_equal(a.state.velocity, b.state.velocity)
