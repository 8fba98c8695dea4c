"""The multipole tree for the tip-tip force (kernels/tree.py) against the direct sum.

The oracle is ``tip_tip_direct`` (itself checked against tests/reference.py in
test_kernels.py). Errors are per tip, ``|F_tree - F_direct| / |F_direct|``,
summarised by the median and the 99th percentile; each bound is about twice
the value measured with the fixed seeds here (noted beside it), so that the
tests catch a lost order of accuracy but not a change of round-off.
"""

import math

import numpy as np
import pytest

from selfas_graph.kernels.tips import tip_tip_direct
from selfas_graph.kernels.tree import build_tip_tree, evaluate_tip_tree, tip_tip_tree
from selfas_graph.model.state import State

RSTAR, KAPPA = 0.06, 1.0


def rods_to_tips(centre, axis, q):
    """SoA tips (x, y, z, charge) of unit rods; tip a = centre - axis/2 carries +q."""
    state = State.from_rods(centre, axis, q, np.zeros(len(q)))
    return (*(np.ascontiguousarray(state.position[:, d]) for d in range(3)), state.tip_charge)


def uniform_rods(n_rods, rng, density=0.19):
    """Rods uniform in a cube at the Fig. 2 density (rods per unit volume)."""
    side = (n_rods / density) ** (1 / 3)
    return rods_to_tips(rng.uniform(0, side, (n_rods, 3)), rng.normal(size=(n_rods, 3)), rng.uniform(2 / 3, 2, n_rods))


def chain_rods(n_chains, length, rng, n_clusters=3, spread=4.0):
    """Aggregates: chains of rods joined tip to tip (tip b of one rod r*/2 from tip a
    of the next, the rest distance of opposite tips), gathered around a few centres."""
    hub = rng.uniform(-15, 15, (n_clusters, 3))
    centre, axis, q = [], [], []
    for c in range(n_chains):
        tip = hub[c % n_clusters] + rng.normal(scale=spread, size=3)
        d = rng.normal(size=3)
        for _ in range(length):
            d = d / np.linalg.norm(d) + 0.4 * rng.normal(size=3)  # a wiggly chain
            d /= np.linalg.norm(d)
            centre.append(tip + d / 2)
            axis.append(d)
            q.append(rng.uniform(2 / 3, 2))
            tip = tip + d * (1 + RSTAR / 2)
    return rods_to_tips(np.array(centre), np.array(axis), np.array(q))


def direct(x, y, z, charge):
    out = np.empty((len(x), 3))
    tip_tip_direct(x, y, z, charge, RSTAR, KAPPA, 0, len(x), out)
    return out


def tree(x, y, z, charge, theta, **knobs):
    out = np.empty((len(x), 3))
    return tip_tip_tree(x, y, z, charge, RSTAR, KAPPA, theta, out, **knobs)


def relative_error(actual, expected):
    return np.linalg.norm(actual - expected, axis=1) / np.linalg.norm(expected, axis=1)


def close(actual, expected):
    """Equal to round-off: as test_kernels.close (sums of many terms of both signs)."""
    scale = np.abs(expected).max(initial=0.0)
    np.testing.assert_allclose(actual, expected, rtol=1e-12, atol=1e-12 * scale)


@pytest.fixture(scope="module")
def uniform():
    return uniform_rods(1500, np.random.default_rng(7))


@pytest.fixture(scope="module")
def chains():
    return chain_rods(60, 25, np.random.default_rng(8))


# measured (median, p99) with these seeds, hexadecapoles, leaves of 64 and groups of 128 (GROUPS; the
# bounds date from octupoles, which erred up to 3 times more; the default groups of 1024 hold a third
# of these 3000 tips each and err 3 to 15 times less, too little left to fall with theta):
# uniform  0.7: (9.5e-4, 1.5e-2)  0.5: (4.9e-4, 7.3e-3)  0.3: (2.0e-5, 2.8e-4)
# chains   0.7: (1.2e-5, 2.0e-3)  0.5: (3.6e-6, 4.3e-4)  0.3: (2.0e-7, 3.0e-5)
# (in aggregates the contact forces dominate, so the relative error is smaller)
GROUPS = 128
BOUNDS = {
    "uniform": {0.7: (6e-3, 7e-2), 0.5: (3e-3, 4e-2), 0.3: (2e-4, 2e-3)},
    "chains": {0.7: (6e-5, 1e-2), 0.5: (2e-5, 2.5e-3), 0.3: (2e-6, 2.5e-4)},
}


@pytest.mark.parametrize("config", ["uniform", "chains"])
def test_error_bounds_and_convergence(config, request):
    """Median and 99th-percentile relative force error stay below the measured
    bounds at three opening angles, and both fall as theta falls (the multipole
    truncation error goes as theta^(order+1); with 3000 tips and leaves of 64
    the fall from 0.7 to 0.5 is only a factor 1.8, hence the factor 0.8)."""
    tips = request.getfixturevalue(config)
    expected = direct(*tips)
    last = (np.inf, np.inf)
    for theta in (0.7, 0.5, 0.3):
        err = relative_error(tree(*tips, theta, group_size=GROUPS), expected)
        med, p99 = np.median(err), np.percentile(err, 99)
        bound = BOUNDS[config][theta]
        assert med < bound[0] and p99 < bound[1], (theta, med, p99)
        assert med < 0.8 * last[0] and p99 < 0.8 * last[1], (theta, med, p99, last)
        last = (med, p99)


