"""The connectivity graph of rods and contacts, and its topology (docs/model.md 'Connectivity graph and topology').

Two layers:

* :func:`classify_rods` -- arrays in, :class:`Topology` out: which rods are free,
  in clusters, dead ends or current-carrying filaments, and which structure each
  rod belongs to.
* :class:`ConnectivityGraph` -- the connectivity *state*: a networkx graph changed
  by contact events only (never rebuilt per step), with :meth:`~ConnectivityGraph.topology`
  and :meth:`~ConnectivityGraph.solve` (nodal analysis, :mod:`.circuit`).

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
import operator
from collections.abc import Callable, Iterable, Mapping

import networkx as nx
import numpy as np

from selfas_graph.kernels.graph import edges_in_blocks_of
from selfas_graph.kernels.graph import structures as component_structures
from selfas_graph.model import events as ev
from selfas_graph.model.circuit import (
    CircuitSolution,
    _as_count,
    _as_index_array,
    _as_resistance,
    merge_tips,
    solve_circuit,
)

__all__ = [
    "FREE",
    "CLUSTER",
    "DEAD_END",
    "FILAMENT",
    "ROLE_NAMES",
    "Topology",
    "classify_rods",
    "ConnectivityGraph",
]

#: rod roles (``Topology.role``)
FREE = 0  #: no contacts at all
CLUSTER = 1  #: stuck to other rods; the structure touches no conductor
DEAD_END = 2  #: in a structure touching a conductor, on no path between different attachments
FILAMENT = 3  #: on a path between conductor attachments of different potential
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
        ``n_filament > 0``: a conducting path joins two different conductor attachments.
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

    @property
    def n_structures(self) -> int:
        """Number of structures (connected aggregates of at least one rod with a contact)."""
        return int(self.structure_size.shape[0])


def _frozen(arr: np.ndarray) -> np.ndarray:
    arr.setflags(write=False)
    return arr


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
        n_rods, node_of_tip, n_nodes, tip_contacts, conductor_tip, key_index)
    largest = int(np.argmax(structure_size)) if structure_size.size else -1
    u = node_of_tip[0::2]
    rod_comp = comp[u]

    filament = np.zeros(n_rods, dtype=bool)
    if candidate.any():
        filament = _filament_rods(n_nodes, u, node_of_tip[1::2], comp, candidate, node_of_tip[conductor_tip],
                                  key_index, n_keys)

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


def _filament_rods(n_nodes, u, v, comp, candidate, cnode, key_index, n_keys) -> np.ndarray:
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

    The blocks through X come from one depth-first search from X over H
    (:func:`selfas_graph.kernels.graph.edges_in_blocks_of`).
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
    edge_in_x = edges_in_blocks_of(n_h, code // stride, code % stride, x_node)
    where = np.minimum(np.searchsorted(code, rod_code), code.shape[0] - 1)
    return rod_in & edge_in_x[where]


# --------------------------------------------------------------------------- state
_DERIVED_KINDS = (ev.SHORT_CIRCUIT, ev.OPEN_CIRCUIT)


class ConnectivityGraph:
    """Connectivity state of the rods: a networkx graph changed by events only.

    Nodes are tips ``0 .. n_tips-1`` (ints), ``("conductor", c)`` for a conductor
    with a fixed potential (electrodes, case (i)), and ``("contact", k, c)`` for
    each contact of tip ``k`` with a conductor whose potential is given per
    contact (the case (ii) filament). Edges carry ``kind="rod"`` (one resistor per
    rod, added at construction) or ``kind="contact"`` (ideal, or a resistor
    ``contact_resistance`` when that is > 0). Potentials are the
    ``potential`` attribute of the conductor / contact node.

    Parameters
    ----------
    n_rods : int
        Number of rods.
    conductor_potential : dict[int, float | None]
        Conductor id (``events.CONDUCTOR_*``) -> fixed potential (units R0 J0), or
        ``None`` when the potential is given per contact (``-delta_J0 z``).
        Conductors not listed are unknown and rejected.
    solver : str
        Linear solver of :meth:`solve` (see ``circuit.solve_circuit``).
    rod_resistance : (n_rods,) float64, optional
        Resistance R_i of each rod (units R0); default R0 = 1 for every rod.
    contact_resistance : float
        Resistance of every contact (units R0); 0 (default) = ideal contacts.
        The topology (:meth:`topology`) does not depend on either.

    Notes
    -----
    Beside the networkx graph the object keeps insertion-ordered dicts of the
    contacts, an index (not a second state: every change goes through the methods
    below, which update both) that makes :meth:`arrays` cost a few ms for 10^5
    contacts instead of an O(edges) walk over networkx's adjacency.
    """

    def __init__(self, n_rods: int, conductor_potential: Mapping[int, float | None], solver: str = "auto",
                 rod_resistance=None, contact_resistance: float = 0.0):
        #: linear solver of :meth:`solve` ("auto", "direct" or "cg"; see circuit.solve_circuit)
        self.solver = solver
        self.n_rods = _as_count(n_rods, "n_rods")
        #: resistance of each rod (units R0), or None for R0 = 1 everywhere (circuit.solve_circuit)
        self.rod_resistance = None if rod_resistance is None else _frozen(
            _as_resistance(rod_resistance, "rod_resistance", self.n_rods, allow_zero=False).copy())
        #: resistance of every contact (units R0); 0 = ideal contacts (circuit.solve_circuit)
        self.contact_resistance = float(contact_resistance)
        if not (np.isfinite(self.contact_resistance) and self.contact_resistance >= 0.0):
            raise ValueError(f"contact_resistance must be finite and >= 0, got {contact_resistance!r}")
        self.n_tips = 2 * self.n_rods
        self._fixed: dict[int, float] = {}
        self._per_contact: set[int] = set()
        for c, pot in dict(conductor_potential).items():
            c = self._conductor_id(c)
            if pot is None:
                self._per_contact.add(c)
            else:
                pot = float(pot)
                if not np.isfinite(pot):
                    raise ValueError(f"conductor {c} potential must be finite, got {pot}")
                self._fixed[c] = pot
        self.graph = nx.Graph()
        self.graph.add_nodes_from(range(self.n_tips))
        self.graph.add_edges_from(
            ((2 * i, 2 * i + 1) for i in range(self.n_rods)), kind="rod"
        )
        for c, pot in self._fixed.items():
            self.graph.add_node(("conductor", c), potential=pot)
        self._tip_contact: dict[tuple[int, int], None] = {}
        self._conductor_contact: dict[tuple[int, int], float] = {}
        self._topology: Topology | None = None
        self._arrays: dict[str, np.ndarray] | None = None
        self.changed = True  # nothing solved yet

    # ------------------------------------------------------------------ validation
    @staticmethod
    def _conductor_id(c) -> int:
        try:
            return operator.index(c)
        except TypeError:
            raise ValueError(f"conductor id must be an integer, got {c!r}") from None

    def _tip(self, k, name: str = "tip") -> int:
        try:
            k = operator.index(k)
        except TypeError:
            raise ValueError(f"{name} must be an integer, got {k!r}") from None
        if not 0 <= k < self.n_tips:
            raise ValueError(f"{name} {k} out of range [0, {self.n_tips})")
        return k

    def _tip_pair(self, k, l) -> tuple[int, int]:
        k, l = self._tip(k), self._tip(l)
        if k // 2 == l // 2:
            raise ValueError(
                f"tips {k} and {l} are the two tips of rod {k // 2}: a rod cannot touch itself"
            )
        return (k, l) if k < l else (l, k)

    def _known_conductor(self, c) -> int:
        c = self._conductor_id(c)
        if c not in self._fixed and c not in self._per_contact:
            known = sorted(self._fixed) + sorted(self._per_contact)
            name = ev.CONDUCTOR_NAMES.get(c, "?")
            raise ValueError(f"unknown conductor {c} ({name}); this graph has conductors {known}")
        return c

    def _conductor_node(self, k: int, c: int):
        return ("conductor", c) if c in self._fixed else ("contact", k, c)

    def _touch(self) -> None:
        self.changed = True
        self._topology = None
        self._arrays = None

    # ------------------------------------------------------------------ mutations
    def add_tip_contact(self, k, l) -> None:
        """Tips ``k`` and ``l`` (of different rods) come into contact.

        Raises ValueError for a tip out of range, the two tips of one rod, or a
        contact that already exists (an event stream never repeats a contact).
        """
        k, l = self._tip_pair(k, l)
        if (k, l) in self._tip_contact:
            raise ValueError(f"tips {k} and {l} are already in contact")
        self.graph.add_edge(k, l, kind="contact")
        self._tip_contact[(k, l)] = None
        self._touch()

    def remove_tip_contact(self, k, l) -> None:
        """Tips ``k`` and ``l`` release. Raises ValueError if they are not in contact."""
        k, l = self._tip_pair(k, l)
        if (k, l) not in self._tip_contact:
            raise ValueError(f"cannot release tips {k} and {l}: they are not in contact")
        self.graph.remove_edge(k, l)
        del self._tip_contact[(k, l)]
        self._touch()

    def add_conductor_contact(self, k, c, potential: float | None = None) -> None:
        """Tip ``k`` touches conductor ``c``.

        For a conductor with a per-contact potential, ``potential`` is the
        contact's potential (``-delta_J0 z``); ``None`` leaves it unset (NaN)
        until :meth:`set_contact_potential`, and :meth:`solve` refuses unset
        potentials. For a fixed-potential conductor ``potential`` must be None or
        equal to the conductor's potential.
        """
        k = self._tip(k)
        c = self._known_conductor(c)
        if (k, c) in self._conductor_contact:
            raise ValueError(f"tip {k} already touches conductor {c} ({ev.CONDUCTOR_NAMES.get(c, '?')})")
        if c in self._fixed:
            if potential is not None and float(potential) != self._fixed[c]:
                raise ValueError(
                    f"conductor {c} has fixed potential {self._fixed[c]}; "
                    f"cannot give contact of tip {k} potential {potential}"
                )
            pot = self._fixed[c]
        else:
            pot = np.nan if potential is None else self._finite(potential, k, c)
            self.graph.add_node(("contact", k, c), potential=pot)
        self.graph.add_edge(k, self._conductor_node(k, c), kind="contact")
        self._conductor_contact[(k, c)] = pot
        self._touch()

    def remove_conductor_contact(self, k, c) -> None:
        """Tip ``k`` leaves conductor ``c``. Raises ValueError if it does not touch it."""
        k = self._tip(k)
        c = self._known_conductor(c)
        if (k, c) not in self._conductor_contact:
            raise ValueError(
                f"cannot release tip {k} from conductor {c} ({ev.CONDUCTOR_NAMES.get(c, '?')}): "
                "it does not touch it"
            )
        node = self._conductor_node(k, c)
        if c in self._fixed:
            self.graph.remove_edge(k, node)
        else:
            self.graph.remove_node(node)
        del self._conductor_contact[(k, c)]
        self._touch()

    def set_contact_potential(self, k, c, potential: float) -> None:
        """Set the potential of tip ``k``'s contact with per-contact conductor ``c``.

        Case (ii): the caller updates ``-delta_J0 z`` as contact heights move.
        Marks the graph changed (the currents must be solved again) but not the
        topology.
        """
        k = self._tip(k)
        c = self._known_conductor(c)
        if c in self._fixed:
            raise ValueError(f"conductor {c} has a fixed potential; it has no per-contact potential")
        if (k, c) not in self._conductor_contact:
            raise ValueError(f"tip {k} does not touch conductor {c}")
        pot = self._finite(potential, k, c)
        self.graph.nodes[("contact", k, c)]["potential"] = pot
        self._conductor_contact[(k, c)] = pot
        self.changed = True
        self._arrays = None

    @staticmethod
    def _finite(potential, k, c) -> float:
        pot = float(potential)
        if not np.isfinite(pot):
            raise ValueError(f"potential of tip {k} on conductor {c} must be finite, got {pot}")
        return pot

    # ------------------------------------------------------------------ events
    def apply(
        self,
        events: Iterable,
        contact_potential: Callable[[int, int], float] | None = None,
    ) -> list[tuple]:
        """Apply a batch of contact events and return the derived circuit events.

        Parameters
        ----------
        events : EVENT_DTYPE array or iterable of ``(step, time, kind, a, b)``
            TIP_CONTACT / TIP_RELEASE (a, b = tips), CONDUCTOR_CONTACT /
            CONDUCTOR_RELEASE (a = tip, b = conductor id). SHORT_CIRCUIT and
            OPEN_CIRCUIT rows are derived data and are skipped, so a recorded log
            can be replayed as is.
        contact_potential : callable ``(tip, conductor) -> float``, optional
            Potential of a new contact with a per-contact conductor; without it
            such contacts start unset (see :meth:`add_conductor_contact`).

        Returns
        -------
        list of ``(step, time, kind, a, b)`` tuples
            ``[(step, time, SHORT_CIRCUIT, n_filament, -1)]`` if the batch made the
            network go from no filament to a filament,
            ``[(step, time, OPEN_CIRCUIT, -1, -1)]`` for the reverse, else ``[]``;
            step and time are those of the batch's last row. The comparison is
            between the graph before and after the batch (the topology before is
            the cached one in a run driven by ``apply``, so it costs nothing).

        Raises
        ------
        ValueError
            For an invalid row (unknown kind or any error of the methods above).
            The batch is then rolled back: the graph is as before the call.
        """
        short_before = self.topology().has_short_circuit
        undo: list[Callable[[], None]] = []
        last = None
        try:
            for row in events:
                step, time, kind, a, b = (row[i] for i in range(5))
                kind = int(kind)
                last = (int(step), float(time))
                if kind == ev.TIP_CONTACT:
                    self.add_tip_contact(a, b)
                    undo.append(lambda a=a, b=b: self.remove_tip_contact(a, b))
                elif kind == ev.TIP_RELEASE:
                    self.remove_tip_contact(a, b)
                    undo.append(lambda a=a, b=b: self.add_tip_contact(a, b))
                elif kind == ev.CONDUCTOR_CONTACT:
                    c = self._known_conductor(b)
                    pot = None
                    if contact_potential is not None and c in self._per_contact:
                        pot = contact_potential(int(a), c)
                    self.add_conductor_contact(a, c, pot)
                    undo.append(lambda a=a, c=c: self.remove_conductor_contact(a, c))
                elif kind == ev.CONDUCTOR_RELEASE:
                    c = self._known_conductor(b)
                    tip = self._tip(a)
                    old = self._conductor_contact.get((tip, c))
                    self.remove_conductor_contact(a, c)
                    old = None if c in self._fixed or old is None or np.isnan(old) else old
                    undo.append(lambda a=a, c=c, old=old: self.add_conductor_contact(a, c, old))
                elif kind in _DERIVED_KINDS:
                    continue
                else:
                    raise ValueError(f"unknown event kind {kind} in row {tuple(row)}")
        except Exception:
            for fn in reversed(undo):
                fn()
            raise
        if last is None or not undo:
            return []
        topo = self.topology()
        if topo.has_short_circuit == short_before:
            return []
        step, time = last
        if topo.has_short_circuit:
            return [(step, time, ev.SHORT_CIRCUIT, topo.n_filament, -1)]
        return [(step, time, ev.OPEN_CIRCUIT, -1, -1)]

    # ------------------------------------------------------------------ queries
    def arrays(self) -> dict[str, np.ndarray]:
        """The contacts as arrays (for HDF5 and for the solvers).

        Returns
        -------
        dict with
            ``tip_contacts`` (m, 2) int64, rows ``(k, l)`` with ``k < l``, sorted;
            ``conductor_tip`` (k,) int64, ``conductor_id`` (k,) int64 and
            ``conductor_potential`` (k,) float64 (NaN where a per-contact potential
            is unset), sorted by (tip, conductor).
        """
        if self._arrays is None:
            if self._tip_contact:
                tc = np.array(list(self._tip_contact), dtype=np.int64)
                tc = tc[np.lexsort((tc[:, 1], tc[:, 0]))]
            else:
                tc = np.zeros((0, 2), dtype=np.int64)
            if self._conductor_contact:
                kc = np.array(list(self._conductor_contact), dtype=np.int64)
                pot = np.fromiter(self._conductor_contact.values(), dtype=np.float64)
                order = np.lexsort((kc[:, 1], kc[:, 0]))
                kc, pot = kc[order], pot[order]
            else:
                kc = np.zeros((0, 2), dtype=np.int64)
                pot = np.zeros(0)
            self._arrays = {
                "tip_contacts": _frozen(tc),
                "conductor_tip": _frozen(np.ascontiguousarray(kc[:, 0])),
                "conductor_id": _frozen(np.ascontiguousarray(kc[:, 1])),
                "conductor_potential": _frozen(pot),
            }
        return dict(self._arrays)

    def conductor_node_key(self, arrays: dict[str, np.ndarray] | None = None) -> np.ndarray:
        """Attachment key of each conductor contact of :meth:`arrays` (see :func:`classify_rods`).

        Fixed-potential conductor ``c`` -> ``c``; per-contact conductors -> a key
        unique to the contact, above every conductor id.
        """
        arrays = self.arrays() if arrays is None else arrays
        cid = arrays["conductor_id"]
        base = max(list(self._fixed) + list(self._per_contact) + [-1]) + 1
        per = np.isin(cid, np.fromiter(self._per_contact, dtype=np.int64, count=len(self._per_contact)))
        return np.where(per, base + np.arange(cid.shape[0]), cid).astype(np.int64)

    def topology(self) -> Topology:
        """Roles and structures of the current graph (cached until the next contact change)."""
        if self._topology is None:
            arr = self.arrays()
            self._topology = classify_rods(
                self.n_rods, arr["tip_contacts"], arr["conductor_tip"], self.conductor_node_key(arr)
            )
        return self._topology

    def solve(self) -> CircuitSolution:
        """Potentials and rod currents of the current graph; clears :attr:`changed`.

        Raises ValueError if a per-contact potential is unset.
        """
        arr = self.arrays()
        pot = arr["conductor_potential"]
        if np.isnan(pot).any():
            i = np.flatnonzero(np.isnan(pot))
            pairs = list(zip(arr["conductor_tip"][i].tolist(), arr["conductor_id"][i].tolist()))
            raise ValueError(f"unset contact potential for (tip, conductor) {pairs[:10]}")
        sol = solve_circuit(self.n_tips, arr["tip_contacts"], arr["conductor_tip"], pot, solver=self.solver,
                            rod_resistance=self.rod_resistance, contact_resistance=self.contact_resistance)
        self.changed = False
        return sol

    @property
    def has_short_circuit(self) -> bool:
        """Whether a filament joins two different conductor attachments now."""
        return self.topology().has_short_circuit

    # ------------------------------------------------------------------ rebuild
    @classmethod
    def from_arrays(
        cls,
        n_rods: int,
        conductor_potential: Mapping[int, float | None],
        arrays: Mapping[str, np.ndarray],
        **kwargs,
    ) -> "ConnectivityGraph":
        """Rebuild a graph from :meth:`arrays` output (e.g. read back from HDF5).

        Per-contact potentials are taken from ``arrays["conductor_potential"]``
        (NaN = unset); for fixed-potential conductors the ``conductor_potential``
        mapping given here wins over the stored value. ``kwargs`` (``solver``,
        ``rod_resistance``, ``contact_resistance``) go to the constructor.
        """
        g = cls(n_rods, conductor_potential, **kwargs)
        tc = _as_index_array(arrays["tip_contacts"], "tip_contacts", 2, g.n_tips)
        ct = _as_index_array(arrays["conductor_tip"], "conductor_tip", 1, g.n_tips)
        cid = _as_index_array(arrays["conductor_id"], "conductor_id", 1, None)
        pot = np.asarray(arrays["conductor_potential"], dtype=np.float64).reshape(-1)
        if not (ct.shape == cid.shape == pot.shape):
            raise ValueError(
                "conductor_tip, conductor_id and conductor_potential must have one entry per "
                f"contact, got shapes {ct.shape}, {cid.shape}, {pot.shape}"
            )
        for k, l in tc.tolist():
            g.add_tip_contact(k, l)
        for k, c, p in zip(ct.tolist(), cid.tolist(), pot.tolist()):
            per = c in g._per_contact
            g.add_conductor_contact(k, c, p if per and not np.isnan(p) else None)
        return g

    def __repr__(self) -> str:
        return (
            f"ConnectivityGraph(n_rods={self.n_rods}, tip_contacts={len(self._tip_contact)}, "
            f"conductor_contacts={len(self._conductor_contact)}, changed={self.changed})"
        )
