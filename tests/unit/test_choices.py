"""Project choices of docs/model.md 'Assumptions and project choices' that no physics test covers otherwise."""

import numpy as np

from conftest import random_rods, simulation
from selfas_graph.model import events as ev
from selfas_graph.model.graph import classify_rods
from selfas_graph.model.params import ChargeDistribution, ExternalDipole
from selfas_graph.model.placement import draw_charges
from selfas_graph.model.terms import external_monopoles


def test_direct_anode_cathode_contact_is_no_short_circuit():
    """B5: a contact joining a cathode-touching tip to an anode-touching tip, no rod between: no filament."""
    # rod 0's tip b (1) touches the cathode, rod 1's tip a (2) the anode, and tips 1 and 2 touch each other
    topo = classify_rods(2, np.array([[1, 2]]), np.array([1, 2]), np.array([ev.CONDUCTOR_CATHODE, ev.CONDUCTOR_ANODE]))
    assert topo.n_filament == 0 and not topo.has_short_circuit


def test_two_level_charges_give_exact_counts():
    """B15: two_level gives exactly round(high_fraction n) rods the high value, at random places."""
    dist = ChargeDistribution(distribution="two_level", low=1.0, high=2.0, high_fraction=1 / 3)
    q = draw_charges(dist, 600, np.random.default_rng(4))
    assert (q == 2.0).sum() == 200 and (q == 1.0).sum() == 400
    assert not np.array_equal(np.flatnonzero(q == 2.0), np.arange(200))  # not simply the first 200


def test_external_dipole_moment_points_along_plus_z():
    """B16: +Z_Mext sits at z = +L_ext/2, so the dipole's moment is along +z (co-directed with B_ext in Fig. 8)."""
    pos, q = external_monopoles(ExternalDipole(magnetic_charge=10.0, length=20.0))
    np.testing.assert_array_equal(pos, [[0, 0, 10.0], [0, 0, -10.0]])
    np.testing.assert_array_equal(q, [10.0, -10.0])
    moment = (q[:, None] * pos).sum(axis=0)
    assert moment[2] > 0


def _term(sim, name):
    return next(t for t in sim.force_field.terms if t.name == name)


def test_yukawa_cut_off_radius():
    """B1: the cut-off r_c is where Z_max^2 times the force's magnitude falls to the tolerance: at r_c it is
    at most the tolerance, 1e-10 closer in above it (the bisection stops at 1e-12 of r_c, and the force's
    logarithmic slope r/R_D + 2 is below 100 here). The Yukawa term uses it with the largest |Z_i|."""
    from selfas_graph.model.terms.pairs import yukawa_cutoff

    def force(r, z_max, screening):
        return z_max**2 * np.exp(-r / screening) * (1 / r**2 + 1 / (screening * r))

    for z_max, screening, tol in ((1.0, 0.8, 1e-4), (2.0, 0.6, 1e-6), (0.5, 3.0, 1e-12)):
        rc = yukawa_cutoff(z_max, screening, tol)
        assert force(rc, z_max, screening) <= tol < force(rc * (1 - 1e-10), z_max, screening)
    assert yukawa_cutoff(0.0, 0.8, 1e-4) == 0.0  # no charge: no term
    state = random_rods(6, np.random.default_rng(2), q=(0.5, 1.5))
    state.rod_charge[3] = -1.9  # the largest |Z_i|, negative
    sim = simulation(state, forces={"yukawa": {"screening_length": 0.8, "tolerance": 1e-5}})
    assert _term(sim, "yukawa").cutoff == yukawa_cutoff(1.9, 0.8, 1e-5)


def test_wire_radius_is_half_the_rod_diameter():
    """A5: both current terms regularise the field of the rod currents with w = D/2, D = rods.diameter."""
    state = random_rods(4, np.random.default_rng(2))
    for diameter in (0.06, 0.1):
        sim = simulation(
            state.copy(),
            rods={"diameter": diameter},
            forces={"tip_magnetic": {}, "electrodes": {"gap": 4.0}, "current_field": {}, "current_lorentz": {}},
            circuit={"delta_J0": 1.0},
        )
        assert _term(sim, "current_field").wire_radius == _term(sim, "current_lorentz").wire_radius == diameter / 2


