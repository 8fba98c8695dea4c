"""The topology and tip merge as computed before the array kernels of ``model/topology.py``:
scipy.sparse.csgraph and networkx, kept as the oracle the kernels must match exactly.

``tests/reference.py`` imports these for the tests (tests/physics/test_graph_kernels.py); the benchmarks
time the kernels against them (``selfas-graph bench circuit``, ``selfas-graph bench events``).
"""

import networkx as nx
import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from selfas_graph.model.graph import CLUSTER, DEAD_END, FILAMENT, FREE, Topology
from selfas_graph.model.validate import _as_count, _as_index_array, _frozen


def component_labels_scipy(n, a, b):
    """(n_components, labels) of scipy's connected_components on the undirected edges (a, b)."""
    adj = sp.coo_matrix((np.ones(len(a), dtype=np.int32), (a, b)), shape=(n, n)).tocsr()
    n_comp, labels = connected_components(adj, directed=False)
    return int(n_comp), labels.astype(np.int64)


def merge_tips_scipy(n_tips, tip_contacts):
    """``circuit.merge_tips`` with scipy's connected_components."""
    tip_contacts = np.asarray(tip_contacts, dtype=np.int64).reshape(-1, 2)
    if tip_contacts.shape[0] == 0:
        return n_tips, np.arange(n_tips, dtype=np.int64)
    return component_labels_scipy(n_tips, tip_contacts[:, 0], tip_contacts[:, 1])


