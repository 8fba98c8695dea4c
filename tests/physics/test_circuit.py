"""Tests of the nodal-analysis circuit solve (docs/model.md 'Circuit').

Networks are written as netlists: a list of rods, each ``(junction of tip a,
junction of tip b)``. Tips meeting at a junction are stuck together by ideal
tip contacts; every tip at junction ``"P"`` touches the anode and every tip at
``"N"`` the cathode. Expected values come from hand calculations (nodal
equations solved on paper, written out in the docstrings) and from
``networkx.resistance_distance`` on the same network, built independently with
networkx.

Tolerances: a sparse direct solve of these small systems is exact up to
round-off, a few ulp of the potentials (O(1)-O(10)); 1e-12 absolute (or
relative for sums) leaves a margin of 100x over what is observed (~1e-14).
"""

from collections import defaultdict

import networkx as nx
import numpy as np
import pytest

from selfas_graph.model.circuit import CircuitSolution, merge_tips, solve_circuit
from selfas_graph.model.events import CONDUCTOR_ANODE, CONDUCTOR_CATHODE

#: small inputs: also run with NUMBA_DISABLE_JIT=1, the kernels as Python (.ci/run)
pytestmark = pytest.mark.jit_off_ok

#: delta_J0 of the paper's Fig. 2 scene (docs/model.md 'Circuit')
DELTA = 2.23
#: round-off of a sparse solve on networks of <= a few hundred rods (observed ~1e-14)
TOL = 1e-12


# ------------------------------------------------------------------------------ helpers
def netlist(rods, anode="P", cathode="N", star=True):
    """Arrays of a network given as rods between named junctions.

    Parameters
    ----------
    rods : list of (junction_a, junction_b)
        Rod ``i`` has its tip a (``2 i``) at ``junction_a`` and tip b at ``junction_b``.
    star : bool
        Tips at one junction are stuck to its first tip (a star of contacts) if
        True, else in a chain ``t0-t1, t1-t2, ...``; electrically the same.

    Returns
    -------
    n_rods, tip_contacts (m, 2), conductor_tip (k,), conductor_id (k,)
    """
    tips_at = defaultdict(list)
    for i, (ja, jb) in enumerate(rods):
        tips_at[ja].append(2 * i)
        tips_at[jb].append(2 * i + 1)
    contacts, ctip, cid = [], [], []
    for j, tips in tips_at.items():
        if j in (anode, cathode):
            ctip += tips
            cid += [CONDUCTOR_ANODE if j == anode else CONDUCTOR_CATHODE] * len(tips)
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


def electrode_potential(cid, voltage):
    """Anode +voltage/2, cathode -voltage/2 (docs/model.md 'Circuit', case (i))."""
    return np.where(cid == CONDUCTOR_ANODE, 0.5 * voltage, -0.5 * voltage)


def solve_netlist(rods, voltage, **kw):
    n_rods, tc, ct, cid = netlist(rods, **kw)
    return solve_circuit(2 * n_rods, tc, ct, electrode_potential(cid, voltage))


def nx_resistance(n_rods, tip_contacts, conductor_tip, conductor_id):
    """Anode-cathode resistance by networkx alone (the oracle).

    Tips, the anode and the cathode are nodes; contacts (ideal) are merged with
    ``nx.connected_components``; rods become edges of conductance 1, parallel rods
    adding up; ``nx.resistance_distance`` on the component holding both electrodes.
    """
    ideal = nx.Graph()
    ideal.add_nodes_from(range(2 * n_rods))
    ideal.add_nodes_from(["anode", "cathode"])
    ideal.add_edges_from(map(tuple, tip_contacts.tolist()))
    for t, c in zip(conductor_tip.tolist(), conductor_id.tolist()):
        ideal.add_edge(t, "anode" if c == CONDUCTOR_ANODE else "cathode")
    merged = {}
    for label, nodes in enumerate(nx.connected_components(ideal)):
        for n in nodes:
            merged[n] = label
    g = nx.Graph()
    for i in range(n_rods):
        a, b = merged[2 * i], merged[2 * i + 1]
        if a == b:
            continue
        w = g.get_edge_data(a, b, {"conductance": 0.0})["conductance"]
        g.add_edge(a, b, conductance=w + 1.0)
    A, C = merged["anode"], merged["cathode"]
    if A == C:
        return 0.0
    if A not in g or C not in g or not nx.has_path(g, A, C):
        return np.inf
    sub = g.subgraph(nx.node_connected_component(g, A))
    return nx.resistance_distance(sub, A, C, weight="conductance", invert_weight=False)


