"""Tests of the rod-current kernels (docs/model.md 'Term 9', 'Term 10').

The oracles (tests/reference.py) are plain numpy / Python loops written from the physics, not from
the kernel code: the segment field in the textbook form (perpendicular foot, cosines
of the end angles), sums with explicit loops, forces with ``np.cross``.
"""

import numpy as np
import pytest
from scipy import integrate

import reference
from selfas_graph.kernels.currents import current_force_on_tips, rod_current_field, segment_field
from selfas_graph.kernels.lorentz import gauss_legendre_01, lorentz_force_on_rods, quadrature_points

#: small inputs: also run with NUMBA_DISABLE_JIT=1, the kernels as Python (.ci/run)
pytestmark = pytest.mark.jit_off_ok


def random_rods(seed, n_rods=40, box=5.0, zero_fraction=0.25):
    """Rods with centres uniform in a box, unit axes uniform on the sphere, random currents.

    About ``zero_fraction`` of the currents are exactly zero; ``active`` lists the others.
    Returns position (2 n_rods, 3), charge (2 n_rods,), current (n_rods,), active (int64).
    """
    rng = np.random.default_rng(seed)
    centre = rng.uniform(-box / 2, box / 2, size=(n_rods, 3))
    axis = rng.normal(size=(n_rods, 3))
    axis /= np.linalg.norm(axis, axis=1)[:, None]
    position = np.empty((2 * n_rods, 3))
    position[0::2] = centre - 0.5 * axis
    position[1::2] = centre + 0.5 * axis
    q = rng.uniform(2 / 3, 2, size=n_rods)
    charge = np.empty(2 * n_rods)
    charge[0::2] = q
    charge[1::2] = -q
    current = rng.uniform(-3, 3, size=n_rods)
    current[rng.random(n_rods) < zero_fraction] = 0.0
    active = np.flatnonzero(current != 0.0).astype(np.int64)
    return position, charge, current, active


def field_call(point, exclude, position, active, current, w):
    out = np.full((len(point), 3), np.nan)  # NaN fill: proves every row is overwritten
    rod_current_field(
        np.ascontiguousarray(point, dtype=float),
        np.asarray(exclude, dtype=np.int64),
        position,
        np.asarray(active, dtype=np.int64),
        current,
        w,
        out,
    )
    return out


def two_rods(A0, B0, A1, B1):
    return np.ascontiguousarray([A0, B0, A1, B1], dtype=float)


EMPTY = np.empty(0, dtype=np.int64)

# ------------------------------------------------------------------------------------
# kernels against oracles on random configurations
# ------------------------------------------------------------------------------------


@pytest.mark.parametrize("w", [0.0, 0.03])
def test_segment_field_matches_oracle(w):
    """The scalar Biot-Savart law equals the textbook finite-wire field at random points."""
    rng = np.random.default_rng(1)
    for _ in range(200):
        x, A, B = rng.uniform(-3, 3, size=(3, 3))
        J = rng.uniform(-3, 3)
        got = np.array(segment_field(*x, *A, *B, J, w))
        ref = reference.segment_field(x, A, B, J, w)
        # the two forms differ only in rounding order; atol covers components that
        # cancel to ~0, at round-off (1e-15) of the field's own magnitude
        np.testing.assert_allclose(got, ref, rtol=1e-12, atol=1e-14 * np.abs(ref).max())


