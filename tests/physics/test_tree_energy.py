"""The tip-tip energy by the tree (kernels/treeenergy.py, kernels/tree.py::tip_tree_energy) against
the direct sum, and the potential of a cell's moments (kernels/multipole.py) against its field and
its tips.

The oracle of the rows is a numpy sum over all tip pairs of the pair law (``laws.tip_potential``,
itself checked against its force in tests/unit/test_laws.py); of the total, the direct kernel
``tips.py::tip_tip_energy``.
"""

import numpy as np
import pytest
from test_tree import KAPPA, RSTAR, chain_rods, cluster_and_targets, uniform_rods

from conftest import random_rods, simulation
from selfas_graph.kernels import multipole as km
from selfas_graph.kernels.tips import tip_tip_energy
from selfas_graph.kernels.tree import build_tip_tree, tip_tree_energy


def pair_energies(x, y, z, q):
    """(n, n) matrix of the pair law U(r_kl) between tips of different rods (0 on a rod's own pairs)."""
    p = np.stack([x, y, z], 1)
    r = np.linalg.norm(p[:, None] - p[None], axis=2)
    qq = q[:, None] * q[None]
    inner = qq * (3 * RSTAR**2 - r**2) / (2 * RSTAR**3) + KAPPA * (RSTAR - r) ** 2 / (2 * RSTAR**3)
    with np.errstate(divide="ignore"):
        u = np.where(r >= RSTAR, qq / r, inner)
    rod = np.arange(len(x)) // 2
    u[rod[:, None] == rod[None]] = 0.0
    return u


def direct_total(x, y, z, q):
    e = np.empty(len(x))
    tip_tip_energy(x, y, z, q, RSTAR, KAPPA, 0, len(x), e)
    return e.sum()


def tree_rows(tips, theta, **knobs):
    t = build_tip_tree(*tips, **knobs)
    return tip_tree_energy(t, RSTAR, KAPPA, theta, np.empty(len(tips[0])))


@pytest.fixture(scope="module")
def gas():
    return uniform_rods(600, np.random.default_rng(3))


@pytest.fixture(scope="module")
def aggregates():
    return chain_rods(24, 25, np.random.default_rng(5))


@pytest.mark.parametrize("config", ["gas", "aggregates"])
@pytest.mark.parametrize("order", [2, 4])
def test_zero_opening_angle_gives_the_direct_rows(config, order, request):
    """theta = 0 accepts no cell: every row is half the exact energy of its tip with the tips of other
    rods (core pairs included, the rod's own pair left out), and the rows add up to the direct
    kernel's total, to round-off (sums of a few thousand terms of both signs: 1e-12 of the largest
    row or of the sum of |rows|)."""
    tips = request.getfixturevalue(config)
    rows = tree_rows(tips, 0.0, order=order)
    expected = 0.5 * pair_energies(*tips).sum(axis=1)
    np.testing.assert_allclose(rows, expected, rtol=1e-12, atol=1e-12 * np.abs(expected).max())
    assert abs(rows.sum() - direct_total(*tips)) <= 1e-12 * np.abs(rows).sum()


# measured with these seeds, order 4, leaves of 64 and groups of 128 (GROUPS: several groups in these small
# scenes, whose tips a group of the default 1024 would hold whole): |E_tree - E| / sum |U_kl| over pairs
# gas 0.7: 3.5e-7, 0.475: 2.2e-7, 0.3: 4.1e-9; aggregates 0.7: 4.4e-8, 0.475: 1.6e-9, 0.3: 4.2e-10
BOUNDS = {"gas": {0.7: 8e-7, 0.475: 5e-7, 0.3: 1e-8}, "aggregates": {0.7: 1e-7, 0.475: 4e-9, 0.3: 1e-9}}
GROUPS = 128


@pytest.mark.parametrize("config", ["gas", "aggregates"])
def test_error_is_small_against_the_pair_energies_and_falls_with_theta(config, request):
    """The total's error, in units of the sum of |U| over all pairs (the scale the far field's
    truncation acts on; the total itself is a near cancellation in a rod gas), stays below about
    twice the value measured (BOUNDS) and falls as the opening angle falls."""
    tips = request.getfixturevalue(config)
    u = pair_energies(*tips)
    exact, scale = 0.5 * u.sum(), 0.5 * np.abs(u).sum()
    last = np.inf
    for theta in (0.7, 0.475, 0.3):
        err = abs(tree_rows(tips, theta, group_size=GROUPS).sum() - exact) / scale
        assert err < BOUNDS[config][theta], (theta, err)
        assert err < last, (theta, err, last)
        last = err


def test_rod_partner_in_an_accepted_cell_is_taken_out():
    """With leaves and groups of one tip, the rod partner of every tip sits in an accepted cell
    from a small opening angle on: its Coulomb term must be taken out of the moments' sum (left in,
    each row would be off by q_k q_p / (2 l), of order 1). At theta 0.05 what is left is the
    truncation of the clusters' moments, about theta^5: measured 7e-10 of the largest row's sum of
    |U| in a row, 1.3e-11 of the sum of |U| in the total."""
    tips = chain_rods(6, 10, np.random.default_rng(9))
    u = pair_energies(*tips)
    rows = tree_rows(tips, 0.05, leaf_size=1, group_size=1)
    assert abs(rows.sum() - 0.5 * u.sum()) < 1e-10 * np.abs(u).sum()
    np.testing.assert_allclose(rows, 0.5 * u.sum(axis=1), rtol=0, atol=2e-9 * np.abs(u).sum(axis=1).max())


