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
    "external_dipole": {
        "external_dipole": {
            "magnetic_charge": 3.0,
            "length": 2.0,
            "line_charge": 1.5,
            "screening_length": 1.2,
            "quadrature_points": 64,
        }
    },
}


@pytest.mark.parametrize("scene", sorted(CONSERVATIVE_SCENES))
def test_conservative_channels_are_minus_energy_gradients(scene):
    """F = -dU/dx for every tip coordinate, by central differences of ForceField.potential_energy."""
    rng = np.random.default_rng(3)
    state = random_rods(5, rng, box=1.8, q=(0.5, 1.5))
    if scene == "electrodes":  # tips inside the walls' range r* = 0.06, one beyond a plane
        state.position[0, 2], state.position[3, 2], state.position[6, 2] = 0.97, -0.98, 1.01
    sim = simulation(
        state,
        forces=CONSERVATIVE_SCENES[scene],
        contacts={"enabled": False},
        placement={"box": [[-3, 3], [-3, 3], [-1.0, 1.0]], "min_tip_distance": 0.0},
    )
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
    # central differences: O(h^2 U''') truncation and O(U eps / h) round-off, ~1e-10 to 1e-8 of the
    # largest force here (measured at most 3.7e-10 over the scenes of CONSERVATIVE_SCENES)
    np.testing.assert_allclose(force, numeric, rtol=0, atol=1e-8 * np.abs(force).max())


def test_ambient_brake_and_electric_field_are_their_formulas(rng):
    """Term 3, ``-M_br v`` on every tip, and term 7, ``Z_i E`` on each rod centre shared half to each tip:
    the channels against the formulas themselves (the energy balance and the finite differences above
    would not see a wrong coefficient that force and energy share). One product each: bit for bit."""
    state = random_rods(5, rng, box=1.8, q=(0.5, 1.5))
    state.velocity[:] = rng.normal(size=state.velocity.shape)
    E = np.array([0.1, 0.4, -0.3])
    sim = simulation(
        state,
        forces={"ambient_brake": {"coefficient": 1.7}, "electric_field": {"E": E.tolist()}},
        contacts={"enabled": False},
        placement={"box": [[-3, 3], [-3, 3], [-1.0, 1.0]], "min_tip_distance": 0.0},
    )
    ff = sim.force_field
    ff.evaluate(state.position, state.velocity)
    np.testing.assert_array_equal(ff.out["ambient_brake"], -1.7 * state.velocity)
    per_tip = np.repeat(0.5 * state.rod_charge[:, None] * E[None, :], 2, axis=0)
    np.testing.assert_array_equal(ff.out["electric_field"], per_tip)
    assert np.abs(per_tip).max() > 0


#: every term that is a source of magnetic field, with the case (i) and case (ii) fields in one scene
SOURCES = {
    "uniform_field": {"B": [0.3, -0.2, 0.7]},
    "plasma_filament": {"radius": 1.5, "current": -2.0},
    "external_filament": {"current": 4.0, "diameter": 0.18},
    "external_dipole": {"magnetic_charge": 3.0, "length": 2.0},
}


def _source_scene(rng, state=None, forces_override=None, **kw):
    state = random_rods(6, rng, box=1.8, q=(0.5, 1.5)) if state is None else state
    # [forces.current_lorentz] keys: the plain 4-point rule unless the test asks for the near pairs
    lorentz = {"quadrature_points": 4, "near_range": 0.0, **(forces_override or {})}
    return state, simulation(
        state,
        forces={"tip_magnetic": {}, **SOURCES, "current_field": {}, "current_lorentz": lorentz},
        circuit={"delta_J0": 1.0},
        placement={"box": [[-3, 3], [-3, 3], [-1.0, 1.0]], "min_tip_distance": 0.0},
        **kw,
    )