def check_laws(sol: CircuitSolution, conductor_tip, conductor_id):
    """Kirchhoff's current law, anode current = cathode current, power balance."""
    assert sol.kirchhoff_residual < TOL
    nodes_a = np.unique(sol.node_of_tip[conductor_tip[conductor_id == CONDUCTOR_ANODE]])
    nodes_c = np.unique(sol.node_of_tip[conductor_tip[conductor_id == CONDUCTOR_CATHODE]])
    into_network = sol.injected_current[nodes_a].sum()
    out_of_network = -sol.injected_current[nodes_c].sum()
    scale = max(1.0, sol.total_current)
    assert abs(into_network - out_of_network) < TOL * scale
    assert abs(into_network - sol.total_current) < TOL * scale
    assert abs(sol.dissipated_power - sol.supplied_power) < TOL * max(1.0, sol.dissipated_power)


# ------------------------------------------------------------------------------ single rods and chains
@pytest.mark.parametrize("flip", [False, True])
def test_single_rod_across_gap_carries_delta(flip):
    """A rod touching both electrodes of a one-rod gap carries delta_J0 (docs/model.md 'Circuit').

    Potentials are +-delta_J0/2, so psi(a) - psi(b) = +-delta_J0 by orientation:
    tip a on the anode gives J = +delta_J0 (from a to b), tip a on the cathode -delta_J0.
    """
    rods = [("N", "P")] if flip else [("P", "N")]
    sol = solve_netlist(rods, DELTA * 1)
    sign = -1.0 if flip else 1.0
    assert sol.current == pytest.approx([sign * DELTA], abs=TOL)
    assert sol.total_current == pytest.approx(DELTA, abs=TOL)
    assert sol.effective_resistance == pytest.approx(1.0, abs=TOL)
    assert sol.dissipated_power == pytest.approx(DELTA**2, abs=TOL)


@pytest.mark.parametrize("n", [1, 3, 7])
def test_straight_chain_carries_delta_and_has_resistance_n(n):
    """A chain of n rods spanning a gap of n rod lengths carries delta_J0 in every rod.

    Electrode potentials +-delta_J0 n/2; series resistance n R0; potentials fall
    linearly, by delta_J0 per rod. Also against networkx.resistance_distance.
    """
    junctions = ["P"] + [f"j{k}" for k in range(1, n)] + ["N"]
    rods = list(zip(junctions[:-1], junctions[1:]))
    n_rods, tc, ct, cid = netlist(rods)
    sol = solve_circuit(2 * n_rods, tc, ct, electrode_potential(cid, DELTA * n))
    np.testing.assert_allclose(sol.current, DELTA, atol=TOL)
    assert sol.effective_resistance == pytest.approx(n, abs=TOL * n)
    assert sol.effective_resistance == pytest.approx(nx_resistance(n_rods, tc, ct, cid), rel=TOL)
    expected_tip_a = DELTA * n / 2 - DELTA * np.arange(n)
    np.testing.assert_allclose(sol.potential[0::2], expected_tip_a, atol=TOL)
    check_laws(sol, ct, cid)


def test_chain_with_mixed_orientation_signs_follow_tips():
    """Rods of a chain laid a->b or b->a carry +-delta_J0: J is positive from tip a to tip b."""
    rods = [("P", "x"), ("y", "x"), ("y", "z"), ("N", "z")]
    sol = solve_netlist(rods, DELTA * 4)
    np.testing.assert_allclose(sol.current, [DELTA, -DELTA, DELTA, -DELTA], atol=TOL)


