"""Fractal dimensions on objects of known dimension at the sizes of the runs (docs/model.md "Measures of the paper's claims").

The objects are built of 100-3000 unit rods that touch tip to tip, as the structures of the
Fig. 2 and Fig. 6 runs are, and are turned to a random orientation (fixed seed) so that no
lattice lines up with anything: straight chains (D = 1), random planar lattice networks
(D = 2), a network on a cylinder around an empty axis (D = 2, its centre of mass in the
hole, as a network wound about the plasma axis), compact 3-D blobs (on a lattice, and grown
off-lattice at random: D = 3), lattice random walks (D = 2), off-lattice diffusion-limited
aggregates of rods (DLA, D = 2.5 in 3-D) and a compact core with long straight branches (no
single dimension: it must stay between 1 and 3).

The tolerances and why:

- Every estimate: D <= 3 + its stated uncertainty (no set in 3-D has a larger dimension).
- Chains, planar networks, the cylinder, lattice blobs: within the fit's stated uncertainty
  ``err`` plus 0.05 (exact objects; 0.05 for the steps of counting a few thousand points).
- Compact blobs grown at random (a rough surface 1-2 L deep on a 4.5-5.4 L radius, whose
  density therefore still falls outwards): D in [2.6, 3 + err]. Measured: 2.68 and 2.78.
- Random walks: their "D = 2" is a mean over walks; one walk of 1000-3000 steps gives a slope
  that scatters by about 0.2 from walk to walk (measured 1.64-2.04 over four walks), so the mean
  of four walks is asked to be within 0.3 of 2 and each walk within 0.5.
- DLA of 1000-2000 rods: 2.5 within 0.4. The local slope of M(r) rises from 1 below one rod
  length to about 2.4 only at r ~ R_g (measured 2.2-2.3 over r = 1..R_g): the rod scale
  pulls a fit at these sizes low; this is the bias a result at these sizes carries.
"""

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.csgraph as csgraph
from scipy.spatial import cKDTree

from selfas_graph.analysis.fractal import (
    MIN_RANGE,
    box_dimension,
    mass_radius_dimension,
    radius_of_gyration,
    rg_dimension,
)

ROUND_OFF = 1e-9  # sums of a few thousand unit-size terms


def rods(a, b):
    """(n_tips, 3) positions of rods from tip a to tip b."""
    a, b = np.asarray(a, float).reshape(-1, 3), np.asarray(b, float).reshape(-1, 3)
    pos = np.empty((2 * len(a), 3))
    pos[0::2], pos[1::2] = a, b
    return pos


def turned(pos, seed=3):
    q, _ = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))
    return pos @ q.T


def chain(n):
    p = np.arange(n + 1.0)[:, None] * np.array([1.0, 0.0, 0.0])
    return rods(p[:-1], p[1:])


def lattice_network(inside, p=0.8, seed=1):
    """Lattice edges between the nodes where ``inside`` (2-D or 3-D bool array), each kept with
    probability p; the largest connected piece."""
    rng = np.random.default_rng(seed)
    dim = inside.ndim
    nodes = np.argwhere(inside)
    index = {tuple(x): i for i, x in enumerate(nodes)}
    ea, eb = [], []
    for x in nodes:
        for d in range(dim):
            y = x.copy()
            y[d] += 1
            if tuple(y) in index and rng.random() < p:
                ea.append(index[tuple(x)])
                eb.append(index[tuple(y)])
    ea, eb = np.array(ea), np.array(eb)
    n = len(nodes)
    _, label = csgraph.connected_components(sp.coo_matrix((np.ones(len(ea)), (ea, eb)), shape=(n, n)), directed=False)
    keep = label[ea] == np.bincount(label[ea]).argmax()
    xyz = np.zeros((n, 3))
    xyz[:, :dim] = nodes
    return rods(xyz[ea[keep]], xyz[eb[keep]])


def sheet(side, seed=1):
    return lattice_network(np.ones((side, side), bool), seed=seed)


def lattice_ball(radius, p=0.8):
    g = np.indices((2 * radius + 1,) * 3) - radius
    return lattice_network((g**2).sum(axis=0) <= radius * radius, p=p)


