"""Graph kernels of the topology and the circuit: connected components and the blocks through a node.

They run once per contact event (``model/topology.py``, ``model/circuit.py``), on graphs of
a few thousand nodes in the Fig. 2 scene: there the cost of building a scipy sparse matrix
and walking a networkx graph is mostly interpreter overhead, which these serial loops do
not have (docs/performance.md, "Topology and circuit per event").

Glossary: ``n`` nodes ``0 .. n-1``; ``a``, ``b`` (m,) int64 the two end nodes of each edge.
"""

import numpy as np

from ._jit import njit


@njit
def component_labels(n, a, b):
    """Connected components of an undirected graph, numbered as scipy numbers them.

    Returns ``(n_components, label)`` with ``label`` (n,) int64. Components are numbered
    in the order of their smallest node (the numbering of
    ``scipy.sparse.csgraph.connected_components``, which starts a new label at each
    unlabelled node in ascending order), so results built on the labels are the same
    with either. Union-find with path halving; edges may repeat or be self-loops.
    """
    parent = np.arange(n)
    for e in range(a.shape[0]):
        x = a[e]
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        y = b[e]
        while parent[y] != y:
            parent[y] = parent[parent[y]]
            y = parent[y]
        if x < y:
            parent[y] = x
        elif y < x:
            parent[x] = y
    label = np.empty(n, dtype=np.int64)
    root_label = np.full(n, -1, dtype=np.int64)
    count = 0
    for i in range(n):
        x = i
        while parent[x] != x:
            x = parent[x]
        if root_label[x] < 0:
            root_label[x] = count
            count += 1
        label[i] = root_label[x]
    return count, label


@njit
def edges_in_blocks_of(n, a, b, root):
    """Which edges lie in a biconnected component (block) that contains node ``root``.

    Returns (m,) bool. An edge lies in such a block iff it lies on a cycle through
    ``root``, or is a bridge at ``root`` (the block of a bridge is the edge itself).
    Edges must not be self-loops; parallel edges are allowed (each lies on the cycle
    the pair forms).

    One iterative depth-first search from ``root`` (Tarjan's low points), no recursion
    and no edge stack: a tree edge ``(p, w)`` opens a new block iff ``low[w] >= disc[p]``;
    that block contains ``root`` only if ``p`` is the root (every other node of it is a
    descendant of ``p``). Otherwise the edge is in the block of the tree edge into ``p``.
    A non-tree edge joins a node to one of its ancestors and is in the block of the tree
    edge into the deeper end. Edges of components without ``root`` are in no such block.
    """
    m = a.shape[0]
    # adjacency in compressed rows: neighbour and edge id
    start = np.zeros(n + 1, dtype=np.int64)
    for e in range(m):
        start[a[e] + 1] += 1
        start[b[e] + 1] += 1
    for i in range(n):
        start[i + 1] += start[i]
    fill = start[:-1].copy()
    nbr = np.empty(2 * m, dtype=np.int64)
    eid = np.empty(2 * m, dtype=np.int64)
    for e in range(m):
        nbr[fill[a[e]]] = b[e]
        eid[fill[a[e]]] = e
        fill[a[e]] += 1
        nbr[fill[b[e]]] = a[e]
        eid[fill[b[e]]] = e
        fill[b[e]] += 1

    disc = np.full(n, -1, dtype=np.int64)
    low = np.zeros(n, dtype=np.int64)
    up_edge = np.full(n, -1, dtype=np.int64)  # tree edge into the node
    up_node = np.full(n, -1, dtype=np.int64)
    nxt = start[:-1].copy()  # next adjacency entry to look at
    order = np.empty(n, dtype=np.int64)  # nodes in discovery order
    stack = np.empty(n, dtype=np.int64)
    disc[root] = 0
    low[root] = 0
    order[0] = root
    n_seen = 1
    stack[0] = root
    top = 1
    while top:
        v = stack[top - 1]
        if nxt[v] < start[v + 1]:
            j = nxt[v]
            nxt[v] += 1
            e = eid[j]
            if e == up_edge[v]:
                continue
            w = nbr[j]
            if disc[w] < 0:
                disc[w] = n_seen
                low[w] = n_seen
                order[n_seen] = w
                n_seen += 1
                up_edge[w] = e
                up_node[w] = v
                stack[top] = w
                top += 1
            elif disc[w] < low[v]:
                low[v] = disc[w]
        else:
            top -= 1
            p = up_node[v]
            if p >= 0 and low[v] < low[p]:
                low[p] = low[v]

    # block membership of the tree edge into each node, in discovery order (parents first)
    into_root_block = np.zeros(n, dtype=np.bool_)
    for k in range(1, n_seen):
        w = order[k]
        p = up_node[w]
        into_root_block[w] = p == root or (low[w] < disc[p] and into_root_block[p])
    out = np.zeros(m, dtype=np.bool_)
    for e in range(m):
        x, y = a[e], b[e]
        if disc[x] < 0 or disc[y] < 0:
            continue
        # the tree edge's child, or the deeper end of a non-tree edge: the larger discovery time
        out[e] = into_root_block[x] if disc[x] > disc[y] else into_root_block[y]
    return out


