"""The fast multipole method for the tip-tip force (kernels/fmm.py) against analytic derivatives,
the field of a cluster of charges and the direct sum.

The oracle of the forces is ``tip_tip_direct`` (itself checked against tests/reference.py); that of
the derivative tensors is their closed form to third order and, above it, central differences of
the order below. Error bounds of the expansions are about twice the values measured with the fixed
seeds here (noted beside them), so that a lost order of accuracy fails but a change of round-off
does not.
"""

import math

import numpy as np
import pytest
from test_tree import KAPPA, RSTAR, rods_to_tips, uniform_rods

from selfas_graph.kernels import fmm
from selfas_graph.kernels.tips import tip_tip_direct
from selfas_graph.kernels.tree import build_tip_tree


def _derivatives(r, p):
    """``{multi-index: d^a (1/|R|)}`` for one ``R`` by :func:`fmm.derivatives` (one lane)."""
    tab = fmm.tables(p)
    work = np.empty((p + 1, tab.degree.shape[0], 1))
    fmm.derivatives(*(np.array([v]) for v in r), p, tab.degree, tab.axis, tab.lower1, tab.lower2, tab.t, work)
    return dict(zip(fmm.multi_indices(p), work[0, :, 0]))


@pytest.mark.jit_off_ok
def test_tables_count_the_multi_indices():
    for p in range(1, 7):
        tab = fmm.tables(p)
        assert tab.degree.shape[0] == math.comb(p + 3, 3)
        # M2L rows: pairs (a, b) with |a| + |b| <= p, i.e. multi-indices of degree <= p in 6 dimensions
        assert tab.m2l.shape[0] == math.comb(p + 6, 6)
    with pytest.raises(ValueError, match="at least 1"):
        fmm.tables(0)


@pytest.mark.jit_off_ok
def test_derivatives_of_one_over_r_in_closed_form():
    x, y, z = r = (0.7, -1.3, 0.4)
    rr = math.sqrt(x * x + y * y + z * z)
    d = _derivatives(r, 3)
    closed = {
        (0, 0, 0): 1 / rr,
        (1, 0, 0): -x / rr**3,
        (0, 0, 1): -z / rr**3,
        (2, 0, 0): (3 * x * x - rr * rr) / rr**5,
        (1, 1, 0): 3 * x * y / rr**5,
        (3, 0, 0): -(15 * x**3 - 9 * x * rr * rr) / rr**7,
        (1, 1, 1): -15 * x * y * z / rr**7,
        (0, 2, 1): -(15 * y * y * z - 3 * z * rr * rr) / rr**7,
    }
    for a, v in closed.items():
        assert d[a] == pytest.approx(v, rel=1e-14), a  # a few roundings of a closed form


@pytest.mark.jit_off_ok
def test_derivatives_are_the_central_differences_of_the_order_below():
    """Every derivative of order 1-6 against the central difference of the one below it along one
    axis, step h = 1e-4 |R|: truncation h^2 |d^3| ~ 1e-8 and round-off eps / h ~ 1e-12 of the
    value, so 1e-6 relative (or of the largest of its order, for a component near zero)."""
    r = np.array([0.9, 0.35, -1.1])
    p = 6
    d = _derivatives(r, p)
    h = 1e-4 * np.linalg.norm(r)
    for a, v in d.items():
        if sum(a) == 0:
            continue
        i = next(j for j in range(3) if a[j] > 0)
        below = list(a)
        below[i] -= 1
        e = np.zeros(3)
        e[i] = h
        diff = (_derivatives(r + e, p)[tuple(below)] - _derivatives(r - e, p)[tuple(below)]) / (2 * h)
        scale = max(abs(w) for b, w in d.items() if sum(b) == sum(a))
        assert abs(diff - v) < 1e-6 * max(abs(v), scale), a


