"""The contacts of a rod network as one immutable value (docs/model.md 'Contacts and events').

:class:`ContactSet` holds the tip pairs in contact and the contacts of tips with conductors (with
each contact's potential), as sorted read-only arrays. What depends on the contacts is a function
of the set: its topology (:attr:`ContactSet.topology`, :func:`.topology.classify_rods`, computed
once per set) and its circuit (:func:`solve_contacts`, :func:`.circuit.solve_circuit`).

A set never changes. :meth:`ContactSet.apply` is the one path that applies contact events: it
returns the set after a batch of event rows, or raises ValueError and leaves nothing changed. A
run (:class:`~.network.Network`) applies the rows of its contact search with it; a replay or a
saved frame (:class:`~.graph.ConnectivityGraph`, :meth:`ContactSet.from_arrays`) the rows read
from a file.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable, Iterable, Mapping
from types import MappingProxyType

import numpy as np

from . import events as ev
from .contact_queries import ContactQueries, solve_contacts
from .topology import Topology, classify_resistive, classify_rods, conductor_node_key
from .validate import _as_count, _as_index_array, _frozen, conductor_id, finite_potential, tip_index, tip_pair

#: ContactQueries and solve_contacts live in .contact_queries, and are imported from here too
__all__ = ["ContactSet", "ContactQueries", "solve_contacts", "DERIVED_KINDS"]

#: event kinds derived from a batch (not contacts): skipped by :meth:`ContactSet.apply`
DERIVED_KINDS = (ev.SHORT_CIRCUIT, ev.OPEN_CIRCUIT)

_NO_TIPS = np.zeros((0, 2), dtype=np.int64)
_NONE = np.zeros(0, dtype=np.int64)


@dataclasses.dataclass(frozen=True, eq=False)
class ContactSet:
    """Tip-tip and tip-conductor contacts of ``n_rods`` rods (read-only; build with :meth:`empty`).

    Tips ``0 .. n_tips-1``; rod ``i`` joins tips ``2 i`` and ``2 i + 1``. A contact joins two tips
    of different rods, or a tip and a conductor: one with a fixed potential (electrodes, case (i))
    or one whose potential is given per contact (the case (ii) filament, ``-delta_J0 z``).

    Attributes
    ----------
    n_rods : int
    fixed : mapping conductor id -> potential (units R0 J0)
        The conductors of fixed potential.
    per_contact : frozenset of int
        The conductors whose potential is given per contact.
    tip_contacts : (m, 2) int64
        Rows ``(k, l)`` with ``k < l``, sorted.
    conductor_tip, conductor_id : (k,) int64
        The conductor contacts, sorted by (tip, conductor).
    conductor_potential : (k,) float64
        Potential of each conductor contact (NaN where a per-contact potential is unset).
    resistive : bool
        The contacts are resistors (``contacts.resistance`` > 0): the topology merges no tips
        (:func:`.topology.classify_resistive`).
    """

    n_rods: int
    fixed: Mapping[int, float]
    per_contact: frozenset
    tip_contacts: np.ndarray
    conductor_tip: np.ndarray
    conductor_id: np.ndarray
    conductor_potential: np.ndarray
    resistive: bool = False

    # ------------------------------------------------------------------ construction
    @classmethod
    def empty(cls, n_rods, conductor_potential: Mapping[int, float | None], resistive=False) -> "ContactSet":
        """No contacts. ``conductor_potential``: conductor id (``events.CONDUCTOR_*``) -> fixed
        potential, or None when the potential is given per contact; other conductors are unknown.
        ``resistive``: contacts of resistance > 0 (the class's attribute)."""
        n_rods = _as_count(n_rods, "n_rods")
        fixed, per = {}, set()
        for c, pot in dict(conductor_potential).items():
            c = conductor_id(c)
            if pot is None:
                per.add(c)
            else:
                pot = float(pot)
                if not np.isfinite(pot):
                    raise ValueError(f"conductor {c} potential must be finite, got {pot}")
                fixed[c] = pot
        return cls(
            n_rods,
            MappingProxyType(fixed),
            frozenset(per),
            _frozen(_NO_TIPS.copy()),
            _frozen(_NONE.copy()),
            _frozen(_NONE.copy()),
            _frozen(np.zeros(0)),
            bool(resistive),
        )

    @classmethod
    def from_arrays(
        cls,
        n_rods,
        conductor_potential: Mapping[int, float | None],
        arrays: Mapping[str, np.ndarray],
        resistive=False,
    ) -> "ContactSet":
        """The set of :meth:`arrays` output (e.g. read back from HDF5), validated as events are.

        Per-contact potentials are taken from ``arrays["conductor_potential"]`` (NaN = unset); for
        fixed-potential conductors the ``conductor_potential`` mapping given here wins over the
        stored value.
        """
        s = cls.empty(n_rods, conductor_potential, resistive)
        tc = _as_index_array(arrays["tip_contacts"], "tip_contacts", 2, s.n_tips)
        ct = _as_index_array(arrays["conductor_tip"], "conductor_tip", 1, s.n_tips)
        cid = _as_index_array(arrays["conductor_id"], "conductor_id", 1, None)
        pot = np.asarray(arrays["conductor_potential"], dtype=np.float64).reshape(-1)
        if not (ct.shape == cid.shape == pot.shape):
            raise ValueError(
                "conductor_tip, conductor_id and conductor_potential must have one entry per "
                f"contact, got shapes {ct.shape}, {cid.shape}, {pot.shape}"
            )
        given = {(k, c): None if np.isnan(p) else p for k, c, p in zip(ct.tolist(), cid.tolist(), pot.tolist())}
        rows = [(0, 0.0, ev.TIP_CONTACT, k, l) for k, l in tc.tolist()]
        rows += [(0, 0.0, ev.CONDUCTOR_CONTACT, k, c) for k, c in zip(ct.tolist(), cid.tolist())]
        return s.apply(rows, contact_potential=lambda k, c: given[(k, c)])

    # ------------------------------------------------------------------ queries
    @property
    def n_tips(self) -> int:
        return 2 * self.n_rods

    @property
    def n_contacts(self) -> int:
        """Number of tip-tip contacts."""
        return int(self.tip_contacts.shape[0])

    @property
    def conductors(self) -> list:
        """Every conductor id: the fixed ones, then those of per-contact potential."""
        return list(self.fixed) + sorted(self.per_contact)

    def arrays(self) -> dict[str, np.ndarray]:
        """The contacts as arrays (for HDF5 and for the solvers): ``tip_contacts``, ``conductor_tip``,
        ``conductor_id``, ``conductor_potential`` (read-only; see the class attributes)."""
        return {
            "tip_contacts": self.tip_contacts,
            "conductor_tip": self.conductor_tip,
            "conductor_id": self.conductor_id,
            "conductor_potential": self.conductor_potential,
        }

    def on_conductor(self, c) -> np.ndarray:
        """(n_tips,) bool: the tips touching conductor ``c`` (all False for a conductor not in the set)."""
        flags = np.zeros(self.n_tips, dtype=bool)
        flags[self.conductor_tip[self.conductor_id == c]] = True
        return flags

    @functools.cached_property
    def search_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(pairs, on_cathode, on_anode, on_filament)``: the tip pairs (sorted by ``k n_tips + l``, the
        order of :attr:`tip_contacts`) and the flags of the three conductors, as the contact search's
        kernels take them (:meth:`~.contacts.ContactTracker.search`); computed once per set."""
        # writable copies: a read-only array is another type to numba (another compilation)
        return (
            np.array(self.tip_contacts, dtype=np.int64, order="C"),
            self.on_conductor(ev.CONDUCTOR_CATHODE),
            self.on_conductor(ev.CONDUCTOR_ANODE),
            self.on_conductor(ev.CONDUCTOR_FILAMENT),
        )

    def node_key(self) -> np.ndarray:
        """Attachment key of each conductor contact (:func:`.topology.conductor_node_key`)."""
        return conductor_node_key(self.conductor_id, self.per_contact, self.conductors)

    @functools.cached_property
    def topology(self) -> Topology:
        """Roles and structures of the rods (:func:`.topology.classify_rods`, or
        :func:`.topology.classify_resistive` for resistive contacts), computed once per set."""
        classify = classify_resistive if self.resistive else classify_rods
        return classify(self.n_rods, self.tip_contacts, self.conductor_tip, self.node_key())

    # ------------------------------------------------------------------ events
    def known_conductor(self, c) -> int:
        """``c`` as a conductor id of this set; ValueError naming the known ones otherwise."""
        c = conductor_id(c)
        if c not in self.fixed and c not in self.per_contact:
            known = sorted(self.fixed) + sorted(self.per_contact)
            name = ev.CONDUCTOR_NAMES.get(c, "?")
            raise ValueError(f"unknown conductor {c} ({name}); this graph has conductors {known}")
        return c

    def apply(
        self, rows: Iterable, contact_potential: Callable[[int, int], float | None] | None = None
    ) -> "ContactSet":
        """The set after a batch of contact events, applied in order.

        Parameters
        ----------
        rows : EVENT_DTYPE array or iterable of ``(step, time, kind, a, b)``
            TIP_CONTACT / TIP_RELEASE (a, b = tips), CONDUCTOR_CONTACT / CONDUCTOR_RELEASE (a = tip,
            b = conductor id). SHORT_CIRCUIT and OPEN_CIRCUIT rows are derived data and skipped.
        contact_potential : callable ``(tip, conductor) -> float or None``, optional
            Potential of a new contact with a per-contact conductor; None (or no callable) leaves
            it unset (NaN), and :func:`solve_contacts` refuses unset potentials.

        Returns
        -------
        ContactSet
            ``self`` if the batch held no contact event.

        Raises
        ------
        ValueError
            For an unknown kind, a tip out of range, the two tips of one rod, a contact that
            exists already, the release of one that does not, an unknown conductor or a
            non-finite potential. Nothing is changed then.
        """
        n_tips = self.n_tips
        tips: dict[int, bool] = {}  # key k n_tips + l -> in contact after the rows so far
        conductors: dict[tuple[int, int], float | None] = {}  # (tip, c) -> potential, None: released
        for row in rows:
            kind, a, b = int(row[2]), row[3], row[4]
            if kind in (ev.TIP_CONTACT, ev.TIP_RELEASE):
                k, l = tip_pair(a, b, n_tips)
                key = k * n_tips + l
                now = tips[key] if key in tips else self._has_tip_key(key)
                if kind == ev.TIP_CONTACT and now:
                    raise ValueError(f"tips {k} and {l} are already in contact")
                if kind == ev.TIP_RELEASE and not now:
                    raise ValueError(f"cannot release tips {k} and {l}: they are not in contact")
                tips[key] = kind == ev.TIP_CONTACT
            elif kind == ev.CONDUCTOR_CONTACT:
                c = self.known_conductor(b)
                pot = contact_potential(int(a), c) if contact_potential is not None and c in self.per_contact else None
                k = tip_index(a, n_tips)
                if self._touches(k, c, conductors):
                    raise ValueError(f"tip {k} already touches conductor {c} ({ev.CONDUCTOR_NAMES.get(c, '?')})")
                if c in self.fixed:
                    pot = self.fixed[c]
                else:
                    pot = np.nan if pot is None else finite_potential(pot, k, c)
                conductors[(k, c)] = pot
            elif kind == ev.CONDUCTOR_RELEASE:
                c = self.known_conductor(b)
                k = tip_index(a, n_tips)
                if not self._touches(k, c, conductors):
                    raise ValueError(
                        f"cannot release tip {k} from conductor {c} ({ev.CONDUCTOR_NAMES.get(c, '?')}): "
                        "it does not touch it"
                    )
                conductors[(k, c)] = None
            elif kind in DERIVED_KINDS:
                continue
            else:
                raise ValueError(f"unknown event kind {kind} in row {tuple(row)}")
        if not tips and not conductors:
            return self
        tc = self.tip_contacts
        if tips:
            keys = self._tip_keys
            changed = np.fromiter(tips, dtype=np.int64, count=len(tips))
            keep = ~np.isin(keys, changed)
            added = np.array([key for key, on in tips.items() if on], dtype=np.int64)
            keys = np.sort(np.concatenate([keys[keep], added]))
            tc = _frozen(np.stack([keys // n_tips, keys % n_tips], axis=1))
        ct, cid, pot = self.conductor_tip, self.conductor_id, self.conductor_potential
        if conductors:
            old = {(k, c): p for k, c, p in zip(ct.tolist(), cid.tolist(), pot.tolist())}
            for kc, p in conductors.items():
                if p is None:
                    old.pop(kc, None)
                else:
                    old[kc] = p
            ct, cid, pot = _sorted_conductor_contacts(old)
        return dataclasses.replace(self, tip_contacts=tc, conductor_tip=ct, conductor_id=cid, conductor_potential=pot)

    def with_potentials(self, tip, c, potential) -> "ContactSet":
        """The set with new potentials ``potential`` (r,) of the contacts of tips ``tip`` (r,) with
        the per-contact conductor ``c`` (case (ii): ``-delta_J0 z`` as contact heights move); tips
        not touching ``c`` are skipped. The topology carries over (potentials do not change it)."""
        c = self.known_conductor(c)
        if c in self.fixed:
            raise ValueError(f"conductor {c} has a fixed potential; it has no per-contact potential")
        tip = np.asarray(tip, dtype=np.int64).reshape(-1)
        value = np.broadcast_to(np.asarray(potential, dtype=np.float64), tip.shape)
        pot = self.conductor_potential.copy()
        mine = np.flatnonzero(self.conductor_id == c)
        where = dict(zip(self.conductor_tip[mine].tolist(), mine.tolist()))
        for k, p in zip(tip.tolist(), value.tolist()):
            if k in where:
                pot[where[k]] = finite_potential(p, k, c)
        new = dataclasses.replace(self, conductor_potential=_frozen(pot))
        if "topology" in self.__dict__:
            new.__dict__["topology"] = self.topology  # the same contacts: the same topology
        return new

    @functools.cached_property
    def _tip_keys(self) -> np.ndarray:
        return self.tip_contacts[:, 0] * self.n_tips + self.tip_contacts[:, 1]

    def _has_tip_key(self, key: int) -> bool:
        keys = self._tip_keys
        i = int(np.searchsorted(keys, key))
        return i < keys.shape[0] and int(keys[i]) == key

    @functools.cached_property
    def _conductor_keys(self) -> frozenset:
        return frozenset(zip(self.conductor_tip.tolist(), self.conductor_id.tolist()))

    def _touches(self, k: int, c: int, pending: dict) -> bool:
        if (k, c) in pending:
            return pending[(k, c)] is not None
        return (k, c) in self._conductor_keys

    def __repr__(self) -> str:
        return (
            f"ContactSet(n_rods={self.n_rods}, tip_contacts={self.n_contacts}, "
            f"conductor_contacts={self.conductor_tip.shape[0]}, conductors={self.conductors})"
        )


def _sorted_conductor_contacts(contacts: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(tip, conductor) -> potential as the three arrays, sorted by (tip, conductor)."""
    if not contacts:
        return _frozen(_NONE.copy()), _frozen(_NONE.copy()), _frozen(np.zeros(0))
    kc = np.array(list(contacts), dtype=np.int64)
    pot = np.fromiter(contacts.values(), dtype=np.float64, count=len(contacts))
    order = np.lexsort((kc[:, 1], kc[:, 0]))
    return (
        _frozen(np.ascontiguousarray(kc[order, 0])),
        _frozen(np.ascontiguousarray(kc[order, 1])),
        _frozen(np.ascontiguousarray(pot[order])),
    )