# ------------------------------------------------------------------------------ parallel, ladder
def test_two_chains_in_parallel():
    """Two chains of 3 rods between the electrodes: each rod delta_J0, R = 3/2, total 2 delta_J0."""
    rods = [("P", "a1"), ("a1", "a2"), ("a2", "N"), ("P", "b1"), ("b1", "b2"), ("b2", "N")]
    n_rods, tc, ct, cid = netlist(rods)
    sol = solve_circuit(2 * n_rods, tc, ct, electrode_potential(cid, DELTA * 3))
    np.testing.assert_allclose(sol.current, DELTA, atol=TOL)
    assert sol.total_current == pytest.approx(2 * DELTA, abs=TOL)
    assert sol.effective_resistance == pytest.approx(1.5, abs=TOL)
    assert sol.effective_resistance == pytest.approx(nx_resistance(n_rods, tc, ct, cid), rel=TOL)
    check_laws(sol, ct, cid)


def test_chains_of_different_length_in_parallel():
    """Chains of 2 and 3 rods across voltage V: V/2 and V/3 per rod, R = 1/(1/2 + 1/3) = 6/5."""
    V = DELTA * 2
    rods = [("P", "a1"), ("a1", "N"), ("P", "b1"), ("b1", "b2"), ("b2", "N")]
    n_rods, tc, ct, cid = netlist(rods)
    sol = solve_circuit(2 * n_rods, tc, ct, electrode_potential(cid, V))
    np.testing.assert_allclose(sol.current, [V / 2] * 2 + [V / 3] * 3, atol=TOL)
    assert sol.effective_resistance == pytest.approx(6 / 5, rel=TOL)
    assert sol.effective_resistance == pytest.approx(nx_resistance(n_rods, tc, ct, cid), rel=TOL)
    check_laws(sol, ct, cid)


def test_ladder_by_hand():
    """Rails P-x-N (2 rods) and P-y-z-N (3 rods) with a rung x-y, anode at V, cathode at 0.

    Nodal equations: 3x - V - y = 0, 3y - V - z - x = 0, 2z - y = 0 give
    x = 7V/13, y = 8V/13, z = 4V/13; rod currents P->x 6V/13, x->N 7V/13,
    P->y 5V/13, y->z 4V/13, z->N 4V/13, rung y->x V/13; R = 13/11.
    """
    V = 1.3
    rods = [("P", "x"), ("x", "N"), ("P", "y"), ("y", "z"), ("z", "N"), ("y", "x")]
    n_rods, tc, ct, cid = netlist(rods)
    sol = solve_circuit(2 * n_rods, tc, ct, electrode_potential(cid, V))
    np.testing.assert_allclose(sol.current, np.array([6, 7, 5, 4, 4, 1]) * V / 13, atol=TOL)
    assert sol.effective_resistance == pytest.approx(13 / 11, rel=TOL)
    assert sol.effective_resistance == pytest.approx(nx_resistance(n_rods, tc, ct, cid), rel=TOL)
    check_laws(sol, ct, cid)


def test_long_ladder_against_networkx():
    """A 2 x 8 ladder with rungs at every level, attached asymmetrically: R from networkx."""
    rods = [("P", "a0"), ("b7", "N"), ("P", "b0")]
    for k in range(7):
        rods += [(f"a{k}", f"a{k + 1}"), (f"b{k}", f"b{k + 1}")]
    rods += [(f"a{k}", f"b{k}") for k in range(8)]
    rods += [("a7", "N")]
    n_rods, tc, ct, cid = netlist(rods, star=False)
    sol = solve_circuit(2 * n_rods, tc, ct, electrode_potential(cid, DELTA))
    assert sol.effective_resistance == pytest.approx(nx_resistance(n_rods, tc, ct, cid), rel=TOL)
    assert sol.total_current == pytest.approx(DELTA / sol.effective_resistance, rel=TOL)
    check_laws(sol, ct, cid)


