"""Figure diagnostics (docs/model.md 'Figure diagnostics') on hand-made frames with known answers.

Geometry used below: a *ring* is N unit rods forming a regular N-gon of
circumradius ``a = 1 / (2 sin(pi / N))`` in a plane z = z0, each carrying J
counter-clockwise (tip a at vertex k, tip b at vertex k + 1), so B_z > 0 inside.

Exact field of the N-gon on its axis, at height h above its plane (derivation):
each side has half-length ``l = a sin(pi/N)`` and its line lies at distance
``rho = sqrt(p^2 + h^2)`` from the axis point, ``p = a cos(pi/N)`` being the
apothem. The finite-segment law (docs/model.md 'Term 9', wire radius w) gives a field of
magnitude ``J rho (cos t1 - cos t2) / (rho^2 + w^2)`` with
``cos t1 - cos t2 = 2 l / sqrt(l^2 + rho^2)``, perpendicular to the side and to
the perpendicular from the side to the point; its z component is that magnitude
times ``p / rho``. By symmetry the in-plane components of the N sides cancel, so::

    B_z(0, h) = N J (2 l / sqrt(l^2 + rho^2)) p / (rho^2 + w^2).

At h = 0, w = 0 this is ``2 N J tan(pi/N) / a``, which tends to the circular-loop
value ``2 pi J / a`` (reduced units: the field of an infinite wire is 2 J / d) with
relative excess ``tan(x)/x - 1 ~ x^2 / 3``, ``x = pi / N``.

Circular loop of radius a, current J (same units): on the axis
``B_z = 2 pi J a^2 / (a^2 + h^2)^(3/2)``; off the axis, with
``D = (a + rho)^2 + h^2`` and ``m = 4 a rho / D`` (K, E complete elliptic
integrals of parameter m)::

    B_z = (2 J / sqrt(D)) [K(m) + (a^2 - rho^2 - h^2) / ((a - rho)^2 + h^2) E(m)]
    flux through the coaxial disc of radius rho = 2 pi rho A_phi
          = 4 pi J sqrt(D) [(1 - m/2) K(m) - E(m)].

Independent oracle for the flux of any set of straight segments (w = 0): Stokes,
``Phi(R) = closed integral of A . dl`` round the circle of radius R, with the
vector potential of a segment ``A = J s_hat ln((|a| + s_hat.a) / (|b| + s_hat.b))``
(``a = x - A``, ``b = x - B``), from ``A = J int dl / |x - x'|``.
"""

import numpy as np
import pytest
from scipy.special import ellipe, ellipk

from selfas_graph.analysis import (
    auto_n_phi,
    bz_profile,
    disc_flux,
    flux_through_disc,
    radial_density,
    rod_centres,
    timeline,
)
from selfas_graph.model import events as ev

W = 0.03  # wire radius D / 2 of the paper's rods (D/L = 0.06)


# ------------------------------------------------------------------------------------
# hand-made frames and oracles
# ------------------------------------------------------------------------------------
def ring(n, z0=0.0):
    """Tip positions of n unit rods forming a regular n-gon around the z axis; its circumradius."""
    a = 1.0 / (2.0 * np.sin(np.pi / n))
    th = 2.0 * np.pi * np.arange(n + 1) / n
    v = np.stack([a * np.cos(th), a * np.sin(th), np.full(n + 1, z0)], axis=1)
    pos = np.empty((2 * n, 3))
    pos[0::2] = v[:-1]
    pos[1::2] = v[1:]
    return pos, a


def polygon_axis_bz(n, a, h, J, w):
    """Exact B_z of the current n-gon on its axis at height h (module docstring)."""
    p, l = a * np.cos(np.pi / n), a * np.sin(np.pi / n)
    rho2 = p * p + h * h
    return n * J * (2.0 * l / np.sqrt(l * l + rho2)) * p / (rho2 + w * w)


def loop_bz(a, rho, h, J):
    """B_z of a circular current loop of radius a at (rho, h) (module docstring)."""
    D = (a + rho) ** 2 + h**2
    m = 4.0 * a * rho / D
    return 2.0 * J / np.sqrt(D) * (ellipk(m) + (a * a - rho * rho - h * h) / ((a - rho) ** 2 + h * h) * ellipe(m))