def test_field_sources_answer_their_field_and_act_on_tips_with_it(rng):
    """Each field source gives its field at points; on tips far from any core the force of the term is
    q_k B(x_k), the field the Lorentz term asks for (docs/model.md 'Term 10')."""
    state, sim = _source_scene(rng)
    ff = sim.force_field
    assert [t.name for t in ff.field_sources] == list(SOURCES)  # all four, in term order
    ff.evaluate(state.position, state.velocity)
    channel = {
        "uniform_field": "uniform_field",
        "plasma_filament": "plasma_filament",
        "external_filament": "external_filament",
        "external_dipole": "external_monopoles",
    }
    far = np.linalg.norm(state.position[:, None, :] - ff.field_sources[-1].source[None], axis=-1).min(axis=1) > 0.06
    assert far.sum() >= 8
    for src in ff.field_sources:
        b = np.empty_like(state.position)
        src.field_at(state.position, b)
        # the same law in the same arithmetic (the dipole's tip law outside its core r*): round-off only
        np.testing.assert_allclose(
            ff.out[channel[src.name]][far], state.tip_charge[far, None] * b[far], rtol=1e-13, atol=1e-13
        )
    b = np.empty((1, 3))
    ff.field_sources[0].field_at(np.zeros((1, 3)), b)
    np.testing.assert_array_equal(b[0], SOURCES["uniform_field"]["B"])


def test_lorentz_term_sums_the_rod_currents_and_every_source_in_term_order(rng):
    """The Lorentz force on rod currents is the one of the field summed kernel by kernel (rod currents,
    then the sources in term order), bit for bit."""
    from selfas_graph.kernels import currents as kc
    from selfas_graph.kernels import external as kx
    from selfas_graph.kernels import fields as kf
    from selfas_graph.kernels import lorentz as kl

    state, sim = _source_scene(rng)
    ff = sim.force_field
    current = np.linspace(-1.0, 1.5, state.n_rods)
    current[2] = 0.0
    ff.set_currents(current)
    ff.evaluate(state.position, state.velocity)
    active = np.flatnonzero(current)
    t, wt = kl.gauss_legendre_01(4)
    pts = np.empty((len(active) * 4, 3))
    kl.quadrature_points(state.position, active, t, pts)
    field, extra = np.empty_like(pts), np.empty_like(pts)
    kc.rod_current_field(pts, np.repeat(active, 4), state.position, active, ff.current, 0.03, field)
    field += np.array(SOURCES["uniform_field"]["B"])
    kf.plasma_field(pts, 0.0, 0.0, 1.5, -2.0, extra)
    field += extra
    kx.filament_field(pts, 4.0, 0.09, extra)
    field += extra
    kx.monopole_field(pts, np.array([[0, 0, 1.0], [0, 0, -1.0]]), np.array([3.0, -3.0]), 0.06, extra)
    field += extra
    want = np.zeros_like(state.position)
    kl.lorentz_force_on_rods(state.position, active, ff.current, field, t, wt, want)
    assert np.abs(want).max() > 1e-3
    np.testing.assert_array_equal(ff.out["current_lorentz"], want)


def test_lorentz_term_near_range_adds_the_pair_correction_to_the_plain_rule(rng):
    """With ``forces.current_lorentz.near_range`` the term is the plain rule (every source) plus the
    kernel's correction of the pairs of current-carrying rods with centres closer than the range
    (docs/model.md 'Term 10'), bit for bit; near_range = 0 leaves the plain rule."""
    from selfas_graph.kernels import cells
    from selfas_graph.kernels import lorentz as kl

    state, plain_sim = _source_scene(rng)
    _, near_sim = _source_scene(None, state.copy(), forces_override={"quadrature_points": 3, "near_range": 1.2})
    current = np.linspace(-1.0, 1.5, state.n_rods)
    current[2] = 0.0
    for sim in (plain_sim, near_sim):
        sim.force_field.set_currents(current)
        sim.force_field.evaluate(state.position, state.velocity)
    _, plain3 = _source_scene(None, state.copy(), forces_override={"quadrature_points": 3})
    plain3.force_field.set_currents(current)
    plain3.force_field.evaluate(state.position, state.velocity)
    want = plain3.force_field.out["current_lorentz"].copy()
    active = np.flatnonzero(current).astype(np.int64)
    centre = 0.5 * (state.position[2 * active] + state.position[2 * active + 1])
    start, index = cells.neighbour_rows(centre, 1.2)
    assert len(index) > 0  # some pairs are near
    t, wt = kl.gauss_legendre_01(3)
    pt, pw = kl.gauss_legendre_01(kl.NEAR_PANEL_POINTS)
    kl.lorentz_near_correction(state.position, active, current, start, index, 0, len(active), t, wt, pt, pw, 0.03, want)
    np.testing.assert_array_equal(near_sim.force_field.out["current_lorentz"], want)
    assert not np.array_equal(want, plain3.force_field.out["current_lorentz"])