# ------------------------------------------------------------------------------ bridges
def test_balanced_wheatstone_bridge_rod_carries_nothing():
    """Arms of one rod each: by symmetry the bridge x-y carries 0, the arms V/2; R = 1."""
    V = DELTA * 2
    rods = [("P", "x"), ("x", "N"), ("P", "y"), ("y", "N"), ("x", "y")]
    n_rods, tc, ct, cid = netlist(rods)
    sol = solve_circuit(2 * n_rods, tc, ct, electrode_potential(cid, V))
    np.testing.assert_allclose(sol.current, [V / 2] * 4 + [0.0], atol=TOL)
    assert sol.effective_resistance == pytest.approx(1.0, rel=TOL)
    assert sol.effective_resistance == pytest.approx(nx_resistance(n_rods, tc, ct, cid), rel=TOL)
    check_laws(sol, ct, cid)


def test_unbalanced_wheatstone_bridge_by_hand():
    """Arms P-x (1 rod), x-m-N (2), P-n-y (2), y-N (1), bridge x-y; anode V, cathode 0.

    Nodal equations: m = x/2, n = (V + y)/2, 2.5x - y = V, 2.5y - x = V/2 give
    x = 4V/7, y = 3V/7, m = 2V/7, n = 5V/7: currents P->x 3V/7, x->m 2V/7,
    m->N 2V/7, P->n 2V/7, n->y 2V/7, y->N 3V/7, bridge x->y V/7; R = 7/5.
    """
    V = 0.7
    rods = [("P", "x"), ("x", "m"), ("m", "N"), ("P", "n"), ("n", "y"), ("y", "N"), ("x", "y")]
    n_rods, tc, ct, cid = netlist(rods)
    sol = solve_circuit(2 * n_rods, tc, ct, electrode_potential(cid, V))
    np.testing.assert_allclose(sol.current, np.array([3, 2, 2, 2, 2, 3, 1]) * V / 7, atol=TOL)
    assert sol.effective_resistance == pytest.approx(7 / 5, rel=TOL)
    assert sol.effective_resistance == pytest.approx(nx_resistance(n_rods, tc, ct, cid), rel=TOL)
    check_laws(sol, ct, cid)


# ------------------------------------------------------------------------------ dead ends, floating
def test_dangling_branch_and_hanging_loop_carry_nothing():
    """Chain P-x-y-N with a branch x-d1-d2 and a triangle y-l1-l2-y hanging off it.

    Only the chain carries current (V/3 per rod); branch and loop sit at the
    potential of their attachment node and carry 0.
    """
    V = DELTA * 3
    rods = [("P", "x"), ("x", "y"), ("y", "N"), ("x", "d1"), ("d1", "d2"),
            ("y", "l1"), ("l1", "l2"), ("l2", "y")]  # fmt: skip
    n_rods, tc, ct, cid = netlist(rods)
    sol = solve_circuit(2 * n_rods, tc, ct, electrode_potential(cid, V))
    np.testing.assert_allclose(sol.current, [V / 3] * 3 + [0.0] * 5, atol=TOL)
    # the branch sits at x's potential, V/2 - V/3
    np.testing.assert_allclose(sol.potential[[7, 9]], V / 2 - V / 3, atol=TOL)
    check_laws(sol, ct, cid)


def test_structure_on_one_electrode_carries_nothing():
    """A U-shaped structure touching only the anode at two points: no current, psi = anode.

    The component has a single Dirichlet value, so it sits there exactly (no solve);
    total current 0 and effective resistance infinite.
    """
    rods = [("P", "x"), ("x", "y"), ("y", "P")]
    sol = solve_netlist(rods, DELTA)
    assert np.all(sol.current == 0.0)
    assert np.all(sol.potential == DELTA / 2)
    assert sol.total_current == 0.0
    assert sol.effective_resistance == np.inf
    assert sol.supplied_power == 0.0 and sol.dissipated_power == 0.0


def test_floating_ring_and_free_rod_have_nan_potential():
    """A ring of 3 rods and a free rod touch no conductor: potential NaN, current 0.

    They sit beside a single rod across the gap, whose current must be unaffected.
    """
    rods = [("P", "N"), ("r1", "r2"), ("r2", "r3"), ("r3", "r1"), ("f1", "f2")]
    sol = solve_netlist(rods, DELTA)
    assert sol.current[0] == pytest.approx(DELTA, abs=TOL)
    assert np.all(sol.current[1:] == 0.0)
    assert np.all(np.isnan(sol.potential[2:]))
    assert not np.isnan(sol.potential[:2]).any()


