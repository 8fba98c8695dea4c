"""Resistor networks with unequal resistances and resistive contacts (docs/model.md 'Circuit').

Three ways in: :func:`solve_network` on a netlist of nodes and resistors,
:func:`solve_circuit` on rods with ``rod_resistance`` and ``contact_resistance``,
and :class:`ConnectivityGraph` with the same keys. Expected values come from hand
calculations (nodal equations solved on paper, in the docstrings), from
``networkx.resistance_distance`` on the weighted graph, and from an independent
dense nodal solve written here with numpy.

Tolerances: the potentials are O(1); a sparse direct solve of a network with
resistances within a factor 100 is exact to a few ulp times the condition number of
the reduced Laplacian (< 1e3 here), i.e. ~1e-13; ``TOL = 1e-12`` leaves a margin of
10x over that (observed: ~1e-15). Where the resistances span 1e6, the condition
number is 1e6 larger and the tolerance says so.
"""

import networkx as nx
import numpy as np
import pytest
from test_circuit import DELTA, check_laws, electrode_potential, netlist, random_network

from selfas_graph.model.circuit import solve_circuit, solve_network
from selfas_graph.model.events import CONDUCTOR_ANODE, CONDUCTOR_CATHODE, SHORT_CIRCUIT
from selfas_graph.model.graph import ConnectivityGraph, classify_rods
from selfas_graph.model.topology import circuit_event, classify_resistive

#: round-off of a sparse solve of O(1) potentials, condition number < 1e3 (observed ~1e-15)
TOL = 1e-12


# ------------------------------------------------------------------------------ helpers
def bridge(R, V=1.0):
    """Wheatstone bridge as a netlist: nodes P=0 (at V), N=1 (at 0), A=2, B=3.

    Resistors P-A R1, P-B R2, A-N R3, B-N R4, A-B R5 (in this order).
    """
    edges = np.array([[0, 2], [0, 3], [2, 1], [3, 1], [2, 3]])
    return solve_network(4, edges, R, [0, 1], [V, 0.0])


def nx_weighted_resistance(n_nodes, edges, resistance, a, b):
    """Resistance between nodes a and b by networkx alone: parallel edges combined by
    adding conductances, self-loops dropped, ``resistance_distance`` with the
    reciprocal of the resistance as edge weight."""
    g = nx.Graph()
    g.add_nodes_from(range(n_nodes))
    for (u, v), r in zip(edges.tolist(), resistance.tolist()):
        if u == v:
            continue
        c = g.get_edge_data(u, v, {"conductance": 0.0})["conductance"]
        g.add_edge(u, v, conductance=c + 1.0 / r)
    sub = g.subgraph(nx.node_connected_component(g, a))
    return nx.resistance_distance(sub, a, b, weight="conductance", invert_weight=False)


def dense_nodal_solve(n_nodes, edges, resistance, fixed_node, fixed_potential):
    """Independent nodal analysis with a dense numpy Laplacian (the oracle).

    Only for networks whose nodes form one connected component with fixed nodes
    of distinct potentials; self-loops and multi-edges enter the Laplacian as they
    are (a self-loop adds +g and -g on the same diagonal entry: nothing).
    """
    L = np.zeros((n_nodes, n_nodes))
    for (u, v), r in zip(edges.tolist(), resistance.tolist()):
        g = 1.0 / r
        L[u, u] += g
        L[v, v] += g
        L[u, v] -= g
        L[v, u] -= g
    fixed = np.zeros(n_nodes, dtype=bool)
    fixed[fixed_node] = True
    psi = np.zeros(n_nodes)
    psi[fixed_node] = fixed_potential
    free = ~fixed
    psi[free] = np.linalg.solve(L[np.ix_(free, free)], -L[np.ix_(free, fixed)] @ psi[fixed])
    current = (psi[edges[:, 0]] - psi[edges[:, 1]]) / resistance
    return psi, current


