"""The mixed-precision Yukawa sum (``forces.yukawa.precision = "mixed"``,
``kernels/yukawa.py::yukawa_centres_sorted_mixed``, docs/model.md 'Term 6') against the float64
kernel and the oracle (tests/reference.py ``yukawa_force``), at the extremes float32 must survive or
hand over to float64.

Tolerance: each rod's force within 1e-6 of sum_l |f_il| (1 + r_il / R_D), the magnitudes of its
pair forces each weighted by its rounding. A pair force is the float32 law on a float32 separation:
the exponential within 1.3 ulp, a square root, a division and a few products, each rounded to half
an ulp, and the argument ``-r / R_D`` rounded to float32, an error that ``exp`` multiplies by
``r / R_D`` (its condition number: 2.4e-6 relative at the 40 screening lengths the mixed sum
allows). The row adds its pair forces in float32, one rounding per term. The magnitudes, not the
net force, set the scale: the net force of a rod among many neighbours cancels far below its
terms. Measured over these scenes and four more seeds: at most 2.1e-7, a margin of 4.7.
"""

import numpy as np
import pytest

import reference as ref
from conftest import random_rods, simulation
from selfas_graph.kernels import yukawa as ky
from selfas_graph.model.neighbours import NeighbourList

#: small inputs: also run with NUMBA_DISABLE_JIT=1, the kernels as Python (.ci/run)
pytestmark = pytest.mark.jit_off_ok

RTOL = 1e-6  # of the sum of a row's weighted pair-force magnitudes (module docstring)


def both(centre, charge, screening=1.0, core=0.0, cutoff=3.0, lo=0, hi=None, skin=0.3):
    """(float64, mixed) forces of the sorted kernels over the same list; untouched rows NaN."""
    centre = np.ascontiguousarray(centre, dtype=np.float64)
    n = len(centre)
    hi = n if hi is None else hi
    nl = NeighbourList(cutoff, skin * cutoff, cell_order=True)
    nl.build(centre)
    order, start, index = nl.sorted_rows
    out = []
    for kernel in (ky.yukawa_centres_sorted, ky.yukawa_centres_sorted_mixed):
        f = np.full((n, 3), np.nan)
        kernel(centre[order], charge[order], order, start, index, screening, core, cutoff, lo, hi, f)
        out.append(f)
    return out


def pair_force_sum(centre, charge, screening=1.0, core=0.0, cutoff=3.0):
    """sum_l |f_il| (1 + r_il / R_D) over the pairs counted (r < cutoff, core clamp): the scale of a
    row's float32 rounding (module docstring)."""
    r = np.linalg.norm(centre[:, None, :] - centre[None, :, :], axis=-1)
    rr = np.maximum(r, core)
    with np.errstate(divide="ignore", invalid="ignore"):
        f = np.abs(np.outer(charge, charge)) * np.exp(-rr / screening) * (1 / rr**2 + 1 / (screening * rr))
        f = np.where(r < core, f * r / core, f)
    f[(r >= cutoff) | (r == 0.0)] = 0.0
    return (f * (1.0 + rr / screening)).sum(axis=1)


def assert_close(mixed, f64, scale):
    err = np.linalg.norm(mixed - f64, axis=1)
    assert (err <= RTOL * scale).all(), (err / np.maximum(scale, 1e-300)).max()


@pytest.mark.parametrize("core", [0.0, 0.06])
@pytest.mark.parametrize("box, cutoff", [(12.0, 3.0), (0.5, 3.0), (8.0, 6.56)])
def test_mixed_sum_matches_float64_and_the_oracle_to_float32_rounding(rng, box, cutoff, core):
    """A random rod gas (several cells a side, all in one cell, the Fig. 2 cut-off across most of the
    box): the mixed forces lie within float32 rounding of the float64 kernel's and of the oracle's."""
    c = rng.uniform(-box / 2, box / 2, (150, 3))
    z = rng.uniform(0.5, 1.5, 150)
    f64, mixed = both(c, z, core=core, cutoff=cutoff)
    scale = pair_force_sum(c, z, core=core, cutoff=cutoff)
    assert_close(mixed, f64, scale)
    assert_close(mixed, ref.yukawa_force(c, z, 1.0, cutoff, core), scale)
    assert not np.array_equal(mixed, f64)  # float32 did run


