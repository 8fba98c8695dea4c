"""The assembled force field: every conservative channel's force is minus the gradient of its energy.

This checks the wiring of the model layer (which kernel fills which channel, forces on rod
centres shared between tips, energy shifts), not only the kernels: a term whose force were
not computed, or computed into the wrong channel, fails here.
"""
import numpy as np
import pytest

from conftest import random_rods, simulation

CONSERVATIVE_SCENES = {
    "tip_magnetic": {"tip_magnetic": {}},
    "uniform_field": {"uniform_field": {"B": [0.3, -0.2, 0.7]}},
    "yukawa": {"yukawa": {"screening_length": 0.8, "tolerance": 1e-12}},
    "electric_field": {"electric_field": {"E": [0.1, 0.4, -0.3]}},
    "electrodes": {"electrodes": {"gap": 2.0}},
    "external_dipole": {"external_dipole": {"magnetic_charge": 3.0, "length": 2.0, "line_charge": 1.5,
                                            "screening_length": 1.2, "quadrature_points": 64}},
}


@pytest.mark.parametrize("scene", sorted(CONSERVATIVE_SCENES))
def test_conservative_channels_are_minus_energy_gradients(scene):
    """F = -dU/dx for every tip coordinate, by central differences of ForceField.potential_energy."""
    rng = np.random.default_rng(3)
    state = random_rods(5, rng, box=1.8, q=(0.5, 1.5))
    if scene == "electrodes":  # tips inside the walls' range r* = 0.06, one beyond a plane
        state.position[0, 2], state.position[3, 2], state.position[6, 2] = 0.97, -0.98, 1.01
    sim = simulation(state, forces=CONSERVATIVE_SCENES[scene], contacts={"enabled": False},
                     placement={"box": [[-3, 3], [-3, 3], [-1.0, 1.0]], "min_tip_distance": 0.0})
    ff = sim.force_field
    ff.evaluate(state.position, state.velocity)
    channels = [c for c, cons in ff.channels if cons]
    force = sum(ff.out[c].copy() for c in channels)
    assert np.abs(force).max() > 1e-3, "the scene must exert a force"
    h = 1e-6
    numeric = np.zeros_like(force)
    for k in range(state.n_tips):
        for d in range(3):
            x = state.position.copy()
            x[k, d] += h
            up = sum(ff.potential_energy(x)[c] for c in channels)
            x[k, d] -= 2 * h
            down = sum(ff.potential_energy(x)[c] for c in channels)
            numeric[k, d] = -(up - down) / (2 * h)
    # central differences: O(h^2 U''') truncation and O(U eps / h) round-off, ~1e-8 of the force here
    np.testing.assert_allclose(force, numeric, rtol=1e-5, atol=1e-6 * np.abs(force).max())
