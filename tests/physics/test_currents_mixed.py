"""Tests of the mixed-precision rod-current kernels (docs/model.md 'Term 9', 'Term 10').

``rod_current_field_mixed`` and ``current_force_on_tips_mixed`` take the segment law in float32
(``segment_field_f32``) with coordinates as float32 hi + lo pairs and float64 sums. They are
held against the float64 oracle of tests/reference.py at float32 tolerances, at the extremes of
the geometry (on the axis, at the ends, inside the wire radius, 1e-3 to 1e3 rod lengths away, a
scene far from the origin) and of the current (1e-6 to 1e3), and through the scenario knob
``precision`` of ``[forces.current_field]`` and ``[forces.current_lorentz]``.

Tolerances: float32 rounds to 6e-8; the law takes about 30 operations, so each segment's field
is good to a few 1e-7 of itself, up to 1e-6 where the cross product ``s x a`` cancels (a point
near the axis: then the field itself is that small). A sum of fields that partly cancel is held
to the same relative error of the sum of their magnitudes, ``sum_j |B_j|``.
"""

import numpy as np
import pytest

import reference
from conftest import SMALL_CIRCUIT_SCENE, random_rods
from selfas_graph.kernels.currents import (
    current_force_on_tips,
    current_force_on_tips_mixed,
    rod_current_field,
    rod_current_field_mixed,
)

#: small inputs: also run with NUMBA_DISABLE_JIT=1, the kernels as Python (.ci/run)
pytestmark = pytest.mark.jit_off_ok


def scene(seed, n_rods=40, box=5.0, shift=0.0):
    """n_rods random rods (conftest.random_rods) with random currents, about a quarter zero."""
    rng = np.random.default_rng(seed)
    state = random_rods(n_rods, rng, box=box)
    position = np.ascontiguousarray(state.position + shift)
    current = rng.uniform(-3, 3, size=n_rods)
    current[rng.random(n_rods) < 0.25] = 0.0
    active = np.flatnonzero(current != 0.0).astype(np.int64)
    return position, state.tip_charge, current, active


def field_mixed(point, exclude, position, active, current, w):
    out = np.full((len(point), 3), np.nan)  # NaN fill: proves every row is overwritten
    rod_current_field_mixed(
        np.ascontiguousarray(point, dtype=float), np.asarray(exclude, dtype=np.int64), position, active, current, w, out
    )
    return out


def magnitude_sum(points, exclude, position, active, current, w):
    """sum_j |B_j(x)| per point, the scale of each row's rounding."""
    out = np.zeros(len(points))
    for p, x in enumerate(points):
        for j in active:
            if j != exclude[p]:
                out[p] += np.linalg.norm(
                    reference.segment_field(x, position[2 * j], position[2 * j + 1], current[j], w)
                )
    return out