@njit
def structures(n_rods, node_of_tip, n_nodes, tip_contacts, conductor_tip, key_index):
    """Structures of the rods and which of them touch conductors (``model/topology.py::classify_rods``).

    ``node_of_tip`` (2 n_rods,) the merged node of each tip (:func:`component_labels` of the
    tip contacts), ``tip_contacts`` (m, 2) those contacts; ``conductor_tip`` (k,) the tip of
    each conductor contact and ``key_index`` (k,) its attachment key as an index
    ``0 .. n_keys-1``. A rod is free if neither tip is in a tip or conductor contact.

    Returns ``(comp, n_comp, free, structure, structure_size, comp_touch, candidate)``:
    the component of each merged node (rods join merged nodes; numbered as
    :func:`component_labels` numbers them), free rods, the structure id of each rod (-1
    free; the components of non-free rods renumbered ``0 .. S-1`` in the order of their
    component labels), the rods per structure, the components touching a conductor, and
    those touching at least two different keys.
    """
    u = np.empty(n_rods, dtype=np.int64)
    v = np.empty(n_rods, dtype=np.int64)
    for i in range(n_rods):
        u[i] = node_of_tip[2 * i]
        v[i] = node_of_tip[2 * i + 1]
    n_comp, comp = component_labels(n_nodes, u, v)
    touched = np.zeros(2 * n_rods, dtype=np.bool_)
    for j in range(tip_contacts.shape[0]):
        touched[tip_contacts[j, 0]] = True
        touched[tip_contacts[j, 1]] = True
    for j in range(conductor_tip.shape[0]):
        touched[conductor_tip[j]] = True
    free = np.empty(n_rods, dtype=np.bool_)
    used = np.zeros(n_comp, dtype=np.bool_)
    for i in range(n_rods):
        free[i] = not (touched[2 * i] or touched[2 * i + 1])
        if not free[i]:
            used[comp[u[i]]] = True
    structure_of_comp = np.full(n_comp, -1, dtype=np.int64)
    n_struct = 0
    for c in range(n_comp):
        if used[c]:
            structure_of_comp[c] = n_struct
            n_struct += 1
    structure = np.full(n_rods, -1, dtype=np.int64)
    structure_size = np.zeros(n_struct, dtype=np.int64)
    for i in range(n_rods):
        if not free[i]:
            s = structure_of_comp[comp[u[i]]]
            structure[i] = s
            structure_size[s] += 1
    comp_touch = np.zeros(n_comp, dtype=np.bool_)
    candidate = np.zeros(n_comp, dtype=np.bool_)
    first_key = np.full(n_comp, -1, dtype=np.int64)
    for j in range(conductor_tip.shape[0]):
        c = comp[node_of_tip[conductor_tip[j]]]
        comp_touch[c] = True
        if first_key[c] < 0:
            first_key[c] = key_index[j]
        elif first_key[c] != key_index[j]:
            candidate[c] = True
    return comp, n_comp, free, structure, structure_size, comp_touch, candidate