def cylinder(radius=6.0, height=40, seed=1):
    """A lattice network on a cylinder about the z axis: rods round it and along it, each kept with p = 0.8."""
    n_phi = int(round(2 * np.pi * radius))
    rr = 0.5 / np.sin(np.pi / n_phi)  # unit rods round the circle
    phi = 2 * np.pi * np.arange(n_phi + 1) / n_phi
    ring = np.column_stack([rr * np.cos(phi), rr * np.sin(phi), 0 * phi])
    rng = np.random.default_rng(seed)
    a, b = [], []
    for z in range(height):
        for i in range(n_phi):
            p = ring[i] + [0, 0, z]
            if rng.random() < 0.8:
                a.append(p), b.append(ring[i + 1] + [0, 0, z])
            if z + 1 < height and rng.random() < 0.8:
                a.append(p), b.append(p + [0, 0, 1])
    return rods(a, b)


def random_walk(n, seed):
    rng = np.random.default_rng(seed)
    step = np.eye(3)[rng.integers(0, 3, n)] * rng.choice([-1.0, 1.0], n)[:, None]
    p = np.vstack([np.zeros(3), np.cumsum(step, axis=0)])
    return rods(p[:-1], p[1:])


def _unit(rng):
    v = rng.normal(size=3)
    return v / np.linalg.norm(v)


def grown(n, seed, sticky):
    """Rods grown one at a time from tips of the cluster, each new tip at least 0.6 L from every other tip.

    ``sticky=False``: an Eden blob (a random tip of the cluster grows a rod in a random
    direction: compact, D = 3). ``sticky=True``: diffusion-limited aggregation, off-lattice
    (a random walker from far away sticks, by a unit rod, to the first cluster tip it comes
    within one rod length of: D = 2.5)."""
    rng = np.random.default_rng(seed)
    pts, a, b = [np.zeros(3)], [], []
    tree, n_tree, r_c = cKDTree(pts), 1, 0.0

    def nearest(x):
        d, j = tree.query(x)
        if n_tree < len(pts):
            dr = np.linalg.norm(np.array(pts[n_tree:]) - x, axis=1)
            k = int(dr.argmin())
            if dr[k] < d:
                d, j = dr[k], n_tree + k
        return d, j

    while len(a) < n:
        if sticky:  # walk with steps as long as the free space around the walker allows
            x = (r_c + 3.0) * _unit(rng)
            while True:
                r = np.linalg.norm(x)
                if r > 4 * r_c + 30:
                    x = (r_c + 3.0) * _unit(rng)
                elif r > r_c + 3.0:
                    x = x + (r - r_c - 2.0) * _unit(rng)
                else:
                    d, j = nearest(x)
                    if d <= 1.02:
                        y = pts[j] + (x - pts[j]) / np.linalg.norm(x - pts[j])
                        break
                    x = x + max(d - 1.0, 0.02) * _unit(rng)
        else:
            j = int(rng.integers(len(pts)))
            y = pts[j] + _unit(rng)
            if nearest(y)[0] < 0.6:
                continue
        a.append(pts[j]), b.append(y), pts.append(y)
        r_c = max(r_c, float(np.linalg.norm(y)))
        if len(pts) > 1.2 * n_tree + 10:
            tree, n_tree = cKDTree(pts), len(pts)
    return rods(a, b)


def core_with_branches(radius=4, n_branches=8, length=150, seed=2):
    """A full cubic-lattice ball (compact core) with straight chains of ``length`` rods leaving it radially."""
    rng = np.random.default_rng(seed)
    parts = [lattice_ball(radius, p=1.0)]
    for _ in range(n_branches):
        v = _unit(rng)
        p = v * radius + np.arange(length + 1.0)[:, None] * v
        parts.append(rods(p[:-1], p[1:]))
    return np.vstack(parts)


@pytest.fixture(scope="module")
def dla():
    return grown(2000, seed=1, sticky=True)  # about 3 s


@pytest.fixture(scope="module")
def eden():
    return grown(2000, seed=1, sticky=False)


def exact(fit, anchor):
    """Within the fit's own uncertainty plus 0.05 (steps of counting points)."""
    assert np.isfinite(fit.value) and np.isfinite(fit.err) and np.isfinite(fit.se), fit
    assert abs(fit.value - anchor) <= fit.err + 0.05, fit
    assert fit.fit_range[0] >= 1.0 - ROUND_OFF  # nothing below one rod length
    assert fit.fit_range[1] >= MIN_RANGE * fit.fit_range[0] - ROUND_OFF  # the stated minimum range


def at_most_three(fit):
    assert not fit.value > 3.0 + fit.err, fit  # NaN passes: refused is allowed