def test_higher_orders_are_more_accurate(uniform):
    """At the same opening angle each order is more accurate than the one below (measured at
    theta 0.5, leaves of 64: median 3.6e-3, 1.3e-3 and 4.7e-4 for orders 2, 3 and 4)."""
    expected = direct(*uniform)
    e = [np.median(relative_error(tree(*uniform, 0.5, order=order), expected)) for order in (2, 3, 4)]
    assert e[1] < e[0] / 2 and e[2] < e[1] / 2, e


def cluster_and_targets(rng, n=40):
    """Rods (tips +-q) inside a ball of radius about 1 around the origin, and target points on a
    ray at distances 6, 12 and 24 (the directions of the tips and the ray at random)."""
    centre = rng.normal(size=(n, 3))
    centre *= 0.5 / np.linalg.norm(centre, axis=1).max()
    x, y, z, q = rods_to_tips(centre, rng.normal(size=(n, 3)), rng.uniform(2 / 3, 2, n))
    ray = rng.normal(size=3)
    return (x, y, z, q), ray / np.linalg.norm(ray) * np.array([6.0, 12.0, 24.0])[:, None]


@pytest.mark.parametrize("order", [2, 3, 4])
def test_multipole_field_falls_with_its_order(order):
    """The field of one cell's moments (the kernels of the far field, float64 and float32) against
    the Coulomb field of its tips: the truncation error of order p falls as 1/d^(p+3) (the first
    moment left out, of order p + 1, has a field falling so), so doubling the distance divides it
    by 2^(p+3): 32, 64, 128 for orders 2, 3, 4 (measured 32-33, 65 and 122-125; a wrong term of
    order n <= p would leave an error falling as 1/d^(n+2) instead). The float32 field, in units of
    the distance as the tree takes it, equals the float64 one to float32 rounding."""
    from selfas_graph.kernels import multipole as km

    tips, points = cluster_and_targets(np.random.default_rng(11))
    t = build_tip_tree(*tips, leaf_size=len(tips[0]), order=order)  # one cell: the root
    mc, c = t.moment[0], t.centre[0]
    errors = []
    for p in points:
        d = p - c
        exact = sum(qk * (p - xk) / np.linalg.norm(p - xk) ** 3 for qk, xk in zip(tips[3], np.stack(tips[:3], 1)))
        field = np.array(km.field_hexadecapole(*d, *mc) if order == 4 else km.field_octupole(*d, *mc[:16]))
        if order == 2:
            # order 2 leaves the octupoles zero: the octupole kernel is the quadrupole one but for
            # the order of its float64 operations (a few ulp, 1e-13 leaves room for cancellation)
            np.testing.assert_allclose(field, km.field_quadrupole(*d, *mc[:9]), rtol=1e-13)
        s = np.linalg.norm(d)
        u = (d / s).astype(np.float32)
        m32 = (mc * s ** -np.repeat([0, 1, 2, 3, 4], [1, 3, 5, 7, 9])).astype(np.float32)
        f32 = km.field_hexadecapole_f32(*u, *m32) if order == 4 else km.field_octupole_f32(*u, *m32[:16])
        # float32 rounding (6e-8) of the inputs and of some 100 operations, with cancellation between
        # the moments' terms: 1e-5 is well above it (the float64 truncation is checked below)
        np.testing.assert_allclose(np.array(f32, dtype=np.float64) / s**2, field, rtol=1e-5)
        errors.append(np.linalg.norm(field - exact))
    ratios = np.array(errors[:-1]) / np.array(errors[1:])
    expected = 2.0 ** (order + 3)
    assert np.all((ratios > 0.8 * expected) & (ratios < 1.25 * expected)), ratios


@pytest.mark.parametrize("config", ["uniform", "chains"])
@pytest.mark.parametrize("theta, order", [(0.0, 2), (0.0, 3), (0.0, 4), (1e-3, 3), (1e-3, 4)])
def test_small_theta_is_direct(config, theta, order, request):
    """theta = 0 accepts no cell: the direct sum to round-off. At theta = 1e-3 only
    cells far beyond their radius are accepted and the truncation error, about theta^4 =
    1e-12 of a cell's field with octupoles, is itself at round-off (measured at most
    4e-14 relative per tip)."""
    tips = request.getfixturevalue(config)
    close(tree(*tips, theta, order=order), direct(*tips))


def test_single_tip_leaves(chains):
    """With one tip per leaf every accepted cell is one tip or a cluster of them;
    the result converges to direct at small theta (partner subtraction exercised:
    the rod partner then always sits in an accepted single-tip cell)."""
    expected = direct(*chains)
    err = relative_error(tree(*chains, 0.05, leaf_size=1, group_size=1), expected)
    assert np.median(err) < 2e-8  # measured 5.5e-9


def test_zero_theta_is_the_reference_sum():
    """At theta = 0 the tree opens every cell and sums every pair of tips of different rods as the
    slow reference of docs/model.md 'Term 1' does (tests/reference.py ``tip_tip_force``, a loop over
    all pairs): 96 tips in chains whose joined tips sit at r*/2 (the core), with the default leaves
    of 64 and with single-tip leaves and groups (every pair reached through the walk). Tolerance:
    ``close``, 1e-12 relative with a floor of 1e-12 of the largest component, the round-off of sums
    of about 100 terms of both signs added in another order (measured at most 9e-16 of the largest)."""
    import reference as ref

    tips = chain_rods(4, 12, np.random.default_rng(9))
    position = np.column_stack(tips[:3])
    expected = ref.tip_tip_force(position, tips[3], RSTAR, KAPPA)
    gap = np.linalg.norm(position[1:-1:2] - position[2::2], axis=1)
    assert (gap < RSTAR).sum() >= 40  # the chains' joints: the core branch is summed
    for knobs in ({}, {"leaf_size": 1, "group_size": 1}):
        close(tree(*tips, 0.0, **knobs), expected)