def random_weighted_network(rng, n_nodes, n_edges, contrast=100.0):
    """A connected random network: a random spanning tree plus random extra edges
    (multi-edges and self-loops included), resistances log-uniform in [1, contrast]."""
    order = rng.permutation(n_nodes)
    tree = [(order[k], order[rng.integers(0, k)]) for k in range(1, n_nodes)]
    extra = rng.integers(0, n_nodes, size=(n_edges - len(tree), 2))
    extra[:5, 1] = extra[:5, 0]  # a few self-loops
    extra[5:10] = extra[10:15]  # a few multi-edges
    edges = np.concatenate([np.array(tree), extra]).astype(np.int64)
    resistance = np.exp(rng.uniform(0.0, np.log(contrast), len(edges)))
    return edges, resistance


# ------------------------------------------------------------------------------ bridges
def test_unbalanced_wheatstone_bridge_with_unequal_resistances_by_hand():
    """R1..R5 = 1, 2, 3, 4, 5, V = 1: nodal equations 23 a - 3 b = 15, 4 a - 19 b = -10.

    So a = 63/85, b = 58/85, the bridge carries (a - b)/5 = 1/85 from A to B, the
    source gives (1 - a)/1 + (1 - b)/2 = 71/170, and R_eff = 170/71.
    """
    R = np.array([1.0, 2.0, 3.0, 4.0, 5.0])
    sol = bridge(R)
    np.testing.assert_allclose(sol.potential, [1.0, 0.0, 63 / 85, 58 / 85], rtol=0, atol=TOL)
    np.testing.assert_allclose(sol.current, [22 / 85, 27 / 170, 63 / 255, 58 / 340, 1 / 85], rtol=0, atol=TOL)
    assert sol.total_current == pytest.approx(71 / 170, rel=TOL)
    assert sol.effective_resistance == pytest.approx(170 / 71, rel=TOL)
    assert sol.effective_resistance == pytest.approx(
        nx_weighted_resistance(4, np.array([[0, 2], [0, 3], [2, 1], [3, 1], [2, 3]]), R, 0, 1), rel=TOL
    )
    assert sol.kirchhoff_residual < TOL
    assert sol.dissipated_power == pytest.approx(sol.supplied_power, rel=TOL)


def test_balanced_bridge_with_unequal_arms_carries_nothing_in_the_bridge():
    """R1/R3 = R2/R4 (1/2 = 3/6), bridge R5 = 7: a = b = 2/3, bridge current 0,
    R_eff = (1 + 2) || (3 + 6) = 27/12."""
    sol = bridge(np.array([1.0, 3.0, 2.0, 6.0, 7.0]))
    assert abs(sol.current[4]) < TOL
    np.testing.assert_allclose(sol.potential[2:], [2 / 3, 2 / 3], rtol=0, atol=TOL)
    assert sol.effective_resistance == pytest.approx(27 / 12, rel=TOL)


def test_bridge_on_rods_matches_the_netlist():
    """The same unbalanced bridge built of five rods with tip contacts: same currents
    (rod i joins junctions as the netlist's edge i), the bridge rod by hand 1/85 V."""
    R = np.array([1.0, 2.0, 3.0, 4.0, 5.0])
    rods = [("P", "A"), ("P", "B"), ("A", "N"), ("B", "N"), ("A", "B")]
    n_rods, tc, ct, cid = netlist(rods)
    V = DELTA
    sol = solve_circuit(2 * n_rods, tc, ct, electrode_potential(cid, V), rod_resistance=R)
    np.testing.assert_allclose(sol.current, V * bridge(R).current, rtol=0, atol=TOL)
    assert sol.effective_resistance == pytest.approx(170 / 71, rel=TOL)
    check_laws(sol, ct, cid)