def loop_flux(a, R, h, J):
    """Flux of a circular loop of radius a through the coaxial disc of radius R at height h."""
    D = (a + R) ** 2 + h**2
    m = 4.0 * a * R / D
    return 4.0 * np.pi * J * np.sqrt(D) * ((1.0 - m / 2.0) * ellipk(m) - ellipe(m))


def stokes_flux(position, current, R, z0, n_theta=4001):
    """Flux of bare (w = 0) segment currents through a disc: trapezoid rule for the line
    integral of the exact vector potential (module docstring). The integrand is periodic and
    analytic when the circle keeps away from the wires, so the rule converges geometrically;
    n_theta is odd so that it does not alias the N-fold harmonics of a ring with N even."""
    th = 2.0 * np.pi * np.arange(n_theta) / n_theta
    x = np.stack([R * np.cos(th), R * np.sin(th), np.full(n_theta, z0)], axis=1)
    A, B = position[0::2], position[1::2]
    s = B - A
    sh = s / np.linalg.norm(s, axis=1)[:, None]
    a = x[:, None, :] - A[None]
    b = x[:, None, :] - B[None]
    log = np.log((np.linalg.norm(a, axis=2) + (a * sh).sum(2)) / (np.linalg.norm(b, axis=2) + (b * sh).sum(2)))
    vec_pot = (current[None, :, None] * sh[None] * log[:, :, None]).sum(axis=1)
    dl = R * np.stack([-np.sin(th), np.cos(th), np.zeros(n_theta)], axis=1)
    return 2.0 * np.pi * (vec_pot * dl).sum(axis=1).mean()


# ------------------------------------------------------------------------------------
# radial density
# ------------------------------------------------------------------------------------
def test_rods_on_a_cylinder_fill_one_shell():
    """Rod centres on a cylinder of radius 3.3 all fall in the shell [3.0, 3.5): its density is
    count / (pi (3.5^2 - 3^2) (z_hi - z_lo)), every other shell is empty; a mask and the z slab
    select subsets. Tolerance 1e-12: a count divided by a volume, only rounding."""
    rng = np.random.default_rng(7)
    n = 500
    phi = rng.uniform(0.0, 2.0 * np.pi, n)
    z = rng.uniform(-4.0, 4.0, n)
    centre = np.stack([3.3 * np.cos(phi), 3.3 * np.sin(phi), z], axis=1)
    edges, dens = radial_density(centre, r_max=6.0, n_bins=12, z_range=(-5.0, 5.0))
    np.testing.assert_allclose(edges, np.arange(13) * 0.5, rtol=0, atol=1e-15)
    expected = np.zeros(12)
    expected[6] = n / (np.pi * (3.5**2 - 3.0**2) * 10.0)
    np.testing.assert_allclose(dens, expected, rtol=1e-12, atol=0)
    assert np.argmax(dens) == 6

    mask = np.arange(n) % 2 == 0
    _, dens_half = radial_density(centre, 6.0, 12, (-5.0, 5.0), mask=mask)
    np.testing.assert_allclose(dens_half[6], mask.sum() / (np.pi * 3.25 * 10.0), rtol=1e-12)

    # a slab of half the rods' height: only centres with 0 <= z <= 4 count, volume uses dz = 4
    _, dens_slab = radial_density(centre, 6.0, 12, (0.0, 4.0))
    np.testing.assert_allclose(dens_slab[6], (z >= 0).sum() / (np.pi * 3.25 * 4.0), rtol=1e-12)


def test_uniform_points_have_flat_radial_density():
    """Centres uniform in a box [-10, 10]^2 x [-5, 5] have density n / 4000 in every shell inside
    r = 10. Each shell's count is binomial (~Poisson); all 20 stay within 4.5 standard deviations
    (a false alarm has probability ~1e-4 for 20 shells; the seed is fixed anyway), and the
    chi-square over 20 shells lies in its central 99.9 % range (5.9 .. 45.3 for 20 dof)."""
    rng = np.random.default_rng(2024)
    n = 200_000
    centre = rng.uniform([-10.0, -10.0, -5.0], [10.0, 10.0, 5.0], (n, 3))
    edges, dens = radial_density(centre, r_max=10.0, n_bins=20, z_range=(-5.0, 5.0))
    volume = np.pi * np.diff(edges**2) * 10.0
    expected_count = n / 4000.0 * volume
    z_score = (dens * volume - expected_count) / np.sqrt(expected_count)
    assert np.all(np.abs(z_score) < 4.5), z_score
    assert 5.9 < np.sum(z_score**2) < 45.3