def test_rows_do_not_depend_on_the_range(rng):
    """Rows lo:hi equal those of the whole sum bit for bit; the other rows are not touched."""
    c = rng.uniform(-4, 4, (200, 3))
    z = rng.uniform(0.5, 1.5, 200)
    _, whole = both(c, z, core=0.06)
    for lo, hi in ((50, 130), (0, 1), (199, 200), (0, 0)):
        _, part = both(c, z, core=0.06, lo=lo, hi=hi)
        np.testing.assert_array_equal(part[lo:hi], whole[lo:hi])
        assert np.isnan(part[:lo]).all() and np.isnan(part[hi:]).all()


def test_core_and_coincident_rods():
    """Inside the core radius the force falls linearly, ``f(a) r / a`` (docs/model.md 'Term 6'); two
    rods on the same point feel nothing from each other (no direction), with or without a core."""
    a = 0.3
    z = np.array([1.0, 0.7, 1.2, 0.9, 1.1])
    c = np.array([[0, 0, 0], [0.1, 0, 0], [1, 1, 1], [1, 1, 1], [1.5, 1, 1]], float)
    f_a = z[0] * z[1] * np.exp(-a) * (1 / a**2 + 1 / a)
    for core in (0.0, a):
        f64, mixed = both(c, z, core=core)
        assert np.isfinite(mixed).all()
        assert_close(mixed, f64, pair_force_sum(c, z, core=core))
        if core:
            two_f64, two = both(c[:2], z[:2], core=a)
            assert two[1, 0] == pytest.approx(f_a * 0.1 / a, rel=RTOL)
            assert two[0, 0] == -two[1, 0] and two[:, 1:].tolist() == [[0.0, 0.0], [0.0, 0.0]]


@pytest.mark.parametrize("shift", [1e4, 1e7])
def test_far_from_the_origin(rng, shift):
    """A scene 1e4 or 1e7 rod lengths from the origin: each separation is taken in float64 before it
    is rounded to float32, so it keeps float32 precision relative to itself."""
    c = rng.uniform(-3, 3, (60, 3))
    z = rng.uniform(0.5, 1.5, 60)
    f64, mixed = both(c + shift, z, core=0.06)
    assert_close(mixed, f64, pair_force_sum(c, z, core=0.06))


#: (name, settings, positions scale) where float32 still runs: at each bound of ky.MIXED_* exactly
INSIDE = [
    ("smallest and largest charges", dict(charge=(ky.MIXED_CHARGE_MIN, ky.MIXED_CHARGE_MAX)), 1.0),
    ("cut-off at the most screening lengths", dict(screening=3.0 / ky.MIXED_RANGE_MAX), 1.0),
    ("shortest lengths", dict(screening=ky.MIXED_LENGTH_MIN, core=ky.MIXED_LENGTH_MIN), 1e-2),
    ("longest lengths", dict(screening=ky.MIXED_LENGTH_MAX, core=ky.MIXED_LENGTH_MAX), 1e3 / 3),
]
#: the same a step beyond: the float64 sum, bit for bit
OUTSIDE = [
    ("charge too small", dict(charge=(np.nextafter(ky.MIXED_CHARGE_MIN, 0), 1.0)), 1.0),
    ("charge too large", dict(charge=(1.0, np.nextafter(ky.MIXED_CHARGE_MAX, np.inf))), 1.0),
    ("charge NaN", dict(charge=(1.0, np.nan)), 1.0),
    ("cut-off beyond the most screening lengths", dict(screening=np.nextafter(3.0 / ky.MIXED_RANGE_MAX, 0)), 1.0),
    ("screening length too short", dict(screening=np.nextafter(ky.MIXED_LENGTH_MIN, 0)), 1e-2),
    ("core radius too short", dict(screening=ky.MIXED_LENGTH_MIN, core=np.nextafter(ky.MIXED_LENGTH_MIN, 0)), 1e-2),
    ("cut-off too short", dict(screening=ky.MIXED_LENGTH_MIN, cutoff=np.nextafter(ky.MIXED_LENGTH_MIN, 0)), 3e-4),
    ("screening length too long", dict(screening=np.nextafter(ky.MIXED_LENGTH_MAX, np.inf)), 1e3 / 3),
    ("core radius too long", dict(core=np.nextafter(ky.MIXED_LENGTH_MAX, np.inf)), 1e3 / 3),
    ("cut-off too long", dict(screening=100.0, cutoff=np.nextafter(ky.MIXED_LENGTH_MAX, np.inf)), 1e3 / 3),
]