def touching_pair_beside_300_rods():
    """Tips of two rods touching at r*/2 (tip b of rod 0 on tip a of rod 1), far from 300 rods."""
    far = uniform_rods(300, np.random.default_rng(3))
    pair = rods_to_tips(
        np.array([[-0.5 - RSTAR / 4, 0, 0], [0.5 + RSTAR / 4, 0, 0]]) - 30.0,
        np.array([[1.0, 0, 0], [1.0, 0, 0]]),
        np.array([1.5, 1.2]),
    )
    return [np.concatenate([p, f]) for p, f in zip(pair, far)]


def test_near_pairs_exact():
    """Two tips closer than r* (a touching pair at r*/2) get exactly the direct core force,
    even at a large opening angle with single-tip leaves, where a plain Barnes-Hut rule
    would accept the partner-of-contact cell as a monopole: the tree must open every cell
    within r* of the target. The far cluster adds a small approximated field, so the
    tolerance is relative to the (large) core force."""
    tips = touching_pair_beside_300_rods()
    expected = direct(*tips)
    for knobs in ({"leaf_size": 1, "group_size": 1}, {}):
        got = tree(*tips, 0.9, **knobs)
        core = np.linalg.norm(expected[1])  # tip b of rod 0 touches tip a of rod 1
        assert core > 100  # inside the core: kappa / r*^3 scale
        np.testing.assert_allclose(got[1:3], expected[1:3], atol=1e-6 * core)


def test_row_range_bitwise(chains):
    """Rows evaluated in several ranges (of odd lengths, so that targets sit at other
    places in the kernel's vector blocks) equal one evaluation of all rows bitwise,
    and rows outside a range are untouched (a caller may split targets over MPI ranks)."""
    t = build_tip_tree(*chains)
    n = len(chains[0])
    whole = np.empty((n, 3))
    evaluate_tip_tree(t, RSTAR, KAPPA, 0.5, whole)
    parts = np.full((n, 3), np.nan)
    m = n // 3 + 1
    evaluate_tip_tree(t, RSTAR, KAPPA, 0.5, parts, 0, m)
    assert np.isnan(parts[m:]).all() and not np.isnan(parts[:m]).any()
    for lo, hi in ((m, m + 1), (m + 1, n - 3), (n - 3, n)):
        evaluate_tip_tree(t, RSTAR, KAPPA, 0.5, parts, lo, hi)
    assert np.array_equal(parts, whole)


@pytest.mark.jit_off_ok
def test_argsort_keys_is_the_stable_argsort():
    """The radix sort of the Morton keys is numpy's stable argsort, ties in tip order: random keys
    over all 63 bits, many equal keys, keys that differ only in their low or only in their high
    digits (passes skipped), one key, none."""
    from selfas_graph.kernels.treebuild import argsort_keys

    rng = np.random.default_rng(12)
    cases = [
        rng.integers(0, 2**63 - 1, 3000, dtype=np.int64, endpoint=True),
        rng.integers(0, 5, 3000).astype(np.int64),
        rng.integers(0, 2**11, 500).astype(np.int64) << 40,
        rng.integers(0, 7, 500).astype(np.int64) + (2**62),
        np.array([2**63 - 1, 0, 2**63 - 1, 1], dtype=np.int64),
        np.array([42], dtype=np.int64),
        np.empty(0, dtype=np.int64),
    ]
    for key in cases:
        assert np.array_equal(argsort_keys(key), np.argsort(key, kind="stable"))


def test_morton_keys_of_both_builds_agree():
    """The serial and the parallel build of ``morton_keys`` (``njit_rows``) give the same integer keys."""
    from selfas_graph.kernels.treebuild import morton_keys

    rng = np.random.default_rng(13)
    x, y, z = (rng.normal(size=1000) for _ in range(3))
    keys = {}
    for build in ("serial", "parallel"):
        keys[build] = np.empty(1000, np.int64)
        getattr(morton_keys, build)(x, y, z, keys[build])
    # 1000 spread points at 21 bits a coordinate: distinct keys but for rare coincidences (not all zero)
    assert np.array_equal(keys["serial"], keys["parallel"]) and len(np.unique(keys["serial"])) > 990


def morton_key_by_hand(x, y, z):
    """The Morton keys of ``treebuild.morton_keys`` by plain Python: each coordinate quantised to
    ``floor((c - min) 2**21 / extent)``, clamped to [0, 2**21 - 1] (extent: the largest of the three
    ranges; all 0 when it is 0), and bit b of the x, y and z integers put at bits 3 b + 2, 3 b + 1 and
    3 b of the key, one bit at a time."""
    bits = 21
    lo = [min(c) for c in (x, y, z)]
    extent = max(max(c) - m for c, m in zip((x, y, z), lo))
    scale = 2.0**bits / extent if extent > 0 else 0.0
    keys = []
    for point in zip(x, y, z):
        ints = [min(max(math.floor((float(c) - m) * scale), 0), 2**bits - 1) for c, m in zip(point, lo)]
        key = 0
        for b in range(bits):
            for shift, i in zip((2, 1, 0), ints):
                key |= ((i >> b) & 1) << (3 * b + shift)
        keys.append(key)
    return keys


