"""Measures of the paper's claims on hand-built objects with known answers (docs/model.md "Measures of the paper's claims").

The objects: a straight chain, a ring, a planar square-lattice sheet, a compact cubic-lattice
block, and a pair of rods head-to-tail and head-to-head. Tips that coincide are in contact.
"""

import itertools

import numpy as np
import pytest
from scipy.spatial import cKDTree

from selfas_graph.analysis.fractal import radius_of_gyration
from selfas_graph.analysis.moments import (
    current_moment,
    junction_charge,
    monopole_moment,
    rod_moment,
    unpaired_charge,
)
from selfas_graph.analysis.skeleton import contact_nodes, cycle_rank, junction_degrees, loop_lengths, structures

ROUND_OFF = 1e-9  # sums of a few thousand unit-size terms: far below any physical difference


def build(a, b, q=1.0):
    """Tips a, b of each rod -> (position, tip charge +q on a and -q on b, coinciding tips in contact)."""
    a, b = np.asarray(a, float).reshape(-1, 3), np.asarray(b, float).reshape(-1, 3)
    pos = np.empty((2 * len(a), 3))
    pos[0::2], pos[1::2] = a, b
    charge = np.empty(2 * len(a))
    charge[0::2], charge[1::2] = q, -q
    pairs = np.array(sorted(cKDTree(pos).query_pairs(1e-6)), dtype=np.int64).reshape(-1, 2)
    return pos, charge, pairs[pairs[:, 0] // 2 != pairs[:, 1] // 2]


def chain(n, q=1.0, direction=(1.0, 0.0, 0.0)):
    """n rods head to tail (tip b of rod i on tip a of rod i+1) along ``direction`` from the origin."""
    pts = np.arange(n + 1.0)[:, None] * np.asarray(direction)
    return build(pts[:-1], pts[1:], q)


def ring(n, q=1.0):
    """n rods head to tail around a regular polygon in the plane z = 0, counter-clockwise."""
    radius = 0.5 / np.sin(np.pi / n)
    phi = 2 * np.pi * np.arange(n + 1) / n
    pts = np.column_stack([radius * np.cos(phi), radius * np.sin(phi), 0 * phi])
    return build(pts[:-1], pts[1:], q)


def lattice(L, dim, closed=True):
    """Unit rods on the edges of a square (dim 2, plane z = 0) or cubic (dim 3) lattice of L cells a side.

    ``closed``: every edge of the L^dim cells; else one rod per node of [0, L)^dim along each
    axis (dim L^dim rods: the far faces left open), whose rod count grows exactly as L^dim.
    """
    a = []
    nodes = range(L + 1) if closed else range(L)
    for p in itertools.product(*([nodes] * dim + [range(1)] * (3 - dim))):
        for d in range(dim):
            if p[d] < L:
                a.append((np.array(p, float), np.eye(3)[d]))
    start = np.array([x for x, _ in a])
    return build(start, start + np.array([e for _, e in a]))


def pair(head_to_head):
    """Two unit rods along x meeting at the origin: +q tip on -q tip (head to tail) or +q on +q."""
    if head_to_head:
        return build([[0, 0, 0], [0, 0, 0]], [[-1, 0, 0], [1, 0, 0]])
    return build([[-1, 0, 0], [0, 0, 0]], [[0, 0, 0], [1, 0, 0]])


# ----------------------------------------------------------------------------- moments
def test_chain_moment_is_n_times_the_rod_moment():
    pos, q, tc = chain(12, q=1.5)
    label, size = structures(12, tc)
    assert size.tolist() == [12]
    m = monopole_moment(pos, q, label)
    np.testing.assert_allclose(m, [[-12 * 1.5, 0, 0]], atol=ROUND_OFF)  # from -q (b) to +q (a): -x
    np.testing.assert_allclose(np.linalg.norm(rod_moment(pos, q), axis=1), 1.5, atol=ROUND_OFF)
    # only the two end tips are free, one +q and one -q; the junctions are balanced
    assert unpaired_charge(q, tc, label).tolist() == [3.0]
    _, node = contact_nodes(12, tc)
    assert junction_charge(q, node, label).tolist() == [0.0]


def test_moment_does_not_depend_on_the_origin():
    pos, q, tc = chain(5, direction=(0.0, 0.6, 0.8))
    label, _ = structures(5, tc)
    np.testing.assert_allclose(
        monopole_moment(pos + [3, -7, 11], q, label), monopole_moment(pos, q, label), atol=ROUND_OFF
    )


def test_rod_pairs_head_to_tail_and_head_to_head():
    pos, q, tc = pair(head_to_head=False)
    label, _ = structures(2, tc)
    np.testing.assert_allclose(monopole_moment(pos, q, label), [[-2, 0, 0]], atol=ROUND_OFF)
    assert unpaired_charge(q, tc, label).tolist() == [2.0]
    pos, q, tc = pair(head_to_head=True)
    label, _ = structures(2, tc)
    np.testing.assert_allclose(monopole_moment(pos, q, label), [[0, 0, 0]], atol=ROUND_OFF)
    assert unpaired_charge(q, tc, label).tolist() == [2.0]  # the two -q ends
    _, node = contact_nodes(2, tc)
    assert junction_charge(q, node, label).tolist() == [2.0]  # +q and +q meet


def test_ring_current_moment_is_current_times_area():
    n, J = 16, 0.7
    pos, q, tc = ring(n)
    label, _ = structures(n, tc)
    area = 0.5 * n * (0.5 / np.sin(np.pi / n)) ** 2 * np.sin(2 * np.pi / n)
    m = current_moment(pos, np.full(n, J), label)
    np.testing.assert_allclose(m, [[0, 0, J * area]], atol=ROUND_OFF)  # counter-clockwise: +z
    # a closed loop's moment does not depend on the origin
    np.testing.assert_allclose(current_moment(pos, np.full(n, J), label, origin=(2.0, -1.0, 5.0)), m, atol=ROUND_OFF)
    # a closed head-to-tail ring has no monopole moment and no free tip
    np.testing.assert_allclose(monopole_moment(pos, q, label), 0.0, atol=ROUND_OFF)
    assert unpaired_charge(q, tc, label).tolist() == [0.0]


def test_open_chains_off_the_axis_current_moment_by_hand():
    """m_J = (1/2) sum_i J_i (x_a,i x x_b,i) about the scene axis (docs/model.md "Measures of the paper's
    claims"), per structure, on two open chains off the z axis whose cross products are worked out by hand.

    Chain A: three unit rods (1,0,0) -> (1,1,0) -> (1,1,1) -> (0,1,1) with currents 2, -0.5, 3 (different
    from rod to rod, as where a chain's junctions also touch a conductor, which joins no structure):
    x_a x x_b = (0,0,1), (1,-1,0), (0,-1,1), so m_J = (1/2)((0,0,2) + (-0.5,0.5,0) + (0,-3,3))
    = (-0.25, -1.25, 2.5). Chain B: (0,-2,0) -> (0,-2,1) -> (-1,-2,1) with currents 1, 1:
    (-2,0,0) and (0,-1,-2), m_J = (-1, -0.5, -1). A wrong sign, factor, tip order or current of a rod
    changes these numbers. An open chain's moment depends on the point o of the axis: m_J(o) = m_J(0)
    - (1/2) sum_i J_i o x (x_b,i - x_a,i), which for o along z leaves m_J,z alone; with o = (0,0,5):
    o x (x_b - x_a) = (-5,0,0), 0, (0,-5,0) on chain A, 0, (0,-5,0) on chain B.
    Every coordinate, current and product here is a small multiple of 1/4, exact in float64: the
    moments are compared exactly.
    """
    a = [[1, 0, 0], [1, 1, 0], [1, 1, 1], [0, -2, 0], [0, -2, 1]]
    b = [[1, 1, 0], [1, 1, 1], [0, 1, 1], [0, -2, 1], [-1, -2, 1]]
    pos, _, tc = build(a, b)
    label, size = structures(5, tc)
    assert sorted(size.tolist()) == [2, 3] and label[0] == label[1] == label[2] != label[3] == label[4]
    current = np.array([2.0, -0.5, 3.0, 1.0, 1.0])
    m = current_moment(pos, current, label)
    np.testing.assert_array_equal(m[label[0]], [-0.25, -1.25, 2.5])
    np.testing.assert_array_equal(m[label[3]], [-1.0, -0.5, -1.0])
    shifted = current_moment(pos, current, label, origin=(0.0, 0.0, 5.0))
    np.testing.assert_array_equal(shifted[label[0]], [-0.25 + 5.0, -1.25 + 7.5, 2.5])
    np.testing.assert_array_equal(shifted[label[3]], [-1.0, -0.5 + 2.5, -1.0])


# ----------------------------------------------------------------------------- skeleton
@pytest.mark.parametrize(
    "obj, rank, lengths, degrees",
    [
        (chain(10), 0, {}, {2: 9}),
        (ring(12), 1, {12: 1}, {2: 12}),
        (lattice(5, 2), 25, {4: 25}, {2: 4, 3: 16, 4: 16}),
        (lattice(2, 3), 28, {4: 28}, {3: 8, 4: 12, 5: 6, 6: 1}),  # E - V + 1 = 54 - 27 + 1
        (pair(True), 0, {}, {2: 1}),
    ],
)
def test_skeleton_of_hand_built_objects(obj, rank, lengths, degrees):
    pos, q, tc = obj
    n = len(q) // 2
    total, per = cycle_rank(n, tc)
    assert total == rank and per.tolist() == [rank]
    for method in ("minimum", "shortest"):
        ll = loop_lengths(n, tc, method=method)
        assert dict(zip(*np.unique(ll, return_counts=True))) == lengths
    assert dict(zip(*np.unique(junction_degrees(n, tc), return_counts=True))) == degrees


def test_fundamental_basis_has_as_many_loops_and_parallel_rods_make_loops_of_two():
    pos, q, tc = lattice(3, 3)
    n = len(q) // 2
    total, _ = cycle_rank(n, tc)
    assert len(loop_lengths(n, tc, method="fundamental")) == total == 3 * 3 * 16 - 64 + 1
    # the shortest loop through each edge off a spanning tree: every one a face of the lattice
    assert loop_lengths(n, tc, method="shortest").tolist() == [4] * total
    # two rods sharing both junctions, and a free rod: one loop of two, the free rod no loop
    pos, q, tc = build([[0, 0, 0], [0, 0, 0], [5, 5, 5]], [[1, 0, 0], [1, 0, 0], [6, 5, 5]])
    assert cycle_rank(3, tc)[0] == 1 and loop_lengths(3, tc).tolist() == [2]


# ----------------------------------------------------------------------------- fractal measures
def test_radius_of_gyration_of_a_chain():
    pos, _, _ = chain(20)
    rg, size = radius_of_gyration(pos)
    np.testing.assert_allclose(rg, [20 / np.sqrt(12)], rtol=1e-12)  # N / sqrt(12), round-off
    assert size.tolist() == [20]


# the dimensions themselves: tests/unit/test_fractal.py (objects of known dimension at the runs' sizes)
