"""Tests of the connectivity graph and the rod topology (docs/model.md 'Connectivity graph and topology').

Networks are netlists: rods between named junctions; tips at a junction are
stuck by ideal contacts, tips at ``"P"`` touch the anode and at ``"N"`` the
cathode. Roles are checked against hand reasoning, against a brute-force
oracle (enumerate every simple path between two different conductor
attachments with networkx) on small random graphs, and against the rule applied
literally with networkx (no reductions) on larger ones. Currents come from the
circuit solve; their tolerance is the round-off of a sparse solve (~1e-14
observed, 1e-12 allowed).
"""

from collections import defaultdict

import networkx as nx
import numpy as np
import pytest

import reference as ref
from selfas_graph.model import events as ev
from selfas_graph.model.graph import (
    CLUSTER,
    DEAD_END,
    FILAMENT,
    FREE,
    ROLE_NAMES,
    ConnectivityGraph,
    classify_rods,
)

#: small inputs: also run with NUMBA_DISABLE_JIT=1, the kernels as Python (.ci/run)
pytestmark = pytest.mark.jit_off_ok

A, C, F = ev.CONDUCTOR_ANODE, ev.CONDUCTOR_CATHODE, ev.CONDUCTOR_FILAMENT
#: delta_J0 of the paper's Fig. 2 scene
DELTA = 2.23
#: round-off of a sparse solve on networks of <= a few hundred rods (observed ~1e-14)
TOL = 1e-12


# ------------------------------------------------------------------------------ helpers
def netlist(rods, star=True):
    """``(n_rods, tip_contacts, conductor_tip, conductor_id)`` of rods between named junctions."""
    tips_at = defaultdict(list)
    for i, (ja, jb) in enumerate(rods):
        tips_at[ja].append(2 * i)
        tips_at[jb].append(2 * i + 1)
    contacts, ctip, cid = [], [], []
    for j, tips in tips_at.items():
        if j in ("P", "N"):
            ctip += tips
            cid += [A if j == "P" else C] * len(tips)
        elif star:
            contacts += [tuple(sorted((tips[0], t))) for t in tips[1:]]
        else:
            contacts += [tuple(sorted(p)) for p in zip(tips[:-1], tips[1:])]
    return (
        len(rods),
        np.array(sorted(contacts), dtype=np.int64).reshape(-1, 2),
        np.array(ctip, dtype=np.int64),
        np.array(cid, dtype=np.int64),
    )


def electrode_graph(rods, voltage=DELTA, star=True):
    """A ConnectivityGraph (case (i), electrodes at -+voltage/2) holding a netlist."""
    n_rods, tc, ct, cid = netlist(rods, star)
    g = ConnectivityGraph(n_rods, {C: -voltage / 2, A: voltage / 2})
    for k, l in tc.tolist():
        g.add_tip_contact(k, l)
    for k, c in zip(ct.tolist(), cid.tolist()):
        g.add_conductor_contact(k, c)
    return g


def roles(rods):
    n_rods, tc, ct, cid = netlist(rods)
    return classify_rods(n_rods, tc, ct, cid)


def random_netlist(n_rods, n_junctions, rng, free_fraction=0.1):
    """Rods between random junctions (P and N among them); some free rods."""
    names = ["P", "N"] + [f"j{k}" for k in range(n_junctions - 2)]
    rods = []
    for i in range(n_rods):
        if rng.random() < free_fraction:
            rods.append((f"free{i}a", f"free{i}b"))
        else:
            a, b = rng.choice(len(names), size=2, replace=False)
            rods.append((names[a], names[b]))
    return rods


# ------------------------------------------------------------------------------ roles by hand
def test_role_codes():
    """Role codes are the documented constants, with names."""
    assert (FREE, CLUSTER, DEAD_END, FILAMENT) == (0, 1, 2, 3)
    assert ROLE_NAMES == {0: "free", 1: "cluster", 2: "dead_end", 3: "filament"}