# ------------------------------------------------------------------------------ chains, contrast
def test_parallel_chains_of_different_resistance():
    """Chain 1: 3 rods of R = 2; chain 2: 5 rods of R = 0.3; chain 3: 1 rod of R = 7.

    Each chain carries V / (its resistance): V/6, V/1.5, V/7; R_eff = 1/(1/6 + 1/1.5 + 1/7).
    """
    rods, R = [], []
    for k, (n, r) in enumerate([(3, 2.0), (5, 0.3), (1, 7.0)]):
        names = ["P"] + [f"c{k}_{j}" for j in range(n - 1)] + ["N"]
        rods += list(zip(names[:-1], names[1:]))
        R += [r] * n
    n_rods, tc, ct, cid = netlist(rods)
    V = 3.0
    sol = solve_circuit(2 * n_rods, tc, ct, electrode_potential(cid, V), rod_resistance=R)
    expected = [V / 6] * 3 + [V / 1.5] * 5 + [V / 7]
    np.testing.assert_allclose(sol.current, expected, rtol=0, atol=TOL)
    assert sol.effective_resistance == pytest.approx(1 / (1 / 6 + 1 / 1.5 + 1 / 7), rel=TOL)
    check_laws(sol, ct, cid)


def test_resistance_contrast_of_a_million():
    """R = 1 in series with (1e6 || 1), and a chain of alternating 1 and 1e6.

    Series-parallel by hand: R_eff = 1 + 1e6/(1e6 + 1); the 1e6 branch carries a
    fraction 1/(1e6 + 1) of the current. The condition number grows with the
    contrast (1e6), so the round-off bound is 1e6 x 1e-16 = 1e-10 relative; 1e-9 allows 10x.
    """
    rel = 1e-9  # contrast 1e6 times eps, with a 10x margin
    edges = np.array([[0, 2], [2, 1], [2, 1]])
    R = np.array([1.0, 1e6, 1.0])
    sol = solve_network(3, edges, R, [0, 1], [1.0, 0.0])
    Reff = 1 + 1e6 / (1e6 + 1)
    assert sol.effective_resistance == pytest.approx(Reff, rel=rel)
    assert sol.current[1] == pytest.approx(1 / Reff / (1e6 + 1), rel=rel)
    assert sol.effective_resistance == pytest.approx(nx_weighted_resistance(3, edges, R, 0, 1), rel=rel)
    # a ladder with rungs of 1e6 and rails of 1, against networkx
    n = 40
    edges, R = [], []
    for k in range(n):
        edges += [(2 * k, 2 * k + 2), (2 * k + 1, 2 * k + 3), (2 * k, 2 * k + 1)]
        R += [1.0, 1.0, 1e6 if k % 2 else 1e-0]
    edges, R = np.array(edges), np.array(R)
    n_nodes = 2 * n + 2
    sol = solve_network(n_nodes, edges, R, [0, n_nodes - 1], [1.0, 0.0])
    assert sol.effective_resistance == pytest.approx(nx_weighted_resistance(n_nodes, edges, R, 0, n_nodes - 1), rel=rel)
    assert sol.kirchhoff_residual < TOL


# ------------------------------------------------------------------------------ random networks
@pytest.mark.parametrize("seed", [11, 12, 13])
def test_solve_network_agrees_with_a_dense_nodal_solve(seed):
    """300-400 edges, resistances within a factor 100, 3 fixed nodes: solve_network
    and the dense numpy solve agree to 1e-12 (both are round-off of O(1) potentials)."""
    rng = np.random.default_rng(seed)
    n_nodes = int(rng.integers(120, 200))
    edges, R = random_weighted_network(rng, n_nodes, int(rng.integers(300, 400)))
    fixed = rng.choice(n_nodes, size=3, replace=False)
    pot = np.array([1.0, -0.5, 0.25])
    sol = solve_network(n_nodes, edges, R, fixed, pot)
    psi, current = dense_nodal_solve(n_nodes, edges, R, fixed, pot)
    np.testing.assert_allclose(sol.potential, psi, rtol=0, atol=TOL)
    np.testing.assert_allclose(sol.current, current, rtol=0, atol=TOL)
    # the two-terminal value against networkx (only two fixed nodes)
    two = solve_network(n_nodes, edges, R, fixed[:2], [1.0, 0.0])
    assert two.effective_resistance == pytest.approx(
        nx_weighted_resistance(n_nodes, edges, R, fixed[0], fixed[1]), rel=TOL
    )


