"""The connectivity graph of rods and contacts, replayed from events (docs/model.md 'Connectivity graph and topology').

:class:`ConnectivityGraph` holds a :class:`~.contactset.ContactSet` that contact events replace
(through :meth:`.ContactSet.apply`, the path a run's network takes too; a batch fails whole or
not at all), with :meth:`~ConnectivityGraph.topology` (:func:`.topology.classify_rods`) and
:meth:`~ConnectivityGraph.solve` (nodal analysis, :mod:`.circuit`). It is the object to
rebuild a saved frame's graph or to replay an event log (``RunFile.graph``, ``selfas-graph
topology``, ``plot``); :meth:`~ConnectivityGraph.to_networkx` gives the graph to networkx's
algorithms. A run keeps its contacts in its :class:`~.network.Network`.

The roles and the topology rule are in :mod:`.topology`; their names are importable from here.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping

import numpy as np

from selfas_graph.model import events as ev
from selfas_graph.model.circuit import CircuitSolution, SolveMemo
from selfas_graph.model.contact_queries import ContactQueries
from selfas_graph.model.contactset import ContactSet
from selfas_graph.model.topology import (
    CLUSTER,
    DEAD_END,
    FILAMENT,
    FREE,
    ROLE_NAMES,
    Topology,
    circuit_event,
    classify_rods,
)
from selfas_graph.model.validate import _as_count, tip_index

__all__ = ["FREE", "CLUSTER", "DEAD_END", "FILAMENT", "ROLE_NAMES", "Topology", "classify_rods", "ConnectivityGraph"]


class ConnectivityGraph(ContactQueries):
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

    Attributes
    ----------
    contacts : ContactSet
        The present contacts (an immutable value, replaced by every change).
    changed : bool
        The contacts or a contact potential changed since the last :meth:`solve`.
    """

    def __init__(
        self,
        n_rods: int,
        conductor_potential: Mapping[int, float | None],
        solver: str = "auto",
        rod_resistance=None,
        contact_resistance: float = 0.0,
    ):
        self._set_circuit(_as_count(n_rods, "n_rods"), solver, rod_resistance, contact_resistance)
        self.contacts = ContactSet.empty(n_rods, conductor_potential, resistive=self.contact_resistance > 0.0)
        self.n_rods = self.contacts.n_rods
        self.n_tips = self.contacts.n_tips
        self.changed = True  # nothing solved yet

    def solve(self, memo: SolveMemo | None = None) -> CircuitSolution:
        """Potentials and rod currents of the present contacts (:meth:`ContactQueries.solve
        <.contact_queries.ContactQueries.solve>`); clears :attr:`changed`."""
        sol = super().solve(memo)
        self.changed = False
        return sol

    # ------------------------------------------------------------------ mutations
    def _replace(self, contacts: ContactSet) -> None:
        if contacts is not self.contacts:
            self.contacts = contacts
            self.changed = True

    def add_tip_contact(self, k, l) -> None:
        """Tips ``k`` and ``l`` (of different rods) come into contact.

        Raises ValueError for a tip out of range, the two tips of one rod, or a
        contact that already exists (an event stream never repeats a contact).
        """
        self._replace(self.contacts.apply([(0, 0.0, ev.TIP_CONTACT, k, l)]))

    def remove_tip_contact(self, k, l) -> None:
        """Tips ``k`` and ``l`` release. Raises ValueError if they are not in contact."""
        self._replace(self.contacts.apply([(0, 0.0, ev.TIP_RELEASE, k, l)]))

    def add_conductor_contact(self, k, c, potential: float | None = None) -> None:
        """Tip ``k`` touches conductor ``c``.

        For a conductor with a per-contact potential, ``potential`` is the
        contact's potential (``-delta_J0 z``); ``None`` leaves it unset (NaN)
        until :meth:`set_contact_potential`, and :meth:`solve` refuses unset
        potentials. For a fixed-potential conductor ``potential`` must be None or
        equal to the conductor's potential.
        """
        k = tip_index(k, self.n_tips)
        c = self.contacts.known_conductor(c)
        fixed = self.contacts.fixed
        if c in fixed and potential is not None and float(potential) != fixed[c]:
            raise ValueError(
                f"conductor {c} has fixed potential {fixed[c]}; cannot give contact of tip {k} potential {potential}"
            )
        row = (0, 0.0, ev.CONDUCTOR_CONTACT, k, c)
        self._replace(self.contacts.apply([row], contact_potential=lambda *_: potential))

    def remove_conductor_contact(self, k, c) -> None:
        """Tip ``k`` leaves conductor ``c``. Raises ValueError if it does not touch it."""
        self._replace(self.contacts.apply([(0, 0.0, ev.CONDUCTOR_RELEASE, k, c)]))

    def set_contact_potential(self, k, c, potential: float) -> None:
        """Set the potential of tip ``k``'s contact with per-contact conductor ``c``.

        Case (ii): the caller updates ``-delta_J0 z`` as contact heights move.
        Marks the graph changed (the currents must be solved again); the topology stays.
        """
        k = tip_index(k, self.n_tips)
        c = self.contacts.known_conductor(c)
        if c not in self.contacts.fixed and not self.contacts.on_conductor(c)[k]:
            raise ValueError(f"tip {k} does not touch conductor {c}")
        self.contacts = self.contacts.with_potentials([k], c, [potential])
        self.changed = True

    # ------------------------------------------------------------------ events
    def apply(
        self,
        events: Iterable,
        contact_potential: Callable[[int, int], float] | None = None,
    ) -> list[tuple]:
        """Apply a batch of contact events (:meth:`.ContactSet.apply`) and return the derived circuit events.

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
            The graph is then as before the call.
        """
        rows = [tuple(row[i] for i in range(5)) for row in events]
        before = self.contacts
        self._replace(before.apply(rows, contact_potential))
        if self.contacts is before:
            return []
        step, time = rows[-1][0], rows[-1][1]
        return circuit_event(before.topology.has_short_circuit, self.topology(), int(step), float(time))

    # ------------------------------------------------------------------ queries
    def conductor_node_key(self) -> np.ndarray:
        """Attachment key of each conductor contact (:meth:`.ContactSet.node_key`)."""
        return self.contacts.node_key()

    def to_networkx(self):
        """The graph as a new ``networkx.Graph`` (a copy: changing it does not change this object).

        Nodes are tips ``0 .. n_tips-1`` (ints), ``("conductor", c)`` for a conductor of fixed
        potential and ``("contact", k, c)`` for each contact of tip ``k`` with a conductor whose
        potential is given per contact; conductor and contact nodes carry ``potential``. Edges
        carry ``kind="rod"`` or ``kind="contact"``.
        """
        import networkx as nx

        cs = self.contacts
        g = nx.Graph()
        g.add_nodes_from(range(self.n_tips))
        g.add_edges_from(((2 * i, 2 * i + 1) for i in range(self.n_rods)), kind="rod")
        for c, pot in cs.fixed.items():
            g.add_node(("conductor", c), potential=pot)
        g.add_edges_from(map(tuple, cs.tip_contacts.tolist()), kind="contact")
        for k, c, pot in zip(cs.conductor_tip.tolist(), cs.conductor_id.tolist(), cs.conductor_potential.tolist()):
            if c in cs.fixed:
                node = ("conductor", c)
            else:
                node = ("contact", k, c)
                # an unset potential is the one object np.nan, so that graphs compare equal
                g.add_node(node, potential=np.nan if np.isnan(pot) else pot)
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
        """Rebuild a graph from :meth:`arrays` output (e.g. read back from HDF5), through
        :meth:`.ContactSet.from_arrays` (the contacts applied as events).

        Per-contact potentials are taken from ``arrays["conductor_potential"]``
        (NaN = unset); for fixed-potential conductors the ``conductor_potential``
        mapping given here wins over the stored value. ``kwargs`` (``solver``,
        ``rod_resistance``, ``contact_resistance``) go to the constructor.
        """
        g = cls(n_rods, conductor_potential, **kwargs)
        g.contacts = ContactSet.from_arrays(n_rods, conductor_potential, arrays, resistive=g.contact_resistance > 0.0)
        return g

    def __repr__(self) -> str:
        return (
            f"ConnectivityGraph(n_rods={self.n_rods}, tip_contacts={self.contacts.n_contacts}, "
            f"conductor_contacts={self.contacts.conductor_tip.shape[0]}, changed={self.changed})"
        )