def _cluster_field(tab, src, q, centre_b, centre_a, targets):
    """The field at ``targets`` of charges ``q`` at ``src`` by P2M about ``centre_b``, M2L about
    ``centre_a`` and L2P: one source cell and one target cell, built by hand."""
    mono = np.empty(tab.degree.shape[0])
    moment = np.zeros(tab.degree.shape[0])
    for s, qi in zip(src - centre_b, q):
        fmm.monomials(*s, tab.axis, tab.lower1, mono)
        moment += qi * mono / tab.fact
    # cell 0 the target, cell 1 its one source (column 1 of moment_t)
    centre = np.array([centre_a, centre_b])
    moment_t = np.zeros((tab.degree.shape[0], 2))
    moment_t[:, 1] = moment
    local = np.empty((2, tab.degree.shape[0]))
    fmm.m2l_lanes(np.array([0, 1, 1]), np.array([1]), centre, moment_t, *_m2l_args(tab), local)
    field = np.empty((len(targets), 3))
    for k, h in enumerate(targets - centre_a):
        fmm.monomials(*h, tab.axis, tab.lower1, mono)
        e = np.zeros(3)
        for (kb, kup, i), w in zip(tab.grad, tab.w_grad):
            e[i] -= w * local[0, kup] * mono[kb]
        field[k] = e
    return field


def test_m2l_field_of_a_cluster_falls_with_its_order():
    """Charges of net zero (as every rod's) in a ball of radius 1 about B, targets within 0.9 of A,
    6 apart: the largest error over the targets, relative to the field, falls by about 4 an order
    from p = 2 (measured 1.0, 1.08, 0.29, 0.083, 0.021, 0.0052 for p = 1-6; at p = 1 the local
    expansion has no field of a neutral cell, at p = 2 only the uniform field of its dipole)."""
    rng = np.random.default_rng(3)
    ball = rng.normal(size=(40, 3))
    ball /= np.maximum(1.0, np.linalg.norm(ball, axis=1))[:, None]
    q = np.repeat([1.0, -1.0], 20)
    cb, ca = np.zeros(3), np.array([6.0, 0.0, 0.0])
    targets = ca + 0.9 * rng.uniform(-1, 1, (30, 3)) / math.sqrt(3)
    sep = targets[:, None, :] - ball[None, :, :]
    exact = (q[None, :, None] * sep / np.linalg.norm(sep, axis=2)[:, :, None] ** 3).sum(axis=1)
    err = []
    for p in range(1, 7):
        field = _cluster_field(fmm.tables(p), ball, q, cb, ca, targets)
        err.append(np.max(np.linalg.norm(field - exact, axis=1) / np.linalg.norm(exact, axis=1)))
    assert all(b < a / 2.5 for a, b in zip(err[1:], err[2:])), err
    assert err[-1] < 1e-2, err


def test_m2l_on_lanes_equals_one_source_at_a_time():
    """A target cell with more sources than :data:`fmm.LANES` (two batches, the last padded): its local
    expansion equals the sum over its sources taken one at a time, to round-off (1e-13 of the
    largest coefficient: sums of up to 84 terms in another order)."""
    rng = np.random.default_rng(5)
    tab = fmm.tables(4)
    k_n = tab.degree.shape[0]
    n_src = fmm.LANES + 7
    centre = np.vstack([np.zeros(3), rng.uniform(5, 9, (n_src, 3)) * rng.choice([-1, 1], (n_src, 3))])
    moment_t = rng.normal(size=(k_n, n_src + 1))
    rows = np.array([0] + [n_src] * (n_src + 1))
    together = np.empty((n_src + 1, k_n))
    fmm.m2l_lanes(rows, np.arange(1, n_src + 1), centre, moment_t, *_m2l_args(tab), together)
    alone = np.zeros(k_n)
    out = np.empty((n_src + 1, k_n))
    for b in range(1, n_src + 1):
        fmm.m2l_lanes(np.array([0] + [1] * (n_src + 1)), np.array([b]), centre, moment_t, *_m2l_args(tab), out)
        alone += out[0]
    assert np.allclose(together[0], alone, rtol=0, atol=1e-13 * np.abs(alone).max())
    assert not together[1:].any()  # cells with no source get zero


def _m2l_args(tab):
    return tab.p, tab.degree, tab.axis, tab.lower1, tab.lower2, tab.t, tab.m2l, tab.w_fwd


@pytest.fixture(scope="module")
def gas():
    tips = uniform_rods(1500, np.random.default_rng(11))
    direct = np.empty((len(tips[0]), 3))
    tip_tip_direct(*tips, RSTAR, KAPPA, 0, len(tips[0]), direct)
    return tips, direct