def test_state_dict_restores_the_next_evaluations_bit_for_bit(rng):
    """ForceField.state_dict / load_state_dict: neighbour lists and the held slow forces (multiple
    time stepping with extrapolation) carry over, so a fresh field with the same currents (their
    owner saves them) continues the same."""
    state, sim = _source_scene(rng, integrator={"slow_every": 4})
    ff = sim.force_field
    x, v = state.position.copy(), state.velocity.copy()
    ff.set_currents(np.linspace(0.5, 1.0, state.n_rods))
    for step in (0, 4):
        ff.evaluate(x + 1e-3 * step * v, v, full=True, step=step)
    d = ff.state_dict()
    assert {"tip_nl_reference", "tip_nl_builds", "mts_stale", "mts_held_tip_far"} <= set(d)
    assert "current" not in d  # one key, written by the owner of the currents (Network.state_dict)
    assert all(isinstance(val, (np.ndarray, int)) for val in d.values())
    _, fresh = _source_scene(None, state.copy(), integrator={"slow_every": 4})
    fresh.force_field.set_currents(ff.current)
    fresh.force_field.load_state_dict(d)
    y = x + 6e-3 * v
    np.testing.assert_array_equal(
        fresh.force_field.evaluate(y, v, full=False, step=6), ff.evaluate(y, v, full=False, step=6)
    )
    np.testing.assert_array_equal(fresh.force_field.active_rod, ff.active_rod)
    # a dict without held forces (another setting, an older checkpoint): every slow term is recomputed
    _, other = _source_scene(None, state.copy(), integrator={"slow_every": 4})
    other.force_field.set_currents(ff.current)
    other.force_field.load_state_dict({})
    assert other.force_field.mts.stale == set(other.force_field.mts.slow_keys)


def test_a_slow_line_charge_is_held_between_full_evaluations_and_the_same_without_them(rng):
    """``forces.external_dipole.line_charge_slow``: under multiple time stepping the line charge is
    computed on full evaluations only and extrapolated between them, as the other slow terms; every
    evaluation is full without multiple time stepping, so the knob then changes nothing, bit for bit."""
    state = random_rods(30, rng)
    dipole = dict(CONSERVATIVE_SCENES["external_dipole"]["external_dipole"])
    x, v = state.position.copy(), rng.normal(0.0, 0.3, state.position.shape)

    def field(slow, **integrator):
        sim = simulation(
            state.copy(), forces={"external_dipole": dipole | {"line_charge_slow": slow}}, integrator=integrator
        )
        return sim.force_field

    every, held = field(False), field(True)
    for step in range(3):
        y = x + 1e-3 * step * v
        np.testing.assert_array_equal(every.evaluate(y, v), held.evaluate(y, v))
    every, held = field(False, slow_every=4), field(True, slow_every=4)
    assert "external_line_charge" in held.mts.slow_keys and "external_line_charge" not in every.mts.slow_keys
    for step in range(6):
        y = x + 1e-3 * step * v
        every.evaluate(y, v, full=step % 4 == 0, step=step)
        held.evaluate(y, v, full=step % 4 == 0, step=step)
        line_every, line_held = every.out["external_line_charge"], held.out["external_line_charge"]
        if step % 4 == 0:
            np.testing.assert_array_equal(line_held, line_every)  # computed on a full evaluation
        else:  # held (extrapolated once two full evaluations are there): not today's force, but near it:
            # the rods move at most 3 steps x 1e-3 x |v| (v ~ 0.3, so ~1e-3 L) since the last full
            # evaluation, on a field that varies on R_Dext = 1.2 L: the held force is off by ~1e-3 of
            # the largest, and 1e-2 leaves a factor 10 for the rods nearest the line
            assert not np.array_equal(line_held, line_every)
            np.testing.assert_allclose(line_held, line_every, rtol=0, atol=1e-2 * np.abs(line_every).max())
    assert held.calls["external_line_charge"] == 2 and every.calls["external_line_charge"] == 6