@pytest.mark.parametrize("seed,w", [(11, 0.0), (12, 0.03), (13, 0.5)])
def test_rod_current_field_matches_oracle(seed, w):
    """Total field of 40 random rods (some without current) at tips and random points."""
    position, _, current, active = random_rods(seed)
    rng = np.random.default_rng(seed + 100)
    extra = rng.uniform(-3, 3, size=(30, 3))
    point = np.vstack([position, extra])
    # tips skip their own rod; free points skip a random rod (or none, -1), so that the
    # exclusion is tested where the skipped rod's field is not zero anyway
    exclude = np.concatenate([np.arange(len(position)) // 2, rng.integers(-1, len(current), size=len(extra))])
    got = field_call(point, exclude, position, active, current, w)
    ref = reference.rod_current_field(point, exclude, position, active, current, w)
    # sums of ~30 terms of size up to ~J/w that partly cancel: atol is round-off
    # (1e-13) relative to the largest field in the set
    np.testing.assert_allclose(got, ref, rtol=1e-12, atol=1e-13 * np.abs(ref).max())


@pytest.mark.parametrize("seed,w", [(21, 0.0), (22, 0.03)])
def test_current_force_on_tips_matches_oracle(seed, w):
    """Term 9: F_k += q_k sum_{j != rod(k)} B_seg(x_k; j), added to what is already in out."""
    position, charge, current, active = random_rods(seed)
    n_tips = len(position)
    base = np.random.default_rng(seed).normal(size=(n_tips, 3))
    out = base.copy()
    current_force_on_tips(position, charge, active, current, w, 0, len(position), out)
    ref = reference.rod_current_field(position, np.arange(n_tips) // 2, position, active, current, w)
    ref = base + charge[:, None] * ref
    # see test_rod_current_field_matches_oracle; base is O(1) so round-off of it too
    np.testing.assert_allclose(out, ref, rtol=1e-12, atol=1e-13 * np.abs(ref).max())


@pytest.mark.parametrize("n_gl", [1, 3, 8])
def test_quadrature_points_matches_oracle(n_gl):
    """Quadrature points x_a + t s along every active rod, rod-major."""
    position, _, _, active = random_rods(31)
    t, _ = gauss_legendre_01(n_gl)
    out = np.full((len(active) * n_gl, 3), np.nan)
    quadrature_points(position, active, t, out)
    # coordinates are O(3); atol is a few ulps of that for coordinates near zero
    np.testing.assert_allclose(out, reference.quadrature_points(position, active, t), rtol=1e-12, atol=1e-14)


@pytest.mark.parametrize("n_gl", [1, 4])
def test_lorentz_force_matches_oracle(n_gl):
    """Term 10 with a random field at the nodes: J w_g s x B_g shared (1-t, t), added to out."""
    position, _, current, active = random_rods(41)
    rng = np.random.default_rng(42)
    t, wts = gauss_legendre_01(n_gl)
    field = rng.normal(size=(len(active) * n_gl, 3))
    base = rng.normal(size=position.shape)
    out = base.copy()
    lorentz_force_on_rods(position, active, current, field, t, wts, out)
    ref = base + reference.lorentz_force_on_rods(position, active, current, field, t, wts)
    # forces are O(1..10); atol is round-off of that for components near zero
    np.testing.assert_allclose(out, ref, rtol=1e-12, atol=1e-13)


def test_gauss_legendre_01():
    """Nodes in (0, 1), weights sum to 1, exact for degree 2n-1; n < 1 is an error."""
    for n in (1, 2, 5, 16):
        t, w = gauss_legendre_01(n)
        assert t.shape == w.shape == (n,)
        assert np.all((t > 0) & (t < 1)) and np.all(w > 0)
        for k in range(2 * n):
            # int_0^1 t^k dt = 1 / (k + 1); 1e-14: round-off of a sum of n O(1) terms
            assert abs(np.dot(w, t**k) - 1.0 / (k + 1)) < 1e-14
    for bad in (0, -3):
        with pytest.raises(ValueError, match="at least 1 node"):
            gauss_legendre_01(bad)


# ------------------------------------------------------------------------------------
# physics of the segment field
# ------------------------------------------------------------------------------------


@pytest.mark.parametrize("d", [0.3, 1.0, 3.0])
@pytest.mark.parametrize("J", [1.7, -0.4])
def test_long_segment_is_infinite_wire(d, J):
    """A segment of length 2000 seen from its mid-plane gives 2 J / d along phi_hat.

    The finite-length factor is 1/sqrt(1 + (2d/L)^2) = 1 - O((d/L)^2) <= 1e-5 off.
    """
    L = 2000.0
    A = (0.0, 0.0, -L / 2)
    B = (0.0, 0.0, L / 2)
    for phi in np.linspace(0.0, 2 * np.pi, 7, endpoint=False):
        x = d * np.array([np.cos(phi), np.sin(phi), 0.0])
        got = np.array(segment_field(*x, *A, *B, J, 0.0))
        phi_hat = np.array([-np.sin(phi), np.cos(phi), 0.0])  # right-hand rule about +z
        expected = 2.0 * J / d * phi_hat
        # 1e-5 relative: finite-length correction 2 (d/L)^2 <= 5e-6 at d = 3
        np.testing.assert_allclose(got, expected, rtol=0, atol=1e-5 * abs(2 * J / d))
        # the component along phi_hat carries the sign of J (right-hand rule)
        assert np.sign(np.dot(got, phi_hat)) == np.sign(J)


def test_segment_field_matches_numerical_biot_savart():
    """Closed form equals quad of J dl x r / |r|^3 along the segment (w = 0), off axis."""
    rng = np.random.default_rng(5)
    for _ in range(12):
        A, B = rng.uniform(-1, 1, size=(2, 3))
        J = rng.uniform(0.5, 2.0)
        s = B - A
        # a point at distance >= 0.2 from the segment's line, so the integrand is smooth
        while True:
            x = rng.uniform(-2, 2, size=3)
            a = x - A
            rho = np.linalg.norm(np.cross(s, a)) / np.linalg.norm(s)
            if rho > 0.2:
                break

        def integrand(t, k):
            r = x - (A + t * s)
            return J * np.cross(s, r)[k] / np.linalg.norm(r) ** 3

        ref = np.array(
            [integrate.quad(integrand, 0.0, 1.0, args=(k,), epsabs=0, epsrel=1e-13, limit=200)[0] for k in range(3)]
        )
        got = np.array(segment_field(*x, *A, *B, J, 0.0))
        # quad is converged to ~1e-13 relative (epsrel), the closed form to round-off (measured 7e-16):
        # 1e-12 of |B|, on every component (atol covers a component near zero)
        np.testing.assert_allclose(got, ref, rtol=1e-12, atol=1e-12 * np.linalg.norm(ref))


def test_wire_radius_regularises_near_wire_and_vanishes_far():
    """w > 0: finite field on and near the wire, bounded by J / w; far away -> w = 0 field.

    Only the denominator changes, so B_w / B_0 = rho^2 / (rho^2 + w^2) exactly; the relative
    difference is w^2 / (rho^2 + w^2) ~ (w / rho)^2.
    """
    J, w = 2.0, 0.03
    A = np.array([0.1, -0.2, 0.3])
    s = np.array([0.6, 0.0, 0.8])  # unit length
    B = A + s
    perp = np.array([0.8, 0.0, -0.6])  # unit, perpendicular to s
    # on the line, inside the segment: finite (exactly or nearly zero by symmetry)
    for t in (0.1, 0.5, 0.9):
        got = np.array(segment_field(*(A + t * s), *A, *B, J, w))
        assert np.all(np.isfinite(got))
        assert np.linalg.norm(got) <= abs(J) / w
    # near the wire: the regularised profile 2 J rho / (rho^2 + w^2) <= J / w
    for rho in (1e-12, 1e-6, 1e-3, w, 0.1):
        got = np.array(segment_field(*(A + 0.5 * s + rho * perp), *A, *B, J, w))
        assert np.all(np.isfinite(got))
        # 1e-12: J / w is the analytic maximum (cos difference <= 2); slack is round-off
        assert np.linalg.norm(got) <= abs(J) / w * (1 + 1e-12)
    # with w = 0 the field at rho = 1e-6 is ~ 2 J / rho: the regularisation is what bounds it
    bare = np.array(segment_field(*(A + 0.5 * s + 1e-6 * perp), *A, *B, J, 0.0))
    assert np.linalg.norm(bare) > 1e5
    # far away the relative difference is exactly w^2 / (rho^2 + w^2)
    for rho in (1.0, 3.0, 10.0):
        x = A + 0.3 * s + rho * perp
        with_w = np.array(segment_field(*x, *A, *B, J, w))
        bare = np.array(segment_field(*x, *A, *B, J, 0.0))
        rel = np.linalg.norm(with_w - bare) / np.linalg.norm(bare)
        # both are closed forms: the difference cancels all but (w / rho)^2 >= 9e-6 of the field, so
        # float64 round-off (1e-16) becomes at most ~1e-11 of the ratio; 1e-9 leaves room
        assert rel == pytest.approx(w**2 / (rho**2 + w**2), rel=1e-9)
        assert rel < 1.01 * (w / rho) ** 2


def test_segment_field_degenerate_points_are_finite():
    """On an end (|a| = 0 or |b| = 0), on the line with w = 0, zero length: zero, not NaN."""
    A = (0.0, 0.0, 0.0)
    B = (0.0, 0.0, 1.0)
    for w in (0.0, 0.03):
        for x in (A, B, (0.0, 0.0, 0.5), (0.0, 0.0, 2.0), (0.0, 0.0, -1.0)):
            got = np.array(segment_field(*x, *A, *B, 1.5, w))
            assert np.all(np.isfinite(got))
            if x in (A, B) or w == 0.0:
                assert np.all(got == 0.0)
    got = np.array(segment_field(1.0, 2.0, 3.0, *A, *A, 1.5, 0.0))
    assert np.all(got == 0.0)


def test_nan_position_passes_through_to_the_field():
    """The degenerate cases are selects, not branches: a NaN coordinate (a run gone wrong)
    must still give a NaN field, not a silent zero, so that the health check sees it."""
    got = np.array(segment_field(np.nan, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 1.5, 0.03))
    assert np.isnan(got).any()
    position = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 1.0], [np.nan, 0.0, 0.0], [1.0, 0.0, 0.0]])
    out = np.zeros((4, 3))
    current_force_on_tips(
        position, np.array([1.0, -1.0, 1.0, -1.0]), np.array([0], dtype=np.int64), np.array([2.0, 0.0]), 0.03, 0, 4, out
    )
    assert np.isnan(out[2]).any() and np.all(np.isfinite(out[3]))