@pytest.mark.jit_off_ok
def test_morton_keys_are_the_bit_interleave_of_the_quantised_coordinates():
    """``morton_keys`` equals a plain-Python interleave of the quantised coordinates (x in the highest
    bit of each triple, then y, then z), integer for integer: on spread points, a flat scene (z all
    equal), all points equal (every key 0), and hand-computed keys of the unit cube's corners: (1, 1, 1)
    is clamped to 2**21 - 1 on each axis (every bit set), (0.5, 0, 0) sets bit 20 of x alone (bit 62),
    (0, 0.5, 0) bit 61, (0, 0, 0.5) bit 60, (0, 0, 2**-21) bit 0."""
    from selfas_graph.kernels.treebuild import morton_keys

    rng = np.random.default_rng(14)
    flat = [rng.uniform(-3, 5, 200), rng.uniform(0, 1, 200), np.full(200, 0.25)]
    corners = np.array([[0, 0, 0], [1, 1, 1], [0.5, 0, 0], [0, 0.5, 0], [0, 0, 0.5], [0, 0, 2.0**-21]]).T
    cases = [[rng.normal(size=500) for _ in range(3)], flat, [np.full(7, 1.5)] * 3, list(corners)]
    for x, y, z in cases:
        got = np.empty(len(x), np.int64)
        morton_keys(*(np.ascontiguousarray(c, dtype=np.float64) for c in (x, y, z)), got)
        assert got.tolist() == morton_key_by_hand(x, y, z)
    assert got.tolist() == [0, 2**63 - 1, 2**62, 2**61, 2**60, 1]


def test_one_rod():
    """A single rod: its two tips do not interact, the force is exactly zero."""
    tips = rods_to_tips(np.zeros((1, 3)), np.array([[0, 0, 1.0]]), np.array([1.3]))
    assert np.array_equal(tree(*tips, 0.5), np.zeros((2, 3)))


def test_two_rods():
    """Two rods: four tips fit one leaf, so the tree is the direct sum to round-off
    at any theta (no cell is ever approximated)."""
    tips = rods_to_tips(
        np.array([[0, 0, 0], [1.7, 0.3, -0.4]]), np.array([[0, 0, 1.0], [1, 1, 0.0]]), np.array([1.3, 0.8])
    )
    close(tree(*tips, 0.9), direct(*tips))