def test_chain_is_filament_and_free_rods_are_free():
    """A chain spanning the gap is FILAMENT (one structure); untouched rods are FREE, structure -1."""
    t = roles([("P", "x"), ("x", "y"), ("y", "N"), ("f1", "f2"), ("f3", "f4")])
    np.testing.assert_array_equal(t.role, [FILAMENT] * 3 + [FREE] * 2)
    np.testing.assert_array_equal(t.structure, [0, 0, 0, -1, -1])
    np.testing.assert_array_equal(t.structure_size, [3])
    assert t.largest_structure == 0 and t.has_short_circuit
    assert (t.n_filament, t.n_dead_end, t.n_cluster, t.n_free) == (3, 0, 0, 2)


def test_single_rod_across_gap_is_filament_with_current_delta():
    """One rod touching both electrodes: FILAMENT, current delta_J0 (gap of one rod)."""
    g = electrode_graph([("P", "N")])
    assert g.topology().role.tolist() == [FILAMENT]
    assert g.solve().current[0] == pytest.approx(DELTA, abs=TOL)


def test_balanced_bridge_rod_is_filament_with_zero_current():
    """Balanced Wheatstone bridge: the bridge rod carries 0 but is FILAMENT (docs/model.md 'Connectivity graph and topology')."""
    g = electrode_graph([("P", "x"), ("x", "N"), ("P", "y"), ("y", "N"), ("x", "y")], DELTA * 2)
    assert np.all(g.topology().role == FILAMENT)
    sol = g.solve()
    assert abs(sol.current[4]) < TOL
    np.testing.assert_allclose(sol.current[:4], DELTA, atol=TOL)


def test_unbalanced_bridge_all_filament_bridge_current_by_hand():
    """Unbalanced bridge (arms of 1 and 2 rods): all FILAMENT, bridge current V/7 (hand nodal solve).

    Nodes x = 4V/7, y = 3V/7 above the cathode (see test_circuit for the algebra).
    """
    V = 0.7
    rods = [("P", "x"), ("x", "m"), ("m", "N"), ("P", "n"), ("n", "y"), ("y", "N"), ("x", "y")]
    g = electrode_graph(rods, V)
    assert np.all(g.topology().role == FILAMENT)
    assert g.solve().current[6] == pytest.approx(V / 7, abs=TOL)


def test_dangling_branch_and_hanging_loop_are_dead_ends():
    """A branch x-d1-d2 and a triangle hanging off a filament: DEAD_END, zero current."""
    rods = [("P", "x"), ("x", "y"), ("y", "N"), ("x", "d1"), ("d1", "d2"),
            ("y", "l1"), ("l1", "l2"), ("l2", "y")]  # fmt: skip
    g = electrode_graph(rods, DELTA * 3)
    t = g.topology()
    np.testing.assert_array_equal(t.role, [FILAMENT] * 3 + [DEAD_END] * 5)
    assert t.n_structures == 1
    np.testing.assert_allclose(g.solve().current[3:], 0.0, atol=TOL)


def test_structure_touching_one_electrode_twice_is_dead_end():
    """A U touching the anode at two points (and a loop on it): no short circuit, DEAD_END.

    The path anode -> U -> anode joins two contacts of the same attachment (same
    potential), so it is no filament; no current flows.
    """
    rods = [("P", "x"), ("x", "y"), ("y", "P"), ("x", "z"), ("z", "y")]
    g = electrode_graph(rods)
    t = g.topology()
    assert np.all(t.role == DEAD_END) and not t.has_short_circuit
    sol = g.solve()
    assert np.all(sol.current == 0.0) and sol.total_current == 0.0