def test_rod_centres_are_tip_midpoints():
    """Rod i's centre is the mean of rows 2 i and 2 i + 1 (docs/model.md 'Rods'); exact."""
    pos = np.array([[0.0, 0, 0], [1, 0, 0], [2, 2, 2], [2, 2, 3]])
    np.testing.assert_array_equal(rod_centres(pos), [[0.5, 0, 0], [2, 2, 2.5]])


# ------------------------------------------------------------------------------------
# B_z profile
# ------------------------------------------------------------------------------------
@pytest.mark.parametrize("axis_xy", [(0.0, 0.0), (0.7, -0.4)])
def test_straight_current_along_z_has_no_bz(axis_xy):
    """A long chain of 20 unit rods along a line parallel to z (on the axis or off it) carries
    J = 2.5: its field is azimuthal about the line, so B_z = 0 on every plane z = const and the
    flux through every disc is 0. Exact: the kernel's z component is s_x a_y - s_y a_x with
    s_x = s_y = 0, which is zero in floating point too."""
    n = 20
    z = np.arange(n + 1, dtype=float) - 10.0
    v = np.stack([np.full(n + 1, axis_xy[0]), np.full(n + 1, axis_xy[1]), z], axis=1)
    pos = np.empty((2 * n, 3))
    pos[0::2], pos[1::2] = v[:-1], v[1:]
    current = np.full(n, 2.5)
    r = np.linspace(0.0, 5.0, 11)
    for z_plane in (-3.3, 0.0, 0.5, 9.0):
        assert np.all(bz_profile(r, z_plane, pos, None, current, W, n_phi=64) == 0.0)
        assert np.all(flux_through_disc(r, z_plane, pos, None, current, W, n_phi=64) == 0.0)


@pytest.mark.parametrize("n", [6, 128])
def test_polygon_centre_field_is_exact(n):
    """B_z on the axis of a current N-gon (hexagon of unit rods, a = 1; and N = 128) equals the
    exact finite-segment sum of the module docstring, on the ring's plane and off it, with the
    regularised law (w = D/2). At r = 0 all azimuthal samples are the same point, so the only
    error is rounding: tolerance 1e-12."""
    J = 1.7
    pos, a = ring(n, z0=0.25)
    current = np.full(n, J)
    for h in (0.0, 0.7, -2.0):
        bz = bz_profile([0.0], 0.25 + h, pos, None, current, W)[0]
        np.testing.assert_allclose(bz, polygon_axis_bz(n, a, h, J, W), rtol=1e-12)


def test_large_ring_field_matches_circular_loop():
    """A ring of 128 unit rods (a = 20.4) has, within 1e-3, the field of a circular loop:
    B_z = 2 pi J / a at the centre, 2 pi J a^2 / (a^2 + h^2)^(3/2) on the axis, and the
    elliptic-integral B_z(rho, h) off the axis averaged over azimuth. The polygon differs
    from the circle by O((pi/N)^2): (pi/128)^2 / 3 = 2.0e-4 at the centre. Off the axis the
    points are on the plane h = 2 L above the ring, with the bare wire (w = 0), and keep 3 L
    from the wire radially: the polygon's sides lie on average a (pi/N)^2 / 3 = 0.004 L inside
    the circle, which near the wire, where B_z changes by ~0.5 per L, shifts B_z by 3e-3 of its
    maximum (measured). The azimuthal rule uses n_phi = 127, coprime with the 128-fold symmetry,
    so its mean is exact to rounding (see the flux test below). The tolerance is 1e-3 of the
    largest |B_z| since B_z changes sign near rho = a."""
    n, J = 128, 1.0
    pos, a = ring(n)
    current = np.full(n, J)
    bz0 = bz_profile([0.0], 0.0, pos, None, current, W)[0]
    np.testing.assert_allclose(bz0, 2.0 * np.pi * J / a, rtol=1e-3)
    for h in (0.5 * a, -a):
        np.testing.assert_allclose(
            bz_profile([0.0], h, pos, None, current, W)[0], 2.0 * np.pi * J * a * a / (a * a + h * h) ** 1.5, rtol=1e-3
        )
    rho = np.linspace(0.5, 1.5 * a, 25)
    rho = rho[np.abs(rho - a) > 3.0]
    got = bz_profile(rho, 2.0, pos, None, current, 0.0, n_phi=127)
    want = loop_bz(a, rho, 2.0, J)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-3 * np.abs(want).max())


