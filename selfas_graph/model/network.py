"""The electrical network of a run: contacts, topology, conductor potentials, circuit and rod currents.

:class:`Network` owns, in one object, what contact events change (docs/model.md 'Contacts and
events', 'Connectivity graph and topology', 'Circuit'):

* the contacts: one :class:`~.contactset.ContactSet` (tip pairs, tips on each conductor with the
  potential of each contact, ``-delta_J0 z`` on the case (ii) filament), replaced by each batch
  of events through :meth:`.ContactSet.apply`, the path a replayed event log takes too
  (:class:`~.graph.ConnectivityGraph`); the search for them is the :class:`~.contacts.ContactTracker`;
* the conductor potentials (electrodes of case (i), ``-delta_J0 z`` along the filament of
  case (ii)) and the filament contact heights at the last solve;
* the topology (``ContactSet.topology``, once per set of contacts), the circuit solve
  (:func:`.contact_queries.solve_contacts`) and the memo of its last linear system
  (:class:`.circuit.SolveMemo`);
* the rod currents (:class:`RodCurrents`): the one store of them in a run. The force field
  is built with this object and its current terms read it (``ForceField.currents``); nothing
  else keeps a copy.

One call per step, :meth:`Network.update`, takes the positions and the tip neighbour list
the contact search runs over, writes the new rod currents into :attr:`Network.currents` and
returns the step's events and whether the currents changed (:class:`NetworkUpdate`). The
simulation then tells the force field that its held current forces are stale.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from . import events as ev
from .circuit import CircuitSolution, SolveMemo, solve_circuit
from .circuitlog import circuit_rows
from .contact_queries import ContactQueries
from .contacts import ContactTracker
from .contactset import ContactSet
from .topology import FILAMENT, circuit_event

__all__ = ["Network", "NetworkUpdate", "RodCurrents"]


class RodCurrents:
    """The rod currents of a run: written at each circuit solve, read by the current terms.

    Parameters
    ----------
    n_rods : int

    Attributes
    ----------
    current : (n_rods,) float64
        J_i, positive from tip a to tip b (units J0); zero until :meth:`set` is called.
    active_rod : (n_active,) int64
        The rods whose current is not exactly zero, sorted: the only rods the kernels visit.
    """

    def __init__(self, n_rods: int):
        self.n_rods = int(n_rods)
        self.current = np.zeros(self.n_rods)
        self.active_rod = np.zeros(0, dtype=np.int64)

    def set(self, current) -> bool:
        """Take the currents ``(n_rods,)``; rods whose current is exactly zero are left out of the kernels.

        Returns False (and keeps the arrays in use) when the currents are those in use, bit for bit. The
        currents are copied: an array the caller changes in place and sets again is taken again.
        """
        current = np.array(current, dtype=np.float64)  # a copy: the caller may change its array later
        if current.shape != (self.n_rods,):
            raise ValueError(f"currents must have shape ({self.n_rods},), got {current.shape}")
        if np.array_equal(current, self.current):
            return False
        self.current = current
        self.active_rod = np.flatnonzero(current != 0.0).astype(np.int64)
        return True


@dataclasses.dataclass
class NetworkUpdate:
    """What one :meth:`Network.update` changed.

    Attributes
    ----------
    events : list of (step, time, kind, a, b)
        Contact events of the step, then a SHORT_CIRCUIT / OPEN_CIRCUIT row if the batch
        made a filament appear or vanish (kinds in :mod:`.events`).
    currents_changed : bool
        Whether the rod currents (:attr:`Network.currents`) changed, bit for bit.
    changed : bool
        Whether the contacts or the contact potentials changed (events, or case (ii)
        contact heights that moved): the integrator's history may be reset then.
    circuit : list of (step, time, kind, total_current, rods_in_series, filament_rods)
        A circuit-log row for the step's SHORT_CIRCUIT / OPEN_CIRCUIT row, if any, from the
        step's solve (:mod:`.circuitlog`).
    """

    events: list
    currents_changed: bool = False
    changed: bool = False
    circuit: list = dataclasses.field(default_factory=list)


class Network(ContactQueries):
    """Contacts, connectivity, conductor potentials and circuit of a run.

    Parameters
    ----------
    n_rods : int
    rstar, release_radius : float
        Contact and release distances of the contact search (:class:`~.contacts.ContactTracker`).
    electrodes : (z_cathode, z_anode) or None
        Electrode planes of case (i).
    filament_radius : float or None
        Radius of the case (ii) filament on the z axis.
    bias : float
        delta_J0: electrode potentials +-delta_J0 gap / 2, filament potential -delta_J0 z.
    circuit : bool
        Solve the circuit when the contacts change (a ``[circuit]`` table is present).
    solver : str
        Linear solver (``circuit.solve_circuit``).
    height_tolerance : float
        Case (ii): a filament contact that moved along z by more than this since the last
        solve gets its new potential and the circuit is solved again.
    rod_resistance : (n_rods,) float64 or None
    contact_resistance : float
    """

    def __init__(
        self,
        n_rods,
        rstar,
        release_radius,
        electrodes=None,
        filament_radius=None,
        bias=0.0,
        circuit=False,
        solver="auto",
        height_tolerance=0.0,
        rod_resistance=None,
        contact_resistance=0.0,
    ):
        self.n_rods = int(n_rods)
        self.n_tips = 2 * self.n_rods
        #: the contact search (keeps no contacts)
        self.tracker = ContactTracker(self.n_tips, rstar, release_radius, electrodes, filament_radius)
        self.bias = float(bias)
        self.circuit = bool(circuit)
        self.height_tolerance = float(height_tolerance)
        self._set_circuit(self.n_rods, solver, rod_resistance, contact_resistance)
        conductors = {}
        if electrodes is not None:
            # the planes are -+gap/2, so their distance is the gap exactly; + 0.0: no negative zero without a bias
            half = 0.5 * self.bias * (electrodes[1] - electrodes[0]) + 0.0
            conductors = {ev.CONDUCTOR_CATHODE: -half + 0.0, ev.CONDUCTOR_ANODE: half}
        if filament_radius is not None:
            conductors[ev.CONDUCTOR_FILAMENT] = None  # psi = -delta_J0 z per contact (docs/model.md 'Circuit')
        #: conductor id -> fixed potential (units R0 J0), None where given per contact (docs/model.md 'Circuit')
        self.conductor_potential = conductors
        #: the electrodes' potentials at a unit bias: the probe of the resistance without a bias (:meth:`_solve_at`)
        self._unit_potential = {}
        if electrodes is not None:
            half_gap = 0.5 * (electrodes[1] - electrodes[0])
            self._unit_potential = {ev.CONDUCTOR_CATHODE: -half_gap, ev.CONDUCTOR_ANODE: half_gap}
        #: the contacts (an immutable value, replaced by each batch of events)
        self.contacts = ContactSet.empty(self.n_rods, conductors, resistive=self.contact_resistance > 0.0)
        #: filament contacts at the last solve, and the heights their potentials -delta_J0 z stand for
        self.filament_tip = np.zeros(0, dtype=np.int64)
        self.filament_z = np.zeros(0)
        self.memo = SolveMemo()
        self.solution: CircuitSolution | None = None
        #: the rod currents (zero off the filament rods): their one store, read by the force field
        self.currents = RodCurrents(self.n_rods)

    @classmethod
    def from_params(cls, params, state) -> "Network":
        """The network of a scene (``params.contacts`` enabled), for ``state``'s rods."""
        cp, el, fil, circ = params.contacts, params.forces.electrodes, params.forces.external_filament, params.circuit
        rstar = params.rods.rstar
        return cls(
            state.n_rods,
            rstar,
            cp.release_factor * rstar,
            electrodes=el.planes if el is not None else None,
            filament_radius=fil.radius if fil is not None else None,
            bias=circ.delta_J0 if circ is not None else 0.0,
            circuit=circ is not None,
            solver=circ.solver if circ is not None else "auto",
            height_tolerance=circ.height_tolerance if circ is not None else 0.0,
            rod_resistance=state.rod_resistance,
            contact_resistance=cp.resistance,
        )

    # ------------------------------------------------------------------ the step
    def update(self, position, neighbours, step, time) -> NetworkUpdate:
        """Search contacts at ``position`` (over ``neighbours``, a tip neighbour list covering the
        release radius), apply them, and solve the circuit if anything changed."""
        before = self.contacts
        rows = self.tracker.search(before, position, neighbours, step, time)
        if rows:
            # a new filament contact is at -delta_J0 z of its tip (docs/model.md 'Circuit')
            self.contacts = before.apply(rows, contact_potential=lambda k, c: -self.bias * float(position[k, 2]))
        moved = self._repotential_moved_contacts(position)
        if not rows and not moved:
            return NetworkUpdate([])
        if rows:
            rows += circuit_event(
                before.topology.has_short_circuit, self.topology(), int(rows[-1][0]), float(rows[-1][1])
            )
        current = None
        currents_changed = False
        if self.circuit:  # something changed (else the update returned above)
            if self.has_short_circuit:
                fil = self.contacts.conductor_id == ev.CONDUCTOR_FILAMENT
                self.solution = self._solve_at(position[self.contacts.conductor_tip[fil], 2])
                # rods off every conductor-to-conductor path carry no current by topology; the
                # solve leaves them round-off currents (measured up to 2e-14 in a Fig. 2 run)
                current = np.where(self.topology().role == FILAMENT, self.solution.current, 0.0)
            else:
                # no rod lies between two conductor attachments: every current is zero, so the
                # linear solve (about 1 ms at 1200 rods) is skipped until a path exists
                self.solution = None
                if np.count_nonzero(self.current):
                    current = np.zeros(self.n_rods)
            currents_changed = current is not None and self.currents.set(current)
            cs = self.contacts
            fil = cs.conductor_id == ev.CONDUCTOR_FILAMENT
            self.filament_tip = cs.conductor_tip[fil]
            # the height each contact's potential -delta_J0 z stands for, not its height now: a contact that
            # crept by less than the tolerance since its potential was set keeps its drift, and is caught
            # once the drift adds up (heights of the last solve let it creep on at the old potential)
            self.filament_z = (
                -cs.conductor_potential[fil] / self.bias if self.bias else position[self.filament_tip, 2].copy()
            )
        total = self.solution.total_current if self.solution is not None else 0.0
        return NetworkUpdate(rows, currents_changed, True, circuit_rows(rows, total, self.current))

    def _repotential_moved_contacts(self, position) -> bool:
        """Case (ii): replace ``self.contacts`` by contacts whose filament contacts that moved along z by
        more than the height tolerance since their potential was set hold their new potential; True if
        any did. The heights the potentials stand for, ``filament_z``, are :meth:`update`'s to refresh
        when it solves."""
        if not len(self.filament_tip) or not self.circuit:
            return False
        z = position[self.filament_tip, 2]
        moved = np.abs(z - self.filament_z) > self.height_tolerance
        if not moved.any():
            return False
        tip = self.filament_tip[moved]
        # contacts released in this step's events are skipped (they have no potential left)
        self.contacts = self.contacts.with_potentials(tip, ev.CONDUCTOR_FILAMENT, -self.bias * position[tip, 2])
        return True

    # ------------------------------------------------------------------ queries
    @property
    def current(self) -> np.ndarray:
        """The rod currents, (n_rods,) float64 (``currents.current``)."""
        return self.currents.current

    @property
    def n_contacts(self) -> int:
        """Number of tip-tip contacts."""
        return self.contacts.n_contacts

    def solve(self, memo: SolveMemo | None = None) -> CircuitSolution:
        """:meth:`.ContactQueries.solve` through :attr:`memo` unless another memo is given."""
        return super().solve(self.memo if memo is None else memo)

    # ------------------------------------------------------------------ state
    def state_dict(self) -> dict:
        """The contacts (as ``contact_pairs`` and conductor flags, and as the ``graph_*`` arrays of
        :meth:`arrays`), filament heights and the rod currents (``current``, the one checkpoint
        key of the currents), as arrays and plain values. The solution and the memo are not saved:
        :meth:`load_state_dict` solves again (the solve is a pure function of the contacts, so
        that is the solution the saved run held)."""
        pairs, on_cathode, on_anode, on_filament = self.contacts.search_arrays
        d = {
            "contact_pairs": pairs.copy(),
            "on_cathode": on_cathode.copy(),
            "on_anode": on_anode.copy(),
            "on_filament": on_filament.copy(),
            "filament_tip": self.filament_tip.copy(),
            "filament_z": self.filament_z.copy(),
            "has_solution": self.solution is not None,
            "current": self.current.copy(),
        }
        d.update({f"graph_{k}": v.copy() for k, v in self.arrays().items()})
        return d

    def load_state_dict(self, d: dict) -> None:
        """Restore :meth:`state_dict` (also as read back from a checkpoint of selfas-graph 0.2): the
        tip pairs from ``contact_pairs``, the conductor contacts from the flags, the filament
        contacts' potentials from the ``graph_*`` arrays."""
        pairs = np.array(d["contact_pairs"], dtype=np.int64).reshape(-1, 2)
        cid = np.asarray(d["graph_conductor_id"])
        fil = cid == ev.CONDUCTOR_FILAMENT
        filament_potential = np.full(self.n_tips, np.nan)
        filament_potential[np.asarray(d["graph_conductor_tip"])[fil]] = np.asarray(d["graph_conductor_potential"])[fil]
        tips, ids, pots = [], [], []
        for c, key in (
            (ev.CONDUCTOR_CATHODE, "on_cathode"),
            (ev.CONDUCTOR_ANODE, "on_anode"),
            (ev.CONDUCTOR_FILAMENT, "on_filament"),
        ):
            if c not in self.conductor_potential:
                continue
            t = np.flatnonzero(np.asarray(d[key], dtype=bool))
            fixed = self.conductor_potential[c]
            tips.append(t)
            ids.append(np.full(len(t), c, dtype=np.int64))
            pots.append(filament_potential[t] if fixed is None else np.full(len(t), float(fixed)))
        arrays = {
            "tip_contacts": pairs,
            "conductor_tip": np.concatenate(tips + [np.zeros(0, dtype=np.int64)]),
            "conductor_id": np.concatenate(ids + [np.zeros(0, dtype=np.int64)]),
            "conductor_potential": np.concatenate(pots + [np.zeros(0)]),
        }
        self.contacts = ContactSet.from_arrays(
            self.n_rods, self.conductor_potential, arrays, resistive=self.contact_resistance > 0.0
        )
        self.filament_tip = np.array(d["filament_tip"], dtype=np.int64)
        self.filament_z = np.array(d["filament_z"], dtype=np.float64)
        self.solution = None
        if bool(d["has_solution"]) and self.circuit:
            self.solution = self._solve_at(self.filament_z)
        if "current" in d:
            self.currents.set(np.array(d["current"], dtype=np.float64))

    def _solve_at(self, filament_z) -> CircuitSolution:
        """:meth:`solve`; without a bias no current flows, so the effective resistance between the
        conductors comes from a second solve at their unit-bias potentials (the electrodes' -+gap/2,
        a filament contact's -z at its height ``filament_z``, in the order of the contacts): the network
        is linear, and any bias gives the same resistance. Only the resistance is taken from it."""
        sol = self.solve()
        if self.bias:
            return sol
        cs = self.contacts
        unit = np.array([self._unit_potential.get(int(c), 0.0) for c in cs.conductor_id], dtype=np.float64)
        unit[cs.conductor_id == ev.CONDUCTOR_FILAMENT] = -np.asarray(filament_z, dtype=np.float64)
        topo = cs.topology
        probe = solve_circuit(
            cs.n_tips, cs.tip_contacts, cs.conductor_tip, unit, solver=self.solver, rod_resistance=self.rod_resistance,
            contact_resistance=self.contact_resistance, merged=(topo.n_nodes, topo.node_of_tip),
        )  # fmt: skip
        return dataclasses.replace(sol, effective_resistance=probe.effective_resistance)

    def __repr__(self) -> str:
        return (
            f"Network(n_rods={self.n_rods}, contacts={self.n_contacts}, "
            f"conductors={sorted(self.conductor_potential)}, solved={self.solution is not None})"
        )