@pytest.mark.parametrize("order", [2, 3, 4])
def test_multipole_potential_is_the_potential_of_its_field_and_of_its_tips(order):
    """potential_hexadecapole of one cell's moments: minus its central-difference gradient is the
    field kernel of the same order (step 1e-4 at distance 6-24: the difference's error h^2 phi''' / 6,
    about 1e-10 of the field, 1e-7 leaves room for round-off of phi / h); against the Coulomb
    potential of the cell's tips its truncation error falls as 1/d^(p+2) (the first moment left out),
    so doubling the distance divides it by 2^(p+2): 16, 32, 64 (measured 16.3-16.6, 33-34, 67-71;
    the difference quotient matched the field to 4e-11-1.5e-10)."""
    tips, points = cluster_and_targets(np.random.default_rng(12))
    t = build_tip_tree(*tips, leaf_size=len(tips[0]), order=order)  # one cell: the root
    mc, c = t.moment[0], t.centre[0]
    errors = []
    for p in points:
        d = p - c
        h = 1e-4
        grad = [
            (km.potential_hexadecapole(*(d + h * e), *mc) - km.potential_hexadecapole(*(d - h * e), *mc)) / (2 * h)
            for e in np.eye(3)
        ]
        field = km.field_hexadecapole(*d, *mc) if order == 4 else km.field_octupole(*d, *mc[:16])
        np.testing.assert_allclose(-np.array(grad), field, rtol=1e-7)
        exact = sum(qk / np.linalg.norm(p - xk) for qk, xk in zip(tips[3], np.stack(tips[:3], 1)))
        errors.append(abs(km.potential_hexadecapole(*d, *mc) - exact))
    ratios = np.array(errors[:-1]) / np.array(errors[1:])
    expected = 2.0 ** (order + 2)
    assert np.all((ratios > 0.8 * expected) & (ratios < 1.25 * expected)), ratios


def test_groups_split_the_rows():
    """Groups evaluated in two runs fill the same rows bit for bit as all at once (how MPI ranks split them)."""
    from selfas_graph.kernels.tree import group_bounds

    tips = uniform_rods(300, np.random.default_rng(4))
    t = build_tip_tree(*tips, group_size=GROUPS)
    assert t.group.shape[0] > 2
    whole = tip_tree_energy(t, RSTAR, KAPPA, 0.475, np.empty(len(tips[0])))
    bounds, _ = group_bounds(t, 2)
    parts = np.full(len(tips[0]), np.nan)
    for r in range(2):
        tip_tree_energy(t, RSTAR, KAPPA, 0.475, parts, groups=bounds[r : r + 2])
    assert np.array_equal(parts, whole)


def test_invalid_input():
    tips = uniform_rods(20, np.random.default_rng(1))
    t = build_tip_tree(*tips)
    with pytest.raises(ValueError, match="theta"):
        tip_tree_energy(t, RSTAR, KAPPA, 1.0, np.empty(40))
    with pytest.raises(ValueError, match="out"):
        tip_tree_energy(t, RSTAR, KAPPA, 0.5, np.empty((40, 3)))
    with pytest.raises(ValueError, match="groups"):
        tip_tree_energy(t, RSTAR, KAPPA, 0.5, np.empty(40), groups=(0, 10**6))


def test_energy_tree_above_picks_the_tree_energy():
    """forces.tip_magnetic.energy_tree_above: the frame's tip-tip energy by the tree from that many
    rods on, the direct sum below; at a tiny opening angle the two agree to round-off, at the
    default angle within the tree's error (groups of 16 tips, so that cells are taken as multipoles
    in these 400 tips, 15 groups: measured 1.6e-7 of the sum of |U|; the one group of the default 1024 would
    sum every pair directly); group_size reaches the energy's tree."""
    state = random_rods(200, np.random.default_rng(6), box=6.0)

    def energy(**tip_magnetic):
        sim = simulation(
            state, forces={"tip_magnetic": tip_magnetic}, placement={"box": [[-3.5, 3.5]] * 3, "min_tip_distance": 0.0}
        )
        term = next(t for t in sim.force_field.terms if t.name == "tip_magnetic")
        return term.tree_energy, sim.energies()["tip_magnetic"]

    tree0, e_direct = energy()
    tree1, e_fine = energy(energy_tree_above=200, opening_angle=1e-6)
    tree2, e_tree = energy(energy_tree_above=200, group_size=16)
    assert (tree0, tree1, tree2) == (False, True, True)
    p = state.position
    scale = 0.5 * np.abs(pair_energies(p[:, 0], p[:, 1], p[:, 2], state.tip_charge)).sum()
    assert abs(e_fine - e_direct) < 1e-12 * scale
    assert 1e-12 * scale < abs(e_tree - e_direct) < 4e-7 * scale
    x, y, z = (np.ascontiguousarray(p[:, d]) for d in range(3))
    t16 = build_tip_tree(x, y, z, state.tip_charge, group_size=16)
    assert e_tree == tip_tree_energy(t16, RSTAR, KAPPA, 0.55, np.empty(len(x))).sum()


def test_tree_energy_passes_nan_on_to_the_health_check():
    """A NaN position (a run gone wrong): no tree can place it, so the energy falls back to the direct
    sum, which gives NaN, as the force does, and the run's health check stops with a diagnosis
    instead of an error from the tree build."""
    state = random_rods(40, np.random.default_rng(2), box=6.0)
    sim = simulation(
        state,
        forces={"tip_magnetic": {"energy_tree_above": 1}},
        placement={"box": [[-3.5, 3.5]] * 3, "min_tip_distance": 0.0},
    )
    sim.state.position[5, 1] = np.nan
    assert np.isnan(sim.energies()["tip_magnetic"])