# ------------------------------------------------------------------------------------
# flux
# ------------------------------------------------------------------------------------
def test_disc_flux_quadrature_is_exact_for_polynomial_fields():
    """The radial rule is Gauss-Legendre on panels: a uniform B gives pi R^2 B and B = r^2 gives
    pi R^4 / 2 (2 pi r B(r) of degree 1 and 3) to rounding, tolerance 1e-13; radii in any order,
    with repeats and R = 0; even one node per panel (the midpoint rule) is exact for the
    uniform field."""
    R = np.array([3.0, 0.0, 1.2, 7.5, 3.0, 0.05])
    B = 0.37
    np.testing.assert_allclose(disc_flux(R, lambda r: np.full_like(r, B)), np.pi * R**2 * B, rtol=1e-13, atol=0)
    np.testing.assert_allclose(
        disc_flux(R, lambda r: np.full_like(r, B), n_r=1, dr_max=10.0), np.pi * R**2 * B, rtol=1e-13, atol=0
    )
    np.testing.assert_allclose(disc_flux(R, lambda r: r**2, n_r=2), np.pi * R**4 / 2, rtol=1e-13, atol=0)
    assert disc_flux([], lambda r: r).shape == (0,)


@pytest.mark.parametrize(
    "R_over_a, z0, rtol, loop_rtol",
    [
        (0.5, 0.0, 1e-12, 1e-3),  # inside the ring, in its plane: integrand smooth on [0, R]
        (0.9, 0.0, 1e-12, 1e-3),  # in the plane, disc edge 2 L from the wire
        (0.99, 0.0, 1e-11, 1e-2),  # in the plane, disc edge 0.2 L from the wire: steep integrand
        (0.5, 1.0, 1e-12, 1e-3),  # a plane 1 L above the ring
        (1.5, 1.0, 1e-12, 1e-3),  # disc wider than the ring, crossing over the wire 1 L below
    ],
)
def test_ring_flux_matches_stokes_oracle_and_loop(R_over_a, z0, rtol, loop_rtol):
    """Flux of a ring of 128 unit rods through discs, with the bare wire (w = 0):
    (1) against the Stokes line integral of the ring's exact vector potential (module docstring),
    which checks the radial quadrature; with the radial defaults (8 nodes per 0.25 L) it
    is exact to rounding (measured <= 4e-15) unless the disc edge comes close to the wire in
    its plane (2e-12 at 0.2 L); tolerances are these with a margin. The azimuthal rule uses
    n_phi = 127, coprime with the ring's 128-fold symmetry: the field on a circle has only
    harmonics that are multiples of 128, and the first one the rule aliases is the 16256th, so
    the azimuthal mean is exact to rounding (n_phi = 64 would alias the 128th harmonic: error
    2e-10 at R = 0.9 a, 7e-5 on the disc wider than the ring);
    (2) against the circular loop's flux, within 1e-3 (the polygon/circle difference, measured
    2.5e-4 .. 7e-4), or 1e-2 with the disc edge 0.2 L from the wire, where the polygon's sides,
    on average 0.004 L inside the circle, make a 4e-3 difference (measured);
    (3) in units of Phi_0 = 4 pi, and of an external dipole's 4 pi Z_Mext."""
    n, J = 128, 1.0
    pos, a = ring(n)
    current = np.full(n, J)
    R = R_over_a * a
    flux = flux_through_disc([R], z0, pos, None, current, 0.0, n_phi=127)[0] * 4.0 * np.pi
    np.testing.assert_allclose(flux, stokes_flux(pos, current, R, z0), rtol=rtol)
    np.testing.assert_allclose(flux, loop_flux(a, R, z0, J), rtol=loop_rtol)
    in_ext = flux_through_disc([R], z0, pos, None, current, 0.0, n_phi=127, z_mext=10.0)[0]
    np.testing.assert_allclose(in_ext, flux / (4.0 * np.pi * 10.0), rtol=1e-14)


