"""Term 10 near pairs: the quadrature adapted to each pair (docs/model.md 'Term 10',
``forces.current_lorentz.near_range``).

The kernel against a Python oracle written from the rule's description (tests/reference.py),
the rule against the converged integral on the geometries that defeat a fixed Gauss-Legendre
rule (a joint, a crossing, rods lying along each other), and the model term with the knob off
(bit for bit the plain rule) and on.
"""

import numpy as np
import pytest

import reference
from selfas_graph.kernels import cells
from selfas_graph.kernels.currents import rod_current_field
from selfas_graph.kernels.lorentz import (
    NEAR_PANEL_POINTS,
    closest_parameter,
    gauss_legendre_01,
    lorentz_force_on_rods,
    lorentz_near_correction,
    quadrature_points,
)

#: small inputs: also run with NUMBA_DISABLE_JIT=1, the kernels as Python (.ci/run)
pytestmark = pytest.mark.jit_off_ok

W = 0.03  # wire radius of the Fig. 2 rods (D / 2)
PANEL = gauss_legendre_01(NEAR_PANEL_POINTS)


def plain_force(position, active, current, rule, w=W):
    """Term 10 from the rods' own fields by the rule ``(t, wt)`` on every rod (no other sources)."""
    t, wt = rule
    n = len(t)
    pts = np.empty((len(active) * n, 3))
    quadrature_points(position, active, t, pts)
    field = np.empty_like(pts)
    rod_current_field(pts, np.repeat(active, n), position, active, current, w, field)
    out = np.zeros_like(position)
    lorentz_force_on_rods(position, active, current, field, t, wt, out)
    return out


def converged_force(position, active, current, w=W):
    """The same integral by 2048 panels of 4 Gauss-Legendre points: converged to about 1e-12 here
    (a panel of 5e-4 against a peak no narrower than w / 2 = 0.015)."""
    t4, w4 = gauss_legendre_01(4)
    edges = np.linspace(0.0, 1.0, 2049)
    t = np.concatenate([a + (b - a) * t4 for a, b in zip(edges[:-1], edges[1:])])
    wt = np.concatenate([(b - a) * w4 for a, b in zip(edges[:-1], edges[1:])])
    return plain_force(position, active, current, (t, wt), w)


def near_force(position, active, current, near_range, n_gl, w=W, r_lo=0, r_hi=None):
    """The plain rule of n_gl points plus the near correction for pairs closer than near_range."""
    rule = gauss_legendre_01(n_gl)
    out = plain_force(position, active, current, rule, w)
    centre = 0.5 * (position[2 * active] + position[2 * active + 1])
    start, index = cells.neighbour_rows(centre, near_range)
    r_hi = len(active) if r_hi is None else r_hi
    lorentz_near_correction(position, active, current, start, index, r_lo, r_hi, *rule, *PANEL, w, out)
    return out


def rods(*segments):
    return np.ascontiguousarray([p for seg in segments for p in seg], dtype=float)


def test_closest_parameter_matches_the_oracle_and_a_dense_search():
    rng = np.random.default_rng(3)
    for _ in range(200):
        A, s, C, u = rng.normal(size=(4, 3))
        t, d = closest_parameter(*A, *s, *C, *u)
        t_ref, d_ref = reference.closest_parameter(A, s, C, u)
        # the same minimum from two formulas: equal to rounding (1e-12 of the unit lengths)
        assert d == pytest.approx(d_ref, abs=1e-12)
        # the parameter of a minimum is set less sharply than the distance: near-parallel segments move it
        # by round-off over the small curvature of d(t), so 1e-9 (the distance itself is checked to 1e-12)
        assert t == pytest.approx(t_ref, abs=1e-9)
        grid = np.linspace(0, 1, 401)
        dense = np.linalg.norm(A + grid[:, None, None] * s - C - grid[None, :, None] * u, axis=-1).min()
        assert d <= dense + 1e-12  # no sampled pair of points is closer than the minimum


@pytest.mark.parametrize("seed", [0, 1])
def test_near_correction_matches_the_oracle(seed):
    rng = np.random.default_rng(seed)
    n = 12
    centre = rng.uniform(0, 2.0, size=(n, 3))  # dense: most pairs are near
    axis = rng.normal(size=(n, 3))
    axis /= np.linalg.norm(axis, axis=1)[:, None]
    position = np.empty((2 * n, 3))
    position[0::2] = centre - 0.5 * axis
    position[1::2] = centre + 0.5 * axis
    current = rng.uniform(-3, 3, size=n)
    current[[2, 7]] = 0.0
    active = np.flatnonzero(current).astype(np.int64)
    gl_t, gl_w = gauss_legendre_01(2)
    c = 0.5 * (position[2 * active] + position[2 * active + 1])
    start, index = cells.neighbour_rows(c, 1.5)
    out = np.zeros_like(position)
    lorentz_near_correction(position, active, current, start, index, 0, len(active), gl_t, gl_w, *PANEL, W, out)
    rows = {int(active[r]): [int(active[q]) for q in index[start[r] : start[r + 1]]] for r in range(len(active))}
    expect = reference.lorentz_near_correction(position, active, current, rows, gl_t, gl_w, *PANEL, W)
    # the same nodes up to the rounding of t* by two formulas (1e-16 relative), the sums in another
    # order: equal to 1e-10 of the largest tip force
    scale = np.abs(expect).max()
    assert np.abs(out - expect).max() <= 1e-10 * scale
    assert not out[2 * np.array([2, 7])].any()  # rods without current: untouched


