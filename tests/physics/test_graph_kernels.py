"""The graph kernels (kernels/graph.py) against scipy and networkx, and the topology built on
them against the scipy/networkx implementation it replaced (tests/reference.py), bit for bit.

Exact equality everywhere: these are integer and boolean results, and the component
numbering feeds the circuit's node order (hence its round-off), so it must not change.
"""

import networkx as nx
import numpy as np
import pytest

import reference as ref
from selfas_graph.kernels.graph import component_labels, edges_in_blocks_of
from selfas_graph.model import events as ev
from selfas_graph.model.circuit import merge_tips, solve_circuit
from selfas_graph.model.graph import classify_rods

A, C = ev.CONDUCTOR_ANODE, ev.CONDUCTOR_CATHODE


def random_edges(n, m, rng):
    a = rng.integers(0, max(n, 1), size=m).astype(np.int64)
    b = rng.integers(0, max(n, 1), size=m).astype(np.int64)
    return a, b


@pytest.mark.parametrize("seed", range(12))
def test_component_labels_match_scipy(seed):
    """Same count and the same labels as scipy's connected_components (self-loops and repeated
    edges included), on sparse to dense random graphs."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 400))
    m = int(rng.integers(0, 2 * n))
    a, b = random_edges(n, m, rng)
    got = component_labels(n, a, b)
    want = ref.component_labels_scipy(n, a, b)
    assert got[0] == want[0]
    np.testing.assert_array_equal(got[1], want[1])


def test_component_labels_empty():
    empty = np.zeros(0, dtype=np.int64)
    assert component_labels(0, empty, empty)[0] == 0
    n, label = component_labels(3, empty, empty)
    assert n == 3 and label.tolist() == [0, 1, 2]


def _blocks_of_root_networkx(n, a, b, root):
    g = nx.Graph()
    g.add_nodes_from(range(n))
    g.add_edges_from(zip(a.tolist(), b.tolist()))
    inside = set()
    for block in nx.biconnected_component_edges(g):
        block = [tuple(sorted(e)) for e in block]
        if any(root in e for e in block):
            inside.update(block)
    return np.array([tuple(sorted(e)) in inside for e in zip(a.tolist(), b.tolist())], dtype=bool)


@pytest.mark.parametrize("seed", range(20))
def test_edges_in_blocks_of_root_match_networkx(seed):
    """The edges in blocks through the root are those of networkx's biconnected components
    that contain it, on simple random graphs from trees to meshes."""
    rng = np.random.default_rng(100 + seed)
    n = int(rng.integers(2, 300))
    m = int(rng.integers(1, 2 * n))
    a, b = random_edges(n, m, rng)
    code = np.unique(np.minimum(a, b) * n + np.maximum(a, b))
    a, b = code // n, code % n
    keep = a != b
    a, b = a[keep], b[keep]
    root = int(rng.integers(0, n))
    np.testing.assert_array_equal(edges_in_blocks_of(n, a, b, root), _blocks_of_root_networkx(n, a, b, root))


def test_edges_in_blocks_of_root_by_hand():
    """A triangle through the root, a bridge at the root, a tail behind a cut vertex,
    a cycle elsewhere, parallel edges away from the root, and an unreachable edge."""
    # 0 is the root: triangle 0-1-2, bridge 0-3, tail 2-4, cycle 4-5-6, parallel 3-7 twice, 8-9 apart
    a = np.array([0, 1, 2, 0, 2, 4, 5, 6, 3, 3, 8])
    b = np.array([1, 2, 0, 3, 4, 5, 6, 4, 7, 7, 9])
    got = edges_in_blocks_of(10, a, b, 0)
    assert got.tolist() == [True, True, True, True, False, False, False, False, False, False, False]


def aggregate(n_rods, rng, loops=0.05, free=0.1):
    """A Fig. 2-like network: rods attach tip to tip onto a growing forest (two or three
    tips per junction), some to the electrodes, with a few closing loops; some rods free."""
    tc, ct, cid = [], [], []
    for i in range(n_rods):
        r = rng.random()
        if r < free or i == 0:
            continue
        if r < free + 0.08:
            ct.append(2 * i + int(rng.integers(2)))
            cid.append(A if rng.random() < 0.5 else C)
        else:
            j = int(rng.integers(0, i))
            tc.append((2 * j + int(rng.integers(2)), 2 * i + int(rng.integers(2))))
        if rng.random() < loops:
            j = int(rng.integers(0, i))
            tc.append((2 * j + int(rng.integers(2)), 2 * i + 1))
    tc = sorted({tuple(sorted(p)) for p in tc if p[0] // 2 != p[1] // 2})
    return (np.array(tc, dtype=np.int64).reshape(-1, 2), np.array(ct, dtype=np.int64), np.array(cid, dtype=np.int64))


def _same_topology(got, want):
    for name in ("role", "structure", "structure_size"):
        np.testing.assert_array_equal(getattr(got, name), getattr(want, name), err_msg=name)
        assert getattr(got, name).dtype == getattr(want, name).dtype, name
    for name in ("largest_structure", "n_filament", "n_dead_end", "n_cluster", "n_free", "has_short_circuit"):
        assert getattr(got, name) == getattr(want, name), name


@pytest.mark.parametrize("seed", range(16))
@pytest.mark.parametrize("n_rods", [60, 1200])
def test_classify_rods_matches_scipy_networkx_version(seed, n_rods):
    """classify_rods gives the topology of the scipy/networkx implementation exactly (roles,
    structure ids and sizes, counts), on aggregates with and without loops, in case (i)
    (keys = conductor ids) and with per-contact keys (case (ii))."""
    rng = np.random.default_rng(1000 + seed)
    tc, ct, cid = aggregate(n_rods, rng, loops=[0.0, 0.05, 0.3, 0.8][seed % 4])
    key = cid if seed % 2 else np.where(rng.random(cid.size) < 0.4, 10 + np.arange(cid.size), cid)
    _same_topology(classify_rods(n_rods, tc, ct, key), ref.classify_rods_scipy_networkx(n_rods, tc, ct, key))
    n_tips = 2 * n_rods
    got, want = merge_tips(n_tips, tc), ref.merge_tips_scipy(n_tips, tc)
    assert got[0] == want[0]
    np.testing.assert_array_equal(got[1], want[1])


def test_classify_rods_matches_on_the_netlists_of_test_graph():
    """The same on the junction netlists of test_graph.py (dense junctions, parallel rods)."""
    from test_graph import netlist, random_netlist

    for seed in range(10):
        rng = np.random.default_rng(seed)
        n_rods, tc, ct, cid = netlist(random_netlist(300, int(rng.integers(20, 300)), rng), star=bool(seed % 2))
        _same_topology(classify_rods(n_rods, tc, ct, cid), ref.classify_rods_scipy_networkx(n_rods, tc, ct, cid))


def test_solve_circuit_node_order_unchanged():
    """The merged node numbering the circuit solve is built on is scipy's: the solution's
    node_of equals the reference labels, so the reduced system (and its round-off) is the same."""
    rng = np.random.default_rng(7)
    tc, ct, cid = aggregate(800, rng, loops=0.3)
    pot = np.where(cid == A, 1.115, -1.115)
    sol = solve_circuit(1600, tc, ct, pot)
    np.testing.assert_array_equal(sol.node_of_tip, ref.merge_tips_scipy(1600, tc)[1])


def test_unchanged_system_is_not_factorised_again(monkeypatch):
    """A solve through a memo whose reduced system equals the last one's returns the same bits
    without a new factorisation; a changed system is solved afresh; the returned arrays are
    copies; a solve without a memo, or with another memo, gives the same bits."""
    import selfas_graph.model.circuit as circuit
    import selfas_graph.model.linear as linear

    rng = np.random.default_rng(11)
    tc, ct, cid = aggregate(600, rng, loops=0.3)
    pot = np.where(cid == A, 1.115, -1.115)
    calls = []
    inner = linear._solve_spd_new
    monkeypatch.setattr(linear, "_solve_spd_new", lambda *a: calls.append(1) or inner(*a))
    memo = circuit.SolveMemo()
    first = solve_circuit(1200, tc, ct, pot, memo=memo)
    # a contact between two free rods far from any current leaves the reduced system as it is
    free_tips = np.setdiff1d(np.arange(1200), np.concatenate([tc.ravel(), ct]))
    free_rods = np.unique(free_tips // 2)
    free_rods = [r for r in free_rods if 2 * r in free_tips and 2 * r + 1 in free_tips][:2]
    extra = np.array([[2 * free_rods[0], 2 * free_rods[1]]])
    second = solve_circuit(1200, np.concatenate([tc, extra]), ct, pot, memo=memo)
    assert len(calls) == 1 and (memo.solved, memo.reused) == (1, 1)
    np.testing.assert_array_equal(second.current, first.current)
    assert second.total_current == first.total_current
    fresh = solve_circuit(1200, np.concatenate([tc, extra]), ct, pot)
    assert len(calls) == 2
    np.testing.assert_array_equal(fresh.potential, second.potential)
    other = circuit.SolveMemo()
    np.testing.assert_array_equal(solve_circuit(1200, tc, ct, pot, memo=other).potential, first.potential)
    assert len(calls) == 3
    solve_circuit(1200, tc, ct, pot * 2.0, memo=memo)  # another right-hand side: solved again
    assert len(calls) == 4 and memo.solved == 2


def test_solve_with_the_topologys_tip_merge_gives_the_same_bits():
    """The circuit solve handed the topology's merge of the tips (``merged=``, the tips merged
    once per event in a run) gives the bits of the solve that merges them itself."""
    from selfas_graph.model.graph import classify_rods

    rng = np.random.default_rng(5)
    tc, ct, cid = aggregate(600, rng, loops=0.3)
    pot = np.where(cid == A, 1.115, -1.115)
    topo = classify_rods(600, tc, ct, cid)
    a = solve_circuit(1200, tc, ct, pot)
    b = solve_circuit(1200, tc, ct, pot, merged=(topo.n_nodes, topo.node_of_tip))
    for name in ("potential", "current", "node_of_tip", "injected_current"):
        np.testing.assert_array_equal(getattr(b, name), getattr(a, name), err_msg=name)
    assert (b.total_current, b.dissipated_power) == (a.total_current, a.dissipated_power)


@pytest.mark.parametrize("seed", range(8))
def test_filament_rods_kernel_matches_networkx(seed):
    """kernels/graph.py::filament_rods, the blocks through X in one kernel, marks the rods the
    networkx version of the same rule marks (selfas_graph/bench/oracles.py), in case (i) and with
    per-contact keys, on the arguments classify_rods hands it."""
    from selfas_graph.bench.oracles import _filament_rods_networkx
    from selfas_graph.kernels.graph import filament_rods, structures

    rng = np.random.default_rng(2000 + seed)
    n_rods = 400
    tc, ct, cid = aggregate(n_rods, rng, loops=[0.05, 0.3, 0.8][seed % 3])
    key = cid if seed % 3 else np.where(rng.random(cid.size) < 0.4, 10 + np.arange(cid.size), cid)
    n_nodes, node_of_tip = merge_tips(2 * n_rods, tc)
    _, key_index = np.unique(key, return_inverse=True)
    key_index = key_index.astype(np.int64)
    n_keys = int(key_index.max()) + 1 if key_index.size else 0
    comp, _, _, _, _, _, candidate = structures(n_rods, node_of_tip, n_nodes, tc, ct, key_index)
    args = (n_nodes, node_of_tip[0::2], node_of_tip[1::2], comp, candidate, node_of_tip[ct], key_index, n_keys)
    assert candidate.any(), "a network of these seeds joins both electrodes"
    want = _filament_rods_networkx(*args)
    assert want.any()
    np.testing.assert_array_equal(filament_rods(*args), want)