def test_small_disc_flux_is_area_times_central_field():
    """For a disc of radius R << a at the ring's centre the field is nearly uniform:
    flux = pi R^2 B_z(0) (1 + O((R/a)^2)); with R = 0.1, a = 20.4 the relative correction is
    ~ (3/4)(R/a)^2 ~ 2e-5 (the loop's B_z grows as 1 + (3/4) rho^2/a^2 near the centre):
    tolerance 1e-4."""
    n, J = 128, 1.0
    pos, a = ring(n)
    current = np.full(n, J)
    bz0 = bz_profile([0.0], 0.0, pos, None, current, W)[0]
    flux = flux_through_disc([0.1], 0.0, pos, None, current, W)[0] * 4.0 * np.pi
    np.testing.assert_allclose(flux, np.pi * 0.01 * bz0, rtol=1e-4)


def test_auto_n_phi_spaces_samples_by_the_wire_radius():
    """The automatic azimuthal sampling puts samples at most one wire radius apart on the largest
    circle, at least 64, rounded up to a multiple of 64: 2 pi 7 / 0.03 = 1466 -> 1472."""
    assert auto_n_phi(7.0, 0.03) == 1472
    assert auto_n_phi(0.0, 0.03) == 64
    assert auto_n_phi(1.0, 0.0) == auto_n_phi(1.0, 0.03)


def test_field_inputs_are_validated():
    """Shapes and indices are checked before the numba kernel (which does not bounds-check)."""
    pos, _ = ring(6)
    current = np.ones(6)
    with pytest.raises(ValueError, match="n_tips"):
        bz_profile([1.0], 0.0, pos[:-1], None, current, W)
    with pytest.raises(ValueError, match="current"):
        bz_profile([1.0], 0.0, pos, None, current[:-1], W)
    with pytest.raises(ValueError, match="outside"):
        bz_profile([1.0], 0.0, pos, [0, 6], current, W)
    with pytest.raises(ValueError, match="distinct"):
        bz_profile([1.0], 0.0, pos, [1, 1], current, W)
    with pytest.raises(ValueError, match="points_r"):
        bz_profile([-1.0], 0.0, pos, None, current, W)
    with pytest.raises(ValueError, match="z_range"):
        radial_density(np.zeros((3, 3)), 1.0, 4, (1.0, 1.0))
    # a mask or float indices would be cast to rod numbers 0 and 1 without a word
    with pytest.raises(TypeError, match="not a mask"):
        bz_profile([1.0], 0.0, pos, current > 0, current, W)
    with pytest.raises(TypeError, match="integer rod indices"):
        bz_profile([1.0], 0.0, pos, [0.0, 1.5], current, W)
    for n_bins in (3.5, True):
        with pytest.raises(TypeError, match="n_bins must be a whole number"):
            radial_density(np.zeros((3, 3)), 1.0, n_bins, (0.0, 1.0))
    # rods without current: no field, and no kernel call
    assert np.all(bz_profile([0.0, 1.0], 0.0, pos, None, np.zeros(6), W) == 0.0)


# ------------------------------------------------------------------------------------
# timeline
# ------------------------------------------------------------------------------------
def test_timeline_takes_first_short_circuit():
    """The short-circuit time is the time of the first SHORT_CIRCUIT event (an OPEN_CIRCUIT
    and a second closing do not move it); none without such an event. Exact."""
    t = np.array([0.0, 0.5, 1.0, 1.5, 2.0])
    n_fil = np.array([0, 0, 0, 45, 45])
    current = np.array([0, 0, 0, 0.57, 2.9])
    events = ev.event_array(
        [
            (100, 0.05, ev.TIP_CONTACT, 0, 3),
            (2529, 1.2645, ev.SHORT_CIRCUIT, 21, -1),
            (2900, 1.45, ev.OPEN_CIRCUIT, -1, -1),
            (3000, 1.5, ev.SHORT_CIRCUIT, 30, -1),
        ]
    )
    tl = timeline(t, n_fil, current, events)
    assert tl.short_circuit_time == 1.2645
    np.testing.assert_array_equal(tl.n_filament, n_fil)
    np.testing.assert_array_equal(tl.total_current, current)
    assert timeline(t, n_fil, None, events[:1]).short_circuit_time is None
    assert timeline(t, n_fil).total_current is None
    with pytest.raises(ValueError):
        timeline(t, n_fil[:-1])


