"""The skeleton of the rod network: loops and junctions (docs/model.md "Measures of the paper's claims").

Arrays in, arrays out. The contact graph is the project's connectivity graph without the
conductors (docs/model.md 'Contacts and events'): tips joined by tip-tip contacts are merged into one
junction node (:func:`selfas_graph.model.circuit.merge_tips`), and every rod is an edge
between the merged nodes of its two tips. It is a multigraph: two rods sharing both
junctions make a loop of two, a rod whose tips sit in one junction a loop of one.

* :func:`structures` -- structure label of each rod (rods joined by tip contacts; -1 for a
  rod with no contact), as :func:`selfas_graph.model.graph.classify_rods` numbers them.
* :func:`cycle_rank` -- independent loops ``E - V + C`` (edges = rods, vertices = merged
  nodes, C = connected components), per structure and in total.
* :func:`loop_lengths` -- lengths (in rods) of as many loops as the cycle rank: networkx's
  minimum cycle basis (every face of a lattice) or, for large graphs, the shortest loop
  through each edge off a spanning tree; loops of one and two rods are counted from the
  multigraph.
* :func:`junction_degrees` -- tips per contact cluster (merged node of two or more tips).
"""

from __future__ import annotations

import networkx as nx
import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from ..model.circuit import merge_tips
from ..model.graph import classify_rods

__all__ = ["contact_nodes", "cycle_rank", "junction_degrees", "loop_lengths", "structures"]

_EMPTY = np.zeros(0, dtype=np.int64)


def _contacts(tip_contacts):
    return np.asarray(tip_contacts, dtype=np.int64).reshape(-1, 2)


def contact_nodes(n_rods, tip_contacts):
    """(n_nodes, node_of_tip): tips merged into junction nodes by their tip-tip contacts."""
    return merge_tips(2 * int(n_rods), _contacts(tip_contacts))


def structures(n_rods, tip_contacts):
    """(structure (n_rods,) int64 with -1 for rods with no contact, structure_size (S,) int64)."""
    topo = classify_rods(int(n_rods), _contacts(tip_contacts), _EMPTY, _EMPTY)
    return np.array(topo.structure), np.array(topo.structure_size)


def cycle_rank(n_rods, tip_contacts, structure=None, n_structures=None):
    """Independent loops ``E - V + C`` of the contact graph.

    Parameters
    ----------
    n_rods : int
    tip_contacts : (m, 2) int
    structure : (n_rods,) int, optional
        Structure labels (default :func:`structures`); -1 rods have no loop.
    n_structures : int, optional

    Returns
    -------
    total : int
        Cycle rank of the whole contact graph.
    per_structure : (n_structures,) int64
        Cycle rank of each structure's component.
    """
    n_rods = int(n_rods)
    n_nodes, node = contact_nodes(n_rods, tip_contacts)
    if structure is None:
        structure, _ = structures(n_rods, tip_contacts)
    structure = np.asarray(structure, dtype=np.int64)
    n_s = int(structure.max(initial=-1)) + 1 if n_structures is None else int(n_structures)
    u, v = node[0::2], node[1::2]
    adj = sp.coo_matrix((np.ones(n_rods, dtype=np.int8), (u, v)), shape=(n_nodes, n_nodes)).tocsr()
    n_comp, _ = connected_components(adj, directed=False)
    total = n_rods - n_nodes + int(n_comp)
    # per structure: its rods minus its nodes plus one (a structure is one component)
    keep = structure >= 0
    edges = np.bincount(structure[keep], minlength=n_s)
    node_structure = np.full(n_nodes, -1, dtype=np.int64)
    node_structure[u[keep]] = structure[keep]
    node_structure[v[keep]] = structure[keep]
    nodes = np.bincount(node_structure[node_structure >= 0], minlength=n_s)
    per = edges - nodes + (edges > 0)
    return int(total), per.astype(np.int64)


def loop_lengths(n_rods, tip_contacts, rods=None, method="auto", minimum_up_to=10):
    """Lengths (in rods) of a cycle basis of the contact graph of ``rods`` (default: all).

    Parameters
    ----------
    method : "auto", "minimum", "shortest" or "fundamental"
        ``minimum``: ``networkx.minimum_cycle_basis`` (the shortest independent loops; every
        face of a lattice); ``shortest``: for each edge off a spanning tree, the shortest loop
        through it (as many loops as the cycle rank, each as short as it can be, though not
        always independent; every face of a lattice, fast); ``fundamental``:
        ``networkx.cycle_basis`` (one loop per edge off a spanning tree closed through the
        tree: quick, longer loops); ``auto``: minimum up to ``minimum_up_to`` independent
        loops, else shortest (networkx's minimum basis took 0.35 s for 25 loops of a lattice,
        34 s for 176, and 3.7 s for 25 loops of a 500-rod Fig. 2 network on this project's
        machine; shortest takes milliseconds).

    Returns
    -------
    (cycle rank,) int64, sorted.
    """
    n_rods = int(n_rods)
    _, node = contact_nodes(n_rods, tip_contacts)
    rods = np.arange(n_rods) if rods is None else np.asarray(rods, dtype=np.int64).reshape(-1)
    u, v = node[2 * rods], node[2 * rods + 1]
    lengths = [1] * int((u == v).sum())
    pairs = {}
    for a, b in zip(u[u != v].tolist(), v[u != v].tolist()):
        key = (a, b) if a < b else (b, a)
        pairs[key] = pairs.get(key, 0) + 1
    lengths += [2] * sum(k - 1 for k in pairs.values())  # each extra parallel rod closes a loop of two
    # the 2-core (dead-end branches pruned away) holds every loop of the simple graph
    g = nx.k_core(nx.Graph(list(pairs)), 2)
    if method not in ("auto", "minimum", "shortest", "fundamental"):
        raise ValueError(f"method must be auto, minimum, shortest or fundamental, got {method!r}")
    if method == "auto":
        rank = g.number_of_edges() - g.number_of_nodes() + nx.number_connected_components(g)
        method = "minimum" if rank <= minimum_up_to else "shortest"
    if method == "shortest":
        lengths += _shortest_through_chords(g)
    else:
        basis = nx.minimum_cycle_basis(g) if method == "minimum" else nx.cycle_basis(g)
        lengths += [len(c) for c in basis]
    return np.sort(np.array(lengths, dtype=np.int64))


def _shortest_through_chords(g):
    """For each edge off a spanning forest of ``g``: the length of the shortest loop through it
    (breadth-first search between its ends with the edge removed), one per independent loop."""
    tree = nx.minimum_spanning_tree(g)
    out = []
    for u, v in g.edges():
        if tree.has_edge(u, v):
            continue
        g.remove_edge(u, v)
        out.append(nx.shortest_path_length(g, u, v) + 1)
        g.add_edge(u, v)
    return out


def junction_degrees(n_rods, tip_contacts):
    """Tips per contact cluster (merged nodes of two or more tips), (n_junctions,) int64."""
    n_nodes, node = contact_nodes(n_rods, tip_contacts)
    counts = np.bincount(node, minlength=n_nodes)
    return counts[counts >= 2].astype(np.int64)