# ------------------------------------------------------------------------------------
# physics of the Lorentz force
# ------------------------------------------------------------------------------------


def tip_torque_about_centre(position, force, j):
    """Torque about rod j's centre of the forces on its two tips."""
    xa, xb = position[2 * j], position[2 * j + 1]
    c = 0.5 * (xa + xb)
    return np.cross(xa - c, force[2 * j]) + np.cross(xb - c, force[2 * j + 1])


@pytest.mark.parametrize("n_gl", [1, 2, 3, 7])
def test_lorentz_uniform_field(n_gl):
    """Uniform B: total force J s x B for any n_gl (weights sum to 1), zero torque about centre."""
    rng = np.random.default_rng(50 + n_gl)
    position = rng.uniform(-2, 2, size=(6, 3))
    current = np.array([1.3, -0.7, 2.1])
    active = np.array([0, 2], dtype=np.int64)  # rod 1 has current but is not active
    Bext = np.array([0.3, -1.1, 0.5])
    t, wts = gauss_legendre_01(n_gl)
    field = np.tile(Bext, (len(active) * n_gl, 1))
    out = np.zeros_like(position)
    lorentz_force_on_rods(position, active, current, field, t, wts, out)
    for j in active:
        s = position[2 * j + 1] - position[2 * j]
        F = out[2 * j] + out[2 * j + 1]
        scale = abs(current[j]) * np.linalg.norm(s) ** 2 * np.linalg.norm(Bext)
        # exact up to round-off of sums of n_gl terms of size `scale`
        np.testing.assert_allclose(F, current[j] * np.cross(s, Bext), rtol=0, atol=1e-14 * scale)
        np.testing.assert_allclose(tip_torque_about_centre(position, out, j), 0.0, atol=1e-14 * scale)
    assert np.all(out[2:4] == 0.0)  # inactive rod untouched