def test_no_conductor_at_all():
    """Without conductor contacts nothing is solved: all NaN, no current, R infinite."""
    sol = solve_circuit(6, [[1, 2], [3, 4]], [], [])
    assert np.all(np.isnan(sol.potential)) and np.all(sol.current == 0.0)
    assert sol.total_current == 0.0 and sol.effective_resistance == np.inf
    sol = solve_circuit(0, np.zeros((0, 2)), [], [])
    assert sol.current.shape == (0,) and sol.potential.shape == (0,)


# ------------------------------------------------------------------------------ junctions
@pytest.mark.parametrize("style", ["star", "chain", "complete"])
def test_star_junction(style):
    """Four rods stuck at one point: two from the anode, two to the cathode.

    The junction sits at 0 by symmetry; each rod carries V/2; R = 1/2 + 1/2 = 1.
    The same whether the junction's tips are stuck as a star, a chain, or every
    pair (redundant contacts change nothing: contacts are ideal).
    """
    V = DELTA
    rods = [("P", "j"), ("P", "j"), ("j", "N"), ("j", "N")]
    n_rods, tc, ct, cid = netlist(rods, star=(style != "chain"))
    if style == "complete":
        tips = [1, 3, 4, 6]
        tc = np.array([(a, b) for i, a in enumerate(tips) for b in tips[i + 1 :]], dtype=np.int64)
    sol = solve_circuit(2 * n_rods, tc, ct, electrode_potential(cid, V))
    np.testing.assert_allclose(sol.current, V / 2, atol=TOL)
    assert len(set(sol.node_of_tip[[1, 3, 4, 6]].tolist())) == 1
    assert sol.effective_resistance == pytest.approx(1.0, rel=TOL)
    check_laws(sol, ct, cid)


def test_contact_cluster_touching_electrode():
    """Three rods with tips a stuck in a cluster; one of those tips touches the anode.

    The ideal contacts put the whole cluster at the anode potential, so each rod
    (tip b on the cathode) carries the full V; R = 1/3.
    """
    V = DELTA
    tc = np.array([[0, 2], [2, 4]])  # tips a of rods 0, 1, 2 stuck together
    ct = np.array([2, 1, 3, 5])
    cid = np.array([CONDUCTOR_ANODE, CONDUCTOR_CATHODE, CONDUCTOR_CATHODE, CONDUCTOR_CATHODE])
    sol = solve_circuit(6, tc, ct, electrode_potential(cid, V))
    np.testing.assert_allclose(sol.current, V, atol=TOL)
    assert sol.effective_resistance == pytest.approx(1 / 3, rel=TOL)
    assert sol.effective_resistance == pytest.approx(nx_resistance(3, tc, ct, cid), rel=TOL)
    check_laws(sol, ct, cid)


def test_rod_shorted_by_contacts_carries_nothing():
    """A rod whose two tips end in one merged node (via another rod's tip) carries 0.

    Rod 0 spans the gap; rod 1 has both tips stuck to rod 0's tip b: rod 1 is a
    self-loop of the merged graph and drops out of the Laplacian.
    """
    sol = solve_circuit(4, [[1, 2], [1, 3]], [0, 1], [DELTA / 2, -DELTA / 2])
    assert sol.current == pytest.approx([DELTA, 0.0], abs=TOL)
    assert sol.node_of_tip[2] == sol.node_of_tip[3] == sol.node_of_tip[1]


# ------------------------------------------------------------------------------ case (ii)
@pytest.mark.parametrize("z_a, z_b", [(0.3, 1.3), (2.0, 1.0), (-0.25, 0.5)])
def test_rod_along_filament_carries_delta_times_height_difference(z_a, z_b):
    """Case (ii): a rod touching the filament with both tips, psi = -delta_J0 z at each.

    J = psi(a) - psi(b) = delta_J0 (z_b - z_a): delta_J0 for a rod of length 1
    parallel to the filament pointing up.
    """
    delta = 2.0
    sol = solve_circuit(2, [], [0, 1], [-delta * z_a, -delta * z_b])
    assert sol.current[0] == pytest.approx(delta * (z_b - z_a), abs=TOL)
    assert sol.effective_resistance == pytest.approx(1.0, rel=TOL)