@pytest.mark.parametrize("seed", [21, 22, 23, 24])
def test_kirchhoff_and_power_balance_on_random_weighted_networks(seed):
    """Random rod networks (free rods, parallel rods and loops included) with rod
    resistances log-uniform in [0.1, 10]: Kirchhoff's law at every inner node, current
    in = current out, supplied power = sum J_i^2 R_i; also with resistive contacts."""
    rng = np.random.default_rng(seed)
    rods = random_network(300, 150, rng)
    n_rods, tc, ct, cid = netlist(rods)
    pot = electrode_potential(cid, DELTA * 10)
    R = np.exp(rng.uniform(np.log(0.1), np.log(10.0), n_rods))
    sol = solve_circuit(2 * n_rods, tc, ct, pot, rod_resistance=R)
    check_laws(sol, ct, cid)
    assert sol.dissipated_power == pytest.approx(float(np.sum(sol.current**2 * R)), rel=TOL)
    for r in (0.05, 2.0):
        sol = solve_circuit(2 * n_rods, tc, ct, pot, rod_resistance=R, contact_resistance=r)
        assert sol.kirchhoff_residual < TOL
        # with resistive contacts each conductor contact is a node of its own
        assert sol.injected_current.sum() == pytest.approx(0.0, abs=TOL * 100)  # sum of O(10) injections
        assert sol.dissipated_power == pytest.approx(sol.supplied_power, rel=TOL)
        assert sol.dissipated_power > float(np.sum(sol.current**2 * R))  # the contacts dissipate too


@pytest.mark.parametrize("seed", [31, 32])
def test_cg_solver_agrees_with_direct_on_weighted_networks(seed):
    """Jacobi-CG to a relative residual 1e-14 on resistances within a factor 100: the
    error is that times the condition number (< 1e4 here), hence 1e-9."""
    rng = np.random.default_rng(seed)
    edges, R = random_weighted_network(rng, 150, 350)
    a = solve_network(150, edges, R, [0, 1, 2], [1.0, 0.0, 0.5])
    b = solve_network(150, edges, R, [0, 1, 2], [1.0, 0.0, 0.5], solver="cg")
    np.testing.assert_allclose(b.potential, a.potential, rtol=0, atol=1e-9)


# ------------------------------------------------------------------------------ any netlist
def test_multi_edges_self_loops_isolated_nodes_and_zero_voltage():
    """Two parallel resistors 2 and 3 (1.2 together) in series with 0.8: R_eff = 2;
    a self-loop carries 0; an isolated node floats (NaN); with V = 0 nothing flows."""
    edges = np.array([[0, 2], [0, 2], [2, 1], [2, 2], [3, 4]])
    R = np.array([2.0, 3.0, 0.8, 5.0, 1.0])
    sol = solve_network(6, edges, R, [0, 1], [2.0, 0.0])
    assert sol.effective_resistance == pytest.approx(2.0, rel=TOL)
    np.testing.assert_allclose(sol.current, [1.2 / 2, 1.2 / 3, 1.0, 0.0, 0.0], rtol=0, atol=TOL)
    assert np.isnan(sol.potential[3:]).all()  # the pair 3-4 and the isolated node 5 float
    zero = solve_network(6, edges, R, [0, 1], [0.5, 0.5])
    assert not zero.current.any() and zero.total_current == 0.0
    assert zero.effective_resistance == np.inf
    np.testing.assert_array_equal(zero.potential[:3], 0.5)