def classify_rods_scipy_networkx(n_rods, tip_contacts, conductor_tip, conductor_node_key) -> Topology:
    """The topology rule of ``model/graph.py`` as it was computed with scipy's
    connected_components and networkx's biconnected components (after exact leaf peeling and
    series reduction): the reference :func:`selfas_graph.model.graph.classify_rods` must
    reproduce bit for bit (roles, structure ids, counts)."""
    n_rods = _as_count(n_rods, "n_rods")
    n_tips = 2 * n_rods
    tip_contacts = _as_index_array(tip_contacts, "tip_contacts", 2, n_tips)
    conductor_tip = _as_index_array(conductor_tip, "conductor_tip", 1, n_tips)
    key = _as_index_array(conductor_node_key, "conductor_node_key", 1, None)
    if key.shape != conductor_tip.shape:
        raise ValueError(
            f"conductor_node_key has shape {key.shape}, conductor_tip has shape "
            f"{conductor_tip.shape}: one key per conductor contact"
        )

    n_nodes, node_of_tip = merge_tips_scipy(n_tips, tip_contacts)
    u = node_of_tip[0::2]
    v = node_of_tip[1::2]

    touched = np.zeros(n_tips, dtype=bool)
    touched[tip_contacts.ravel()] = True
    touched[conductor_tip] = True
    free = ~(touched[0::2] | touched[1::2])

    # components of merged nodes joined by rods (self-loop rods are harmless here)
    adj = sp.coo_matrix((np.ones(n_rods, dtype=np.int32), (u, v)), shape=(n_nodes, n_nodes)).tocsr()
    n_comp, comp = connected_components(adj, directed=False)
    rod_comp = comp[u]

    # structures: components holding at least one non-free rod, renumbered 0..S-1
    structure = np.full(n_rods, -1, dtype=np.int64)
    comp_ids, inverse = np.unique(rod_comp[~free], return_inverse=True)
    structure[~free] = inverse
    structure_size = np.bincount(inverse, minlength=comp_ids.shape[0]).astype(np.int64)
    largest = int(np.argmax(structure_size)) if structure_size.size else -1

    # components touching a conductor, and those touching >= 2 different keys
    cnode = node_of_tip[conductor_tip]
    ccomp = comp[cnode]
    comp_touch = np.zeros(n_comp, dtype=bool)
    comp_touch[ccomp] = True
    key_values, key_index = np.unique(key, return_inverse=True)
    n_keys = key_values.shape[0]
    comp_key = np.unique(ccomp * max(n_keys, 1) + key_index)  # distinct (component, key)
    n_keys_of_comp = np.bincount(comp_key // max(n_keys, 1), minlength=n_comp)
    candidate = n_keys_of_comp >= 2

    filament = np.zeros(n_rods, dtype=bool)
    if candidate.any():
        filament = _filament_rods_networkx(n_nodes, u, v, comp, candidate, cnode, key_index, n_keys)

    role = np.full(n_rods, CLUSTER, dtype=np.int8)
    role[comp_touch[rod_comp]] = DEAD_END
    role[filament] = FILAMENT
    role[free] = FREE
    counts = np.bincount(role, minlength=4)
    return Topology(
        role=_frozen(role),
        structure=_frozen(structure),
        structure_size=_frozen(structure_size),
        largest_structure=largest,
        n_filament=int(counts[FILAMENT]),
        n_dead_end=int(counts[DEAD_END]),
        n_cluster=int(counts[CLUSTER]),
        n_free=int(counts[FREE]),
        has_short_circuit=bool(counts[FILAMENT] > 0),
    )


def _filament_rods_networkx(n_nodes, u, v, comp, candidate, cnode, key_index, n_keys) -> np.ndarray:
    """Rods in a biconnected component with the virtual node X (see module docstring).

    Auxiliary simple graph H: merged nodes ``0 .. n_nodes-1`` of the candidate
    components, attachment of key ``j`` as node ``n_nodes + j``, X as node
    ``n_nodes + n_keys``; a merged node that touches exactly one key is replaced by
    that key's attachment node. Edges are the rods, the contacts of merged nodes that
    touch two or more keys (merged node -> attachment) and X -> attachment. Edges are
    coded ``lo * stride + hi``.

    Parallel rods collapse to one edge of H. That is exact: two parallel rods
    share the block of their common edge (or form a block of their own, which
    cannot contain X). Self-loop rods are never filament.

    Two exact reductions run before networkx, in numpy/scipy (they cut the
    graph networkx walks to its cyclic skeleton). Leaf peeling: an edge to a
    node of degree 1 (not X) is a bridge, a block without X; peeling layer by
    layer leaves the 2-core. Series reduction: a node w != X of degree 2
    in H, with edges (a, w) and (w, b), lies on a cycle through X only if that
    cycle uses both edges, so both edges are in X's block or neither is, and
    the same holds for the single edge (a, b) that replaces them. A maximal
    chain of degree-2 nodes is therefore replaced by one edge between its two
    end nodes; if both ends are the same node the chain and that node form a
    cycle that is a block of its own, filament iff the node is X (a single rod
    or chain touching two attachments); a closed ring of degree-2 nodes touches
    nothing.
    """
    x_node = n_nodes + n_keys
    n_h = x_node + 1
    stride = np.int64(n_h)
    att_in = candidate[comp[cnode]]
    # contacts are ideal, so a merged node touching exactly one attachment key is that
    # attachment electrically: it becomes the attachment node itself. A path through it
    # then ends there, and a loop that leaves an electrode and comes back to it (both ends
    # pinned at the same potential, no current) is a cycle through that attachment alone.
    # Nodes touching two or more keys keep one edge to each attachment.
    node_key = np.unique(cnode[att_in] * np.int64(n_keys) + key_index[att_in])  # distinct (node, key)
    nk_node, nk_key = node_key // n_keys, node_key % n_keys
    keys_per_node = np.bincount(nk_node, minlength=n_nodes)
    rep = np.arange(n_nodes, dtype=np.int64)
    single = keys_per_node[nk_node] == 1
    rep[nk_node[single]] = n_nodes + nk_key[single]
    ru, rv = rep[u], rep[v]
    rod_in = candidate[comp[u]] & (ru != rv)
    rod_code = np.minimum(ru, rv) * stride + np.maximum(ru, rv)
    multi = keys_per_node[nk_node] >= 2
    att_code = nk_node[multi] * stride + (n_nodes + nk_key[multi])
    keys_used = np.unique(key_index[att_in]) + n_nodes
    # unique edges of H; attachment < X, so (attachment, X) is (lo, hi)
    code = np.unique(np.concatenate([rod_code[rod_in], att_code, keys_used * stride + x_node]))
    p, q = code // stride, code % stride

    # ---- leaf peeling (the 2-core of H): a node of degree 1 other than X ends a
    # bridge, a block without X; dangling trees go layer by layer
    core = np.ones(code.shape[0], dtype=bool)
    live = np.arange(code.shape[0])
    while live.size:
        deg = np.bincount(p[live], minlength=n_h) + np.bincount(q[live], minlength=n_h)
        leaf = deg == 1
        leaf[x_node] = False
        drop = leaf[p[live]] | leaf[q[live]]
        if not drop.any():
            break
        core[live[drop]] = False
        live = live[~drop]

    # ---- series reduction: label chains of degree-2 nodes with scipy components
    code_all = code
    p, q, code = p[core], q[core], code[core]
    deg = np.bincount(p, minlength=n_h) + np.bincount(q, minlength=n_h)
    two = deg == 2
    two[x_node] = False
    inner = two[p] & two[q]
    n_inner = int(inner.sum())
    _, label = connected_components(
        sp.coo_matrix((np.ones(n_inner, dtype=np.int32), (p[inner], q[inner])), shape=(n_h, n_h)),
        directed=False,
    )
    w = np.where(two[p], p, q)  # a degree-2 end of the edge, if it has one
    in_chain = two[p] | two[q]
    chain = np.where(in_chain, label[w], -1)
    # end edges (exactly one degree-2 end): each chain has two, or none if it is a ring
    end = two[p] ^ two[q]
    end_chain = chain[end]
    end_node = np.where(two[p], q, p)[end]
    order = np.argsort(end_chain, kind="stable")
    end_chain, end_node = end_chain[order], end_node[order]
    assert np.array_equal(end_chain[0::2], end_chain[1::2]), "a chain of degree-2 nodes has two ends"
    chain_id = end_chain[0::2]
    a, b = end_node[0::2], end_node[1::2]
    # a == b: the chain closes a cycle through that one node, a block of its own,
    # which contains X only if that node is X
    open_chain = a != b
    x_loop = chain_id[(a == b) & (a == x_node)]
    chain_id = chain_id[open_chain]
    chain_code = np.minimum(a, b)[open_chain] * stride + np.maximum(a, b)[open_chain]

    reduced = np.unique(np.concatenate([code[~in_chain], chain_code]))
    graph = nx.Graph()
    graph.add_edges_from(zip((reduced // stride).tolist(), (reduced % stride).tolist()))

    # flatten the blocks with a block id, then keep the blocks that contain X
    block_lo: list[int] = []
    block_hi: list[int] = []
    block_id: list[int] = []
    for bid, block in enumerate(nx.biconnected_component_edges(graph)):
        for e0, e1 in block:
            block_lo.append(e0)
            block_hi.append(e1)
        block_id.extend([bid] * len(block))
    e0 = np.asarray(block_lo, dtype=np.int64)
    e1 = np.asarray(block_hi, dtype=np.int64)
    bid = np.asarray(block_id, dtype=np.int64)
    in_x = np.isin(bid, np.unique(bid[(e0 == x_node) | (e1 == x_node)]))
    x_codes = np.minimum(e0[in_x], e1[in_x]) * stride + np.maximum(e0[in_x], e1[in_x])

    # ---- back to the edges of H, then to the rods
    chain_in_x = np.zeros(n_h, dtype=bool)
    chain_in_x[chain_id] = np.isin(chain_code, x_codes)
    chain_in_x[x_loop] = True
    edge_in_x = np.zeros(code_all.shape[0], dtype=bool)
    edge_in_x[core] = np.where(in_chain, chain_in_x[np.maximum(chain, 0)], np.isin(code, x_codes))
    where = np.minimum(np.searchsorted(code_all, rod_code), code_all.shape[0] - 1)
    return rod_in & edge_in_x[where]