def test_rod_touching_filament_with_one_tip_carries_nothing():
    """Case (ii): one tip on the filament at height z: the rod sits at -delta z, no current."""
    delta, z = 2.0, 0.7
    sol = solve_circuit(2, [], [1], [-delta * z])
    assert sol.current[0] == 0.0
    np.testing.assert_allclose(sol.potential, -delta * z, atol=TOL)


def test_cluster_touching_filament_twice_takes_mean_potential():
    """Case (ii): two stuck tips touching the filament at heights z1, z2 form one node.

    The node's potential is the mean of the given potentials (documented choice);
    a rod from it to a third contact at z3 carries psi_mean - psi3.
    """
    delta, z1, z2, z3 = 2.0, 0.00, 0.06, 1.0
    # rod 0 tip a and rod 1 tip a stuck; both on the filament; rod 0 tip b on the filament at z3
    sol = solve_circuit(4, [[0, 2]], [0, 2, 1], [-delta * z1, -delta * z2, -delta * z3])
    mean = -delta * (z1 + z2) / 2
    assert sol.potential[0] == pytest.approx(mean, abs=TOL)
    assert sol.current[0] == pytest.approx(mean + delta * z3, abs=TOL)
    assert sol.current[1] == 0.0  # rod 1 dangles from the cluster


# ------------------------------------------------------------------------------ random networks
def random_network(n_rods, n_junctions, rng, free_fraction=0.15):
    """A random netlist: rods between random junctions (parallel rods and loops included).

    About ``free_fraction`` of the rods get private junctions (free rods); the
    anode P and cathode N are two of the junctions, so several rods span them.
    """
    names = ["P", "N"] + [f"j{k}" for k in range(n_junctions - 2)]
    rods = []
    for i in range(n_rods):
        if rng.random() < free_fraction:
            rods.append((f"free{i}a", f"free{i}b"))
            continue
        a, b = rng.choice(len(names), size=2, replace=False)
        rods.append((names[a], names[b]))
    return rods


@pytest.mark.parametrize("seed", [1, 2, 3, 4])
def test_conservation_laws_on_random_networks(seed):
    """KCL at every inner node, anode current = cathode current, dissipated = supplied power.

    Random networks of 300 rods on 150 junctions (cycles, dead ends, parallel
    rods, free rods); R_eff also against networkx.resistance_distance.
    """
    rng = np.random.default_rng(seed)
    rods = random_network(300, 150, rng)
    n_rods, tc, ct, cid = netlist(rods, star=bool(seed % 2))
    sol = solve_circuit(2 * n_rods, tc, ct, electrode_potential(cid, DELTA * 10))
    assert sol.total_current > 0
    check_laws(sol, ct, cid)
    # networkx's resistance distance inverts the Laplacian of 300 nodes densely: its own round-off is
    # eps times the Laplacian's condition number (about 1e3-1e4 here), so 1e-10, looser than TOL
    assert sol.effective_resistance == pytest.approx(nx_resistance(n_rods, tc, ct, cid), rel=1e-10)
    # per-rod Ohm's law from the tip potentials (floating rods: NaN -> 0 current)
    j = np.nan_to_num(sol.potential[0::2] - sol.potential[1::2], nan=0.0)
    np.testing.assert_allclose(sol.current, j, atol=0)