def test_ideal_edges_merge_their_nodes():
    """A zero-resistance edge makes its two nodes one (as ideal contacts do); its own
    current is not fixed by the potentials and is reported as NaN."""
    edges = np.array([[0, 2], [2, 3], [3, 1]])
    sol = solve_network(4, edges, [1.0, 0.0, 1.0], [0, 1], [1.0, 0.0])
    assert sol.node_of[2] == sol.node_of[3]
    np.testing.assert_allclose(sol.current[[0, 2]], 0.5, rtol=0, atol=TOL)
    assert np.isnan(sol.current[1])
    assert sol.effective_resistance == pytest.approx(2.0, rel=TOL)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(resistance=[1.0, -1.0]), "resistance must be finite and >= 0; entry 1"),
        (dict(resistance=[1.0, np.inf]), "resistance must be finite"),
        (dict(resistance=[1.0]), r"resistance must be a number or have shape \(2,\)"),
        (dict(edges=[[0, 5], [1, 2]]), "edges holds tip index 5"),
        (dict(fixed_potential=[1.0]), "one potential per fixed node"),
    ],
)
def test_solve_network_invalid_input(kwargs, message):
    """Bad resistances, indices or potentials raise ValueError naming the argument."""
    args = dict(n_nodes=3, edges=[[0, 1], [1, 2]], resistance=[1.0, 1.0], fixed_node=[0, 2], fixed_potential=[1.0, 0.0])
    args.update(kwargs)
    with pytest.raises(ValueError, match=message):
        solve_network(**args)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(rod_resistance=[1.0, 0.0]), "rod_resistance must be finite and > 0; entry 1"),
        (dict(rod_resistance=[1.0, 1.0, 1.0]), r"rod_resistance must be a number or have shape \(2,\)"),
        (dict(contact_resistance=-0.1), "contact_resistance must be finite and >= 0"),
        # a conductance 1/R or a power J^2 R that float64 does not hold: inf and NaN potentials before
        (dict(rod_resistance=[1.0, 1e-310]), r"rod_resistance must lie within \[1e-100, 1e\+100\]"),
        (dict(rod_resistance=1e308), r"rod_resistance must lie within"),
        (dict(contact_resistance=1e-310), r"contact_resistance must be 0 or lie within"),
    ],
)
def test_solve_circuit_invalid_resistances(kwargs, message):
    with pytest.raises(ValueError, match=message):
        solve_circuit(4, [[1, 2]], [0, 3], [1.0, -1.0], **kwargs)


@pytest.mark.parametrize("holder", ["graph", "network"])
@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(rod_resistance=[1.0, 0.0]), "rod_resistance must be finite and > 0; entry 1"),
        (dict(rod_resistance=[1.0, 1.0, 1.0]), r"rod_resistance must be a number or have shape \(2,\)"),
        (dict(contact_resistance=-0.1), "contact_resistance must be finite and >= 0"),
        (dict(contact_resistance=float("nan")), "contact_resistance must be finite and >= 0"),
        (dict(solver="lu"), "solver must be one of"),
    ],
)
def test_the_holders_of_contacts_check_the_circuit_settings_alike(holder, kwargs, message):
    """ConnectivityGraph and Network take the circuit's settings through one check (ContactQueries), when
    they are made: the network took any rod or contact resistance and solver and failed at its first solve,
    or solved with a negative contact resistance."""
    from selfas_graph.model.graph import ConnectivityGraph
    from selfas_graph.model.network import Network

    with pytest.raises(ValueError, match=message):
        if holder == "graph":
            ConnectivityGraph(2, {0: -1.0, 1: 1.0}, **kwargs)
        else:
            Network(2, 1.0, 1.2, electrodes=(-2.0, 2.0), bias=1.0, circuit=True, **kwargs)
    ok = ConnectivityGraph(2, {0: -1.0, 1: 1.0}, rod_resistance=[1.0, 2.0]) if holder == "graph" else None
    ok = ok or Network(2, 1.0, 1.2, rod_resistance=[1.0, 2.0], contact_resistance=0.5)
    assert not ok.rod_resistance.flags.writeable and ok.rod_resistance.tolist() == [1.0, 2.0]