def test_loop_pinned_at_one_electrode_is_dead_end_even_where_it_leads_on():
    """A loop whose two ends both touch the cathode carries nothing, even though its far end
    is a junction from which a rod leads on to the anode.

    Rods 0 and 1 run cathode -> x -> y, and y touches the cathode too; rod 2 runs y -> anode.
    Contacts are ideal, so y sits at the cathode's potential: rods 0 and 1 have both ends
    pinned there (DEAD_END, zero current); rod 2 alone carries delta_J0 (a one-rod chain).
    """
    g = ConnectivityGraph(3, {C: -DELTA / 2, A: DELTA / 2})
    g.add_conductor_contact(0, C)
    g.add_tip_contact(1, 2)
    g.add_tip_contact(3, 4)
    g.add_conductor_contact(3, C)
    g.add_conductor_contact(5, A)
    np.testing.assert_array_equal(g.topology().role, [DEAD_END, DEAD_END, FILAMENT])
    sol = g.solve()
    np.testing.assert_allclose(sol.current, [0.0, 0.0, -DELTA], atol=TOL)


def test_floating_ring_is_cluster_with_nan_potential():
    """A closed ring touching nothing: CLUSTER, potential NaN, current 0."""
    rods = [("P", "N"), ("r1", "r2"), ("r2", "r3"), ("r3", "r1")]
    g = electrode_graph(rods)
    t = g.topology()
    np.testing.assert_array_equal(t.role, [FILAMENT, CLUSTER, CLUSTER, CLUSTER])
    np.testing.assert_array_equal(t.structure, [0, 1, 1, 1])
    assert t.largest_structure == 1
    sol = g.solve()
    assert np.all(np.isnan(sol.potential[2:])) and np.all(sol.current[1:] == 0.0)


def test_star_junction_and_contact_cluster_on_electrode():
    """Tips of four rods stuck at one point, and a tip cluster touching the anode once: FILAMENT."""
    t = roles([("P", "j"), ("P", "j"), ("j", "N"), ("j", "N")])
    assert np.all(t.role == FILAMENT)
    # tips a of rods 0..2 stuck; only tip 2 touches the anode; tips b on the cathode
    t = classify_rods(3, [[0, 2], [2, 4]], [2, 1, 3, 5], [A, C, C, C])
    assert np.all(t.role == FILAMENT)


def test_parallel_and_self_loop_rods():
    """Parallel rods spanning the gap are FILAMENT; parallel rods dangling are DEAD_END.

    A rod with both tips in one merged node (self-loop) is never FILAMENT.
    """
    rods = [("P", "x"), ("P", "x"), ("x", "N"), ("x", "d"), ("x", "d"), ("x", "x")]
    t = roles(rods)
    np.testing.assert_array_equal(t.role, [FILAMENT] * 3 + [DEAD_END] * 3)
    # the self-loop in a floating structure is a CLUSTER rod
    t = roles([("P", "N"), ("r", "s"), ("s", "s")])
    np.testing.assert_array_equal(t.role, [FILAMENT, CLUSTER, CLUSTER])


def test_rod_touching_only_a_conductor_is_dead_end_not_free():
    """A rod with one tip on the anode and no other contact: in a structure, DEAD_END."""
    t = roles([("P", "loose"), ("P", "N")])
    np.testing.assert_array_equal(t.role, [DEAD_END, FILAMENT])
    # conductors do not join structures: two structures of one rod each
    np.testing.assert_array_equal(t.structure, [0, 1])


def test_structures_and_largest():
    """Structure ids, sizes and the largest structure (two aggregates and a free rod)."""
    rods = [("a", "b"), ("b", "c"), ("c", "d"), ("e", "f"), ("f", "g"), ("h", "i")]
    t = roles(rods)
    np.testing.assert_array_equal(t.role, [CLUSTER] * 5 + [FREE])
    assert t.structure[:3].tolist() == [t.structure[0]] * 3
    assert t.structure[3] == t.structure[4] != t.structure[0]
    assert sorted(t.structure_size.tolist()) == [2, 3]
    assert t.structure_size[t.largest_structure] == 3
    assert t.n_cluster == 5 and t.n_free == 1 and not t.has_short_circuit