@pytest.mark.parametrize("seed", [5, 6])
def test_case_ii_conservation_on_random_networks(seed):
    """Case (ii): random per-contact potentials -delta z; KCL and power balance still hold."""
    rng = np.random.default_rng(seed)
    rods = random_network(200, 120, rng)
    n_rods, tc, _, _ = netlist(rods, anode=None, cathode=None)
    ct = rng.choice(2 * n_rods, size=25, replace=False)
    pot = -2.0 * rng.uniform(-10, 10, ct.size)
    sol = solve_circuit(2 * n_rods, tc, ct, pot)
    assert sol.kirchhoff_residual < TOL
    assert abs(sol.injected_current.sum()) < TOL * 100  # sum of O(10) injections
    assert sol.dissipated_power == pytest.approx(sol.supplied_power, rel=TOL)


@pytest.mark.parametrize("seed", [7, 8])
def test_cg_solver_agrees_with_direct(seed):
    """The optional conjugate-gradient solver gives the direct solution to ~1e-11.

    CG stops at a relative residual of 1e-14; the error of the potentials is that
    times the condition number (< 1e3 here), hence the 1e-10 tolerance.
    """
    rng = np.random.default_rng(seed)
    rods = random_network(300, 150, rng)
    n_rods, tc, ct, cid = netlist(rods)
    pot = electrode_potential(cid, DELTA * 10)
    direct = solve_circuit(2 * n_rods, tc, ct, pot)
    iterative = solve_circuit(2 * n_rods, tc, ct, pot, solver="cg")
    np.testing.assert_allclose(iterative.current, direct.current, atol=1e-10)
    np.testing.assert_array_equal(np.isnan(iterative.potential), np.isnan(direct.potential))


def test_merge_tips_labels_contact_components():
    """merge_tips gives one label per set of tips joined by contacts."""
    n_nodes, node = merge_tips(6, np.array([[0, 3], [3, 5]]))
    assert n_nodes == 4
    assert node[0] == node[3] == node[5]
    assert len({node[1], node[2], node[4], node[0]}) == 4


def test_solution_arrays_are_read_only():
    """CircuitSolution is frozen, arrays included (the graph caches and shares it)."""
    sol = solve_netlist([("P", "N")], 1.0)
    with pytest.raises(ValueError):
        sol.current[0] = 5.0
    with pytest.raises(AttributeError):
        sol.total_current = 2.0  # type: ignore[misc]


# ------------------------------------------------------------------------------ invalid input
@pytest.mark.parametrize(
    "args, message",
    [
        ((5, [], [], []), "n_tips must be even"),
        ((-2, [], [], []), "non-negative"),
        ((4, [[0, 4]], [], []), "tip_contacts holds tip index 4"),
        ((4, [[0, -1]], [], []), "tip_contacts holds tip index -1"),
        ((4, [0, 1], [], []), r"tip_contacts must have shape \(m, 2\)"),
        ((4, [[0.5, 1]], [], []), "tip_contacts must hold integers"),
        ((4, [], [7], [1.0]), "conductor_tip holds tip index 7"),
        ((4, [], [0, 1], [1.0]), "one potential per conductor contact"),
        ((4, [], [0], [np.nan]), "conductor_potential must be finite"),
    ],
)
def test_invalid_input_raises(args, message):
    """Wrong sizes, out-of-range tips and non-finite potentials raise ValueError naming the problem."""
    with pytest.raises(ValueError, match=message):
        solve_circuit(*args)


def test_unknown_solver_raises():
    """An unknown solver name is a ValueError listing the valid ones."""
    with pytest.raises(ValueError, match="solver must be one of"):
        solve_circuit(2, [], [0, 1], [0.5, -0.5], solver="magic")


def test_many_parallel_rods_between_two_clusters():
    """300 parallel rods between two tip clusters (more than an int8 count): conductance 300.

    Chain P -x- (300 rods) -y- N across voltage V: R = 2 + 1/300, total current V / R.
    """
    V = DELTA
    rods = [("P", "x")] + [("x", "y")] * 300 + [("y", "N")]
    n_rods, tc, ct, cid = netlist(rods)
    sol = solve_circuit(2 * n_rods, tc, ct, electrode_potential(cid, V))
    R = 2 + 1 / 300
    assert sol.effective_resistance == pytest.approx(R, rel=TOL)
    np.testing.assert_allclose(sol.current[1:-1], V / R / 300, atol=TOL)
    check_laws(sol, ct, cid)