def _errors(force, direct):
    err = np.linalg.norm(force - direct, axis=1) / np.linalg.norm(direct, axis=1)
    return np.median(err), np.percentile(err, 99)


def test_opening_angle_zero_is_the_direct_sum(gas):
    """theta = 0 takes every pair of leaves as near: the direct sum, each tip's own rod left out, to
    round-off (sums in another order; measured 2.4e-15 median)."""
    tips, direct = gas
    tree = build_tip_tree(*tips)
    f = fmm.fmm_forces(tree, fmm.tables(4), 0.0, RSTAR, KAPPA)
    assert fmm.interaction_lists(tree, 0.0, RSTAR).far.shape[0] == 0
    assert np.max(np.linalg.norm(f - direct, axis=1) / np.linalg.norm(direct, axis=1)) < 1e-12


#: measured (median, 99th percentile) of the relative error in the gas of :func:`gas`, per leaf size,
#: order and opening angle; the bounds are twice these
MEASURED = {
    (16, 4, 0.3): (2.8e-4, 4.8e-3),
    (16, 4, 0.5): (3.8e-3, 5.5e-2),
    (16, 6, 0.3): (1.4e-5, 3.5e-4),
    (16, 6, 0.5): (5.5e-4, 1.1e-2),
    (64, 4, 0.3): (1.1e-14, 2.6e-4),  # most tips see only near leaves in 1500 rods: the median is round-off
    (64, 4, 0.5): (5.2e-4, 8.8e-3),
    (64, 6, 0.3): (1.1e-14, 1.9e-5),
    (64, 6, 0.5): (6.9e-5, 1.4e-3),
}


@pytest.mark.parametrize("leaf", [16, 64])
def test_error_falls_with_order_and_opening_angle(gas, leaf):
    """A rod gas of 1500 rods against the direct sum: the 99th percentile of the error falls with the
    order at a given opening angle and with the angle at a given order, and every error is within
    twice the value measured (:data:`MEASURED`)."""
    tips, direct = gas
    tree = build_tip_tree(*tips, leaf_size=leaf)
    p99 = {}
    for p in (4, 6):
        tab = fmm.tables(p)
        for theta in (0.3, 0.5):
            med, p99[p, theta] = _errors(fmm.fmm_forces(tree, tab, theta, RSTAR, KAPPA), direct)
            bound = MEASURED[leaf, p, theta]
            # a median of round-off (1e-14) moves with the vector width of the reference's sums: 1e-12
            # as for theta = 0
            assert med < max(2 * bound[0], 1e-12), (p, theta, med)
            assert p99[p, theta] < 2 * bound[1], (p, theta, p99[p, theta])
    assert p99[6, 0.5] < p99[4, 0.5] and p99[6, 0.3] < p99[4, 0.3]
    assert p99[4, 0.3] < p99[4, 0.5] and p99[6, 0.3] < p99[6, 0.5]


def test_every_pair_of_tips_is_taken_once_and_far_pairs_lie_outside_the_core():
    """On a small tree of 8-tip leaves, the ordered pairs of tips the far and near lists cover are
    every pair exactly once (a count per pair, not per tip), and no tip pair of a far cell pair is
    within r* (the far field is the Coulomb law only outside the core)."""
    tips = uniform_rods(150, np.random.default_rng(2), density=1.0)
    tree = build_tip_tree(*tips, leaf_size=8)
    lists = fmm.interaction_lists(tree, 0.6, RSTAR)
    assert lists.far.shape[0] > 0
    n = tree.x.shape[0]
    count = np.zeros((n, n), np.int64)
    span = [np.arange(s, e) for s, e in zip(tree.start, tree.end)]
    for a, b in np.vstack([lists.far, lists.near]):
        count[np.ix_(span[a], span[b])] += 1
        if a != b:
            count[np.ix_(span[b], span[a])] += 1
    assert np.all(count == 1)
    pos = np.stack([tree.x, tree.y, tree.z], axis=1)
    for a, b in lists.far:
        gap = np.linalg.norm(pos[span[a]][:, None, :] - pos[span[b]][None, :, :], axis=2)
        assert gap.min() > RSTAR