def test_walls_and_poles_brake_with_the_tip_brake_coefficient():
    """B2: the electrode walls and the dipole's end monopoles brake a touching tip with -k_br v, k_br of
    [forces.tip_brake]; without that table they do not brake (explicit brake, so that the brake is a force)."""
    state = random_rods(4, np.random.default_rng(2), box=1.0)
    state.velocity[:] = 1.0
    state.position[0] = [0.0, 0.0, -0.99]  # within r* of the cathode plane at z = -1
    state.position[1] = state.position[0] + [0.0, 0.0, 1.0]
    state.position[2] = [0.01, 0.0, 0.8 - 0.02]  # within r* of the dipole's upper pole at z = +0.8
    state.position[3] = state.position[2] - [0.0, 0.6, 0.8]
    forces = {"electrodes": {"gap": 2.0}, "external_dipole": {"magnetic_charge": 1.0, "length": 1.6}}
    placement = {"box": [[-3, 3], [-3, 3], [-1.0, 1.0]], "min_tip_distance": 0.0}
    for tip_brake in ({}, {"tip_brake": {"coefficient": 37.0}}):
        sim = simulation(
            state.copy(), forces={**forces, **tip_brake}, integrator={"brake": "explicit"}, placement=placement
        )
        ff = sim.force_field
        ff.evaluate(sim.state.position, sim.state.velocity)
        k = 37.0 if tip_brake else 0.0
        assert _term(sim, "electrodes").k == _term(sim, "external_dipole").k == k
        np.testing.assert_array_equal(ff.out["electrode_brake"][0], -k * state.velocity[0])
        np.testing.assert_array_equal(ff.out["external_monopole_brake"][2], -k * state.velocity[2])
        assert not ff.out["electrode_brake"][2:].any() and not ff.out["external_monopole_brake"][[0, 1, 3]].any()


def test_external_filament_neither_pushes_nor_brakes_a_touching_tip():
    """B20: a tip inside the external filament's radius feels only q_k B of the filament: no elastic push,
    no brake (the term has a single channel, its force is the field's to the last bit)."""
    from selfas_graph.kernels import external as kx

    state = random_rods(3, np.random.default_rng(2), box=1.0)
    state.velocity[:] = 1.0
    state.position[0] = [0.03, 0.02, 0.1]  # inside the filament (radius 0.09)
    state.position[1] = state.position[0] + [0.6, 0.0, 0.8]
    sim = simulation(
        state,
        forces={"external_filament": {"current": 4.0, "diameter": 0.18}},
        placement={"box": [[-3, 3], [-3, 3], [-1.0, 1.0]], "min_tip_distance": 0.0},
    )
    term = _term(sim, "external_filament")
    assert [c for c, _ in term.channels] == ["external_filament"]
    ff = sim.force_field
    ff.evaluate(state.position, state.velocity)
    b = np.empty_like(state.position)
    kx.filament_field(state.position, 4.0, 0.09, b)
    np.testing.assert_array_equal(ff.out["external_filament"], state.tip_charge[:, None] * b)


def test_placement_keeps_tips_in_the_box_and_apart():
    """A7: every tip of the initial state lies in the placement box, no two tips of different rods are
    closer than placement.min_tip_distance, and the velocities are zero."""
    from selfas_graph import load_scenario
    from selfas_graph.model.placement import random_state

    params = load_scenario("scenarios/quick.toml").params
    state = random_state(params)
    box = np.array(params.placement.box)
    assert ((state.position >= box[:, 0]) & (state.position <= box[:, 1])).all()
    d = np.linalg.norm(state.position[:, None, :] - state.position[None, :, :], axis=-1)
    rod = np.arange(state.n_tips) // 2
    d[rod[:, None] == rod[None, :]] = np.inf
    assert d.min() >= params.min_tip_distance > 0
    assert not state.velocity.any()
