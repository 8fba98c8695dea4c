"""What an object that holds its contacts asks of them (:class:`ContactQueries`, shared by
:class:`~.graph.ConnectivityGraph` and :class:`~.network.Network`), and the circuit of a set of
contacts (:func:`solve_contacts`, :func:`.circuit.solve_circuit`; docs/model.md 'Circuit').
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from .circuit import SOLVERS, CircuitSolution, SolveMemo, solve_circuit
from .topology import Topology
from .validate import _as_contact_resistance, _as_resistance, _frozen

if TYPE_CHECKING:
    from .contactset import ContactSet

__all__ = ["ContactQueries", "solve_contacts"]


def solve_contacts(
    contacts: ContactSet,
    solver: str = "auto",
    rod_resistance=None,
    contact_resistance: float = 0.0,
    memo: SolveMemo | None = None,
) -> CircuitSolution:
    """Potentials and rod currents of ``contacts`` (:func:`.circuit.solve_circuit`).

    The tips are merged once, by the set's topology (:attr:`Topology.node_of_tip`). ``memo``: a
    :class:`~.circuit.SolveMemo` that remembers the last reduced system. Raises ValueError if a
    per-contact potential is unset.
    """
    pot = contacts.conductor_potential
    if np.isnan(pot).any():
        i = np.flatnonzero(np.isnan(pot))
        pairs = list(zip(contacts.conductor_tip[i].tolist(), contacts.conductor_id[i].tolist()))
        raise ValueError(f"unset contact potential for (tip, conductor) {pairs[:10]}")
    topo = contacts.topology
    return solve_circuit(
        contacts.n_tips,
        contacts.tip_contacts,
        contacts.conductor_tip,
        pot,
        solver=solver,
        rod_resistance=rod_resistance,
        contact_resistance=contact_resistance,
        memo=memo,
        merged=(topo.n_nodes, topo.node_of_tip),
    )


class ContactQueries:
    """What an object that holds its contacts asks of them: the queries and the solve that
    :class:`~.graph.ConnectivityGraph` and :class:`~.network.Network` share.

    The object keeps the present contacts as ``contacts`` (a :class:`ContactSet`, replaced by each
    batch of events) and the circuit's ``solver``, ``rod_resistance`` and ``contact_resistance`` (set and
    checked once, by :meth:`_set_circuit`).
    """

    def _set_circuit(self, n_rods, solver, rod_resistance, contact_resistance) -> None:
        """Check and keep the circuit's settings: ``solver`` one of :data:`~.circuit.SOLVERS`;
        ``rod_resistance`` None (R0 = 1 everywhere) or a finite resistance > 0 per rod (or one for all),
        kept frozen; ``contact_resistance`` finite and >= 0 (0: ideal contacts). ValueError naming the
        setting otherwise."""
        if solver not in SOLVERS:
            raise ValueError(f"solver must be one of {SOLVERS}, got {solver!r}")
        #: linear solver of :meth:`solve` (:func:`~.circuit.solve_circuit`)
        self.solver = solver
        #: resistance of each rod (units R0), or None for R0 = 1 everywhere
        self.rod_resistance = (
            None
            if rod_resistance is None
            else _frozen(_as_resistance(rod_resistance, "rod_resistance", n_rods, allow_zero=False).copy())
        )
        #: resistance of every contact (units R0); 0 = ideal contacts
        self.contact_resistance = _as_contact_resistance(contact_resistance)

    def arrays(self) -> dict[str, np.ndarray]:
        """The contacts as arrays (:meth:`ContactSet.arrays`): ``tip_contacts`` (m, 2) int64 rows
        ``(k, l)`` with ``k < l``, sorted; ``conductor_tip``, ``conductor_id`` (k,) int64 and
        ``conductor_potential`` (k,) float64 (NaN where a per-contact potential is unset), sorted by
        (tip, conductor)."""
        return self.contacts.arrays()

    def topology(self) -> Topology:
        """Roles and structures of the rods (computed once per set of contacts). A call here, where
        :attr:`ContactSet.topology` is a property: the contacts this reads are replaced at every batch of
        events, so it always answers for the present ones."""
        return self.contacts.topology

    @property
    def has_short_circuit(self) -> bool:
        """Whether a filament joins two different conductor attachments now."""
        return self.contacts.topology.has_short_circuit

    def solve(self, memo: SolveMemo | None = None) -> CircuitSolution:
        """Potentials and rod currents of the present contacts (:func:`solve_contacts`, through
        ``memo`` when given). Raises ValueError if a per-contact potential is unset."""
        return solve_contacts(self.contacts, self.solver, self.rod_resistance, self.contact_resistance, memo)