def test_a_rod_partner_taken_by_the_expansions_is_taken_off():
    """Rods 100 apart with leaves of one tip: every tip's partner is a far cell of radius 0 (its
    expansion exact), so the partner's force, about 1e6 times the other rods' dipole fields, comes
    through the expansions and must be taken off. At opening angle 0.1 and order 6 the rest is
    round-off of that force against the others' (1e-16 / 1e-6; measured 5.5e-10): 1e-8. (At 0.5 the
    cells that hold two rods 100 apart, mostly empty, are expanded with their charges at their
    edges, and the error is of order 1 there: a worst case of the opening-angle test, not of the
    partner.)"""
    rng = np.random.default_rng(4)
    centre = 100.0 * np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 1], [2, 0, 1]], dtype=float)
    tips = rods_to_tips(centre, rng.normal(size=(5, 3)), rng.uniform(2 / 3, 2, 5))
    tree = build_tip_tree(*tips, leaf_size=1)
    lists = fmm.interaction_lists(tree, 0.1, RSTAR)
    partner_far = {tuple(sorted(p)) for p in lists.far.tolist()}
    leaf_of = {tree.start[c]: c for c in range(tree.start.shape[0]) if tree.next[c] == c + 1}
    pairs = [tuple(sorted((leaf_of[tree.rank[2 * k]], leaf_of[tree.rank[2 * k + 1]]))) for k in range(5)]
    assert all(p in partner_far for p in pairs)  # the case this test is for
    direct = np.empty((10, 3))
    tip_tip_direct(*tips, RSTAR, KAPPA, 0, 10, direct)
    err = np.linalg.norm(fmm.fmm_forces(tree, fmm.tables(6), 0.1, RSTAR, KAPPA) - direct, axis=1)
    assert np.max(err / np.linalg.norm(direct, axis=1)) < 1e-8


def test_an_opening_angle_of_one_or_more_is_refused(gas):
    tree = build_tip_tree(*gas[0])
    for theta in (1.0, 1.5, -0.1):
        with pytest.raises(ValueError, match="opening angle"):
            fmm.interaction_lists(tree, theta, RSTAR)


def test_every_pair_of_leaves_is_taken_once(gas):
    """The dual walk covers every pair of tips exactly once: the far pairs' and the near pairs' tips
    multiply up to all ordered pairs."""
    tips, _ = gas
    tree = build_tip_tree(*tips, leaf_size=32)
    lists = fmm.interaction_lists(tree, 0.5, RSTAR)
    size = tree.end - tree.start
    cover = np.zeros((tree.x.shape[0],), np.int64)
    for a, b in np.vstack([lists.far, lists.near]):
        cover[tree.start[a] : tree.end[a]] += size[b]
        if a != b:
            cover[tree.start[b] : tree.end[b]] += size[a]
    assert np.all(cover == tree.x.shape[0])


@pytest.mark.parametrize("p", [1, 3, 6])
def test_moments_shifted_up_are_the_moments_of_all_the_tips(p):
    """P2M at the leaves and M2M up the tree (exact shifts of a polynomial) give every cell the moments
    sum_i q_i (x_i - c)^a / a! of all its tips about its own centre, summed here in numpy.
    Tolerance: sums of up to 600 terms of size up to max|q| (2 r)^p / a!, cancelling, in another order."""
    rng = np.random.default_rng(8)
    x, y, z, q = uniform_rods(300, rng)
    tree = build_tip_tree(x, y, z, q, leaf_size=8, group_size=8, order=4)
    tab = fmm.tables(p)
    moment = fmm.moments(tree, tab)
    idx = np.array(fmm.multi_indices(p))
    pos = np.stack([tree.x, tree.y, tree.z], 1)
    for c in range(len(tree.start)):
        s = pos[tree.start[c] : tree.end[c]] - tree.centre[c]
        qc = tree.charge[tree.start[c] : tree.end[c]]
        want = (qc[:, None] * np.prod(s[:, None, :] ** idx[None], axis=2)).sum(0) / tab.fact
        scale = np.abs(qc).max() * max(1.0, 2 * tree.radius[c]) ** p * len(qc)
        np.testing.assert_allclose(moment[c], want, rtol=0, atol=1e-12 * scale)
