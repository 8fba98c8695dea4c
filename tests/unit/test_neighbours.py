"""The Verlet neighbour list holds every pair within the cut-off, before and after moves."""

import numpy as np
import pytest

import reference as ref
from selfas_graph.kernels.cells import INT32_MAX, list_dtype, max_displacement2, neighbour_rows
from selfas_graph.model.neighbours import NeighbourList

#: small inputs: also run with NUMBA_DISABLE_JIT=1, the kernels as Python (.ci/run)
pytestmark = pytest.mark.jit_off_ok


def listed(nl):
    return {(k, int(l)) for k in range(len(nl.start) - 1) for l in nl.index[nl.start[k] : nl.start[k + 1]] if k < l}


def test_list_covers_cutoff_through_moves(rng):
    """After random moves below skin/2 the list is reused and still covers the cut-off; beyond, it rebuilds."""
    x = rng.uniform(0, 5, (300, 3))
    nl = NeighbourList(0.6, 0.4, exclude_same_rod=True)
    assert nl.update(x)
    for _ in range(20):
        x = x + rng.normal(scale=0.03, size=x.shape)
        nl.update(x)
        assert ref.neighbour_pairs(x, 0.6, True) <= listed(nl)
    assert 1 < nl.n_builds < 20


def test_same_rod_pairs_excluded(rng):
    x = rng.uniform(0, 1, (40, 3))
    nl = NeighbourList(2.0, 0.1, exclude_same_rod=True)
    nl.build(x)
    assert all(k // 2 != l // 2 for k, l in listed(nl))
    assert listed(nl) == ref.neighbour_pairs(x, 2.1, True)


def test_compressed_rows_symmetric(rng):
    x = rng.uniform(0, 3, (100, 3))
    nl = NeighbourList(0.5, 0.1)
    nl.build(x)
    for k in range(100):
        for l in nl.index[nl.start[k] : nl.start[k + 1]]:
            assert k in nl.index[nl.start[l] : nl.start[l + 1]]


# -- the cell-list build (kernels/cells.py) against the brute-force pair set -------------------------


def rows(start, index):
    """The compressed rows as a set of ordered pairs; also checks no row lists a point twice."""
    out = set()
    for k in range(len(start) - 1):
        row = index[start[k] : start[k + 1]].tolist()
        assert len(set(row)) == len(row)
        out |= {(k, l) for l in row}
    return out


def both_ways(pairs):
    return pairs | {(l, k) for k, l in pairs}


@pytest.mark.parametrize("n", [0, 1, 2, 3])
def test_cell_rows_few_points(n):
    """0 and 1 points have no pairs; 2 and 3 points at hand-placed distances give exactly the close ones."""
    x = np.array([[0.0, 0.0, 0.0], [0.5, 0.0, 0.0], [0.0, 0.0, 2.0]])[:n]
    start, index = neighbour_rows(x, 1.0)
    assert start.shape == (n + 1,) and start[0] == 0 and start[-1] == len(index)
    expected = {(0, 1)} if n >= 2 else set()
    assert rows(start, index) == both_ways(expected)


def test_cell_rows_two_points_of_one_rod():
    """The two tips of one rod are no pair with exclude_same_rod; tips of different rods are."""
    x = np.array([[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.0, 0.1, 0.0]])
    assert rows(*neighbour_rows(x, 1.0, exclude_same_rod=True)) == both_ways({(0, 2), (1, 2)})
    assert rows(*neighbour_rows(x, 1.0)) == both_ways({(0, 1), (0, 2), (1, 2)})


@pytest.mark.parametrize("exclude", [False, True])
@pytest.mark.parametrize("box, radius", [(5.0, 0.6), (1.0, 2.0), (1e-3, 0.5), (50.0, 0.3)])
def test_cell_rows_equal_brute_force(rng, box, radius, exclude):
    """Same pair set as all-pairs distances: several cells per axis, all points in one cell, sparse points."""
    x = rng.uniform(-box, box, (300, 3))
    assert rows(*neighbour_rows(x, radius, exclude)) == both_ways(ref.neighbour_pairs(x, radius, exclude))


def test_cell_rows_flat_and_coincident_points(rng):
    """Points in a plane (one cell thick), on a line, and on top of each other are all found."""
    x = rng.uniform(0, 4, (200, 3))
    x[:, 2] = 0.0
    x[100:, 1] = 1.0
    x[150:160] = x[150]
    assert rows(*neighbour_rows(x, 0.7)) == both_ways(ref.neighbour_pairs(x, 0.7, False))


def test_cell_rows_points_far_apart(rng):
    """Clusters 1e12 apart: the grid is capped (memory stays O(n)) and every close pair is still found."""
    x = np.concatenate([rng.uniform(0, 1, (50, 3)), rng.uniform(0, 1, (50, 3)) + 1e12])
    start, index = neighbour_rows(x, 0.4, max_cells=64)
    assert rows(start, index) == both_ways(ref.neighbour_pairs(x, 0.4, False))


def test_cell_rows_independent_of_grid_and_deterministic(rng):
    """A coarser grid (cap on the cells) gives the same pairs; the same positions give identical rows."""
    x = rng.uniform(0, 6, (400, 3))
    a = neighbour_rows(x, 0.5)
    b = neighbour_rows(x.copy(), 0.5)
    c = neighbour_rows(x, 0.5, max_cells=8)
    np.testing.assert_array_equal(a[0], b[0])
    np.testing.assert_array_equal(a[1], b[1])
    assert rows(*a) == rows(*c)


@pytest.mark.parametrize("bad", [np.nan, np.inf, 1e200])
def test_build_with_broken_positions_lists_nothing(rng, bad):
    """A NaN, inf or absurdly far point does not crash the build; the list is empty until the run stops."""
    x = rng.uniform(0, 1, (20, 3))
    x[3, 1] = bad
    nl = NeighbourList(0.5, 0.1)
    nl.build(x)
    assert nl.start.shape == (21,) and len(nl.index) == 0 and nl.pairs.shape == (0, 2)


def test_pairs_sorted_once_each(rng):
    """``pairs`` holds each listed pair once, k < l, sorted by (k, l), and follows a rebuild."""
    x = rng.uniform(0, 2, (80, 3))
    nl = NeighbourList(0.5, 0.1)
    nl.build(x)
    p = nl.pairs
    assert set(map(tuple, p.tolist())) == ref.neighbour_pairs(x, 0.6, False)
    assert (p[:, 0] < p[:, 1]).all()
    np.testing.assert_array_equal(p, p[np.lexsort((p[:, 1], p[:, 0]))])
    nl.build(x[:10])
    assert set(map(tuple, nl.pairs.tolist())) == ref.neighbour_pairs(x[:10], 0.6, False)


def test_max_displacement_is_the_numpy_value_to_the_bit(rng):
    """The kernel the list checks its skin with gives what the numpy passes it replaced gave, bit for
    bit: the sum of the squared columns in the order (x + z) + y (numpy 2's einsum order for three)."""
    for n in (1, 7, 2400):
        r0 = rng.uniform(-10, 10, size=(n, 3))
        for scale in (1e-9, 1e-3, 1.0):
            x = r0 + scale * rng.normal(size=(n, 3))
            d = x - r0
            want = ((d[:, 0] * d[:, 0] + d[:, 2] * d[:, 2]) + d[:, 1] * d[:, 1]).max(initial=0.0)
            assert max_displacement2(x, r0) == want
    assert max_displacement2(np.zeros((0, 3)), np.zeros((0, 3))) == 0.0
    x = r0.copy()
    x[3, 1] = np.nan
    assert max_displacement2(x, r0) == np.inf  # NaN forces a rebuild, as the numpy check did


def test_cell_rows_on_the_radius_and_across_cells():
    """A pair exactly at the radius is not listed (the test is ``r < radius``), one a hair inside is,
    also when the two points are 2 cells apart (cells of side radius / 2) or more with a capped grid."""
    radius = 2.0  # the squared distances below are exact in binary
    x = np.array([[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 2.0 - 1e-12, 0.0], [0.0, 0.0, -2.0], [9.0, 9.0, 9.0]])
    expected = both_ways({(0, 2)})
    assert rows(*neighbour_rows(x, radius)) == expected
    assert rows(*neighbour_rows(x, radius, max_cells=2)) == expected


@pytest.mark.parametrize("n", [5, 7])
def test_cell_rows_odd_count_with_same_rod_excluded(rng, n):
    """With an odd number of points the last has no partner tip; the counts and the rows still agree."""
    x = rng.uniform(0, 0.5, (n, 3))
    assert rows(*neighbour_rows(x, 1.0, True)) == both_ways(ref.neighbour_pairs(x, 1.0, True))


def test_cell_rows_in_cell_order(rng):
    """Each row lists its neighbours in the order the cells are visited: ascending cell, then
    ascending point index within a cell (the module docstring), the same for any thread count."""
    from selfas_graph.kernels import cells

    x = rng.uniform(0, 4, (200, 3))
    radius = 0.9
    start, index = neighbour_rows(x, radius)
    lo, h, g = cells.cell_grid(x, radius / cells.CELLS_PER_RADIUS, max(16 * len(x), 1000))
    c = np.minimum(np.maximum(((x - lo) / h).astype(np.int64), 0), g - 1)
    cell = (c[:, 0] * g[1] + c[:, 1]) * g[2] + c[:, 2]
    for k in range(len(x)):
        row = index[start[k] : start[k + 1]]
        key = cell[row] * len(x) + row
        assert (np.diff(key) > 0).all()


@pytest.mark.parametrize("exclude", [False, True])
@pytest.mark.parametrize("n", [0, 1, 2, 150])
def test_rows_numbered_by_cell(rng, n, exclude):
    """The rows numbered by cell (``cell_order=True``) are the rows renumbered by the build's cell
    order (reference.rows_in_cell_order); the order is a permutation; the plain rows are unchanged."""
    x = rng.uniform(0, 3, (n, 3))
    start, index = neighbour_rows(x, 0.8, exclude)
    s2, i2, (order, start_t, index_t) = neighbour_rows(x, 0.8, exclude, cell_order=True)
    np.testing.assert_array_equal(s2, start)
    np.testing.assert_array_equal(i2, index)
    np.testing.assert_array_equal(np.sort(order), np.arange(n))
    ref_start, ref_index = ref.rows_in_cell_order(start, index, order)
    np.testing.assert_array_equal(start_t, ref_start)
    np.testing.assert_array_equal(index_t, ref_index)


def test_sorted_rows_of_a_list_with_and_without_cell_order(rng):
    """``sorted_rows`` is the same whether the build made it (``cell_order``) or it is made on first
    use, follows rebuilds, and is a trivial order for a broken (NaN) state that lists nothing."""
    x = rng.uniform(0, 3, (120, 3))
    a = NeighbourList(0.5, 0.1, cell_order=True)
    b = NeighbourList(0.5, 0.1)
    for points in (x, x + 0.3):
        a.build(points)
        b.build(points)
        for u, v in zip(a.sorted_rows, b.sorted_rows):
            np.testing.assert_array_equal(u, v)
    x[4, 0] = np.nan
    a.build(x)
    order, start, index = a.sorted_rows
    np.testing.assert_array_equal(order, np.arange(120))
    assert start.shape == (121,) and len(index) == 0


@pytest.mark.parametrize("rows", [(0, 0), (0, 37), (37, 80), (79, 80)])
def test_a_block_of_rows_is_those_rows_of_the_whole_list_bit_for_bit(rng, rows):
    """``neighbour_rows(..., rows=(lo, hi))`` (an MPI rank's block): the rows of the points in the
    block are the whole list's rows, in the same order, in plain and cell numbering; the others are
    empty."""
    x = rng.uniform(0.0, 3.0, size=(80, 3))
    start, index, (order, start_t, index_t) = neighbour_rows(x, 0.9, cell_order=True)
    s, i, (o, s_t, i_t) = neighbour_rows(x, 0.9, cell_order=True, rows=rows)
    assert np.array_equal(o, order)
    lo, hi = rows
    for k in range(80):
        got = i[s[k] : s[k + 1]]
        want = index[start[k] : start[k + 1]] if lo <= k < hi else np.zeros(0, np.int64)
        assert np.array_equal(got, want)
    for t, k in enumerate(order):
        got = i_t[s_t[t] : s_t[t + 1]]
        want = index_t[start_t[t] : start_t[t + 1]] if lo <= k < hi else np.zeros(0, np.int64)
        assert np.array_equal(got, want)
    nl = NeighbourList(0.6, 0.3, rows=rows)
    nl.build(x)
    assert np.array_equal(nl.start, s) and np.array_equal(nl.index, i)


def test_list_entries_are_int32_while_the_point_numbers_fit():
    """A list's entries are int32 up to 2^31 - 1 points and int64 beyond (no entry wraps around);
    its offsets int64, for every list the model makes (empty ones too: one compiled version of each
    kernel)."""
    assert list_dtype(0) == np.int32 and list_dtype(INT32_MAX) == np.int32
    assert list_dtype(INT32_MAX + 1) == np.int64
    x = np.random.default_rng(1).uniform(0, 2, (50, 3))
    start, index, (order, start_t, index_t) = neighbour_rows(x, 0.7, cell_order=True)
    assert index.dtype == index_t.dtype == np.int32 and start.dtype == start_t.dtype == order.dtype == np.int64
    for n in (0, 1):
        start, index = neighbour_rows(np.zeros((n, 3)), 0.7)
        assert index.dtype == np.int32 and start.dtype == np.int64
    nl = NeighbourList(0.5, 0.1)
    assert nl.index.dtype == np.int32 and nl.start.dtype == np.int64
    for points in (x, np.full((4, 3), np.nan)):
        nl.build(points)
        assert nl.index.dtype == np.int32 and nl.start.dtype == np.int64
    assert nl.pairs.dtype == np.int64


def test_int32_and_int64_lists_give_the_same_forces_bit_for_bit(rng):
    """The kernels read the same numbers whatever their integer type: every sum over a list is the
    same bit for bit with the entries as int32 (the builds') and as int64 (exact equality: the
    compiler may order a sum as it likes, and must not order it by the entries' type)."""
    from selfas_graph.kernels import brakes, contacts, tips, yukawa

    x = rng.uniform(0, 3, (200, 3))
    v = rng.normal(size=x.shape)
    q = rng.uniform(-1, 1, x.shape[0])
    start, index, (order, start_t, index_t) = neighbour_rows(x, 1.2, cell_order=True)
    wide = [(start, index, start_t, index_t), (start, index.astype(np.int64), start_t, index_t.astype(np.int64))]
    assert index.dtype == np.int32
    got = []
    for s, i, st, it in wide:
        r = {}
        for name, kernel in (("f64", yukawa.yukawa_centres_sorted), ("mixed", yukawa.yukawa_centres_sorted_mixed)):
            r[name] = np.zeros((x.shape[0], 3))
            kernel(x[order], q[order], order, st, it, 1.0, 0.06, 1.2, 0, x.shape[0], r[name])
        r["yukawa"] = np.zeros((x.shape[0], 3))
        yukawa.yukawa_centres(x, q, s, i, 1.0, 0.06, 1.2, 0, x.shape[0], r["yukawa"])
        r["energy"] = np.zeros(x.shape[0])
        yukawa.yukawa_energy(x, q, s, i, 1.0, 0.06, 1.2, 0, x.shape[0], r["energy"])
        r["fast"] = np.zeros((x.shape[0], 3))
        tips.tip_tip_fast(x, q, s, i, 0.06, 100.0, 0.6, 0.9, r["fast"])
        r["brake"] = np.zeros((x.shape[0], 3))
        brakes.tip_brake(x, v, s, i, 0.5, 3.0, r["brake"])
        r["pairs"] = contacts.close_pairs(x, s, i, 0.5)
        r["fast rows"] = np.zeros((x.shape[0], 3))
        tips.tip_tip_fast_rows(x, q, s, i, 0.06, 100.0, 0.6, 0.9, 20, 150, r["fast rows"])
        r["pair k"], r["pair l"] = np.zeros(s[-1], np.int64), np.zeros(s[-1], np.int64)
        m = brakes.close_pairs_rows(x, s, i, 0.5, 20, 150, r["pair k"], r["pair l"], s[20])
        r["pair k"], r["pair l"] = r["pair k"][s[20] : s[20] + m], r["pair l"][s[20] : s[20] + m]
        got.append(r)
    assert got[0]["pairs"].shape[0] > 0
    for key in got[0]:
        assert np.any(got[0][key]), key
        np.testing.assert_array_equal(got[0][key], got[1][key], err_msg=key)
