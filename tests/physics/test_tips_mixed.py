"""The mixed-precision direct tip-tip sum (``forces.tip_magnetic.precision = "mixed"``,
``kernels/tips.py::tip_tip_direct_mixed``) against the float64 kernel and the oracle
(tests/reference.py), at the extremes float32 must survive or hand over to float64."""

import numpy as np
import pytest

import reference
from conftest import random_rods, simulation
from selfas_graph.kernels import tips as kt

#: small inputs: also run with NUMBA_DISABLE_JIT=1, the kernels as Python (.ci/run)
pytestmark = pytest.mark.jit_off_ok

RSTAR, KAPPA = 0.06, 1.0


def both(position, charge, lo=0, hi=None):
    x, y, z = (np.ascontiguousarray(position[:, d]) for d in range(3))
    hi = len(x) if hi is None else hi
    f64 = np.full((len(x), 3), np.nan)
    mixed = np.full((len(x), 3), np.nan)
    kt.tip_tip_direct(x, y, z, charge, RSTAR, KAPPA, lo, hi, f64)
    kt.tip_tip_direct_mixed(x, y, z, charge, RSTAR, KAPPA, lo, hi, mixed)
    return f64, mixed


def pair_force_sum(position, charge):
    """sum_l |f_kl| for every tip k: the scale of the float32 rounding of its sum."""
    d = position[:, None, :] - position[None, :, :]
    r = np.linalg.norm(d, axis=-1)
    p = charge[:, None] * charge[None, :]
    f = np.where(r >= RSTAR, np.abs(p) / np.maximum(r, 1e-150) ** 2, np.abs(p * r + KAPPA * (RSTAR - r)) / RSTAR**3)
    k = np.arange(len(charge))
    f[k[:, None] // 2 == k[None, :] // 2] = 0.0
    return f.sum(axis=1)


@pytest.mark.parametrize("box", [1.0, 4.0])
def test_mixed_sum_matches_the_oracle_to_float32_rounding(rng, box):
    state = random_rods(150, rng, box=box)
    f64, mixed = both(state.position, state.tip_charge)
    # the float64 sum against the loop oracle: sums of 300 pair forces (up to ~1e3 in the cores) in
    # another order, round-off ~1e-13 of the terms; 1e-9 leaves room (the mixed sum's bound follows)
    np.testing.assert_allclose(
        f64, reference.tip_tip_force(state.position, state.tip_charge, RSTAR, KAPPA), rtol=1e-9, atol=1e-9
    )
    # each pair's float32 force is within a few 6e-8 of itself (separations from hi + lo parts,
    # the law in float32); the block sums of 128 add a rounding of the partial sum: 1e-6 of the
    # sum of the pair forces' magnitudes bounds both with a margin of about 3
    bound = 1e-6 * pair_force_sum(state.position, state.tip_charge)
    assert (np.linalg.norm(mixed - f64, axis=1) <= bound).all()
    assert not np.array_equal(mixed, f64)  # float32 did run


def test_rows_do_not_depend_on_the_range(rng):
    state = random_rods(80, rng)
    _, whole = both(state.position, state.tip_charge)
    _, part = both(state.position, state.tip_charge, lo=37, hi=101)
    np.testing.assert_array_equal(part[37:101], whole[37:101])
    assert np.isnan(part[:37]).all() and np.isnan(part[101:]).all()  # other rows untouched


def test_far_from_the_origin_and_spread_wide(rng):
    """Tips 1e4 rod lengths from the origin, or 1e4 apart: the hi + lo coordinates keep each
    separation to float32 precision of itself."""
    state = random_rods(40, rng, box=3.0)
    for shift, spread in ((1e4, 1.0), (0.0, 1e4)):
        pos = state.position.copy()
        pos[: len(pos) // 2] += spread - 1.0
        pos += shift
        f64, mixed = both(pos, state.tip_charge)
        bound = 1e-6 * pair_force_sum(pos, state.tip_charge)
        assert (np.linalg.norm(mixed - f64, axis=1) <= bound).all()


def test_core_and_coincident_tips():
    """Tips inside r* (the core) and tips of different rods on the same point (no direction: 0)."""
    pos = np.array(
        [[0, 0, 0], [1, 0, 0], [0.03, 0, 0], [0.03, 1, 0], [5, 5, 5], [6, 5, 5], [5, 5, 5], [5, 6, 5]], float
    )
    q = np.array([1.0, -1.0, 1.5, -1.5, 0.7, -0.7, 1.2, -1.2])
    f64, mixed = both(pos, q)
    assert np.isfinite(mixed).all()
    bound = 1e-6 * pair_force_sum(pos, q)
    assert (np.linalg.norm(mixed - f64, axis=1) <= bound).all()


@pytest.mark.parametrize("case", ["spread beyond float32", "tiny charge", "huge charge", "NaN"])
def test_outside_float32_the_float64_sum_is_taken(rng, case):
    state = random_rods(20, rng)
    pos, q = state.position.copy(), state.tip_charge.copy()
    if case == "spread beyond float32":
        pos[0] += 1e16
    elif case == "tiny charge":
        q[4], q[5] = 1e-20, -1e-20
    elif case == "huge charge":
        q[4], q[5] = 1e20, -1e20
    else:
        pos[3, 1] = np.nan
    f64, mixed = both(pos, q)
    np.testing.assert_array_equal(mixed, f64)  # bit for bit: the float64 loop, NaN included


def test_precision_knob_picks_the_mixed_direct_sum(rng):
    state = random_rods(30, rng, box=2.0)
    out = {}
    for precision in ("float64", "mixed"):
        sim = simulation(state.copy(), forces={"tip_magnetic": {"method": "direct", "precision": precision}})
        sim.force_field.evaluate(state.position, state.velocity)
        out[precision] = sim.force_field.out["tip_magnetic"].copy()
    f64, mixed = both(state.position, state.tip_charge)
    np.testing.assert_array_equal(out["float64"], f64)
    np.testing.assert_array_equal(out["mixed"], mixed)
    with pytest.raises(ValueError, match="forces.tip_magnetic.precision"):
        simulation(state.copy(), forces={"tip_magnetic": {"precision": "float32"}})