def test_empty_inputs():
    """No rods, or no contacts at all: every rod FREE, no structures."""
    t = classify_rods(0, [], [], [])
    assert t.role.shape == (0,) and t.largest_structure == -1
    t = classify_rods(3, [], [], [])
    assert np.all(t.role == FREE) and t.n_structures == 0


# ------------------------------------------------------------------------------ case (ii)
def test_case_ii_rod_along_filament():
    """Case (ii): both tips on the filament at heights z, z+1: FILAMENT, J = delta_J0.

    A rod touching with one tip: DEAD_END and no current. Per-contact keys make
    the two contacts of the first rod different attachments.
    """
    delta = 2.0
    g = ConnectivityGraph(2, {F: None})
    g.add_conductor_contact(0, F, -delta * 0.4)
    g.add_conductor_contact(1, F, -delta * 1.4)
    g.add_conductor_contact(3, F, -delta * 3.0)
    assert ("contact", 0, F) in g.to_networkx() and ("contact", 3, F) in g.to_networkx()
    np.testing.assert_array_equal(g.topology().role, [FILAMENT, DEAD_END])
    sol = g.solve()
    assert sol.current[0] == pytest.approx(delta * 1.0, abs=TOL)
    assert sol.current[1] == 0.0
    # heights move: the caller updates the potentials and solves again
    g.set_contact_potential(1, F, -delta * 2.4)
    assert g.changed
    assert g.solve().current[0] == pytest.approx(delta * 2.0, abs=TOL)


def test_case_ii_events_with_potential_callback():
    """apply() takes the potential of new filament contacts from a callback (tip, conductor)."""
    height = {0: 0.0, 1: 1.0}
    g = ConnectivityGraph(1, {F: None})
    rows = [(1, 0.1, ev.CONDUCTOR_CONTACT, 0, F), (1, 0.1, ev.CONDUCTOR_CONTACT, 1, F)]
    derived = g.apply(rows, contact_potential=lambda k, c: -2.0 * height[k])
    assert derived == [(1, 0.1, ev.SHORT_CIRCUIT, 1, -1)]
    assert g.solve().current[0] == pytest.approx(2.0, abs=TOL)


# ------------------------------------------------------------------------------ oracles
@pytest.mark.parametrize("seed", range(40))
def test_roles_match_brute_force_path_enumeration(seed):
    """On small random graphs FILAMENT is exactly 'on a simple path between different attachments'.

    Keys mix case (i) (shared anode/cathode keys) and case (ii) (a key per
    contact); parallel rods, loops, contact clusters and free rods all occur.
    """
    rng = np.random.default_rng(seed)
    rods = random_netlist(int(rng.integers(4, 13)), int(rng.integers(4, 9)), rng)
    n_rods, tc, ct, cid = netlist(rods, star=bool(seed % 2))
    key = cid.copy()
    if seed % 3 == 0:  # case (ii)-like: some contacts get keys of their own
        own = rng.random(key.size) < 0.5
        key[own] = 100 + np.flatnonzero(own)
    t = classify_rods(n_rods, tc, ct, key)
    np.testing.assert_array_equal(t.role == FILAMENT, ref.brute_force_filament(n_rods, tc, ct, key))


@pytest.mark.parametrize("seed, density", [(s, d) for s in range(6) for d in (1.0, 0.6)])
def test_roles_match_networkx_rule_on_larger_graphs(seed, density):
    """On 400-rod random graphs classify_rods (with its leaf peeling and series reduction)
    agrees with the biconnected-component rule applied literally with networkx.

    density = junctions per rod: 1.0 gives long chains and trees, 0.6 a denser mesh.
    """
    rng = np.random.default_rng(100 + seed)
    rods = random_netlist(400, int(400 * density), rng)
    n_rods, tc, ct, cid = netlist(rods, star=bool(seed % 2))
    key = cid if seed % 2 else np.where(rng.random(cid.size) < 0.3, 10 + np.arange(cid.size), cid)
    t = classify_rods(n_rods, tc, ct, key)
    np.testing.assert_array_equal(t.role == FILAMENT, ref.rule_filament(n_rods, tc, ct, key))


