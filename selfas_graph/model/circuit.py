"""Nodal analysis of the rod network: potentials and rod currents (docs/model.md 'Circuit').

Arrays in, arrays out: ``contact_queries.solve_contacts`` hands over the contacts as arrays (for
``network.Network.solve`` in a run, ``graph.ConnectivityGraph.solve`` for a saved graph).
:func:`solve_network` solves any resistor network (the reduced system in :mod:`.linear`);
:func:`solve_circuit` turns rods and contacts into one.

Model
-----
* Rod ``i`` is a resistor ``R_i`` (``R0 = 1`` unless given) between its tips
  ``a = 2 i`` and ``b = 2 i + 1``. Its current ``J_i = (psi(a) - psi(b)) / R_i`` is
  positive from tip a to tip b (units J0; potentials in units R0 J0).
* With ``contact_resistance`` r > 0 every contact is a resistor r: between two tips,
  or from a tip to a node of its own held at the conductor contact's potential.
  What follows is the ideal case, r = 0 (the default):
* Contacts are ideal: tip-tip and tip-conductor contacts merge tips into one
  electrical node (connected components of the contact edges).
* A merged node holding a conductor contact is a Dirichlet node with the given
  potential. If one merged node holds several conductor contacts with different
  potentials (case (ii): a tip cluster touching the filament at slightly
  different heights) its potential is the **mean** of the given values; the
  ideal contacts short those heights together, and the mean is the simplest
  choice that is exact when they agree.
* Only connected components (of merged nodes joined by rods) that hold at least
  two different Dirichlet values are solved. A component with one Dirichlet
  value sits at that value exactly (no current); a component with none floats
  (potential NaN, no current). So the reduced matrix is always non-singular:
  every block of the interior system touches a Dirichlet node.

The reduced system is ``L_II psi_I = -L_ID psi_D`` with ``L`` the graph
Laplacian of the resistors on merged nodes, weighted by their conductances
(parallel resistors add their conductances; resistors whose two ends are in one
merged node are dropped: they carry 0).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from selfas_graph.kernels.graph import component_labels
from selfas_graph.model.linear import SolveMemo, _potentials
from selfas_graph.model.validate import (
    _as_contact_resistance,
    _as_count,
    _as_index_array,
    _as_potentials,
    _as_resistance,
    _frozen,
    _validate,
)

__all__ = ["CircuitSolution", "NetworkSolution", "SolveMemo", "solve_circuit", "solve_network", "merge_tips", "SOLVERS"]

#: linear solvers for the reduced system (``solve_circuit(..., solver=...)``)
SOLVERS = ("direct", "cg", "auto")


# --------------------------------------------------------------------------- topology helper
def merge_tips(n_tips: int, tip_contacts: np.ndarray) -> tuple[int, np.ndarray]:
    """Merge tips joined by ideal contacts into electrical nodes.

    Parameters
    ----------
    n_tips : int
        Number of tips (``2 n_rods``).
    tip_contacts : (m, 2) int64
        Pairs of tips in contact (already validated).

    Returns
    -------
    n_nodes : int
        Number of merged electrical nodes.
    node_of_tip : (n_tips,) int64
        Merged node of each tip: merged nodes are numbered in the order of their
        smallest tip (the numbering of ``scipy.sparse.csgraph.connected_components``).
    """
    m = tip_contacts.shape[0]
    if m == 0:
        return n_tips, np.arange(n_tips, dtype=np.int64)
    n_nodes, labels = component_labels(
        n_tips,
        np.ascontiguousarray(tip_contacts[:, 0], dtype=np.int64),
        np.ascontiguousarray(tip_contacts[:, 1], dtype=np.int64),
    )
    return int(n_nodes), labels


# --------------------------------------------------------------------------- result
@dataclasses.dataclass(frozen=True, eq=False)
class CircuitSolution:
    """Result of one nodal-analysis solve (arrays are read-only).

    Attributes
    ----------
    potential : (n_tips,) float64
        Potential of each tip (units R0 J0); NaN for tips in floating components.
    current : (n_rods,) float64
        Rod current J_i = (psi(2i) - psi(2i+1)) / R_i (units J0); 0 for floating rods
        and rods whose two tips are in one merged node.
    node_of_tip : (n_tips,) int64
        Merged electrical node of each tip (with resistive contacts: the tip itself;
        the nodes ``n_tips + j`` are then the conductor contacts j).
    injected_current : (n_nodes,) float64
        Net current from the rods out of each merged node: the current a conductor
        injects there; zero (to round-off) at nodes without a conductor contact.
    total_current : float
        The current from the conductors into the network (= into the lower-potential ones).
    supplied_power : float
        sum over conductor nodes of psi * injected current.
    dissipated_power : float
        sum_i J_i^2 R_i, plus J^2 r over the contacts when they are resistive.
    effective_resistance : float
        (psi_max - psi_min over conductor nodes in current-carrying components) / total_current,
        units R0; ``inf`` when no current flows. Case (i): the resistance between the
        electrodes; case (ii): a summary number only (the filament is not two terminals).
    kirchhoff_residual : float
        max |net current| at merged nodes without a conductor contact.
    """

    potential: np.ndarray
    current: np.ndarray
    node_of_tip: np.ndarray
    injected_current: np.ndarray
    total_current: float
    supplied_power: float
    dissipated_power: float
    effective_resistance: float
    kirchhoff_residual: float

    @property
    def n_nodes(self) -> int:
        """Number of merged electrical nodes."""
        return int(self.injected_current.shape[0])


@dataclasses.dataclass(frozen=True, eq=False)
class NetworkSolution:
    """Result of :func:`solve_network` (arrays are read-only).

    Attributes
    ----------
    potential : (n_nodes,) float64
        Potential of each node; NaN in floating components.
    current : (m,) float64
        Current of each resistor from ``edges[:, 0]`` to ``edges[:, 1]``; 0 for
        floating resistors and for resistors whose ends are joined by ideal
        (zero-resistance) edges, NaN for the ideal edges themselves (their current
        is not fixed by the potentials).
    node_of : (n_nodes,) int64
        Merged node of each node (nodes joined by ideal edges share one).
    injected_current : (n_merged,) float64
        Net current leaving each merged node through the resistors: the current
        a source injects there; zero (to round-off) at nodes without a fixed potential.
    total_current, supplied_power, dissipated_power, effective_resistance, kirchhoff_residual
        As in :class:`CircuitSolution`; ``dissipated_power`` is sum_e J_e^2 R_e.
    """

    potential: np.ndarray
    current: np.ndarray
    node_of: np.ndarray
    injected_current: np.ndarray
    total_current: float
    supplied_power: float
    dissipated_power: float
    effective_resistance: float
    kirchhoff_residual: float


def _solve(
    n_nodes, edges, resistance, fixed_node, fixed_potential, solver, resistance_is_one=False, memo=None, merged=None
):
    """Core of :func:`solve_network` on validated arrays; see there.

    ``resistance_is_one``: every resistance is 1 (the default rods); the currents
    are then the potential differences themselves, with no division. ``memo``: a
    :class:`SolveMemo`. ``merged``: ``(n_merged, node_of)``, the merge of the nodes by the
    ideal edges when the caller has it already (it must be what :func:`merge_tips` gives).
    """
    if solver not in SOLVERS:
        raise ValueError(f"solver must be one of {SOLVERS}, got {solver!r}")
    ideal = resistance == 0.0
    n_merged, node_of = merge_tips(n_nodes, edges[ideal]) if merged is None else merged

    # Dirichlet values: mean of the given potentials of the fixed nodes in each merged node
    cnode = node_of[fixed_node]
    count = np.bincount(cnode, minlength=n_merged)
    is_dir = count > 0
    psi_dir = np.zeros(n_merged)
    psi_dir[is_dir] = np.bincount(cnode, weights=fixed_potential, minlength=n_merged)[is_dir] / count[is_dir]

    # resistors as edges between merged nodes; those inside one merged node are dropped
    res = ~ideal
    u_all = node_of[edges[res, 0]]
    v_all = node_of[edges[res, 1]]
    r_all = resistance[res]
    g_all = 1.0 / r_all
    keep = u_all != v_all
    psi, comp, comp_active = _potentials(n_merged, u_all[keep], v_all[keep], g_all[keep], is_dir, psi_dir, solver, memo)

    psi0 = np.where(np.isnan(psi), 0.0, psi)
    drop = psi0[u_all] - psi0[v_all]  # exactly 0 for shorted and floating resistors
    current_res = drop if resistance_is_one else drop / r_all
    injected = np.bincount(u_all, weights=current_res, minlength=n_merged) - np.bincount(
        v_all, weights=current_res, minlength=n_merged
    )
    dir_nodes = np.flatnonzero(is_dir)
    total_current = float(injected[dir_nodes][injected[dir_nodes] > 0].sum())
    supplied_power = float(np.dot(psi_dir[dir_nodes], injected[dir_nodes]))
    if resistance_is_one:
        dissipated_power = float(np.dot(current_res, current_res))
    else:
        dissipated_power = float(np.dot(current_res, drop))
    active_dir = dir_nodes[comp_active[comp[dir_nodes]]]
    if active_dir.size and total_current > 0:
        spread = float(psi_dir[active_dir].max() - psi_dir[active_dir].min())
        effective_resistance = spread / total_current
    else:
        effective_resistance = float("inf")
    inner = ~is_dir
    kirchhoff_residual = float(np.abs(injected[inner]).max()) if inner.any() else 0.0

    if ideal.any():
        current = np.full(edges.shape[0], np.nan)
        current[res] = current_res
    else:
        current = current_res
    return NetworkSolution(
        potential=_frozen(psi[node_of]),
        current=_frozen(current),
        node_of=_frozen(node_of),
        injected_current=_frozen(injected),
        total_current=total_current,
        supplied_power=supplied_power,
        dissipated_power=dissipated_power,
        effective_resistance=effective_resistance,
        kirchhoff_residual=kirchhoff_residual,
    )


def solve_network(
    n_nodes, edges, resistance, fixed_node, fixed_potential, solver: str = "direct", memo: SolveMemo | None = None
) -> NetworkSolution:
    """Solve Kirchhoff's laws on any network of resistors with nodes of fixed potential.

    The general form of the nodal analysis of :func:`solve_circuit` (docs/model.md
    'Circuit'), for netlists of any origin: per-edge resistances, parallel edges
    (multi-edges), self-loops (they carry 0), isolated nodes (potential NaN), zero
    applied voltage (every node at it, no current).

    Parameters
    ----------
    n_nodes : int
        Number of nodes ``0 .. n_nodes-1``.
    edges : (m, 2) int
        The two nodes of each resistor.
    resistance : float or (m,) float64
        Resistance of each edge (units R0), finite and >= 0. An edge of resistance
        0 is an ideal wire: its two nodes become one node, as contacts do in
        :func:`solve_circuit`.
    fixed_node : (k,) int
        Nodes held at a given potential (sources); a node may be listed several
        times, and a merged node holding different values takes their mean
        (docs/model.md 'Circuit', choice B3).
    fixed_potential : (k,) float64
        The potential of each entry of ``fixed_node`` (units R0 J0).
    solver : {"direct", "cg", "auto"}
        As in :func:`solve_circuit`.
    memo : SolveMemo, optional
        As in :func:`solve_circuit`.

    Returns
    -------
    NetworkSolution
    """
    n_nodes = _as_count(n_nodes, "n_nodes")
    edges = _as_index_array(edges, "edges", 2, n_nodes)
    resistance = _as_resistance(resistance, "resistance", edges.shape[0], allow_zero=True)
    fixed_node = _as_index_array(fixed_node, "fixed_node", 1, n_nodes)
    fixed_potential = _as_potentials(
        fixed_potential, fixed_node, "fixed_potential", "fixed_node", "fixed node entry", "node"
    )
    return _solve(n_nodes, edges, resistance, fixed_node, fixed_potential, solver, memo=memo)


def _netlist(n_tips, tip_contacts, conductor_tip, r_rod, r_contact) -> tuple[np.ndarray, np.ndarray]:
    """``(edges, resistance)``: the rods (tips 2i, 2i+1), the tip contacts, then the conductor contacts,
    contact j joining its tip to node ``n_tips + j``, which is held at its potential."""
    n_rods, m, k = n_tips // 2, tip_contacts.shape[0], conductor_tip.shape[0]
    edges = np.empty((n_rods + m + k, 2), dtype=np.int64)
    edges[:n_rods] = np.arange(n_tips).reshape(n_rods, 2)
    edges[n_rods : n_rods + m] = tip_contacts
    edges[n_rods + m :, 0] = conductor_tip
    edges[n_rods + m :, 1] = n_tips + np.arange(k)
    return edges, np.concatenate([r_rod, np.full(m + k, r_contact)])


def _merge_with_conductors(merged, conductor_tip):
    """The caller's merge of the tips (:func:`merge_tips`, or None) with ideal contacts, extended to
    :func:`_netlist`'s conductor nodes: each takes its tip's merged node."""
    if merged is None:
        return None
    n_merged, node_of_tip = merged
    return int(n_merged), np.concatenate([node_of_tip, node_of_tip[conductor_tip]])


def solve_circuit(
    n_tips,
    tip_contacts,
    conductor_tip,
    conductor_potential,
    solver: str = "direct",
    rod_resistance=None,
    contact_resistance: float = 0.0,
    memo: SolveMemo | None = None,
    merged=None,
) -> CircuitSolution:
    """Solve Kirchhoff's laws on the rod network.

    Parameters
    ----------
    n_tips : int
        Number of tips, ``2 n_rods``; rod ``i`` joins tips ``2 i`` and ``2 i + 1``.
    tip_contacts : (m, 2) int64
        Pairs of tips in contact.
    conductor_tip : (k,) int64
        Tips touching a conductor, one entry per contact.
    conductor_potential : (k,) float64
        Given potential of each conductor contact (units R0 J0): ``-/+ delta_J0 dZ/2``
        for cathode/anode in case (i), ``-delta_J0 z_contact`` on the filament in
        case (ii).
    solver : {"direct", "cg", "auto"}
        Linear solver of the reduced system (symmetric positive definite).
        ``"direct"`` (default): sparse LU (SuperLU) with a symmetric minimum-degree
        ordering, exact to round-off; fast for the branched, quasi-one-dimensional
        networks filaments form, slow on a diluted cubic lattice.
        ``"cg"``: Jacobi-preconditioned conjugate gradients to a relative residual
        :data:`.linear.CG_RTOL` (round-off level): faster on the lattice, slower than "direct" on
        chains; it falls back to the direct solver if it has not converged after
        ``min(2 n, 2000) + 10`` iterations (n unknowns). ``"auto"``: "direct" up to
        :data:`.linear.AUTO_CG_UNKNOWNS` unknowns, "cg" above; the timings behind that
        choice are in its comment (``selfas-graph bench circuit``).
    rod_resistance : float or (n_rods,) float64, optional
        Resistance R_i of each rod (units R0, > 0); default 1 for every rod.
    contact_resistance : float
        Resistance r of every tip-tip and tip-conductor contact (units R0, >= 0).
        0 (default): ideal contacts, tips in contact merged into one node. r > 0:
        every contact is a resistor r, and each conductor contact joins its tip to
        a node of its own held at the contact's potential.
    memo : SolveMemo, optional
        The caller's memo of the last reduced system (a run's :class:`~.network.Network`
        holds one); without it every call solves afresh, with the same bits.
    merged : (n_nodes, node_of_tip), optional
        The merge of the tips by their contacts (:func:`merge_tips`), when the caller has it
        already (:class:`~.topology.Topology` carries it); used with ideal contacts only.

    Returns
    -------
    CircuitSolution

    Raises
    ------
    ValueError
        Odd ``n_tips``, tip index out of range, wrong shapes, non-finite potentials,
        resistances not > 0 (rods) or negative (contacts).
    """
    n_tips, tip_contacts, conductor_tip, conductor_potential = _validate(
        n_tips, tip_contacts, conductor_tip, conductor_potential
    )
    n_rods = n_tips // 2
    unit = rod_resistance is None
    r_rod = np.ones(n_rods) if unit else _as_resistance(rod_resistance, "rod_resistance", n_rods, allow_zero=False)
    r_contact = _as_contact_resistance(contact_resistance)
    k = conductor_tip.shape[0]
    edges, resistance = _netlist(n_tips, tip_contacts, conductor_tip, r_rod, r_contact)
    merged = _merge_with_conductors(merged, conductor_tip) if r_contact == 0.0 else None
    net = _solve(
        n_tips + k,
        edges,
        resistance,
        n_tips + np.arange(k),
        conductor_potential,
        solver,
        resistance_is_one=unit and r_contact == 0.0,
        memo=memo,
        merged=merged,
    )
    current = net.current[:n_rods]
    return CircuitSolution(
        potential=_frozen(net.potential[:n_tips].copy()),
        current=_frozen(current.copy()),
        node_of_tip=_frozen(net.node_of[:n_tips].copy()),
        injected_current=net.injected_current,
        total_current=net.total_current,
        supplied_power=net.supplied_power,
        dissipated_power=net.dissipated_power,
        effective_resistance=net.effective_resistance,
        kirchhoff_residual=net.kirchhoff_residual,
    )