@njit
def filament_rods(n_nodes, u, v, comp, candidate, cnode, key_index, n_keys):
    """The rods in a block (biconnected component) with the virtual node X: the filament rods of
    ``model/topology.py::classify_rods`` (its module docstring gives the rule and the graph H).

    ``u``, ``v`` (n_rods,) the merged nodes of each rod's tips, ``comp`` (n_nodes,) their components,
    ``candidate`` (n_comp,) the components touching two or more keys, ``cnode`` (k,) the merged node
    and ``key_index`` (k,) the key (``0 .. n_keys-1``) of each conductor contact. Returns (n_rods,)
    bool.

    H's nodes: the merged nodes, attachment node ``n_nodes + key`` of each key, X = ``n_nodes +
    n_keys``; a merged node touching exactly one key is replaced by that key's attachment. Its
    edges, each once (parallel rods collapse to one edge, which is exact: they share its block or
    form one of their own without X): the rods of candidate components whose ends differ, an edge
    from each merged node touching two or more keys to each of those keys' attachments, and X to
    each attachment in use; coded ``lo * stride + hi`` with ``stride`` the number of H's nodes. One depth-first search from X
    (:func:`edges_in_blocks_of`) then marks the edges in X's blocks. The sets are those of the numpy
    steps it replaced (tests/physics/test_graph_kernels.py holds it to networkx).
    """
    n_keys = np.int64(n_keys)
    x_node = n_nodes + n_keys
    stride = np.int64(x_node + 1)
    k = cnode.shape[0]
    # the distinct (merged node, key) pairs of the contacts in candidate components
    pair = np.empty(k, dtype=np.int64)
    m = 0
    for j in range(k):
        if candidate[comp[cnode[j]]]:
            pair[m] = cnode[j] * n_keys + key_index[j]
            m += 1
    node_key = np.unique(pair[:m])
    keys_of = np.zeros(n_nodes, dtype=np.int64)
    key_used = np.zeros(n_keys, dtype=np.bool_)
    for c in node_key:
        keys_of[c // n_keys] += 1
        key_used[c % n_keys] = True
    rep = np.arange(n_nodes, dtype=np.int64)
    for c in node_key:
        if keys_of[c // n_keys] == 1:
            rep[c // n_keys] = n_nodes + c % n_keys
    n_rods = u.shape[0]
    code = np.empty(n_rods + node_key.shape[0] + n_keys, dtype=np.int64)
    rod_code = np.empty(n_rods, dtype=np.int64)
    rod_in = np.zeros(n_rods, dtype=np.bool_)
    e = 0
    for i in range(n_rods):
        ru, rv = rep[u[i]], rep[v[i]]
        rod_code[i] = min(ru, rv) * stride + max(ru, rv)
        if candidate[comp[u[i]]] and ru != rv:
            rod_in[i] = True
            code[e] = rod_code[i]
            e += 1
    for c in node_key:
        if keys_of[c // n_keys] >= 2:
            code[e] = (c // n_keys) * stride + n_nodes + c % n_keys
            e += 1
    for key in range(n_keys):
        if key_used[key]:  # attachment < X, so (attachment, X) is (lo, hi)
            code[e] = (n_nodes + key) * stride + x_node
            e += 1
    code = np.unique(code[:e])
    in_x = edges_in_blocks_of(x_node + 1, code // stride, code % stride, x_node)
    out = np.zeros(n_rods, dtype=np.bool_)
    for i in range(n_rods):
        if rod_in[i]:
            out[i] = in_x[np.searchsorted(code, rod_code[i])]
    return out