@pytest.mark.parametrize("seed", range(4))
def test_current_flows_only_in_filaments(seed):
    """Rods that carry current are FILAMENT; DEAD_END, CLUSTER and FREE rods carry none.

    (The converse fails only for balanced rods, measure zero in random graphs.)
    """
    rng = np.random.default_rng(200 + seed)
    g = electrode_graph(random_netlist(300, 150, rng), DELTA * 10)
    t, sol = g.topology(), g.solve()
    assert t.has_short_circuit
    assert np.all(np.abs(sol.current[t.role != FILAMENT]) < TOL)
    assert np.all(t.role[np.abs(sol.current) > 1e-9] == FILAMENT)
    assert sol.kirchhoff_residual < TOL


# ------------------------------------------------------------------------------ ConnectivityGraph
def test_graph_nodes_and_edges():
    """Tips are int nodes, rods are kind='rod' edges, contacts kind='contact' edges."""
    g = ConnectivityGraph(2, {C: -0.5, A: 0.5, F: None})
    assert set(range(4)) <= set(g.to_networkx().nodes)
    assert g.to_networkx().edges[0, 1]["kind"] == "rod" and g.to_networkx().edges[2, 3]["kind"] == "rod"
    assert g.to_networkx().nodes[("conductor", A)]["potential"] == 0.5
    g.add_tip_contact(3, 0)
    g.add_conductor_contact(1, A)
    g.add_conductor_contact(2, F, potential=-1.0)
    assert g.to_networkx().edges[0, 3]["kind"] == "contact"
    assert g.to_networkx().edges[1, ("conductor", A)]["kind"] == "contact"
    assert g.to_networkx().nodes[("contact", 2, F)]["potential"] == -1.0
    arr = g.arrays()
    np.testing.assert_array_equal(arr["tip_contacts"], [[0, 3]])
    np.testing.assert_array_equal(arr["conductor_tip"], [1, 2])
    np.testing.assert_array_equal(arr["conductor_id"], [A, F])
    np.testing.assert_array_equal(arr["conductor_potential"], [0.5, -1.0])
    assert arr["tip_contacts"].dtype == np.int64 and arr["conductor_potential"].dtype == np.float64
    g.remove_conductor_contact(2, F)
    assert ("contact", 2, F) not in g.to_networkx()


def test_events_in_sequence_equal_direct_build():
    """stick, stick, release applied as events give the same arrays as building directly."""
    g = ConnectivityGraph(3, {C: -1.0, A: 1.0})
    rows = ev.event_array([
        (1, 0.01, ev.TIP_CONTACT, 1, 2),
        (2, 0.02, ev.TIP_CONTACT, 3, 4),
        (3, 0.03, ev.TIP_RELEASE, 1, 2),
        (3, 0.03, ev.CONDUCTOR_CONTACT, 0, A),
    ])  # fmt: skip
    for row in rows:
        g.apply([row])
    direct = ConnectivityGraph(3, {C: -1.0, A: 1.0})
    direct.add_tip_contact(4, 3)
    direct.add_conductor_contact(0, A)
    for k, v in direct.arrays().items():
        np.testing.assert_array_equal(g.arrays()[k], v, err_msg=k)
    assert nx.utils.graphs_equal(g.to_networkx(), direct.to_networkx())