# ------------------------------------------------------------------------------ contact resistance
@pytest.mark.parametrize("n", [1, 2, 5, 17])
@pytest.mark.parametrize("r", [0.0, 0.1, 3.0])
def test_chain_with_resistive_contacts_carries_delta_over_total_resistance(n, r):
    """A chain of n rods of resistance R between the electrodes has n + 1 contacts
    (cathode-tip, n - 1 tip-tip, tip-anode), all of resistance r: every rod carries
    V / (n R + (n + 1) r), and across each tip-tip contact the potential drops by J r."""
    R, V = 1.7, DELTA * n
    rods = [("N" if i == 0 else f"j{i}", "P" if i == n - 1 else f"j{i + 1}") for i in range(n)]
    n_rods, tc, ct, cid = netlist(rods)
    sol = solve_circuit(2 * n_rods, tc, ct, electrode_potential(cid, V), rod_resistance=R, contact_resistance=r)
    J = V / (n * R + (n + 1) * r)
    np.testing.assert_allclose(sol.current, -J, rtol=TOL)  # tip a at the cathode side: J flows b -> a
    assert sol.effective_resistance == pytest.approx(n * R + (n + 1) * r, rel=TOL)
    psi = sol.potential
    np.testing.assert_allclose(psi[2::2] - psi[1:-1:2], J * r, rtol=0, atol=TOL)  # tip b of i -> tip a of i+1
    assert sol.dissipated_power == pytest.approx(J * J * (n * R + (n + 1) * r), rel=TOL)


def test_chain_with_unequal_rods_and_contacts():
    """Rod resistances R_i and contact resistance r in series: J = V / (sum R_i + (n + 1) r)."""
    R = np.array([0.5, 2.0, 1.0, 4.0])
    r, V = 0.25, 1.0
    rods = [("N", "a"), ("a", "b"), ("b", "c"), ("c", "P")]
    n_rods, tc, ct, cid = netlist(rods)
    sol = solve_circuit(2 * n_rods, tc, ct, electrode_potential(cid, V), rod_resistance=R, contact_resistance=r)
    np.testing.assert_allclose(sol.current, -V / (R.sum() + 5 * r), rtol=TOL)


def test_small_contact_resistance_tends_to_ideal_contacts():
    """As r -> 0 the currents tend to those of ideal contacts, linearly in r: the
    differences at r = 1e-3, 1e-4, 1e-5 fall by 10 at each step (to 1%: the r^2 term
    is 1e-3 of the linear one at most). Smaller r is not tried: the conductance
    contrast 1/r raises the round-off as eps R / r (2e-7 at r = 1e-9)."""
    rng = np.random.default_rng(5)
    rods = random_network(200, 80, rng)
    n_rods, tc, ct, cid = netlist(rods)
    pot = electrode_potential(cid, 10.0)
    ideal = solve_circuit(2 * n_rods, tc, ct, pot)
    diff = [
        np.abs(solve_circuit(2 * n_rods, tc, ct, pot, contact_resistance=r).current - ideal.current).max()
        for r in (1e-3, 1e-4, 1e-5)
    ]
    assert diff[0] / diff[1] == pytest.approx(10.0, rel=0.01)
    assert diff[1] / diff[2] == pytest.approx(10.0, rel=0.01)
    # the currents move linearly with the contact resistance (ratios of 10 above): at 1e-5 R0 by about
    # 1e-5 of their size, so 1e-4 leaves a factor 10
    assert diff[2] < 1e-4 * np.abs(ideal.current).max()


def test_anode_and_cathode_joined_by_a_resistive_contact_pair_conduct():
    """A tip touching both electrodes: ideal contacts short the electrodes without any
    current in a rod (choice B5); resistive ones carry V / (2 r) through the two contacts."""
    V, r = 2.0, 0.5
    ct = np.array([0, 0])
    pot = np.array([V / 2, -V / 2])
    ideal = solve_circuit(2, np.zeros((0, 2)), ct, pot)
    assert ideal.total_current == 0.0 and ideal.potential[0] == 0.0
    sol = solve_circuit(2, np.zeros((0, 2)), ct, pot, contact_resistance=r)
    assert sol.total_current == pytest.approx(V / (2 * r), rel=TOL)
    assert sol.current[0] == 0.0  # the rod itself hangs from that tip only
    # the topology agrees: a short circuit (choice B29), whose event counts no filament rod
    topo = classify_resistive(1, np.zeros((0, 2), dtype=np.int64), ct, np.array([CONDUCTOR_CATHODE, CONDUCTOR_ANODE]))
    assert topo.has_short_circuit and topo.n_filament == 0
    assert circuit_event(False, topo, 7, 0.5) == [(7, 0.5, SHORT_CIRCUIT, 0, -1)]