@pytest.mark.parametrize("seed,w,shift", [(31, 0.0, 0.0), (32, 0.03, 0.0), (33, 0.5, 0.0), (34, 0.03, 1.0e4)])
def test_mixed_field_matches_oracle(seed, w, shift):
    """The mixed field of 40 random rods at tips and free points, against the float64 oracle;
    ``shift`` puts the scene 1e4 from the origin, where float32 coordinates alone would be 1e-3
    off: the hi + lo pairs relative to the rods' centre keep it exact."""
    position, _, current, active = scene(seed, shift=shift)
    rng = np.random.default_rng(seed + 100)
    point = np.vstack([position, rng.uniform(-3, 3, size=(30, 3)) + shift])
    exclude = np.concatenate([np.arange(len(position)) // 2, rng.integers(-1, len(current), size=30)])
    got = field_mixed(point, exclude, position, active, current, w)
    ref = reference.rod_current_field(point, exclude, position, active, current, w)
    scale = magnitude_sum(point, exclude, position, active, current, w)
    # float32 rounding of each segment's field (module docstring): 1e-6 of sum_j |B_j|
    err = np.linalg.norm(got - ref, axis=1)
    assert np.all(err <= 1e-6 * scale + 1e-30), (err / scale).max()


@pytest.mark.parametrize("seed,w", [(41, 0.0), (42, 0.03)])
def test_mixed_tip_force_matches_oracle_and_float64_kernel(seed, w):
    """Term 9 in mixed precision: added to ``out``, own rod skipped, tips ``lo:hi`` only; within
    float32 rounding of the float64 kernel."""
    position, charge, current, active = scene(seed)
    n_tips = len(position)
    base = np.random.default_rng(seed).normal(size=(n_tips, 3))
    got = base.copy()
    current_force_on_tips_mixed(position, charge, active, current, w, 3, n_tips - 5, got)
    want = base.copy()
    current_force_on_tips(position, charge, active, current, w, 3, n_tips - 5, want)
    np.testing.assert_array_equal(got[:3], base[:3])
    np.testing.assert_array_equal(got[n_tips - 5 :], base[n_tips - 5 :])
    own = np.arange(n_tips) // 2
    ref = base + charge[:, None] * reference.rod_current_field(position, own, position, active, current, w)
    scale = np.abs(charge) * magnitude_sum(position, own, position, active, current, w)
    for other in (ref, want):
        err = np.linalg.norm(got - other, axis=1)[3 : n_tips - 5]
        # see test_mixed_field_matches_oracle; base is added in float64
        assert np.all(err <= 1e-6 * scale[3 : n_tips - 5] + 1e-14), (err / scale[3 : n_tips - 5]).max()


def one_segment_field(points, A, B, J, w):
    position = np.ascontiguousarray([A, B], dtype=float)
    one = np.array([0], dtype=np.int64)
    got = field_mixed(points, -np.ones(len(points), dtype=np.int64), position, one, np.array([J]), w)
    f64 = np.empty_like(got)
    rod_current_field(
        np.ascontiguousarray(points), -np.ones(len(points), dtype=np.int64), position, one, np.array([J]), w, f64
    )
    ref = np.array([reference.segment_field(x, A, B, J, w) for x in points])
    return got, f64, ref


@pytest.mark.parametrize("J", [1e-6, 1.0, -1e3])
@pytest.mark.parametrize("w", [0.0, 0.09])
def test_mixed_law_at_distances_from_1e_minus_3_to_1e3(J, w):
    """Points in all directions at 1e-3 to 1e3 rod lengths from a unit segment (beside it, beyond
    its ends, inside the wire radius), currents 1e-6 to 1e3. The float32 coordinates of ``a`` and
    ``b`` are good to 6e-8 of |a| and |b|; the distance rho to the line (in ``s x a``) is then good
    to 6e-8 |a| / rho: the field errs about 6e-8 / sin(theta) of itself, theta the angle under which
    the point sees the line from the nearer end. Held: error x sin(theta) <= 4e-6 everywhere
    (4e-5 of the field at 1e-3 lengths from the wire's middle), median error <= 5e-7; the far
    field (1e3 lengths, beyond the ends), which the plain cos t1 - cos t2 form would lose to
    1e-4, keeps float32 rounding."""
    rng = np.random.default_rng(5)
    A = np.array([0.3, -0.2, 0.1])
    axis = np.array([1.0, 2.0, 2.0]) / 3.0
    B = A + axis
    u = rng.normal(size=(400, 3))
    u /= np.linalg.norm(u, axis=1)[:, None]
    d = np.geomspace(1e-3, 1e3, 400)
    # half the points about the midpoint, half about tip a: near points lie beside the wire,
    # inside its radius, and beyond an end
    centre = np.where((np.arange(400) % 2 == 0)[:, None], A + 0.5 * axis, A)
    points = centre + d[:, None] * u
    got, f64, ref = one_segment_field(points, A, B, J, w)
    # the float64 kernel is the oracle's law; the oracle's cos t1 - cos t2 loses eps (d / L)^2 to
    # cancellation at d = 1e3 rod lengths beyond an end (2e-10; measured 6.9e-12 at d = 732)
    np.testing.assert_allclose(f64, ref, rtol=1e-9, atol=1e-300)
    rho = np.linalg.norm(points - A - np.outer((points - A) @ axis, axis), axis=1)
    nearer = np.minimum(np.linalg.norm(points - A, axis=1), np.linalg.norm(points - B, axis=1))
    sin = rho / nearer
    err = np.linalg.norm(got - ref, axis=1) / np.linalg.norm(ref, axis=1)
    assert (err * sin).max() <= 4e-6, (err * sin).max()
    assert np.median(err) <= 5e-7
    far = d > 100.0
    assert err[far & (sin > 1e-3)].max() <= 2e-6


@pytest.mark.parametrize("w", [0.0, 0.09])
def test_mixed_law_on_the_axis_and_at_the_ends(w):
    """On a segment end the field is exactly zero (as in float64); on the axis beyond the ends,
    at 1e-3 to 1e3 lengths, it is zero up to float32 rounding of the cross product: with w > 0
    at most 1e-6 of the field |J| |s| / (d (d + |s|)) a point at that distance beside the
    segment's end feels. With w = 0 the law is ill-conditioned on the line in float64 too (the
    oracle gives fields of order 1 at points 1e-17 off it): there both are only finite."""
    A = np.array([0.3, -0.2, 0.1])
    axis = np.array([1.0, 2.0, 2.0]) / 3.0
    B = A + axis
    J = 2.5
    got, _, _ = one_segment_field(np.array([A, B]), A, B, J, w)
    np.testing.assert_array_equal(got, 0.0)
    d = np.geomspace(1e-3, 1e3, 60)
    points = np.vstack([B + d[:, None] * axis, A - d[:, None] * axis])
    got, _, ref = one_segment_field(points, A, B, J, w)
    assert np.all(np.isfinite(got))
    if w == 0.0:
        return
    dd = np.concatenate([d, d])
    side = J / (dd * (dd + 1.0))  # |B| beside the segment's end at distance d, w << d
    assert np.all(np.linalg.norm(got - ref, axis=1) <= 1e-6 * side)


def test_mixed_law_degenerate_inputs_are_finite():
    """A zero-length segment, w = 0 on the line through the segment, the segment's own points:
    finite (zero or small) fields, as the float64 law."""
    A = np.array([0.0, 0.0, 0.0])
    got, _, _ = one_segment_field(np.array([[1.0, 1.0, 0.0], [0.0, 0.0, 0.0]]), A, A, 1.0, 0.0)
    np.testing.assert_array_equal(got, 0.0)
    B = np.array([1.0, 0.0, 0.0])
    got, _, _ = one_segment_field(np.array([[0.5, 0.0, 0.0], [2.0, 0.0, 0.0], [-1.0, 0.0, 0.0]]), A, B, 1.0, 0.0)
    np.testing.assert_array_equal(got, 0.0)


def test_mixed_kernels_with_no_current():
    """No active rod: the field is zero and the tip forces are unchanged."""
    position, charge, current, _ = scene(51)
    empty = np.empty(0, dtype=np.int64)
    out = np.ones_like(position)
    current_force_on_tips_mixed(position, charge, empty, current, 0.03, 0, len(position), out)
    np.testing.assert_array_equal(out, 1.0)
    got = field_mixed(position, np.full(len(position), -1), position, empty, current, 0.03)
    np.testing.assert_array_equal(got, 0.0)


@pytest.mark.parametrize("key", ["current_field", "current_lorentz"])
def test_precision_knob_picks_the_mixed_kernel(key):
    """``precision = "mixed"`` in [forces.current_field] or [forces.current_lorentz]: that term's
    force is the one of the mixed kernel, within float32 rounding of the float64 term; any other
    value is refused naming the key."""
    import tomllib

    from selfas_graph.io.scenario import parameters_from_dict
    from selfas_graph.model.simulation import Simulation

    raw = tomllib.loads(SMALL_CIRCUIT_SCENE)
    forces = {}
    for precision in ("float64", "mixed"):
        raw["forces"][key] = {**raw["forces"][key], "precision": precision}
        sim = Simulation(parameters_from_dict(raw))
        ff = sim.force_field
        rng = np.random.default_rng(3)
        ff.set_currents(rng.uniform(-2.0, 2.0, sim.state.n_rods))
        ff.evaluate(sim.state.position, sim.state.velocity, full=True, step=0)
        forces[precision] = ff.out[key].copy()
    f64, mixed = forces["float64"], forces["mixed"]
    assert np.abs(f64).max() > 1e-3
    assert not np.array_equal(f64, mixed)
    # float32 rounding of sums of 60 fields (module docstring), relative to the largest force
    np.testing.assert_allclose(mixed, f64, rtol=0, atol=1e-5 * np.abs(f64).max())
    raw["forces"][key]["precision"] = "float32"
    with pytest.raises(ValueError, match=f"forces.{key}.precision"):
        parameters_from_dict(raw)


def test_mixed_nan_position_passes_through_to_the_field():
    """As in float64 (tests/physics/test_kernels_currents.py): a NaN target or source coordinate (a run
    gone wrong) gives a NaN field, not a silent zero, so that the health check sees it."""
    position = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 1.0], [np.nan, 0.0, 0.0], [1.0, 0.0, 0.0]])
    charge = np.array([1.0, -1.0, 1.0, -1.0])
    out = np.zeros((4, 3))
    current_force_on_tips_mixed(position, charge, np.array([0], dtype=np.int64), np.array([2.0, 0.0]), 0.03, 0, 4, out)
    assert np.isnan(out[2]).any() and np.all(np.isfinite(out[3]))
    out = np.zeros((4, 3))
    current_force_on_tips_mixed(position, charge, np.array([1], dtype=np.int64), np.array([0.0, 2.0]), 0.03, 0, 4, out)
    assert np.isnan(out[0]).any()