def test_short_and_open_circuit_rows():
    """Closing the last gap of a chain emits SHORT_CIRCUIT (a = filament rods); the release OPEN_CIRCUIT.

    Derived rows carry the step and time of the batch's last row; batches that
    do not flip the state emit nothing.
    """
    g = ConnectivityGraph(3, {C: -1.0, A: 1.0})
    assert g.apply([(5, 0.5, ev.CONDUCTOR_CONTACT, 0, A), (6, 0.6, ev.CONDUCTOR_CONTACT, 3, C)]) == []
    assert g.apply([(7, 0.7, ev.TIP_CONTACT, 1, 2)]) == [(7, 0.7, ev.SHORT_CIRCUIT, 2, -1)]
    # rod 2 from the middle junction to the cathode: a parallel branch, still shorted
    assert g.apply([(8, 0.8, ev.TIP_CONTACT, 1, 4), (8, 0.8, ev.CONDUCTOR_CONTACT, 5, C)]) == []
    assert g.topology().n_filament == 3
    assert g.apply([(9, 0.9, ev.TIP_RELEASE, 1, 4), (10, 1.0, ev.TIP_RELEASE, 1, 2)]) == [
        (10, 1.0, ev.OPEN_CIRCUIT, -1, -1)
    ]
    assert g.apply([]) == []


def test_release_splitting_a_filament_opens_circuit():
    """A 4-rod filament split in the middle by a release: OPEN_CIRCUIT; both halves become DEAD_END."""
    g = electrode_graph([("P", "x"), ("x", "y"), ("y", "z"), ("z", "N")], 4.0, star=False)
    assert g.has_short_circuit
    derived = g.apply([(3, 0.3, ev.TIP_RELEASE, 3, 4)])  # rod 1 tip b leaves rod 2 tip a
    assert derived == [(3, 0.3, ev.OPEN_CIRCUIT, -1, -1)]
    assert np.all(g.topology().role == DEAD_END)
    assert np.all(g.solve().current == 0.0)


def test_replaying_a_log_with_derived_rows_gives_same_graph():
    """A recorded log (contact rows plus the derived rows apply() returned) replays to the same graph."""
    g = ConnectivityGraph(2, {C: -1.0, A: 1.0})
    log = []
    for batch in ([(1, 0.1, ev.CONDUCTOR_CONTACT, 0, A), (1, 0.1, ev.CONDUCTOR_CONTACT, 3, C)],
                  [(2, 0.2, ev.TIP_CONTACT, 1, 2)], [(3, 0.3, ev.TIP_RELEASE, 1, 2)]):  # fmt: skip
        log += batch + g.apply(batch)
    assert [r[2] for r in log].count(ev.SHORT_CIRCUIT) == 1
    replay = ConnectivityGraph(2, {C: -1.0, A: 1.0})
    derived = replay.apply(ev.event_array(log))
    assert derived == []  # shorted then opened within the batch: no net flip
    for k, v in g.arrays().items():
        np.testing.assert_array_equal(replay.arrays()[k], v)


def test_arrays_round_trip():
    """from_arrays(arrays()) rebuilds an identical graph, per-contact potentials (even unset) included."""
    rng = np.random.default_rng(3)
    n_rods, tc, ct, cid = netlist(random_netlist(60, 50, rng))
    pots = {C: -3.0, A: 3.0, F: None}
    g = ConnectivityGraph(n_rods, pots)
    for k, l in tc.tolist():
        g.add_tip_contact(k, l)
    for k, c in zip(ct.tolist(), cid.tolist()):
        g.add_conductor_contact(k, c)
    g.add_conductor_contact(5, F, -0.25)
    g.add_conductor_contact(7, F)  # unset potential
    h = ConnectivityGraph.from_arrays(n_rods, pots, g.arrays())
    for k, v in g.arrays().items():
        np.testing.assert_array_equal(h.arrays()[k], v, err_msg=k)
    assert nx.utils.graphs_equal(g.to_networkx(), h.to_networkx())
    assert (
        h.to_networkx().nodes[("contact", 7, F)]["potential"] != h.to_networkx().nodes[("contact", 7, F)]["potential"]
    )
    np.testing.assert_array_equal(g.topology().role, h.topology().role)
    assert h.has_short_circuit == g.has_short_circuit