def extreme_scene(rng, settings, scale):
    """24 rods in a box of side 6 * scale, cut-off 3 * scale (unless set), charges 0.5-1.5 (or a
    pair of values alternating, and two uncharged rods)."""
    s = dict(screening=1.0, core=0.0, cutoff=3.0 * scale)
    s.update({k: v for k, v in settings.items() if k != "charge"})
    c = rng.uniform(-3 * scale, 3 * scale, (24, 3))
    z = rng.uniform(0.5, 1.5, 24)
    if "charge" in settings:
        z = np.resize(np.array(settings["charge"], float), 24)
        z[[5, 6]] = 0.0
    return c, z, s


@pytest.mark.parametrize("name, settings, scale", INSIDE, ids=[c[0] for c in INSIDE])
def test_at_the_float32_bounds_the_mixed_sum_runs(rng, name, settings, scale):
    c, z, s = extreme_scene(rng, settings, scale)
    f64, mixed = both(c, z, **s)
    assert_close(mixed, f64, pair_force_sum(c, z, **s))
    assert not np.array_equal(mixed, f64)  # float32 did run


@pytest.mark.parametrize("name, settings, scale", OUTSIDE, ids=[c[0] for c in OUTSIDE])
def test_beyond_the_float32_bounds_the_float64_sum_is_taken(rng, name, settings, scale):
    c, z, s = extreme_scene(rng, settings, scale)
    f64, mixed = both(c, z, **s)
    np.testing.assert_array_equal(mixed, f64)  # bit for bit: the float64 loop, NaN included


@pytest.mark.parametrize("gap", [1e-10, 1e-14, 0.0, 1e-30])
def test_close_centres_without_a_core(rng, gap):
    """Without a core, ``1/r^3`` overflows float32 for centres closer than about 1e-13: the rows that
    overflow (inf, or NaN from inf - inf) are summed in float64, bit for bit, the others in float32.
    At 1e-10 float32 holds the pair; centres on the same point feel nothing from each other. Below
    about 3e-23 ``r^2`` underflows float32 to 0 and the pair counts as coincident
    (``laws.yukawa_force_over_r_f32``), where float64 gives a force above 1e45."""
    c = rng.uniform(-2, 2, (30, 3))
    z = rng.uniform(0.5, 1.5, 30)
    c[0] = 0.0
    c[1] = [gap, 0.0, 0.0]
    with np.errstate(over="ignore", invalid="ignore"):  # the overflow, when the kernels run as Python
        f64, mixed = both(c, z)
    scale = pair_force_sum(c, z)
    assert_close(mixed[2:], f64[2:], scale[2:])
    if gap == 1e-14:
        np.testing.assert_array_equal(mixed[:2], f64[:2])
    elif gap == 1e-30:
        c[1] = c[0]
        assert_close(mixed, both(c, z)[0], scale)
    else:
        assert_close(mixed[:2], f64[:2], scale[:2])
        assert not np.array_equal(mixed[:2], f64[:2])


def test_nan_position_takes_the_float64_rows(rng):
    """A NaN centre makes its row and its neighbours' rows NaN in float32: those rows are summed in
    float64 (NaN where the float64 sum gives NaN), bit for bit."""
    c = rng.uniform(-2, 2, (30, 3))
    z = rng.uniform(0.5, 1.5, 30)
    c[4, 1] = np.nan
    f64, mixed = both(c, z, core=0.06)
    np.testing.assert_array_equal(np.isnan(mixed), np.isnan(f64))
    bad = np.isnan(f64).any(axis=1)
    np.testing.assert_array_equal(mixed[bad], f64[bad])


def test_precision_knob_picks_the_mixed_kernel(rng):
    """``forces.yukawa.precision = "mixed"`` gives the float64 term's forces to float32 rounding and
    the same (float64) energy; other values are refused."""
    state = random_rods(40, rng, box=3.0)
    forces, energy = {}, {}
    for precision in ("float64", "mixed"):
        sim = simulation(state.copy(), forces={"yukawa": {"core_radius": 0.06, "precision": precision}})
        ff = sim.force_field
        ff.evaluate(state.position, state.velocity)
        forces[precision] = ff.out["yukawa"].copy()
        energy[precision] = ff.potential_energy(state.position)["yukawa"]
        cutoff = ff.describe()["yukawa_cutoff"]
    centre = 0.5 * (state.position[0::2] + state.position[1::2])
    scale = np.repeat(0.5 * pair_force_sum(centre, state.rod_charge, core=0.06, cutoff=cutoff), 2)
    assert_close(forces["mixed"], forces["float64"], scale)
    assert not np.array_equal(forces["mixed"], forces["float64"])
    assert energy["mixed"] == energy["float64"]
    with pytest.raises(ValueError, match="forces.yukawa.precision"):
        simulation(state.copy(), forces={"yukawa": {"precision": "float32"}})
