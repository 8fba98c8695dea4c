"""The connectivity graph of rods and contacts, replayed from events (docs/model.md 'Connectivity graph and topology').

:class:`ConnectivityGraph` holds a set of contacts changed by contact events (a batch fails
whole or not at all), with :meth:`~ConnectivityGraph.topology` (:func:`.topology.classify_rods`)
and :meth:`~ConnectivityGraph.solve` (nodal analysis, :mod:`.circuit`). It is the object to
rebuild a saved frame's graph or to replay an event log (``RunFile.graph``, ``selfas-graph
topology``, ``plot``); :meth:`~ConnectivityGraph.to_networkx` gives the graph to networkx's
algorithms. A run keeps its contacts in its :class:`~.network.Network`.

The roles and the topology rule are in :mod:`.topology`; their names are importable from here.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping

import numpy as np

from selfas_graph.model import events as ev
from selfas_graph.model.topology import (
    CLUSTER,
    DEAD_END,
    FILAMENT,
    FREE,
    ROLE_NAMES,
    ContactArrays,
    Topology,
    circuit_event,
    classify_rods,
)
from selfas_graph.model.validate import (
    _as_count,
    _as_index_array,
    _as_resistance,
    _frozen,
    conductor_id,
    finite_potential,
    tip_index,
    tip_pair,
)

__all__ = ["FREE", "CLUSTER", "DEAD_END", "FILAMENT", "ROLE_NAMES", "Topology", "classify_rods", "ConnectivityGraph"]


# --------------------------------------------------------------------------- state
_DERIVED_KINDS = (ev.SHORT_CIRCUIT, ev.OPEN_CIRCUIT)


class ConnectivityGraph(ContactArrays):
    """Connectivity state of the rods: the rods (fixed) and the contacts, changed by events only.

    Tips ``0 .. n_tips-1``; rod ``i`` joins tips ``2 i`` and ``2 i + 1``. A contact joins two
    tips of different rods, or a tip and a conductor: one with a fixed potential (electrodes,
    case (i)) or one whose potential is given per contact (the case (ii) filament).
    :meth:`to_networkx` draws it as a networkx graph.

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
    The contacts are stored once, in two insertion-ordered dicts (tip pairs; (tip, conductor)
    -> potential); :meth:`arrays` sorts them into arrays (a few ms for 10^5 contacts, cached
    until the next change). A networkx graph kept beside them cost an O(edges) walk to read
    back (about 1 s for 10^5 contacts), so it is built only on request (:meth:`to_networkx`).
    """

    def __init__(
        self,
        n_rods: int,
        conductor_potential: Mapping[int, float | None],
        solver: str = "auto",
        rod_resistance=None,
        contact_resistance: float = 0.0,
    ):
        #: linear solver of :meth:`solve` ("auto", "direct" or "cg"; see circuit.solve_circuit)
        self.solver = solver
        self.n_rods = _as_count(n_rods, "n_rods")
        #: resistance of each rod (units R0), or None for R0 = 1 everywhere (circuit.solve_circuit)
        self.rod_resistance = (
            None
            if rod_resistance is None
            else _frozen(_as_resistance(rod_resistance, "rod_resistance", self.n_rods, allow_zero=False).copy())
        )
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
        self._tip_contact: dict[tuple[int, int], None] = {}
        self._conductor_contact: dict[tuple[int, int], float] = {}
        self._topology: Topology | None = None
        self._arrays: dict[str, np.ndarray] | None = None
        self.changed = True  # nothing solved yet

    # ------------------------------------------------------------------ validation
    _conductor_id = staticmethod(conductor_id)

    def _tip(self, k, name: str = "tip") -> int:
        return tip_index(k, self.n_tips, name)

    def _tip_pair(self, k, l) -> tuple[int, int]:
        return tip_pair(k, l, self.n_tips)

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
        self._tip_contact[(k, l)] = None
        self._touch()

    def remove_tip_contact(self, k, l) -> None:
        """Tips ``k`` and ``l`` release. Raises ValueError if they are not in contact."""
        k, l = self._tip_pair(k, l)
        if (k, l) not in self._tip_contact:
            raise ValueError(f"cannot release tips {k} and {l}: they are not in contact")
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
        self._conductor_contact[(k, c)] = pot
        self._touch()

    def remove_conductor_contact(self, k, c) -> None:
        """Tip ``k`` leaves conductor ``c``. Raises ValueError if it does not touch it."""
        k = self._tip(k)
        c = self._known_conductor(c)
        if (k, c) not in self._conductor_contact:
            raise ValueError(
                f"cannot release tip {k} from conductor {c} ({ev.CONDUCTOR_NAMES.get(c, '?')}): it does not touch it"
            )
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
        self._conductor_contact[(k, c)] = pot
        self.changed = True
        self._arrays = None

    _finite = staticmethod(finite_potential)

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
        return circuit_event(short_before, self.topology(), *last)

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

    def _conductors(self) -> tuple[set, list]:
        return self._per_contact, list(self._fixed) + list(self._per_contact)

    def to_networkx(self):
        """The graph as a new ``networkx.Graph`` (a copy: changing it does not change this object).

        Nodes are tips ``0 .. n_tips-1`` (ints), ``("conductor", c)`` for a conductor of fixed
        potential and ``("contact", k, c)`` for each contact of tip ``k`` with a conductor whose
        potential is given per contact; conductor and contact nodes carry ``potential``. Edges
        carry ``kind="rod"`` or ``kind="contact"``.
        """
        import networkx as nx

        g = nx.Graph()
        g.add_nodes_from(range(self.n_tips))
        g.add_edges_from(((2 * i, 2 * i + 1) for i in range(self.n_rods)), kind="rod")
        for c, pot in self._fixed.items():
            g.add_node(("conductor", c), potential=pot)
        g.add_edges_from(self._tip_contact, kind="contact")
        for (k, c), pot in self._conductor_contact.items():
            node = self._conductor_node(k, c)
            if c not in self._fixed:
                g.add_node(node, potential=pot)
            g.add_edge(k, node, kind="contact")
        return g

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