def test_changed_flag():
    """changed is set by every change (potential updates included) and cleared by solve()."""
    g = ConnectivityGraph(1, {C: -0.5, A: 0.5, F: None})
    assert g.changed
    g.solve()
    assert not g.changed
    g.add_conductor_contact(0, A)
    assert g.changed
    g.solve()
    g.topology()
    assert not g.changed
    g.add_conductor_contact(1, F, 0.0)
    g.solve()
    g.set_contact_potential(1, F, -1.0)
    assert g.changed
    g.solve()
    g.remove_conductor_contact(0, A)
    assert g.changed


def test_failed_batch_is_rolled_back():
    """An invalid row makes apply() raise ValueError and leaves the graph as before the batch."""
    g = ConnectivityGraph(3, {C: -1.0, A: 1.0, F: None})
    g.add_conductor_contact(2, F, 0.5)
    before = g.arrays()
    rows = [(1, 0.1, ev.TIP_CONTACT, 1, 2), (1, 0.1, ev.CONDUCTOR_RELEASE, 2, F),
            (1, 0.1, ev.TIP_RELEASE, 3, 4)]  # fmt: skip
    with pytest.raises(ValueError, match="not in contact"):
        g.apply(rows)
    for k, v in before.items():
        np.testing.assert_array_equal(g.arrays()[k], v)
    assert g.to_networkx().nodes[("contact", 2, F)]["potential"] == 0.5


# ------------------------------------------------------------------------------ invalid input
@pytest.mark.parametrize(
    "action, message",
    [
        (lambda g: g.add_tip_contact(0, 6), r"tip 6 out of range \[0, 6\)"),
        (lambda g: g.add_tip_contact(-1, 2), "tip -1 out of range"),
        (lambda g: g.add_tip_contact(2, 3), "two tips of rod 1"),
        (lambda g: g.add_tip_contact(1.5, 2), "tip must be an integer"),
        (lambda g: g.remove_tip_contact(1, 2), "not in contact"),
        (lambda g: (g.add_tip_contact(1, 2), g.add_tip_contact(2, 1)), "already in contact"),
        (lambda g: g.add_conductor_contact(0, 7), "unknown conductor 7"),
        (lambda g: g.add_conductor_contact(0, F), r"unknown conductor 2 \(filament\)"),
        (lambda g: g.remove_conductor_contact(0, A), "does not touch"),
        (lambda g: g.add_conductor_contact(0, A, potential=3.0), "fixed potential"),
        (lambda g: g.set_contact_potential(0, A, 1.0), "fixed potential"),
        (lambda g: g.apply([(0, 0.0, 99, 0, 1)]), "unknown event kind 99"),
        (lambda g: g.apply([(0, 0.0, ev.CONDUCTOR_CONTACT, 0, 5)]), "unknown conductor 5"),
    ],
)
def test_invalid_graph_operations_raise(action, message):
    """Bad tips, self-contacts of a rod, missing contacts and unknown conductors raise ValueError."""
    g = ConnectivityGraph(3, {C: -1.0, A: 1.0})
    with pytest.raises(ValueError, match=message):
        action(g)


def test_invalid_per_contact_potentials_raise():
    """Unset per-contact potentials block solve(); non-finite potentials are refused."""
    g = ConnectivityGraph(1, {F: None})
    g.add_conductor_contact(0, F)
    with pytest.raises(ValueError, match=r"unset contact potential for \(tip, conductor\) \[\(0, 2\)\]"):
        g.solve()
    with pytest.raises(ValueError, match="must be finite"):
        g.set_contact_potential(0, F, np.inf)
    with pytest.raises(ValueError, match="does not touch"):
        g.set_contact_potential(1, F, 0.0)
    with pytest.raises(ValueError, match="must be finite"):
        ConnectivityGraph(1, {A: np.nan})


def test_classify_rods_invalid_input():
    """classify_rods checks shapes and tip ranges."""
    with pytest.raises(ValueError, match="tip_contacts holds tip index 4"):
        classify_rods(2, [[0, 4]], [], [])
    with pytest.raises(ValueError, match="one key per conductor contact"):
        classify_rods(2, [], [0, 1], [A])
