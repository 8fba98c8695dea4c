"""Roles of the rods and the structures they form, from contact arrays (docs/model.md 'Connectivity graph and topology').

:func:`classify_rods` -- arrays in, :class:`Topology` out: which rods are free, in
clusters, dead ends or current-carrying filaments, and which structure each rod
belongs to. The contacts are a :class:`~.contactset.ContactSet`, whose ``topology``
calls it once per set (in a run, :class:`~.network.Network`; for an event log or a
saved frame, :class:`~.graph.ConnectivityGraph`).

Topology rule
-------------
Tips joined by ideal contacts form one merged electrical node; rods are edges
between merged nodes. Each conductor contact carries a *key*: contacts with the
same key are one attachment (case (i): all anode contacts share the anode's key,
all cathode contacts the cathode's; case (ii): every filament contact has its
own key, since the filament potential varies along it). Each key becomes one
attachment node. Contacts with conductors are ideal like tip contacts, so a merged
node that touches exactly one key *is* that attachment node (its tips sit at the
conductor's potential); a merged node touching several keys is joined to each of
them. A virtual node X is joined to every attachment node. A rod is **FILAMENT**
iff it lies on a simple path between two *different* attachment nodes, i.e. iff its
edge lies on a cycle through X, i.e. iff it is in a biconnected component that
contains X (one depth-first search from X, :func:`selfas_graph.kernels.graph.edges_in_blocks_of`;
the tests hold it to networkx's ``biconnected_component_edges``). Merging same-key contacts is
what keeps a loop from the anode back to the anode from counting as a filament,
also when the loop's far end touches the anode at a junction that leads on to the
cathode: both ends of such a loop are pinned at the anode's potential, and no
current flows in it.

A balanced bridge rod is FILAMENT (it lies on such a path) although its current
is zero; the circuit solve reports the current, this module the topology.

Structures are the connected components of rods joined by tip-tip contacts;
conductors do **not** join structures (two aggregates that both touch the anode
are two structures). A rod with no contact at all is FREE and has no structure.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from selfas_graph.kernels.graph import filament_rods
from selfas_graph.kernels.graph import structures as component_structures
from selfas_graph.model import events as ev
from selfas_graph.model.circuit import merge_tips
from selfas_graph.model.validate import _as_count, _as_index_array, _frozen

__all__ = [
    "FREE",
    "CLUSTER",
    "DEAD_END",
    "FILAMENT",
    "ROLE_NAMES",
    "Topology",
    "classify_resistive",
    "classify_rods",
    "conductor_node_key",
    "circuit_event",
]

#: rod roles (``Topology.role``)
FREE = 0  #: no contacts at all
CLUSTER = 1  #: stuck to other rods; the structure touches no conductor
DEAD_END = 2  #: in a structure touching a conductor, on no path between different attachments
FILAMENT = 3  #: on a path between different conductor attachments
ROLE_NAMES = {FREE: "free", CLUSTER: "cluster", DEAD_END: "dead_end", FILAMENT: "filament"}


# --------------------------------------------------------------------------- topology
@dataclasses.dataclass(frozen=True, eq=False)
class Topology:
    """Roles of the rods and the structures they form (arrays are read-only).

    Attributes
    ----------
    role : (n_rods,) int8
        FREE, CLUSTER, DEAD_END or FILAMENT.
    structure : (n_rods,) int64
        Structure id of each rod, ``-1`` for free rods. Ids are ``0 .. n_structures-1``.
    structure_size : (n_structures,) int64
        Number of rods in each structure.
    largest_structure : int
        Id of the structure with the most rods (lowest id on ties), -1 if none.
    n_filament, n_dead_end, n_cluster, n_free : int
        Number of rods with each role.
    has_short_circuit : bool
        A conducting path joins two different conductor attachments: ``n_filament > 0``, or with
        resistive contacts also a tip touching both electrodes (:func:`classify_resistive`).
    n_nodes, node_of_tip : int, (n_tips,) int64
        The merged electrical nodes (:func:`~.circuit.merge_tips`), handed on to the circuit
        solve so that the tips are merged once.
    """

    role: np.ndarray
    structure: np.ndarray
    structure_size: np.ndarray
    largest_structure: int
    n_filament: int
    n_dead_end: int
    n_cluster: int
    n_free: int
    has_short_circuit: bool
    n_nodes: int | None = None
    node_of_tip: np.ndarray | None = None

    @property
    def n_structures(self) -> int:
        """Number of structures (connected aggregates of at least one rod with a contact)."""
        return int(self.structure_size.shape[0])


def classify_rods(n_rods, tip_contacts, conductor_tip, conductor_node_key) -> Topology:
    """Classify rods as free, cluster, dead end or filament (docs/model.md 'Connectivity graph and topology').

    Parameters
    ----------
    n_rods : int
        Number of rods; rod ``i`` has tips ``2 i`` and ``2 i + 1``.
    tip_contacts : (m, 2) int64
        Pairs of tips in contact.
    conductor_tip : (k,) int64
        Tips touching a conductor, one entry per contact.
    conductor_node_key : (k,) int64
        Attachment key of each conductor contact: contacts with equal keys are one
        attachment (case (i): the conductor id; case (ii) filament: a key unique
        to the contact).

    Returns
    -------
    Topology

    Notes
    -----
    Cost: two passes of union-find over all tips and rods (the tip merge and the
    components, :mod:`selfas_graph.kernels.graph`), and one depth-first search over
    the components that touch at least two different attachment keys (no other
    component can hold a filament). Measured at the Fig. 2 sizes (1200 rods): 0.16 ms
    before the first short circuit, 0.5 ms with 700 filament rods, 6 times less than
    with scipy's ``connected_components`` and networkx (docs/performance.md,
    "Topology and circuit per event").
    """
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

    n_nodes, node_of_tip = merge_tips(n_tips, tip_contacts)
    if key.size:
        key_values, key_index = np.unique(key, return_inverse=True)
        key_index = key_index.astype(np.int64, copy=False)
    else:
        key_values, key_index = key, key
    n_keys = key_values.shape[0]
    # components of merged nodes joined by rods (self-loop rods are harmless here); structures:
    # components holding at least one non-free rod, renumbered 0..S-1; components touching a
    # conductor, and those touching >= 2 different keys
    comp, n_comp, free, structure, structure_size, comp_touch, candidate = component_structures(
        n_rods, node_of_tip, n_nodes, tip_contacts, conductor_tip, key_index
    )
    largest = int(np.argmax(structure_size)) if structure_size.size else -1
    u = node_of_tip[0::2]
    rod_comp = comp[u]

    filament = np.zeros(n_rods, dtype=bool)
    if candidate.any():
        filament = filament_rods(
            n_nodes, u, node_of_tip[1::2], comp, candidate, node_of_tip[conductor_tip], key_index, n_keys
        )

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
        n_nodes=int(n_nodes),
        node_of_tip=_frozen(node_of_tip),
    )


def classify_resistive(n_rods, tip_contacts, conductor_tip, conductor_node_key) -> Topology:
    """:func:`classify_rods` for resistive contacts (``contacts.resistance`` > 0, choice B29): no tips are
    merged, and each contact is a resistor of its own, so a rod is FILAMENT iff it lies on a simple path
    between two different attachments through rods *and* contacts (a loop pinned at one electrode by two
    tips that a contact joins, or a rod whose tips touch both sides of a contact, then carries current).

    Each contact becomes a virtual rod between ideal merges: tip-tip contact ``(i, j)`` a rod whose
    tips merge with ``i`` and ``j``; conductor contact ``d`` on tip ``t`` a rod whose one tip merges with
    ``t`` and whose other touches the conductor. The rule of :func:`classify_rods` on that system gives
    the real rods' roles and structures (virtual rods left out of the counts and sizes);
    ``has_short_circuit`` holds when any rod, virtual ones included, is FILAMENT (a tip touching both
    electrodes conducts through its two contacts)."""
    n_rods = _as_count(n_rods, "n_rods")
    tip_contacts = _as_index_array(tip_contacts, "tip_contacts", 2, 2 * n_rods)
    conductor_tip = _as_index_array(conductor_tip, "conductor_tip", 1, 2 * n_rods)
    m, k = tip_contacts.shape[0], conductor_tip.shape[0]
    first = 2 * n_rods + 2 * np.arange(m + k, dtype=np.int64)  # the first tip of each virtual rod
    merges = np.concatenate(
        [
            np.column_stack([tip_contacts[:, 0], first[:m]]),
            np.column_stack([first[:m] + 1, tip_contacts[:, 1]]),
            np.column_stack([conductor_tip, first[m:]]),
        ]
    )
    aug = classify_rods(n_rods + m + k, merges, first[m:] + 1, conductor_node_key)
    role, structure = aug.role[:n_rods].copy(), aug.structure[:n_rods].copy()
    # every structure holds a real rod (a virtual rod hangs on a real tip): the ids stay 0..S-1
    size = np.bincount(structure[structure >= 0], minlength=aug.structure_size.shape[0]).astype(np.int64)
    counts = np.bincount(role, minlength=4)
    return Topology(
        role=_frozen(role),
        structure=_frozen(structure),
        structure_size=_frozen(size),
        largest_structure=int(np.argmax(size)) if size.size else -1,
        n_filament=int(counts[FILAMENT]),
        n_dead_end=int(counts[DEAD_END]),
        n_cluster=int(counts[CLUSTER]),
        n_free=int(counts[FREE]),
        has_short_circuit=aug.has_short_circuit,
    )


def conductor_node_key(conductor_id: np.ndarray, per_contact, conductor_ids) -> np.ndarray:
    """Attachment key of each conductor contact (see :func:`classify_rods`).

    A conductor of fixed potential ``c`` -> ``c``; a conductor in ``per_contact`` (potential
    given per contact, the case (ii) filament) -> a key unique to the contact, above every id
    in ``conductor_ids``.
    """
    base = max(list(conductor_ids) + [-1]) + 1
    per = np.isin(conductor_id, np.fromiter(per_contact, dtype=np.int64, count=len(per_contact)))
    return np.where(per, base + np.arange(conductor_id.shape[0]), conductor_id).astype(np.int64)


def circuit_event(short_before: bool, topology: Topology, step: int, time: float) -> list[tuple]:
    """The derived event row of a batch of contact events, given whether a filament existed before it.

    ``[(step, time, SHORT_CIRCUIT, n_filament, -1)]`` if the network went from no filament to a
    filament, ``[(step, time, OPEN_CIRCUIT, -1, -1)]`` for the reverse, else ``[]``.
    """
    if topology.has_short_circuit == short_before:
        return []
    if topology.has_short_circuit:
        return [(step, time, ev.SHORT_CIRCUIT, topology.n_filament, -1)]
    return [(step, time, ev.OPEN_CIRCUIT, -1, -1)]