def test_coincident_tips():
    """All tips on one point: every key is equal, the tree is one leaf (no endless
    splitting) and the force is zero (the law gives 0 at r = 0). Tips 1e-13 apart
    split normally and agree with the direct sum."""
    n = 40
    x = np.zeros(n)
    charge = np.tile([1.0, -1.0], n // 2)
    assert np.array_equal(tree(x, x, x, charge, 0.5), np.zeros((n, 3)))
    rng = np.random.default_rng(4)
    tips = [1e-13 * rng.normal(size=n) for _ in range(3)] + [charge]
    close(tree(*tips, 0.5), direct(*tips))


@pytest.mark.parametrize("offset", [1e6, 1e9])
def test_huge_spread(offset):
    """Two clusters of 300 rods ``offset`` lengths apart. The 21-bit keys resolve
    ``offset / 2**21``: 0.5 at 1e6, 480 at 1e9, where each cluster shares one key and
    becomes one leaf of 600 tips at the depth cap. The build terminates and the error
    stays as in a uniform gas (measured median 6e-4 and p99 1.2e-2 at 1e6, less at
    1e9 where each cluster is summed exactly)."""
    rng = np.random.default_rng(5)
    a = uniform_rods(300, rng)
    b = uniform_rods(300, rng)
    tips = [np.concatenate([u, v + (offset if d < 3 else 0.0)]) for d, (u, v) in enumerate(zip(a, b))]
    t = build_tip_tree(*tips)
    leaf = t.next == np.arange(len(t.start)) + 1
    if offset > 1e8:
        assert (t.end - t.start)[leaf].max() == 600
    expected = direct(*tips)
    out = np.empty((len(tips[0]), 3))
    err = relative_error(evaluate_tip_tree(t, RSTAR, KAPPA, 0.5, out), expected)
    assert np.median(err) < 1.5e-3 and np.percentile(err, 99) < 2.5e-2


def test_invalid_input():
    """NaN or inf coordinates raise ValueError in the front end (a NaN tip has no place
    in the tree, and numba would not notice); so do mismatched shapes and odd tip counts."""
    tips = list(rods_to_tips(np.zeros((2, 3)) + [[0, 0, 0], [2, 0, 0]], np.ones((2, 3)), np.ones(2)))
    bad = [t.copy() for t in tips]
    bad[1][2] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        tree(*bad, 0.5)
    bad = [t.copy() for t in tips]
    bad[3][0] = np.inf
    with pytest.raises(ValueError, match="NaN or inf"):
        tree(*bad, 0.5)
    with pytest.raises(ValueError, match="shape"):
        tree(tips[0], tips[1][:3], tips[2], tips[3], 0.5)
    with pytest.raises(ValueError, match="even"):
        tree(*(t[:3] for t in tips), 0.5)
    with pytest.raises(ValueError, match="theta"):
        tree(*tips, 1.0)
    t = build_tip_tree(*tips)
    with pytest.raises(ValueError, match="lo"):
        evaluate_tip_tree(t, RSTAR, KAPPA, 0.5, np.empty((4, 3)), 3, 2)
    with pytest.raises(ValueError, match="out"):
        evaluate_tip_tree(t, RSTAR, KAPPA, 0.5, np.empty((3, 3)))


# ------------------------------------------------------------------ in the force field
def _field(n_rods, method, seed=4, **tip_magnetic):
    from conftest import random_rods, simulation

    state = random_rods(n_rods, np.random.default_rng(seed), box=8.0)
    sim = simulation(
        state,
        forces={"tip_magnetic": {"method": method, **tip_magnetic}},
        placement={"box": [[-4.5, 4.5]] * 3, "min_tip_distance": 0.0},
    )
    return sim.force_field, state


def test_auto_picks_the_tree_from_tree_above_rods():
    """forces.tip_magnetic.method = auto: direct below tree_above rods, the tree from there on."""
    assert _field(50, "auto", tree_above=51)[0].describe()["tip_magnetic_sum"] == "direct"
    assert _field(50, "auto", tree_above=50)[0].describe()["tip_magnetic_sum"].startswith("tree")
    assert _field(50, "direct", tree_above=1)[0].describe()["tip_magnetic_sum"] == "direct"


def test_force_field_tree_matches_direct_within_its_error():
    """The force field's tip-tip channel by the tree equals the direct one to the tree's
    truncation error (median relative error measured 2.4e-4 here at the default angle with groups
    of 128 tips: the default groups of 1024 would hold these 800 tips in one group and sum every
    pair directly), and to round-off at a tiny opening angle."""
    ff_d, state = _field(400, "direct")
    ff_t, _ = _field(400, "tree", group_size=128)
    ff_0, _ = _field(400, "tree", opening_angle=1e-9, group_size=128)
    f = [ff.evaluate(state.position, state.velocity).copy() for ff in (ff_d, ff_t, ff_0)]
    err = np.linalg.norm(f[1] - f[0], axis=1) / np.linalg.norm(f[0], axis=1)
    assert 1e-6 < np.median(err) < 1e-3
    # at a tiny opening angle every pair is summed directly, in the tree's order: float64 round-off of sums
    # of 800 terms (forces of order 1 to 1e3 in the cores), far below 1e-10
    np.testing.assert_allclose(f[2], f[0], rtol=1e-10, atol=1e-10)


def test_group_size_reaches_the_tree():
    """forces.tip_magnetic.group_size sets the tree's target groups: the force field's tip-tip channel
    equals the kernel's with that group size bit for bit, and differs from that of groups of 128 (a
    cell is accepted for a whole group by its distance from the group's box). The energy's tree:
    tests/physics/test_tree_energy.py::test_energy_tree_above_picks_the_tree_energy."""
    ff_g, state = _field(400, "tree", group_size=16)
    ff_d, _ = _field(400, "tree", group_size=128)
    f_g, f_d = [(ff.evaluate(state.position, state.velocity), ff.out["tip_magnetic"].copy())[1] for ff in (ff_g, ff_d)]
    term = next(t for t in ff_g.terms if t.name == "tip_magnetic")
    x, y, z = (np.ascontiguousarray(state.position[:, d]) for d in range(3))
    out = np.empty((len(x), 3))
    expected = tip_tip_tree(x, y, z, ff_g.tip_charge, term.rstar, term.kappa, term.theta, out, group_size=16)
    assert np.array_equal(f_g, expected)
    assert not np.array_equal(f_g, f_d)
    assert "groups of up to 16 tips" in ff_g.describe()["tip_magnetic_sum"]


def test_force_field_tree_passes_nan_on_to_the_health_check():
    """A NaN position (a run gone wrong) gives NaN forces, as with the direct sum, instead of
    an error from the tree build: the run's health check then stops it with a diagnosis."""
    ff, state = _field(40, "tree")
    pos = state.position.copy()
    pos[3] = np.nan
    f = ff.evaluate(pos, state.velocity)
    assert np.isnan(f).any()


# ------------------------------------------------------------- mixed-precision near field
# precision="mixed" sums the near pairs in float32 (kernels/tree.py evaluate_tip_tree).
# Measured with the fixtures here (theta 0.4 and 0): |F_mixed - F_float64| at most 1.1e-6 of
# the largest force, median 4e-7 - 5e-7 of each tip's force (float32 rounding, 6e-8, of terms
# that partly cancel). The bounds are ten times (MIXED_ATOL) and four times (MIXED_MEDIAN) that.
# The 99th percentile of |F_mixed - F_float64| / |F| in the chains depends on the vector width
# the build compiles the float32 law for: LLVM takes 1/sqrt from the reciprocal square root
# estimate and one Newton step, vrsqrt14ps (14 bits) on 512-bit vectors, vrsqrtps (12 bits) on
# 256-bit ones (the AVX2 build, and the host build of Intel's AVX-512 CPUs, whose LLVM tuning
# prefers 256-bit vectors): measured 6.9e-6 with the first (Zen 4, Zen 5), 1.33e-5 with the second
# (Intel Xeon, host and AVX2 builds). MIXED_P99 is 1.5 times the larger.
MIXED_ATOL = 1e-5
MIXED_MEDIAN = 2e-6
MIXED_P99 = 2e-5


def mixed(x, y, z, charge, theta, **knobs):
    return tree(x, y, z, charge, theta, precision="mixed", **knobs)


def close_mixed(actual, expected):
    """Equal to float32 rounding of the near field: MIXED_ATOL of the largest force."""
    np.testing.assert_allclose(actual, expected, rtol=0, atol=MIXED_ATOL * np.abs(expected).max())


@pytest.mark.parametrize("config", ["uniform", "chains"])
@pytest.mark.parametrize("theta", [0.4, 0.0])
def test_mixed_matches_float64(config, theta, request):
    """The mixed tree equals the float64 tree to float32 rounding, and its error against the
    direct sum is the tree's own: measured median and p99 within 1.3 % of the float64 tree's in
    the gas (the float32 difference, 4e-7 of a force, adds to a truncation error of 1e-5 to 1e-4),
    and within 2.3e-7 (median, truncation error 1.3e-7) and 3.6e-6 (p99, 2.8e-5) of it in the
    chains with 512-bit vectors, 3.7e-7 and 1.35e-5 with 256-bit ones (MIXED_P99)."""
    tips = request.getfixturevalue(config)
    f64 = tree(*tips, theta)
    f32 = mixed(*tips, theta)
    close_mixed(f32, f64)
    assert np.median(relative_error(f32, f64)) < MIXED_MEDIAN
    if theta > 0:
        expected = direct(*tips)
        e64, e32 = relative_error(f64, expected), relative_error(f32, expected)
        # in the chains the hexadecapole tree errs only 1e-7 to 1e-6 (median) and 3e-5 (p99), where
        # the float32 rounding of the near pairs is as large (MIXED_MEDIAN; its p99 is 6.9e-6 or
        # 1.33e-5 of a tip's force in the chains by the build's vector width, MIXED_P99): it may add that much
        for stat, rounding in ((np.median, MIXED_MEDIAN), (lambda e: np.percentile(e, 99), MIXED_P99)):
            assert abs(stat(e32) - stat(e64)) < 0.05 * stat(e64) + rounding


def test_mixed_far_from_the_origin(chains):
    """The whole scene shifted by 1e4: coordinates are taken relative to the group's box
    centre before the cast to float32, so the mixed tree still equals the float64 tree of the
    shifted scene to float32 rounding (a cast of absolute coordinates, 1e4 +- 5e-4, would not
    resolve tips in contact, r*/2 = 0.03 apart)."""
    shifted = [t + (1e4 if d < 3 else 0.0) for d, t in enumerate(chains)]
    close_mixed(mixed(*shifted, 0.4), tree(*shifted, 0.4))


def test_mixed_single_leaf_is_direct(chains):
    """One leaf and one group hold every tip: no cell is accepted, the mixed tree is the direct
    sum in float32 (measured 1.1e-6 of the largest force)."""
    n = len(chains[0])
    close_mixed(mixed(*chains, 0.4, leaf_size=n, group_size=n), direct(*chains))


@pytest.mark.jit_off_ok
def test_mixed_core_and_same_rod():
    """Small scenes (also run with NUMBA_DISABLE_JIT=1): one rod gives exactly zero (its two tips
    are the same rod, excluded as in float64); coincident tips give exactly zero (r = 0); two
    rods whose tips sit inside the soft core, r*/2 apart, get the direct core force to float32
    rounding."""
    one = rods_to_tips(np.zeros((1, 3)), np.array([[0, 0, 1.0]]), np.array([1.3]))
    assert np.array_equal(mixed(*one, 0.5), np.zeros((2, 3)))
    x = np.zeros(8)
    assert np.array_equal(mixed(x, x, x, np.tile([1.0, -1.0], 4), 0.5), np.zeros((8, 3)))
    pair = rods_to_tips(
        np.array([[-0.5 - RSTAR / 4, 0, 0], [0.5 + RSTAR / 4, 0.001, 0]]),
        np.array([[1.0, 0, 0], [1.0, 0, 0]]),
        np.array([1.5, 1.2]),
    )
    expected = direct(*pair)
    assert np.linalg.norm(expected[1]) > 100  # inside the core: kappa / r*^3 scale
    close_mixed(mixed(*pair, 0.9), expected)


def test_mixed_core_among_many():
    """A touching pair beside 300 rods, single-tip leaves and a large opening angle (as
    test_near_pairs_exact): the core force is exact to float32 rounding of the core force."""
    tips = touching_pair_beside_300_rods()
    expected = direct(*tips)
    core = np.linalg.norm(expected[1])
    for knobs in ({"leaf_size": 1, "group_size": 1}, {}):
        np.testing.assert_allclose(mixed(*tips, 0.9, **knobs)[1:3], expected[1:3], atol=1e-5 * core)


def test_mixed_row_ranges_bitwise(chains):
    """Row ranges evaluated separately equal one mixed evaluation bitwise (each target's float32
    sum does not depend on the other targets); an empty range writes nothing, and ranges in
    which most groups have no target are skipped group by group."""
    t = build_tip_tree(*chains)
    n = len(chains[0])
    whole = np.empty((n, 3))
    evaluate_tip_tree(t, RSTAR, KAPPA, 0.5, whole, precision="mixed")
    parts = np.full((n, 3), np.nan)
    evaluate_tip_tree(t, RSTAR, KAPPA, 0.5, parts, 7, 7, precision="mixed")
    assert np.isnan(parts).all()
    m = n // 3 + 1
    for lo, hi in ((0, m), (m, m + 1), (m + 1, n - 3), (n - 3, n)):
        evaluate_tip_tree(t, RSTAR, KAPPA, 0.5, parts, lo, hi, precision="mixed")
    assert np.array_equal(parts, whole)


@pytest.mark.parametrize("precision", ["float64", "mixed"])
def test_group_runs_bitwise(chains, precision):
    """Runs of groups (as MPI ranks take them, kernels/tree.py group_bounds) evaluated separately
    equal one evaluation bitwise; each run writes exactly the rows of its tips, a contiguous run in
    Morton order, and the runs hold about equal numbers of tips."""
    from selfas_graph.kernels.tree import group_bounds

    t = build_tip_tree(*chains, leaf_size=16, group_size=32)
    n = len(chains[0])
    whole = np.empty((n, 3))
    evaluate_tip_tree(t, RSTAR, KAPPA, 0.5, whole, precision=precision)
    bounds, tips = group_bounds(t, 3)
    assert bounds[0] == 0 and bounds[-1] == len(t.group) and tips[0] == 0 and tips[-1] == n
    assert np.all(np.diff(tips) > n / 3 - 32) and np.all(np.diff(tips) < n / 3 + 32)
    parts = np.full((n, 3), np.nan)
    for r in range(3):
        evaluate_tip_tree(t, RSTAR, KAPPA, 0.5, parts, precision=precision, groups=bounds[r : r + 2])
        done = np.zeros(n, bool)
        done[t.index[: tips[r + 1]]] = True
        assert np.array_equal(~np.isnan(parts[:, 0]), done)
    assert np.array_equal(parts, whole)
    with pytest.raises(ValueError, match="groups"):
        evaluate_tip_tree(t, RSTAR, KAPPA, 0.5, parts, groups=(2, len(t.group) + 1))


def test_cells_filled_in_runs_give_the_same_tree(chains):
    """The moments of a planned tree filled in runs of cells (as MPI ranks share them,
    kernels/tree.py cell_bounds) equal one build bitwise, and the runs split the cells' work
    (their tips) about evenly."""
    from selfas_graph.kernels.tree import cell_bounds, fill_cells, finish_tip_tree, plan_tip_tree

    whole = build_tip_tree(*chains)
    t = plan_tip_tree(*chains)
    bounds = cell_bounds(t, 3)
    assert bounds[0] == 0 and bounds[-1] == len(t.start) and np.all(np.diff(bounds) > 0)
    work = np.add.reduceat(t.end - t.start, bounds[:-1])
    # a cut falls between cells, so a run exceeds a third of the work by less than its first cell's work
    # (run 0 by nothing): at most the largest cell below the root, 842 tips against a third of 4100 here, a
    # bound of 1.21; measured 1.03 (integer counts on a fixed tree: the same on any CPU)
    assert work.max() < 1.25 * work.sum() / 3
    for r in range(3):
        fill_cells(t, bounds[r], bounds[r + 1])
    t = finish_tip_tree(t)
    for name in ("box", "centre", "radius", "moment", "near32", "charge32", "rod32", "group", "index"):
        assert np.array_equal(getattr(t, name), getattr(whole, name)), name


def test_mixed_invalid_precision(chains):
    t = build_tip_tree(*chains)
    with pytest.raises(ValueError, match="precision must be one of 'float64', 'mixed'"):
        evaluate_tip_tree(t, RSTAR, KAPPA, 0.5, np.empty((len(chains[0]), 3)), precision="float32")


def test_force_field_precision():
    """forces.tip_magnetic.precision = mixed reaches the tree: the force field's forces
    equal those with float64 to float32 rounding, and the dry run's settings say so (groups of 128,
    so that the far field is used in these 800 tips)."""
    ff_64, state = _field(400, "tree", group_size=128)
    ff_32, _ = _field(400, "tree", precision="mixed", group_size=128)
    assert (
        ff_32.describe()["tip_magnetic_sum"]
        == "tree (order 4, opening angle 0.55, leaves of up to 64 tips, groups of up to 128 tips, mixed near field)"
    )
    assert (
        _field(40, "tree")[0]
        .describe()["tip_magnetic_sum"]
        .startswith("tree (order 4, opening angle 0.55, leaves of up to 64 tips, groups of up to 1024")
    )
    f = [ff.evaluate(state.position, state.velocity).copy() for ff in (ff_64, ff_32)]
    close_mixed(f[1], f[0])


def test_leaf_size_reaches_the_tree():
    """forces.tip_magnetic.leaf_size is the tree's leaf: the force field's channel is the kernel's
    evaluation of a tree with those leaves bit for bit, and leaves of 8 tips give other cells (so
    other sums) than the default's 64, both within the tree's error of the direct sum (groups of 128,
    so that far cells act in these 800 tips)."""
    from selfas_graph.kernels.tree import LEAF_SIZE

    forces = {}
    for leaf in (8, LEAF_SIZE):
        ff, state = _field(400, "tree", group_size=128, leaf_size=leaf)
        ff.evaluate(state.position, state.velocity)
        forces[leaf] = ff.out["tip_magnetic"].copy()
        x, y, z = (np.ascontiguousarray(state.position[:, d]) for d in range(3))
        t = build_tip_tree(x, y, z, state.tip_charge, leaf_size=leaf, group_size=128)
        f = np.empty((state.n_tips, 3))
        evaluate_tip_tree(t, RSTAR, KAPPA, 0.55, f)
        assert np.array_equal(forces[leaf], f)
        assert f"leaves of up to {leaf} tips" in ff.describe()["tip_magnetic_sum"]
    assert not np.array_equal(forces[8], forces[LEAF_SIZE])
    exact, _ = _field(400, "direct")
    exact.evaluate(state.position, state.velocity)
    for leaf in forces:
        # the tree's truncation error, as test_force_field_tree_matches_direct_within_its_error
        assert 1e-6 < np.median(relative_error(forces[leaf], exact.out["tip_magnetic"])) < 1e-3


# ------------------------------------------------------------------ mixed far field
# precision="mixed" also takes each accepted cell's field in float32 (offsets and moments in
# units of the cell's distance from the group, kernels/multipole.py make_fields, float32), added in
# float64 over the cells. Measured on the Fig. 2 scene at 6000 and 24 000 rods: it moves the
# forces by a median 2e-8 and at most 2e-6 of a tip's force, inside the bounds above.


def line_of_rods(n_rods, spacing=2.0):
    """Rods on the x axis, end to end with gaps (tips at spacing / 2 +- 0.5): a linear scene."""
    centre = np.zeros((n_rods, 3))
    centre[:, 0] = spacing * np.arange(n_rods)
    axis = np.tile([1.0, 0.0, 0.0], (n_rods, 1))
    return rods_to_tips(centre, axis, np.random.default_rng(9).uniform(2 / 3, 2, n_rods))


def test_mixed_far_field_matches_the_float64_multipoles(uniform):
    """With leaves of one tip and theta 0.5 most of each tip's force comes from accepted cells:
    the float32 far field equals the float64 one to float32 rounding of the largest force, for
    every order (order 2 runs the octupole formula with zero octupole moments). Each group records
    hundreds of cells here, several chunks of FAR_CHUNK, the last one padded."""
    for order in (2, 3, 4):
        knobs = {"leaf_size": 1, "group_size": 8, "order": order}
        close_mixed(mixed(*uniform, 0.5, **knobs), tree(*uniform, 0.5, **knobs))


@pytest.mark.parametrize("group_size", [16, 4096])
def test_mixed_linear_scene(group_size):
    """All tips on one line (every box flat in y and z). With groups of 4096 tips, each spanning
    4000 lengths, and leaves of one tip, the tips just beyond a group's end are accepted cells
    1.5 lengths from a box 4000 long (span / distance 2700, measured): beyond SPAN32, they take
    the float64 loop. Mixed equals float64 to float32 rounding, and both the direct sum to the
    tree's error (measured median 1.5e-4 with groups of 16; 1e-10 and, mixed, 2.6e-7 with
    groups of 4096, whose boxes accept only small cells far away)."""
    tips = line_of_rods(4096)
    knobs = {"leaf_size": 1, "group_size": group_size}
    f64 = tree(*tips, 0.5, **knobs)
    f32 = mixed(*tips, 0.5, **knobs)
    close_mixed(f32, f64)
    expected = direct(*tips)
    assert np.median(relative_error(f64, expected)) < 3e-4
    assert np.median(relative_error(f32, expected)) < 3e-4


def test_mixed_flat_scene_on_cell_borders():
    """Tips on an integer grid in one plane (z = 0): the Morton cube is a power of two wide, so
    many tips sit exactly on cell borders, and every box is flat. Mixed equals float64 to
    float32 rounding and both are the direct sum at theta 0."""
    g = np.arange(16, dtype=float)
    gx, gy = np.meshgrid(g, g, indexing="ij")
    n = gx.size // 2 * 2
    x = np.ascontiguousarray(gx.ravel()[:n])
    y = np.ascontiguousarray(gy.ravel()[:n])
    z = np.zeros(n)
    charge = np.tile([1.0, -1.0], n // 2) * np.repeat(np.linspace(0.7, 1.9, n // 2), 2)
    for knobs in ({"leaf_size": 4, "group_size": 8}, {}):
        close_mixed(mixed(x, y, z, charge, 0.5, **knobs), tree(x, y, z, charge, 0.5, **knobs))
        close_mixed(mixed(x, y, z, charge, 0.0, **knobs), direct(x, y, z, charge))


@pytest.mark.parametrize("offset", [1e6, 1e9])
def test_mixed_huge_spread(offset):
    """As test_huge_spread, mixed: the other cluster's field is taken in float32 in units of its
    distance (1e6 or 1e9: unscaled, 1/R^9 would underflow float32), so mixed equals float64."""
    rng = np.random.default_rng(5)
    a = uniform_rods(300, rng)
    b = uniform_rods(300, rng)
    tips = [np.concatenate([u, v + (offset if d < 3 else 0.0)]) for d, (u, v) in enumerate(zip(a, b))]
    close_mixed(mixed(*tips, 0.5), tree(*tips, 0.5))


@pytest.mark.jit_off_ok
def test_acceptance_is_the_rule_on_the_box(rng):
    """kernels/treewalk.py accepts: a cell of radius b acts through its moments on a group's box
    exactly when the distance d of its centre from the box (0 inside it, numpy's clip) has
    b < theta d and b + r* < d, so that no tip of the cell comes within r* of any point of the
    box; hand-placed cells on both sides of each bound, and random ones against numpy."""
    from selfas_graph.kernels.treewalk import accepts

    box = (0.0, 0.0, 0.0, 1.0, 2.0, 1.0)
    theta = 0.5

    def rule(centre, radius):
        return [accepts(centre, radius, c, *box, theta * theta, RSTAR)[0] for c in range(len(radius))]

    # d = 2 beyond the x face: b = 0.99 (< theta d = 1) accepted, b = 1.01 not; a cell inside the box never
    centre = np.array([[3.0, 1.0, 0.5], [3.0, 1.0, 0.5], [0.5, 1.0, 0.5], [0.5, 1.0, 0.5]])
    assert rule(centre, np.array([0.99, 1.01, 0.0, 1e-9])) == [True, False, False, False]
    # a small cell close to the box (d = 0.1): theta d = 0.05 passes b = 0.03 and 0.045, and r* decides:
    # b + r* = 0.09 < d, 0.105 > d
    assert rule(np.array([[1.1, 1.0, 0.5]] * 2), np.array([0.03, 0.045])) == [True, False]
    centre = rng.uniform(-4, 5, (2000, 3))
    radius = rng.uniform(0, 2, 2000)
    lo, hi = np.array(box[:3]), np.array(box[3:])
    d2 = ((centre - np.clip(centre, lo, hi)) ** 2).sum(1)
    want = (d2 * theta**2 > radius**2) & (d2 > (radius + RSTAR) ** 2)
    got = [accepts(centre, radius, c, *box, theta * theta, RSTAR) for c in range(2000)]
    np.testing.assert_array_equal([g[0] for g in got], want)
    np.testing.assert_allclose([g[1] for g in got], d2, rtol=1e-15, atol=0)
    assert 200 < want.sum() < 1800
