"""The kernels that replace the per-step numpy glue: each against its slow reference (tests/reference.py)
and, bit for bit, against the numpy code it replaced (a run's results must not change by a bit)."""

import platform

import numpy as np
import pytest

import reference as ref
from conftest import random_rods
from selfas_graph import load_scenario
from selfas_graph.kernels import brakes, contacts
from selfas_graph.kernels import fields as kf
from selfas_graph.kernels import integrate as ki
from selfas_graph.kernels import rigid as kr
from selfas_graph.model.neighbours import NeighbourList
from selfas_graph.model.simulation import Simulation
from selfas_graph.model.terms.base import kinetic

#: small inputs: also run with NUMBA_DISABLE_JIT=1, the kernels as Python (.ci/run)
pytestmark = pytest.mark.jit_off_ok

RSTAR = 0.06
#: the brake radius of the pair tests: wider than r*, so that 300 random tips make many pairs and junctions
RADIUS = 0.15


def same_bits(a, b):
    """Equal to the last bit (also -0.0 against 0.0, and NaN payloads)."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    assert a.shape == b.shape
    np.testing.assert_array_equal(a.view(np.int64), b.view(np.int64))


def channels(rng, n_ch=11, n=500):
    """Force channels of very different scales, with exact zeros and negative zeros (a channel off)."""
    c = rng.normal(size=(n_ch, n, 3)) * 10.0 ** rng.uniform(-8, 8, size=(n_ch, 1, 1))
    c[3] = 0.0
    c[5] = -0.0
    c[7, ::3] = -0.0
    return c


def test_channel_sum_is_the_reference(rng):
    c = channels(rng, n=60)
    out = np.full((60, 3), np.nan)
    ki.channel_sum(out, c)
    same_bits(out, ref.channel_sum(c))


def test_channel_sum_is_the_numpy_loop_bit_for_bit(rng):
    """The loop the force field ran: fill with 0, add each channel in order (numpy's a + b + c is (a + b) + c);
    the kernel adds four channels a pass: every remainder, and an element of -0 in every channel (0 + -0 is
    +0: the sum must start from 0, not from the first channel)."""
    for n_ch in (0, 1, 2, 4, 5, 7, 8, 11):
        c = channels(rng, n_ch=max(n_ch, 8))[:n_ch].copy()
        c[:, 7, 1] = -0.0
        before = np.zeros((500, 3))
        before.fill(0.0)
        for j in range(n_ch):
            before += c[j]
        out = np.full((500, 3), np.nan)
        ki.channel_sum(out, np.ascontiguousarray(c.reshape(n_ch, 500, 3)))
        same_bits(out, before)


def test_extrapolate_is_the_reference_and_the_numpy_code(rng):
    rate = rng.normal(size=(400, 3)) * 1e-3
    base = rng.normal(size=(400, 3)) * 1e3
    for steps in (0, 1, 5, 16, 31):
        old = np.empty_like(base)
        np.multiply(rate, steps, out=old)  # the numpy code it replaced (steps a Python int)
        old += base
        out = np.full_like(base, np.nan)
        ki.extrapolate(out, rate, base, float(steps))
        same_bits(out, old)
        same_bits(out, ref.extrapolate(rate, base, float(steps)))


@pytest.fixture
def crowded(rng):
    """Tips in a small box: many pairs within r*, junctions of several tips."""
    s = random_rods(150, rng, box=1.2)
    s.velocity[:] = rng.normal(size=s.velocity.shape)
    nl = NeighbourList(RADIUS, 0.05, exclude_same_rod=True)
    nl.build(s.position)
    return s, nl


@pytest.mark.parametrize("k_dt", [0.1, 3.0])
def test_fused_split_brake_is_the_two_calls_bit_for_bit(crowded, k_dt):
    s, nl = crowded
    v_old, v_new = s.velocity.copy(), s.velocity.copy()
    pairs = contacts.close_pairs(s.position, nl.start, nl.index, RADIUS)
    assert len(pairs) > 20
    w_old = brakes.brake_pairs_exact(v_old, pairs, k_dt / 1e-3, 1e-3)
    w_new, m = brakes.brake_close_pairs_exact(s.position, v_new, nl.start, nl.index, RADIUS, k_dt / 1e-3, 1e-3)
    assert m == len(pairs)
    same_bits(v_new, v_old)
    same_bits(w_new, w_old)


def test_fused_split_brake_is_the_reference(crowded):
    s, nl = crowded
    # pair after pair, the order matters: rows sorted, the kernel brakes in the reference's (k, l) order
    index = np.concatenate([np.sort(nl.index[a:b]) for a, b in zip(nl.start[:-1], nl.start[1:])])
    v = s.velocity.copy()
    work, m = brakes.brake_close_pairs_exact(s.position, v, nl.start, index, RADIUS, 100.0, 1e-3)
    v_ref, w_ref, m_ref = ref.brake_close_pairs(s.position, s.velocity, RADIUS, 100.0, 1e-3)
    assert m == m_ref > 20
    np.testing.assert_allclose(v, v_ref, rtol=1e-12, atol=1e-14)  # the same arithmetic; numpy floats vs Python
    assert work == pytest.approx(w_ref, rel=1e-12)  # a sum of m_ref terms of one sign, in the same order: round-off


def test_both_paths_of_the_split_brake_agree_bit_for_bit(crowded, monkeypatch):
    """Above PARALLEL_ROWS tips the pairs are listed on all threads first: the same result."""
    s, nl = crowded
    v_serial, v_listed = s.velocity.copy(), s.velocity.copy()
    got_serial = brakes.brake_close_pairs(s.position, v_serial, nl.start, nl.index, RADIUS, 100.0, 1e-3)
    monkeypatch.setattr(brakes, "PARALLEL_ROWS", 0)
    got_listed = brakes.brake_close_pairs(s.position, v_listed, nl.start, nl.index, RADIUS, 100.0, 1e-3)
    assert got_serial == got_listed
    same_bits(v_serial, v_listed)
    far = s.position * 100.0  # no pair close: nothing braked
    assert brakes.brake_close_pairs(far, v_listed, nl.start, nl.index, RADIUS, 100.0, 1e-3) == (0.0, 0)


def old_electrode_split(term, position, velocity, dt):
    """The numpy code the electrode brake kernel replaced."""
    z = position[:, 2]
    touching = (z - term.z[0] < term.rstar).astype(np.float64) + (term.z[1] - z < term.rstar)
    tips = np.flatnonzero(touching)
    if not len(tips) or term.k == 0.0:
        return {}
    before = kinetic(velocity, tips)
    velocity[tips] *= np.exp(-term.k * touching[tips] * dt)[:, None]
    return {"electrode_brake": kinetic(velocity, tips) - before}


@pytest.fixture
def electrodes():
    sim = Simulation.from_scenario(load_scenario("scenarios/fig2.toml", overrides=["rods.count=60"]))
    ff = sim.force_field
    return ff, next(t for t in ff.terms if t.name == "electrodes")


@pytest.mark.parametrize("gap", [None, 0.1])
def test_electrode_split_is_the_numpy_code_bit_for_bit(electrodes, rng, gap):
    """Tips near either plane (and, with a gap below 2 r*, near both), over several steps."""
    ff, term = electrodes
    if gap is not None:
        term.z = (-0.5 * gap, 0.5 * gap)
    n = ff.n_tips
    x = rng.normal(size=(n, 3))
    x[:, 2] = rng.choice([term.z[0], term.z[1], 0.0], size=n) + rng.uniform(-0.1, 0.1, size=n)
    v_old = rng.normal(size=(n, 3))
    v_new = v_old.copy()
    for dt in (1e-3, 1e-3, 2e-3):
        old = old_electrode_split(term, x, v_old, dt)
        ff.bind(x, v_new)
        new = term.split(ff.context, dt)
        assert old.keys() == new.keys() == {"electrode_brake"}
        same_bits(new["electrode_brake"], old["electrode_brake"])
        same_bits(v_new, v_old)
    v_ref, w_ref = ref.electrode_brake(x, v_old, *term.z, term.rstar, term.k, 1e-3)
    ff.bind(x, v_new)
    w = term.split(ff.context, 1e-3)["electrode_brake"]
    np.testing.assert_allclose(v_new, v_ref, rtol=1e-14)  # exp here, numpy's exp there: round-off apart
    assert w == pytest.approx(w_ref, rel=1e-10)  # a difference of kinetic energies, summed in another order
    if gap is not None:
        return
    x[:, 2] = 0.0  # no tip touches: no work, no change
    assert term.split(ff.context, 1e-3) == {} == old_electrode_split(term, x, v_old, 1e-3)


@pytest.fixture
def monopoles():
    sim = Simulation.from_scenario(load_scenario("scenarios/fig8_quick.toml", overrides=["rods.count=60"]))
    ff = sim.force_field
    return ff, next(t for t in ff.terms if t.name == "external_dipole")


@pytest.mark.parametrize("sources", ["the scene's", "within 2 r* of each other"])
def test_monopole_split_is_the_exact_brake_and_the_compiled_kernel(monopoles, rng, sources):
    """The split brake of the external dipole's monopoles (``ExternalDipoleForce.split``) is the exact brake
    (a tip within r* of n poles: v exp(-n k_br dt), the work its change of kinetic energy), and the compiled
    steps' kernel (``step_tasks._monopole_brake_exact``) is that code bit for bit; with the poles closer than
    2 r*, tips inside both cores are braked twice as hard."""
    from selfas_graph.kernels.step_tasks import _monopole_brake_exact

    ff, term = monopoles
    assert ff.params.integrator.brake == "split" and term.k > 0
    if sources != "the scene's":
        term.source = np.array([[0.0, 0.0, 0.02], [0.0, 0.0, -0.02]])
    n = ff.n_tips
    x = rng.normal(size=(n, 3))
    near = rng.choice(2, size=n // 2)  # half the tips within r* of a pole (of both when the poles are close)
    x[: n // 2] = term.source[near] + rng.uniform(-0.034, 0.034, size=(n // 2, 3))
    touching = (np.linalg.norm(x[:, None, :] - term.source[None], axis=-1) < term.rstar).sum(axis=1)
    assert (touching >= 1).sum() >= n // 2 and ((touching == 2).any() == (sources != "the scene's"))
    v0 = rng.normal(size=(n, 3))
    dt = 1e-3
    v_ref, w_ref = ref.monopole_brake(x, v0, term.source, term.rstar, term.k, dt)
    v = v0.copy()
    ff.bind(x, v)
    w = term.split(ff.context, dt)["external_monopole_brake"]
    np.testing.assert_allclose(v, v_ref, rtol=1e-14)  # exp here, math.exp there: round-off apart
    assert w == pytest.approx(w_ref, rel=1e-12)  # a difference of kinetic energies (both ~1), summed in another order
    assert w < 0
    # the compiled kernel with the decay factors the compiled steps compute (model/compiled.py)
    decay = np.zeros(3)
    decay[1:] = np.exp(-term.k * np.array([1.0, 2.0]) * dt)
    v_kernel = v0.copy()
    w_kernel, m = _monopole_brake_exact(x, v_kernel, term.source, term.rstar, decay, np.empty((n, 3)), np.empty((n, 3)))
    assert m == np.count_nonzero(touching)
    same_bits(v_kernel, v)
    same_bits(w_kernel, w)
    x[:, 2] += 100.0  # no tip touches: no work, no change
    ff.bind(x, v)
    assert term.split(ff.context, dt) == {}
    assert (
        _monopole_brake_exact(x, v_kernel, term.source, term.rstar, decay, np.empty((n, 3)), np.empty((n, 3)))[1] == 0
    )


def test_uniform_force_is_the_reference_and_the_numpy_broadcast(rng):
    q = rng.normal(size=301)
    B = np.array([0.1, -0.0, 0.5])
    out = np.full((301, 3), np.nan)
    kf.uniform_force_on_tips(q, B, out)
    same_bits(out, ref.uniform_force(q, B))
    old = np.empty((301, 3))
    np.multiply(q[:, None], B[None, :], out=old)  # the numpy code it replaced
    same_bits(out, old)


# ----------------------------------------------------------------------------- fewer calls per step
def test_dot_is_numpys_einsum_bit_for_bit(rng):
    """The sum of the powers and kinetic energies: as np.einsum("ij,ij->") sums them on x86-64, for every
    length (blocks of eight elements and each tail), scale and sign, and the reference to round-off."""
    dot = ki.dot_as_numpy
    for n in list(range(0, 20)) + [333, 2400]:
        for _ in range(5):
            a = rng.normal(size=(n, 3)) * 10.0 ** rng.uniform(-6, 6, size=(n, 1))
            b = rng.normal(size=(n, 3))
            b[::4] = -0.0
            got = dot(a.reshape(-1), b.reshape(-1), 3 * n)
            if platform.machine() in ("x86_64", "AMD64"):
                same_bits(got, np.einsum("ij,ij->", a, b))
            scale = float(np.abs(a * b).sum())
            assert abs(got - ref.dot(a, b)) <= 1e-13 * scale  # 3n additions in another order: n eps of the sum
    a = rng.normal(size=(50, 3))
    for m in (0, 1, 7, 33):  # the first m rows of a buffer, as the electrode brake sums them
        if platform.machine() in ("x86_64", "AMD64"):
            same_bits(dot(a.reshape(-1), a.reshape(-1), 3 * m), np.einsum("ij,ij->", a[:m], a[:m]))


def test_channel_sum_power_is_the_sum_and_the_einsum_loop_bit_for_bit(rng):
    """The force field's evaluation: channel_sum, then the power of each non-conservative channel (the
    channels summed four at a time and their powers three at a time: every remainder of both)."""
    cases = (
        (11, [1, 2, 4, 7, 9, 10]),
        (3, [0]),
        (2, []),
        (4, [3, 0]),
        (8, [0, 1, 2, 3]),
        (5, [4, 0, 1, 2, 3]),
        (9, []),
    )
    for n_ch, powered in cases:
        c = channels(rng, n_ch=max(n_ch, 8))[:n_ch].copy()
        v = rng.normal(size=(500, 3))
        total_old = np.full((500, 3), np.nan)
        ki.channel_sum(total_old, c)
        power_old = np.array([np.einsum("ij,ij->", c[j], v) for j in powered])  # the numpy code it replaced
        total, power = np.full((500, 3), np.nan), np.full(len(powered), np.nan)
        ki.channel_sum_power(total, c, v, np.array(powered, dtype=np.int64), power)
        same_bits(total, total_old)
        if platform.machine() in ("x86_64", "AMD64"):
            same_bits(power, power_old)
        for j, p in zip(powered, power):
            assert abs(p - ref.dot(c[j], v)) <= 1e-13 * float(np.abs(c[j] * v).sum())  # see the test above


def test_extrapolate_all_is_one_extrapolate_per_array(rng):
    held = [rng.normal(size=(400, 3)) for _ in range(4)]
    rate = rng.normal(size=(4, 400, 3)) * 1e-3
    base = rng.normal(size=(4, 400, 3)) * 1e3
    steps = np.array([3.0, np.nan, 16.0, 0.0])  # NaN: left as it is
    old = [h.copy() for h in held]
    for j, s in enumerate(steps):
        if not np.isnan(s):
            ki.extrapolate(old[j], rate[j], base[j], s)
    new = tuple(h.copy() for h in held)
    ki.extrapolate_all(new, rate, base, steps)
    for j in range(4):
        same_bits(new[j], old[j])
        if not np.isnan(steps[j]):
            same_bits(new[j], ref.extrapolate(rate[j], base[j], steps[j]))
    same_bits(new[1], held[1])


@pytest.mark.parametrize("unit", [True, False])
def test_ab4_step_is_the_two_updates_and_the_bond_check(rng, unit):
    s = random_rods(200, rng)
    length = np.zeros(0) if unit else rng.uniform(0.5, 2.0, size=200)
    hist_v, hist_a = rng.normal(size=(4, 400, 3)), rng.normal(size=(4, 400, 3)) * 10.0
    slots = np.array([3, 2, 1, 0], dtype=np.int64)
    x_old, v_old = s.position.copy(), s.velocity.copy()
    ki.ab4_update(x_old, *(hist_v[j] for j in slots), 1e-3, x_old)  # the calls it replaced
    ki.ab4_update(v_old, *(hist_a[j] for j in slots), 1e-3, v_old)
    err_old = kr.bond_length_error(x_old, length)
    x, v = s.position.copy(), s.velocity.copy()
    err = ki.ab4_step(x, v, hist_v, hist_a, slots, 1e-3, length)
    same_bits(x, x_old)
    same_bits(v, v_old)
    same_bits(err, err_old)
    x_ref, v_ref, err_ref = ref.ab4_step(s.position, s.velocity, hist_v, hist_a, slots, 1e-3, None if unit else length)
    same_bits(x, x_ref)  # the same arithmetic, element by element, in Python floats
    same_bits(v, v_ref)
    assert err == pytest.approx(err_ref, rel=1e-12, abs=1e-15)  # a square root of a sum in another order


@pytest.mark.parametrize("project", [True, False])
@pytest.mark.parametrize("correct", [True, False])
@pytest.mark.parametrize("unit", [True, False])
def test_constrain_bonds_checked_is_the_constraint_and_both_checks(rng, project, correct, unit):
    s = random_rods(200, rng)
    length = np.zeros(0) if unit else rng.uniform(0.5, 2.0, size=200)
    x0 = s.position + 1e-4 * rng.normal(size=s.position.shape)  # bonds off by a step's error
    v0 = rng.normal(size=x0.shape)
    x_old, v_old = x0.copy(), v0.copy()
    err_old = kr.bond_length_error(x_old, length)
    if project or correct:  # the calls it replaced (the integrator skipped the constraint with neither)
        kr.constrain_bonds(x_old, v_old, project, correct, length)
        err_old = kr.bond_length_error(x_old, length) if project else err_old
    vmax_old = float(np.abs(v_old).max(initial=0.0))  # the health check's
    x, v = x0.copy(), v0.copy()
    err, vmax = kr.constrain_bonds_checked(x, v, project, correct, length)
    same_bits(x, x_old)
    same_bits(v, v_old)
    same_bits(err, err_old)
    same_bits(vmax, vmax_old)
    x_ref, v_ref = ref.constrain_bonds(x0, v0, project, correct, None if unit else length)
    # the projection about the centre, computed otherwise: a few ulp of coordinates of order 1 (x), and of
    # velocities of order 1 (normal draws, up to about 4) less their parts along the bond (v); the bond error is a
    # difference of such positions' lengths, and the largest |v| one of those velocities
    np.testing.assert_allclose(x, x_ref, rtol=0, atol=1e-14)
    np.testing.assert_allclose(v, v_ref, rtol=0, atol=1e-13)
    assert err == pytest.approx(ref.bond_length_error(x_ref, None if unit else length), abs=1e-14)
    assert vmax == pytest.approx(float(np.abs(v_ref).max()), rel=1e-13)


def test_constrain_bonds_checked_reports_nan_and_inf_as_numpy_does(rng):
    s = random_rods(20, rng)
    for bad in (np.nan, np.inf, -np.inf):
        v = rng.normal(size=s.position.shape)
        v[7, 1] = bad
        _, vmax = kr.constrain_bonds_checked(s.position.copy(), v, False, False, np.zeros(0))
        same_bits(vmax, np.abs(v).max(initial=0.0))
    assert kr.constrain_bonds_checked(np.zeros((0, 3)), np.zeros((0, 3)), True, True, np.zeros(0)) == (0.0, 0.0)


# -- the kernels of the compiled steps by blocks of rods (kernels/steps.py, kernels/team.py): over any
# split of the rods into blocks, the same numbers as the kernel over all of them, bit for bit


def splits(n_rods, rng, count=4):
    """Block edges (in rods) for ``count`` random splits of ``n_rods`` rods, one block and empty blocks among them."""
    out = [np.array([0, n_rods])]
    for _ in range(count - 1):
        inner = np.sort(rng.integers(0, n_rods + 1, size=rng.integers(1, 6)))
        out.append(np.concatenate([[0], inner, [n_rods]]))
    return out


def test_tip_fast_by_blocks_is_tip_tip_fast(crowded, rng):
    from selfas_graph.kernels import tips

    s, nl = crowded
    args = (s.position, s.tip_charge, nl.start, nl.index, RSTAR, 30.0, 0.05, 0.12)
    whole = np.full_like(s.position, np.nan)
    tips.tip_tip_fast(*args, whole)
    assert np.count_nonzero(whole) > 100
    for edges in splits(s.n_rods, rng):
        parts = np.full_like(s.position, np.nan)
        for r0, r1 in zip(edges[:-1], edges[1:]):
            tips.tip_tip_fast_rows(*args, 2 * r0, 2 * r1, parts)
        same_bits(parts, whole)


@pytest.mark.parametrize("k_dt", [0.1, 3.0])
def test_split_brake_by_blocks_is_the_one_pass(crowded, rng, k_dt):
    """The pairs found block by block (each block's from ``start`` of its first tip on), then braked in
    that order: the velocities, work and count of :func:`brake_close_pairs_exact`."""
    s, nl = crowded
    k_br, dt = k_dt / 1e-3, 1e-3
    v_one = s.velocity.copy()
    w_one, m_one = brakes.brake_close_pairs_exact(s.position, v_one, nl.start, nl.index, RADIUS, k_br, dt)
    assert m_one > 20
    for edges in splits(s.n_rods, rng):
        v = s.velocity.copy()
        pair_k = np.full(nl.index.shape[0], -1)
        pair_l = np.full(nl.index.shape[0], -1)
        found = []
        for r0, r1 in zip(edges[:-1], edges[1:]):
            t0 = 2 * r0
            found.append(
                (
                    t0,
                    brakes.close_pairs_rows(
                        s.position, nl.start, nl.index, RADIUS, t0, 2 * r1, pair_k, pair_l, nl.start[t0]
                    ),
                )
            )
        work, m = 0.0, 0
        for t0, count in found:
            work = brakes.brake_found_pairs(v, pair_k, pair_l, nl.start[t0], count, k_br, dt, work)
            m += count
        assert m == m_one
        same_bits(v, v_one)
        same_bits(work, w_one)


def test_contact_test_by_blocks_is_the_one_pass(rng):
    """contacts_part over blocks of contacts and tips: every part ok and the counts equal exactly when
    contacts_unchanged is True, on states where it is True and where each of its tests fails."""
    s = random_rods(150, rng, box=1.2)
    nl = NeighbourList(RADIUS, 0.05, exclude_same_rod=True)
    nl.build(s.position)
    close = contacts.close_pairs(s.position, nl.start, nl.index, RSTAR)
    assert len(close) > 5
    n = s.n_tips
    z = s.position[:, 2]
    z_c, z_a = z.min() - 0.5 * RSTAR, z.max() + 0.5 * RSTAR
    on_c = z - z_c < RSTAR
    on_a = z_a - z < RSTAR
    no = np.zeros(n, dtype=bool)
    cases = {
        "quiet": (close, on_c, on_a),
        "a close pair not a contact": (close[1:], on_c, on_a),
        "a contact beyond release": (np.vstack([close, [[0, n - 1]]]), on_c, on_a),
        "a tip on the cathode not listed": (close, no, on_a),
    }
    for name, (pairs, oc, oa) in cases.items():
        args = (RSTAR, 1.5 * RSTAR, z_c, z_a, oc, oa, np.nan, no)
        whole = contacts.contacts_unchanged(s.position, nl.start, nl.index, pairs, *args)
        assert whole == (name == "quiet"), name
        for edges in splits(s.n_rods, rng):
            ok, known, near = True, 0, 0
            blocks = len(edges) - 1
            m = len(pairs)
            for j, (r0, r1) in enumerate(zip(edges[:-1], edges[1:])):
                part = contacts.contacts_part(
                    s.position, nl.start, nl.index, pairs, j * m // blocks, (j + 1) * m // blocks, 2 * r0, 2 * r1, *args
                )
                ok &= part[0]
                known += part[1]
                near += part[2]
            assert (ok and known == near) == whole, name


@pytest.mark.parametrize("unit", [True, False])
def test_ab4_by_blocks_is_ab4_step(rng, unit):
    s = random_rods(200, rng)
    length = np.zeros(0) if unit else rng.uniform(0.5, 2.0, size=200)
    hist_v, hist_a = rng.normal(size=(4, 400, 3)), rng.normal(size=(4, 400, 3)) * 10.0
    slots = np.array([3, 2, 1, 0], dtype=np.int64)
    x1, v1 = s.position.copy(), s.velocity.copy()
    err = ki.ab4_step(x1, v1, hist_v, hist_a, slots, 1e-3, length)
    for edges in splits(200, rng):
        x, v = s.position.copy(), s.velocity.copy()
        worst = 0.0
        for r0, r1 in zip(edges[:-1], edges[1:]):
            worst = max(worst, ki.ab4_rods(x, v, hist_v, hist_a, slots, 1e-3, length, r0, r1))
        same_bits(x, x1)
        same_bits(v, v1)
        same_bits(worst, err)


def test_channel_sums_by_blocks_and_powers_by_group_are_channel_sum_power(rng):
    for n_ch, powered in ((11, [0, 2, 3, 5, 9]), (8, [1]), (9, [0, 1, 2, 3, 4, 5])):
        c = channels(rng, n_ch=n_ch)
        v = rng.normal(size=(500, 3))
        powered = np.array(powered, dtype=np.int64)
        out1, p1 = np.zeros((500, 3)), np.zeros(len(powered))
        ki.channel_sum_power(out1, c, v, powered, p1)
        rows = c.reshape(n_ch, 1500)
        for edges in splits(250, rng):
            out = np.full((500, 3), np.nan)
            for r0, r1 in zip(edges[:-1], edges[1:]):
                ki.sum_rows_range(out.reshape(-1), rows, 6 * r0, 6 * r1)
            same_bits(out, out1)
        p = np.full(len(powered), np.nan)
        for j in range(0, len(powered), 3):
            ki.power_group(rows, v.reshape(-1), powered, p, j)
        same_bits(p, p1)


# -- the same block kernels against the slow references (tests/reference.py) directly


def test_block_kernels_are_the_slow_references(crowded, rng):
    """Over one split into blocks: the pairs found, the brake, the AB4 update, the channel sums and the
    powers, each against its reference, not only against the one-pass kernel above."""
    s, nl = crowded
    # rows sorted, so that the pairs come in the reference's (k, l) order
    index = np.concatenate([np.sort(nl.index[a:b]) for a, b in zip(nl.start[:-1], nl.start[1:])])
    edges = splits(s.n_rods, rng)[1]
    pair_k = np.full(index.shape[0], -1)
    pair_l = np.full(index.shape[0], -1)
    v, work, found = s.velocity.copy(), 0.0, []
    for r0, r1 in zip(edges[:-1], edges[1:]):
        t0 = 2 * r0
        m = brakes.close_pairs_rows(s.position, nl.start, index, RADIUS, t0, 2 * r1, pair_k, pair_l, nl.start[t0])
        block = list(zip(pair_k[nl.start[t0] : nl.start[t0] + m], pair_l[nl.start[t0] : nl.start[t0] + m]))
        want = sorted(p for p in ref.neighbour_pairs(s.position, RADIUS, True) if t0 <= p[0] < 2 * r1)
        assert block == want
        found.append((nl.start[t0], m))
    for offset, m in found:
        work = brakes.brake_found_pairs(v, pair_k, pair_l, offset, m, 100.0, 1e-3, work)
    v_ref, w_ref, m_ref = ref.brake_close_pairs(s.position, s.velocity, RADIUS, 100.0, 1e-3)
    assert sum(m for _, m in found) == m_ref > 20
    np.testing.assert_allclose(v, v_ref, rtol=1e-12, atol=1e-14)  # the same arithmetic; numpy floats vs Python
    assert work == pytest.approx(w_ref, rel=1e-12)  # a sum of m_ref such terms, in the same order

    length = rng.uniform(0.5, 2.0, size=s.n_rods)
    hist_v, hist_a = rng.normal(size=(4, s.n_tips, 3)), rng.normal(size=(4, s.n_tips, 3)) * 10.0
    slots = np.array([3, 2, 1, 0], dtype=np.int64)
    x, v = s.position.copy(), s.velocity.copy()
    worst = max(ki.ab4_rods(x, v, hist_v, hist_a, slots, 1e-3, length, r0, r1) for r0, r1 in zip(edges[:-1], edges[1:]))
    x_ref, v_ref, err_ref = ref.ab4_step(s.position, s.velocity, hist_v, hist_a, slots, 1e-3, length)
    same_bits(x, x_ref)  # the same five products and four sums per element, in the same order
    same_bits(v, v_ref)
    assert worst == pytest.approx(err_ref, rel=1e-12, abs=1e-15)  # a square root of a sum in another order

    c = channels(rng, n_ch=9, n=s.n_tips)
    out = np.full((s.n_tips, 3), np.nan)
    rows = c.reshape(9, -1)
    for r0, r1 in zip(edges[:-1], edges[1:]):
        ki.sum_rows_range(out.reshape(-1), rows, 6 * r0, 6 * r1)
    same_bits(out, ref.channel_sum(c))  # element by element from 0.0, in channel order
    powered = np.array([0, 2, 3, 5, 8], dtype=np.int64)
    p = np.full(len(powered), np.nan)
    for j in range(0, len(powered), 3):
        ki.power_group(rows, s.velocity.reshape(-1), powered, p, j)
    for j, ch in enumerate(powered):
        # the kernel's pairwise sum against the correctly rounded one: within 1e-13 of the sum of |products|
        bound = 1e-13 * ref.dot(np.abs(c[ch]), np.abs(s.velocity))
        assert p[j] == pytest.approx(ref.dot(c[ch], s.velocity), abs=bound)


def test_contact_test_by_blocks_counts_the_reference_pairs(rng):
    """On a quiet state, each block's counts are the listed contacts and the pairs k < l of its tips
    closer than r*, counted by all distances."""
    s = random_rods(150, rng, box=1.2)
    nl = NeighbourList(RADIUS, 0.05, exclude_same_rod=True)
    nl.build(s.position)
    close = sorted(ref.neighbour_pairs(s.position, RSTAR, True))
    pairs = np.array(close, dtype=np.int64).reshape(-1, 2)
    assert len(pairs) > 5
    no = np.zeros(s.n_tips, dtype=bool)
    args = (RSTAR, 1.5 * RSTAR, np.nan, np.nan, no, no, np.nan, no)
    edges = splits(s.n_rods, rng)[2]
    blocks = len(edges) - 1
    m = len(pairs)
    for j, (r0, r1) in enumerate(zip(edges[:-1], edges[1:])):
        p_lo, p_hi = j * m // blocks, (j + 1) * m // blocks
        ok, known, near = contacts.contacts_part(
            s.position, nl.start, nl.index, pairs, p_lo, p_hi, 2 * r0, 2 * r1, *args
        )
        assert ok
        assert known == p_hi - p_lo
        assert near == sum(1 for k, _ in close if 2 * r0 <= k < 2 * r1)