def test_flux_through_rim_is_the_disc_flux_of_the_same_currents():
    """Stokes: the rim integral of the rods' vector potential is the area integral of the bare line
    currents' field (wire radius 0): to 1e-10 of the flux where no rod crosses the plane (both
    quadratures converge to round-off there; measured 1e-15). Term 9's law is that field times
    rho^2 / (rho^2 + w^2), so against it (w = 0.03) the two differ by (w / rho)^2 near each wire:
    within 1e-3 with every rod at least 0.2 L from the plane (measured 1.4e-4), within 3e-3 for
    random tangles of rods crossing it (measured 1e-3)."""
    from selfas_graph.analysis.diagnostics import flux_through_disc, flux_through_rim

    rng = np.random.default_rng(11)
    for crossing, tol in ((False, 1e-3), (True, 3e-3)):
        for _ in range(3):
            centres = rng.uniform(-2.0, 2.0, (40, 3)) * [1, 1, 0.5]
            axis = rng.normal(size=(40, 3))
            axis /= np.linalg.norm(axis, axis=1)[:, None]
            if not crossing:  # rods lying flat-ish, every tip at least 0.2 above or below the plane
                axis[:, 2] *= 0.2
                axis /= np.linalg.norm(axis, axis=1)[:, None]
                centres[:, 2] = np.sign(centres[:, 2] - 0.1) * (0.5 + np.abs(centres[:, 2])) + 0.1
            pos = np.empty((80, 3))
            pos[0::2], pos[1::2] = centres - 0.5 * axis, centres + 0.5 * axis
            cur = rng.uniform(-1.0, 1.0, 40)
            disc = flux_through_disc([3.5], 0.1, pos, None, cur, 0.03)[0]
            rim = flux_through_rim(3.5, 0.1, pos, None, cur, 0.03)
            assert abs(rim - disc) <= tol * max(abs(disc), 1e-2), (crossing, rim, disc)
            if not crossing:
                bare = flux_through_disc([3.5], 0.1, pos, None, cur, 0.0, dr_max=0.1)[0]
                assert abs(rim - bare) <= 1e-10 * abs(bare), (rim, bare)


def test_flux_through_rim_of_simple_currents():
    """A wire along the axis has no flux through a disc about it (A along z, the rim in the plane);
    reversing every current reverses the flux; no current, no flux; a rod crossing the rim stays finite."""
    from selfas_graph.analysis.diagnostics import flux_through_rim

    axial = np.array([[0.0, 0.0, -0.5], [0.0, 0.0, 0.5]])
    assert flux_through_rim(2.0, 0.0, axial, None, np.array([3.0]), 0.03) == 0.0
    square = np.array([[1, -1, 0], [1, 1, 0], [1, 1, 0], [-1, 1, 0], [-1, 1, 0], [-1, -1, 0], [-1, -1, 0], [1, -1, 0]])
    square = square.astype(float) * 0.5 + [0, 0, 0.3]
    phi = flux_through_rim(2.0, 0.0, square, None, np.ones(4), 0.03)
    assert phi != 0.0 and flux_through_rim(2.0, 0.0, square, None, -np.ones(4), 0.03) == pytest.approx(-phi, rel=1e-14)
    assert flux_through_rim(2.0, 0.0, square, None, np.zeros(4), 0.03) == 0.0
    crossing = np.array([[2.0, -0.5, 0.0], [2.0, 0.5, 0.0]])
    assert np.isfinite(flux_through_rim(2.0, 0.0, crossing, None, np.array([1.0]), 0.03))