@pytest.mark.parametrize("n_gl", [2, 3, 6])
def test_lorentz_linear_field_is_integrated_exactly(n_gl):
    """B = (0, 0, g x): n_gl >= 2 gives the exact force and torque of the continuous current.

    With x(t) = x_a + t s and c the centre: F = J s x B(c) and, since
    B(x(t)) = B(c) + (t - 1/2) g s_x z_hat and int (t - 1/2)^2 dt = 1/12,
    torque about c = J g s_x / 12 * s x (s x z_hat).
    """
    g = 0.7
    xa = np.array([0.4, -0.3, 1.2])
    s = np.array([0.48, 0.6, 0.64])  # unit
    position = np.array([xa, xa + s])
    J = 1.9
    current = np.array([J])
    active = np.array([0], dtype=np.int64)
    t, wts = gauss_legendre_01(n_gl)
    pts = np.empty((n_gl, 3))
    quadrature_points(position, active, t, pts)
    field = np.zeros_like(pts)
    field[:, 2] = g * pts[:, 0]
    out = np.zeros_like(position)
    lorentz_force_on_rods(position, active, current, field, t, wts, out)
    c = xa + 0.5 * s
    zhat = np.array([0.0, 0.0, 1.0])
    F_exact = J * np.cross(s, g * c[0] * zhat)
    tau_exact = J * g * s[0] / 12.0 * np.cross(s, np.cross(s, zhat))
    # the quadrature is exact (degree <= 2 <= 2 n_gl - 1); tolerance is round-off of O(1) sums
    np.testing.assert_allclose(out.sum(axis=0), F_exact, rtol=1e-13, atol=1e-15)
    np.testing.assert_allclose(tip_torque_about_centre(position, out, 0), tau_exact, rtol=1e-13, atol=1e-15)