JOINT = rods([[0, 0, 0], [1, 0, 0]], [[1.06, 0, 0], [1.06, 1, 0]])  # tips r* = D apart, at a right angle
CROSSING = rods([[0, 0, 0], [1, 0, 0]], [[0.4, -0.5, 0.01], [0.4, 0.5, 0.01]])  # 0.01 apart at t = 0.4
ALONG = rods([[0, 0, 0], [1, 0, 0]], [[0.3, 0.004, 0.0], [1.3, 0.004, 0.0]])  # overlapping, 0.004 apart


@pytest.mark.parametrize("position", [JOINT, CROSSING, ALONG], ids=["joint", "crossing", "along"])
def test_near_rule_converges_where_the_plain_rule_does_not(position):
    active = np.array([0, 1], dtype=np.int64)
    current = np.array([1.5, -2.0])
    exact = converged_force(position, active, current)
    scale = np.abs(exact).max()
    plain = plain_force(position, active, current, gauss_legendre_01(4))
    near = near_force(position, active, current, 2.0, n_gl=2)
    # the fixed 4-point rule misses the peak of the neighbour's field by percents of the force ...
    assert np.abs(plain - exact).max() > 1e-2 * scale
    # ... the adapted panels (each no longer than the distance to the other rod) resolve it: measured
    # 8e-6 (joint), 4e-7 (crossing) and 4e-5 (along) of the largest tip force, against 6 %, 220 %
    # and 20 % for the plain rule; 1e-4 keeps that margin and room for rounding across builds
    assert np.abs(near - exact).max() < 1e-4 * scale


def test_pairs_beyond_the_range_keep_the_plain_rule():
    position = rods([[0, 0, 0], [1, 0, 0]], [[0, 3, 0], [0, 3, 1]])  # centres 3.04 apart
    active = np.array([0, 1], dtype=np.int64)
    current = np.array([1.0, 1.0])
    rule = gauss_legendre_01(2)
    assert np.array_equal(
        near_force(position, active, current, 2.0, n_gl=2), plain_force(position, active, current, rule)
    )


def test_rows_do_not_depend_on_the_range_of_rods():
    position, _, current, active = reference_rods(seed=5, n_rods=14, box=2.5)
    gl = gauss_legendre_01(2)
    c = 0.5 * (position[2 * active] + position[2 * active + 1])
    start, index = cells.neighbour_rows(c, 1.5)

    def correction(r_lo, r_hi):
        out = np.zeros_like(position)
        lorentz_near_correction(position, active, current, start, index, r_lo, r_hi, *gl, *PANEL, W, out)
        return out

    k = len(active) // 2
    # each rod's tips are written by the call that owns the rod alone, the same bits as in one call
    assert np.array_equal(correction(0, k) + correction(k, len(active)), correction(0, len(active)))


def reference_rods(seed, n_rods, box):
    rng = np.random.default_rng(seed)
    centre = rng.uniform(0, box, size=(n_rods, 3))
    axis = rng.normal(size=(n_rods, 3))
    axis /= np.linalg.norm(axis, axis=1)[:, None]
    position = np.empty((2 * n_rods, 3))
    position[0::2] = centre - 0.5 * axis
    position[1::2] = centre + 0.5 * axis
    current = rng.uniform(-3, 3, size=n_rods)
    return position, None, current, np.arange(n_rods, dtype=np.int64)


@pytest.mark.parametrize("w", [0.0, 0.03])
def test_touching_and_coincident_rods_stay_finite(w):
    """Extremes: segments that touch (distance 0), coincide, or meet end to end on one line."""
    touching = rods([[0, 0, 0], [1, 0, 0]], [[0.5, -0.5, 0], [0.5, 0.5, 0]])
    coincident = rods([[0, 0, 0], [1, 0, 0]], [[0, 0, 0], [1, 0, 0]])
    in_line = rods([[0, 0, 0], [1, 0, 0]], [[1, 0, 0], [2, 0, 0]])
    active = np.array([0, 1], dtype=np.int64)
    for position in (touching, coincident, in_line):
        f = near_force(position, active, np.array([1.0, 2.0]), 2.0, n_gl=2, w=w)
        assert np.isfinite(f).all()


def test_nan_positions_end_the_kernel():
    position = rods([[0, 0, 0], [1, 0, 0]], [[0.5, 0.2, 0], [np.nan, 0.5, 0]])
    active = np.array([0, 1], dtype=np.int64)
    start = np.array([0, 1, 2], dtype=np.int64)
    index = np.array([1, 0], dtype=np.int64)
    out = np.zeros_like(position)
    gl = gauss_legendre_01(2)
    # returns (no endless panel loop); the NaN reaches the forces, where the health check stops the run
    lorentz_near_correction(position, active, np.array([1.0, 1.0]), start, index, 0, 2, *gl, *PANEL, W, out)
    assert np.isnan(out).any()
