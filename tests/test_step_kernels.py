"""The kernels that replace the per-step numpy glue: each against its slow reference (tests/reference.py)
and, bit for bit, against the numpy code it replaced (a run's results must not change by a bit)."""

import numpy as np
import pytest

import reference as ref
from conftest import random_rods
from selfas_graph import load_scenario
from selfas_graph.kernels import fields as kf
from selfas_graph.kernels import integrate as ki
from selfas_graph.kernels import pairs as kp
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
    """The loop the force field ran: fill with 0, add each channel in order (numpy's a + b + c is (a + b) + c)."""
    for n_ch in (0, 1, 2, 11):
        c = channels(rng, n_ch=max(n_ch, 8))[:n_ch]
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
    pairs = kp.close_pairs(s.position, nl.start, nl.index, RADIUS)
    assert len(pairs) > 20
    w_old = kp.brake_pairs_exact(v_old, pairs, k_dt / 1e-3, 1e-3)
    w_new, m = kp.brake_close_pairs_exact(s.position, v_new, nl.start, nl.index, RADIUS, k_dt / 1e-3, 1e-3)
    assert m == len(pairs)
    same_bits(v_new, v_old)
    same_bits(w_new, w_old)


def test_fused_split_brake_is_the_reference(crowded):
    s, nl = crowded
    # pair after pair, the order matters: rows sorted, the kernel brakes in the reference's (k, l) order
    index = np.concatenate([np.sort(nl.index[a:b]) for a, b in zip(nl.start[:-1], nl.start[1:])])
    v = s.velocity.copy()
    work, m = kp.brake_close_pairs_exact(s.position, v, nl.start, index, RADIUS, 100.0, 1e-3)
    v_ref, w_ref, m_ref = ref.brake_close_pairs(s.position, s.velocity, RADIUS, 100.0, 1e-3)
    assert m == m_ref > 20
    np.testing.assert_allclose(v, v_ref, rtol=1e-12, atol=1e-14)  # the same arithmetic; numpy floats vs Python
    assert work == pytest.approx(w_ref, rel=1e-12)


def test_both_paths_of_the_split_brake_agree_bit_for_bit(crowded, monkeypatch):
    """Above PARALLEL_ROWS tips the pairs are listed on all threads first: the same result."""
    s, nl = crowded
    v_serial, v_listed = s.velocity.copy(), s.velocity.copy()
    got_serial = kp.brake_close_pairs(s.position, v_serial, nl.start, nl.index, RADIUS, 100.0, 1e-3)
    monkeypatch.setattr(kp, "PARALLEL_ROWS", 0)
    got_listed = kp.brake_close_pairs(s.position, v_listed, nl.start, nl.index, RADIUS, 100.0, 1e-3)
    assert got_serial == got_listed
    same_bits(v_serial, v_listed)
    far = s.position * 100.0  # no pair close: nothing braked
    assert kp.brake_close_pairs(far, v_listed, nl.start, nl.index, RADIUS, 100.0, 1e-3) == (0.0, 0)


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
        ff._bind(x, v_new)
        new = term.split(ff, dt)
        assert old.keys() == new.keys() == {"electrode_brake"}
        same_bits(new["electrode_brake"], old["electrode_brake"])
        same_bits(v_new, v_old)
    v_ref, w_ref = ref.electrode_brake(x, v_old, *term.z, term.rstar, term.k, 1e-3)
    ff._bind(x, v_new)
    w = term.split(ff, 1e-3)["electrode_brake"]
    np.testing.assert_allclose(v_new, v_ref, rtol=1e-14)  # exp here, numpy's exp there: round-off apart
    assert w == pytest.approx(w_ref, rel=1e-10)  # a difference of kinetic energies, summed in another order
    if gap is not None:
        return
    x[:, 2] = 0.0  # no tip touches: no work, no change
    assert term.split(ff, 1e-3) == {} == old_electrode_split(term, x, v_old, 1e-3)


def test_uniform_force_is_the_reference_and_the_numpy_broadcast(rng):
    q = rng.normal(size=301)
    B = np.array([0.1, -0.0, 0.5])
    out = np.full((301, 3), np.nan)
    kf.uniform_force_on_tips(q, B, out)
    same_bits(out, ref.uniform_force(q, B))
    old = np.empty((301, 3))
    np.multiply(q[:, None], B[None, :], out=old)  # the numpy code it replaced
    same_bits(out, old)