def parallel_rod_forces(J0, J1, L, d, n_gl, w=0.0):
    """Total force on each of two parallel rods along z at x = 0 and x = d (term 10 pipeline)."""
    position = two_rods((0, 0, -L / 2), (0, 0, L / 2), (d, 0, -L / 2), (d, 0, L / 2))
    current = np.array([J0, J1])
    active = np.array([0, 1], dtype=np.int64)
    t, wts = gauss_legendre_01(n_gl)
    pts = np.empty((2 * n_gl, 3))
    quadrature_points(position, active, t, pts)
    exclude = np.repeat(active, n_gl)  # a rod does not act on itself
    field = field_call(pts, exclude, position, active, current, w)
    out = np.zeros_like(position)
    lorentz_force_on_rods(position, active, current, field, t, wts, out)
    return out[0] + out[1], out[2] + out[3]


def test_parallel_currents_attract_antiparallel_repel():
    """Equal currents attract, opposite currents repel, along the line joining the rods."""
    d = 1.0
    for J0, J1, sign in ((1.0, 1.0, -1), (1.0, -1.0, +1), (-2.0, -0.5, -1)):
        F0, F1 = parallel_rod_forces(J0, J1, L=1.0, d=d, n_gl=8)
        # force on rod 1 (at x = d) points to -x when attracted
        assert np.sign(F1[0]) == sign
        assert np.sign(F0[0]) == -sign
        # purely along x (by symmetry), and opposite on the two rods: round-off of O(1) forces
        np.testing.assert_allclose(F1[1:], 0.0, atol=1e-13)
        np.testing.assert_allclose(F0, -F1, rtol=1e-12, atol=1e-13)


def test_long_parallel_rods_match_infinite_wire_law():
    """Two parallel rods of length 200 at distance 1: |F| ~ 2 J1 J2 L / d.

    The exact finite-wire result is 2 J1 J2 (sqrt(L^2 + d^2) - d) / d, a relative end
    correction d / L = 5e-3, inside the 1e-2 tolerance against the infinite-wire law.
    """
    L, d, J0, J1 = 200.0, 1.0, 1.3, 0.8
    F0, F1 = parallel_rod_forces(J0, J1, L, d, n_gl=64)
    infinite = 2 * J0 * J1 * L / d
    # 1e-2: end effects (d / L = 5e-3) plus quadrature error of the end regions
    assert -F1[0] == pytest.approx(infinite, rel=1e-2)
    assert F0[0] == pytest.approx(infinite, rel=1e-2)
    # and the quadrature follows the exact finite result much more closely (measured
    # 1.6e-8: 64 nodes resolve the O(d) end regions of a rod 200 d long; 1e-6 has margin)
    finite = 2 * J0 * J1 * (np.sqrt(L**2 + d**2) - d) / d
    assert -F1[0] == pytest.approx(finite, rel=1e-6)


# ------------------------------------------------------------------------------------
# bookkeeping: inactive rods, empty lists, own rod
# ------------------------------------------------------------------------------------