# ----------------------------------------------------------------------------- mass-radius
@pytest.mark.parametrize(
    "make, anchor",
    [
        (lambda: chain(300), 1),
        (lambda: chain(3000), 1),
        (lambda: sheet(20), 2),  # 600 rods, R_g 7.9 L
        (lambda: sheet(30), 2),  # 1400 rods
        (lambda: cylinder(), 2),  # 2400 rods round an empty axis
        (lambda: lattice_ball(6), 3),  # 1950 rods, R_g 4.5 L
        (lambda: lattice_ball(8), 3),  # 4600 rods
    ],
)
def test_mass_radius_recovers_exact_objects(make, anchor):
    """Chains, planar networks (also wound round an empty axis) and lattice blobs give 1, 2, 3."""
    fit = mass_radius_dimension(turned(make()))
    exact(fit, anchor)
    at_most_three(fit)


def test_mass_radius_of_compact_random_blobs(eden):
    """Off-lattice compact blobs of 1000 and 2000 rods: near 3, never above (their rough surface pulls low)."""
    for n in (1000, 2000):
        fit = mass_radius_dimension(turned(eden[: 2 * n]))
        assert 2.6 <= fit.value <= 3.0 + fit.err, fit


def test_mass_radius_of_random_walks():
    """Lattice random walks (D = 2), whose centre of mass is usually off the walk."""
    fits = [
        mass_radius_dimension(turned(random_walk(n, seed))) for n, seed in ((1000, 1), (3000, 1), (3000, 7), (2000, 4))
    ]
    values = np.array([f.value for f in fits])
    assert np.all(np.abs(values - 2.0) <= 0.5), fits  # one walk scatters by ~0.2 (module notes)
    assert abs(values.mean() - 2.0) <= 0.3, values
    for f in fits:
        at_most_three(f)


def test_mass_radius_of_dla(dla):
    """Off-lattice DLA of 1000-2000 rods: 2.5 within 0.4 (the rod-scale crossover pulls low)."""
    for n in (1000, 2000):
        fit = mass_radius_dimension(turned(dla[: 2 * n]))
        assert abs(fit.value - 2.5) <= 0.4, fit
        at_most_three(fit)


def test_mass_radius_of_a_core_with_branches():
    """A compact core with long straight branches has no single dimension: between 1 and 3."""
    fit = mass_radius_dimension(turned(core_with_branches()))
    assert 1.0 - fit.err <= fit.value <= 3.0 + fit.err, fit


def test_a_hole_at_the_centre_of_mass_gives_no_dimension_above_three():
    """The cause of D > 3 up to 0.3.0: counts about a centre of mass in a hole (a ring of
    blobs, a cylinder) rose faster than r^3. About centres on the structure they do not; a
    ring with no point within R_g / 2 of its centre of mass is refused (NaN)."""
    ring_of_blobs = np.vstack(
        [lattice_ball(2, p=1.0) + [12 * np.cos(t), 12 * np.sin(t), 0] for t in np.linspace(0, 2 * np.pi, 9)[:-1]]
    )
    for pos in (cylinder(), cylinder(radius=10, height=12), ring_of_blobs):
        at_most_three(mass_radius_dimension(turned(pos)))


def test_too_small_structures_are_not_testable():
    """R_g below MIN_RANGE rod lengths, or fewer than 30 rods: NaN with the reason."""
    for pos in (chain(10), lattice_ball(3)):  # 10 rods; 380 rods with R_g 2.3 L
        fit = mass_radius_dimension(pos)
        assert np.isnan(fit.value) and np.isnan(fit.err) and np.isnan(fit.se) and fit.note, fit
    assert "not testable" in mass_radius_dimension(lattice_ball(3)).note


# ----------------------------------------------------------------------------- R_g over structures
SIZES = (3, 5, 8, 13, 21, 34, 55, 89, 144, 233, 377, 610, 1000, 1600)


def _over(pieces):
    rg, size = zip(*[(g[0], s[0]) for g, s in (radius_of_gyration(p) for p in pieces)])
    return np.array(size), np.array(rg)