def test_explicit_unit_resistance_and_ideal_contacts_are_bit_for_bit_the_default():
    """rod_resistance = 1 everywhere and contact_resistance = 0 give the default's bits."""
    rng = np.random.default_rng(9)
    rods = random_network(300, 150, rng)
    n_rods, tc, ct, cid = netlist(rods)
    pot = electrode_potential(cid, DELTA * 10)
    a = solve_circuit(2 * n_rods, tc, ct, pot)
    b = solve_circuit(2 * n_rods, tc, ct, pot, rod_resistance=np.ones(n_rods), contact_resistance=0.0)
    for name in ("potential", "current", "injected_current"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    assert a.dissipated_power == b.dissipated_power and a.total_current == b.total_current


# ------------------------------------------------------------------------------ the graph
def test_graph_roles_do_not_depend_on_resistances():
    """The topology is the same with and without resistances; the solve uses them."""
    rng = np.random.default_rng(3)
    rods = random_network(120, 60, rng)
    n_rods, tc, ct, cid = netlist(rods)
    arrays = {
        "tip_contacts": tc,
        "conductor_tip": ct,
        "conductor_id": cid,
        "conductor_potential": electrode_potential(cid, 4.0),
    }
    conductors = {CONDUCTOR_CATHODE: -2.0, CONDUCTOR_ANODE: 2.0}
    R = rng.uniform(0.5, 2.0, n_rods)
    plain = ConnectivityGraph.from_arrays(n_rods, conductors, arrays)
    weighted = ConnectivityGraph.from_arrays(n_rods, conductors, arrays, rod_resistance=R, contact_resistance=0.3)
    np.testing.assert_array_equal(plain.topology().role, weighted.topology().role)
    np.testing.assert_array_equal(
        weighted.topology().role, classify_rods(n_rods, tc, ct, weighted.conductor_node_key()).role
    )
    sol = weighted.solve()
    direct = solve_circuit(2 * n_rods, tc, ct, electrode_potential(cid, 4.0), rod_resistance=R, contact_resistance=0.3)
    np.testing.assert_array_equal(sol.current, direct.current)


# ------------------------------------------------------------------------------ resistive topology
def _resistive_network(rows):
    from selfas_graph.model import events as ev
    from selfas_graph.model.network import Network

    net = Network(3, 0.06, 0.09, electrodes=(-2.0, 2.0), bias=1.0, circuit=True, contact_resistance=1.0)
    net.tracker.search = lambda *a, **k: [rows.pop(0) for _ in range(len(rows))]  # the search is not under test
    net.update(np.zeros((6, 3)), None, 1, 0.1)
    return net, ev


def test_with_resistive_contacts_a_loop_pinned_at_the_anode_carries_its_current():
    """Anode - rod 0 - contact - rod 1 - tip 3, which touches the anode and, through a contact, rod 2 to the
    cathode (r = R = 1, gap 4, delta 1: anode +2, cathode -2). With ideal contacts rods 0 and 1 would be a
    loop pinned at the anode (dead ends, no current); with resistors each tip is a node of its own, and the
    nodal equations of its 8 nodes (the 6 tips and the two electrodes, as a dense solve checks) give rods 0
    and 1 4/19 and rod 2 20/19.
    The run zeroed the first two as dead ends: Kirchhoff's law failed at tip 3 in the currents the forces
    use."""
    from selfas_graph.model import events as ev
    from selfas_graph.model.topology import FILAMENT

    rows = [(1, 0.1, ev.TIP_CONTACT, 1, 2), (1, 0.1, ev.TIP_CONTACT, 3, 4)]
    rows += [(1, 0.1, ev.CONDUCTOR_CONTACT, k, c) for k, c in ((0, 1), (3, 1), (5, 0))]
    net, _ = _resistive_network(rows)
    assert list(net.topology().role) == [FILAMENT] * 3
    np.testing.assert_allclose(net.current, [4 / 19, 4 / 19, 20 / 19], rtol=0, atol=TOL)


def test_with_resistive_contacts_a_rod_across_a_contact_between_the_electrodes_is_a_short_circuit():
    """Rod 0's tips touch tip 2 (on the anode) and tip 4 (on the cathode), and tips 2 and 4 touch each other.
    Ideal, that is one node touching both electrodes: no short circuit (choice B5). Resistive (B29), the
    tips are nodes of their own and rod 0 carries 4/11 (hand solve: tips 2, 4 at +-6/11, rod 0's at
    +-2/11): the run saw no short circuit, solved nothing and gave every rod 0."""
    from selfas_graph.model import events as ev

    rows = [(1, 0.1, ev.TIP_CONTACT, 0, 2), (1, 0.1, ev.TIP_CONTACT, 1, 4), (1, 0.1, ev.TIP_CONTACT, 2, 4)]
    rows += [(1, 0.1, ev.CONDUCTOR_CONTACT, 2, ev.CONDUCTOR_ANODE), (1, 0.1, ev.CONDUCTOR_CONTACT, 4, 0)]
    net, _ = _resistive_network(rows)
    assert net.has_short_circuit and net.solution is not None
    np.testing.assert_allclose(net.current, [4 / 11, 0.0, 0.0], rtol=0, atol=TOL)


@pytest.mark.parametrize("seed", range(6))
def test_resistive_topology_against_networkx_and_the_solve(seed):
    """On random networks of rods, tip contacts and contacts with the two electrodes: a rod is FILAMENT
    iff networkx puts its edge in a biconnected component with a node X joined to the electrodes, in
    the graph whose nodes are the tips (none merged) and whose edges are the rods and every contact; a
    rod off every such path carries no current in the resistive solve (to round-off)."""
    from selfas_graph.model import events as ev
    from selfas_graph.model.topology import FILAMENT, classify_resistive

    rng = np.random.default_rng(seed)
    n_rods = 12
    pairs = {tuple(sorted(rng.choice(2 * n_rods, 2, replace=False))) for _ in range(14)}
    tc = np.array([p for p in pairs if p[0] // 2 != p[1] // 2], dtype=np.int64).reshape(-1, 2)
    tips = rng.choice(2 * n_rods, 6, replace=False)
    cid = rng.integers(0, 2, 6)
    order = np.lexsort((cid, tips))
    ct, cid = tips[order], cid[order]
    topo = classify_resistive(n_rods, tc, ct, cid)
    g = nx.Graph()
    g.add_edges_from((2 * i, 2 * i + 1) for i in range(n_rods))
    g.add_edges_from(map(tuple, tc.tolist()))
    g.add_edges_from((int(t), ("C", int(c))) for t, c in zip(ct, cid))
    g.add_edges_from(("X", ("C", int(c))) for c in set(cid.tolist()))
    in_x = set()
    for block in nx.biconnected_component_edges(g):
        block = list(block)
        if any("X" in e for e in block):
            in_x |= {frozenset(e) for e in block}
    want = [frozenset((2 * i, 2 * i + 1)) in in_x for i in range(n_rods)]
    assert [r == FILAMENT for r in topo.role] == want
    pot = np.where(cid == ev.CONDUCTOR_ANODE, 2.0, -2.0)
    sol = solve_circuit(2 * n_rods, tc, ct, pot, contact_resistance=1.0)
    off = np.flatnonzero(~np.array(want, dtype=bool))
    assert np.abs(sol.current[off]).max(initial=0.0) < TOL