def test_inactive_rods_contribute_nothing():
    """Only rods in active_rod act: currents of rods outside it are ignored, zeros add nothing."""
    position, charge, current, active = random_rods(61, zero_fraction=0.0)
    subset = active[::3].copy()
    masked = np.zeros_like(current)
    masked[subset] = current[subset]
    point = np.random.default_rng(62).uniform(-3, 3, size=(20, 3))
    exclude = -np.ones(20, dtype=np.int64)
    all_rods = np.arange(len(current), dtype=np.int64)
    got = field_call(point, exclude, position, subset, current, 0.03)
    ref = field_call(point, exclude, position, all_rods, masked, 0.03)
    # zero-current rods add exact zeros, but summation order differs: round-off only
    np.testing.assert_allclose(got, ref, rtol=1e-13, atol=1e-15)

    out_sub = np.zeros_like(position)
    out_all = np.zeros_like(position)
    current_force_on_tips(position, charge, subset, current, 0.03, 0, len(position), out_sub)
    current_force_on_tips(position, charge, all_rods, masked, 0.03, 0, len(position), out_all)
    np.testing.assert_allclose(out_sub, out_all, rtol=1e-13, atol=1e-15)


def test_empty_active_list():
    """No current-carrying rod: zero field, forces unchanged, no quadrature points, no error."""
    position, charge, current, _ = random_rods(71)
    point = np.ones((5, 3))
    field = field_call(point, -np.ones(5, dtype=np.int64), position, EMPTY, current, 0.03)
    assert np.all(field == 0.0)

    base = np.random.default_rng(72).normal(size=position.shape)
    out = base.copy()
    current_force_on_tips(position, charge, EMPTY, current, 0.03, 0, len(position), out)
    assert np.array_equal(out, base)

    t, wts = gauss_legendre_01(4)
    pts = np.empty((0, 3))
    quadrature_points(position, EMPTY, t, pts)
    lorentz_force_on_rods(position, EMPTY, current, np.empty((0, 3)), t, wts, out)
    assert np.array_equal(out, base)


def test_field_exclusion_skips_only_the_named_rod():
    """exclude_rod[p] removes exactly that rod's field at point p, and nothing else."""
    position, _, current, active = random_rods(81, zero_fraction=0.0)
    x = np.array([[0.2, -0.1, 0.4]])
    full = field_call(x, [-1], position, active, current, 0.03)[0]
    for j in active[:5]:
        own = reference.segment_field(x[0], position[2 * j], position[2 * j + 1], current[j], 0.03)
        got = field_call(x, [j], position, active, current, 0.03)[0]
        # difference of sums of ~40 O(1) terms: round-off relative to the largest term
        np.testing.assert_allclose(got, full - own, rtol=1e-12, atol=1e-13 * np.abs(full).max())
        assert np.linalg.norm(own) > 1e-3  # the skipped term is not negligible


def test_tip_force_skips_own_rod():
    """A single active rod exerts no force on its own tips, but does on other rods' tips."""
    position = two_rods((0, 0, 0), (0, 0, 1), (0.5, 0, 0.5), (0.5, 1, 0.5))
    charge = np.array([1.0, -1.0, 1.5, -1.5])
    current = np.array([2.0, 0.0])
    out = np.zeros_like(position)
    current_force_on_tips(position, charge, np.array([0], dtype=np.int64), current, 0.03, 0, len(position), out)
    assert np.all(out[:2] == 0.0)
    for k in (2, 3):
        expected = charge[k] * reference.segment_field(position[k], position[0], position[1], 2.0, 0.03)
        assert np.linalg.norm(expected) > 0.1
        # same law, different rounding order: round-off of an O(1) value
        np.testing.assert_allclose(out[k], expected, rtol=1e-12, atol=1e-15)


def test_packed_segments_are_the_active_rods_ends_and_currents(rng):
    """Rows A (tip a), B (tip b) and J of each active rod, in the order of ``active_rod``."""
    from selfas_graph.kernels.currents import packed_segments

    position = rng.normal(size=(20, 3))
    current = rng.normal(size=10)
    active = np.array([7, 0, 3], dtype=np.int64)
    seg = packed_segments(position, active, current)
    np.testing.assert_array_equal(seg[0:3], position[2 * active].T)
    np.testing.assert_array_equal(seg[3:6], position[2 * active + 1].T)
    np.testing.assert_array_equal(seg[6], current[active])