def test_rg_dimension_of_chains_sheets_and_dla(dla):
    """Chains 1 and sheets 2 within err + 0.05; DLA clusters of 3-1600 rods (every prefix of a DLA
    cluster is one) between 1.8 and 2.75, and 2.5 within two of the fit's own errors, below 0.6. The
    walk that grows the cluster is chaotic: the last bits of numpy's sums differ between CPUs, so each
    CPU grows another cluster, and the bounds are set by the scatter between clusters. Measured on an
    Intel Xeon: 2.19 +- 0.41 for this cluster (seed 1), 2.13-2.47 over seeds 1-8 (mean 2.28, standard
    deviation 0.12, fit errors 0.11-0.91); 2.06 +- 0.42 on an AMD EPYC Zen 5. The rod-scale crossover
    pulls every one below the 2.5 of large DLA. The bounds lie four standard deviations from that mean,
    0.26 below the lowest value seen and 0.28 above the highest (2, the sheet's, would be 0.06 from the
    AMD value). The error-relative check alone accepts a compact object (3) whose fit is clean: the
    clusters of seeds 6 and 8 with R_g rescaled to give D = 2.94 +- 0.53 and 2.96 +- 0.27 pass it, and
    fail the upper bound. Chains (1) and compact blobs (3; the Eden blobs here give 3.6) lie outside
    the bounds; a sheet (2) inside: at these sizes the R_g dimension does not tell DLA from a sheet."""
    exact(rg_dimension(*_over([chain(n) for n in SIZES])), 1)
    exact(rg_dimension(*_over([sheet(s) for s in (4, 6, 8, 11, 16, 23, 30)])), 2)
    fit = rg_dimension(*_over([dla[: 2 * n] for n in SIZES]))
    assert 1.8 <= fit.value <= 2.75 and abs(fit.value - 2.5) <= 2 * fit.err and fit.err < 0.6, fit
    assert fit.fit_range[0] >= 3, fit


def test_rg_dimension_refuses_a_range_under_the_minimum(eden):
    """Compact random blobs of 3-1600 rods (R_g 0.8-5.1 L; those with R_g >= 1 L span a factor 4.06)
    whose density still grows with size: not above 3 by more than the uncertainty (measured
    3.6 +- 0.7); the blobs up to 300 rods span R_g 1.25-3.2 L, under the minimum: NaN, not testable."""
    size, rg = _over([eden[: 2 * n] for n in SIZES])
    fit = rg_dimension(size, rg)
    assert np.isnan(fit.value) or fit.value <= 3.0 + fit.err, fit
    small = rg_dimension(size[size <= 300], rg[size <= 300])
    assert np.isnan(small.value) and "not testable" in small.note, small


# ----------------------------------------------------------------------------- box counting
def test_box_counting_is_biased_low_at_these_sizes(dla):
    """Why the box-counting dimension is no claim measure: exact on a chain, but below 2 - 0.15 on a
    1400-rod sheet and below 2.5 - 0.4 on a 2000-rod DLA, outside its own uncertainty on the sheet."""
    exact(box_dimension(turned(chain(300))), 1)
    sheet_fit = box_dimension(turned(sheet(30)))
    assert sheet_fit.value < 1.85 and sheet_fit.value + sheet_fit.err < 2.0, sheet_fit
    assert box_dimension(turned(dla)).value < 2.1


def test_rod_points_are_spread_by_length_so_their_count_is_rod_length():
    """Rods of length 1, 2 and 0.5 L get 8, 16 and 4 points (per_rod = 8 per L), evenly at the middles of
    their pieces: counts of points over 8 are rod lengths also where the rods' lengths differ. For rods
    of length 1 the points are those of per_rod equal pieces, bit for bit."""
    from selfas_graph.analysis.fractal import rod_points

    tips = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 3, 0], [0, 0, 5], [0, 0, 5.5]], dtype=np.float64)
    x = rod_points(tips)
    assert x.shape == (28, 3)
    assert np.allclose(x[:8, 0], (np.arange(8) + 0.5) / 8) and np.allclose(x[8:24, 1], 1 + (np.arange(16) + 0.5) / 8)
    assert np.allclose(x[24:, 2], 5 + (np.arange(4) + 0.5) / 8)
    rng = np.random.default_rng(3)
    u = rng.normal(size=(50, 3))
    u /= np.linalg.norm(u, axis=1)[:, None]
    c = rng.uniform(-3, 3, (50, 3))
    unit = np.empty((100, 3))
    unit[0::2], unit[1::2] = c - 0.5 * u, c + 0.5 * u
    t = (np.arange(8) + 0.5) / 8
    pieces = (unit[0::2][:, None, :] + t[None, :, None] * (unit[1::2] - unit[0::2])[:, None, :]).reshape(-1, 3)
    assert np.array_equal(rod_points(unit), pieces)
