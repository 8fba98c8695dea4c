"""Event records: what changed in the contact network, and when.

An event is one row ``(step, time, kind, a, b)``. ``kind`` is one of the
integer codes below; ``a`` and ``b`` are ids whose meaning depends on the kind:

==================  ======================  =====================================
kind                a                       b
==================  ======================  =====================================
TIP_CONTACT         tip k                   tip l (k < l)
TIP_RELEASE         tip k                   tip l (k < l)
CONDUCTOR_CONTACT   tip k                   conductor id (see ``CONDUCTOR_*``)
CONDUCTOR_RELEASE   tip k                   conductor id
SHORT_CIRCUIT       number of filament rods -1
OPEN_CIRCUIT        -1                      -1
==================  ======================  =====================================

Tips are numbered ``2 i`` (tip a, magnetic charge +q_i) and ``2 i + 1``
(tip b, -q_i) for rod ``i`` (docs/model.md 'Rods').

SHORT_CIRCUIT is emitted when the network goes from carrying no current-carrying
filament to carrying one (a conducting path now joins two different conductor
attachments, docs/model.md 'Connectivity graph and topology'); OPEN_CIRCUIT when the last such path is broken
(docs/model.md 'Contacts and events').
"""

import enum
from typing import NamedTuple

import numpy as np


class EventKind(enum.IntEnum):
    """Event kinds by name; each equals its integer code (``EventKind.SHORT_CIRCUIT == 5``), and
    ``EventKind(row.kind).label`` is the name stored in run files (``kind_names``): the one table of the
    kinds, from which the module's constants and :data:`KIND_NAMES` are made."""

    TIP_CONTACT = 1
    TIP_RELEASE = 2
    CONDUCTOR_CONTACT = 3
    CONDUCTOR_RELEASE = 4
    SHORT_CIRCUIT = 5
    OPEN_CIRCUIT = 6

    @property
    def label(self) -> str:
        return self.name.lower()


#: the kinds as plain integers, for the arrays and the compiled kernels
TIP_CONTACT = int(EventKind.TIP_CONTACT)
TIP_RELEASE = int(EventKind.TIP_RELEASE)
CONDUCTOR_CONTACT = int(EventKind.CONDUCTOR_CONTACT)
CONDUCTOR_RELEASE = int(EventKind.CONDUCTOR_RELEASE)
SHORT_CIRCUIT = int(EventKind.SHORT_CIRCUIT)
OPEN_CIRCUIT = int(EventKind.OPEN_CIRCUIT)
#: code -> the name stored in run files
KIND_NAMES = {int(k): k.label for k in EventKind}
#: the order of the contact search's events within a step (releases first, then contacts; the rows of
#: one kind by their ids): a kind the search emits must be here, as one a replay meets must be handled
#: by ``model/contactset.py::ContactSet.apply`` (or be one of its ``DERIVED_KINDS``); a kind triggered
#: by geometry must also make the compiled steps' quiet-step test unsure (``kernels/contacts.py``)
SEARCH_ORDER = {TIP_RELEASE: 0, CONDUCTOR_RELEASE: 1, TIP_CONTACT: 2, CONDUCTOR_CONTACT: 3}


class Event(NamedTuple):
    """One event with its kind by name (see the table at the top of this module)."""

    step: int
    time: float
    kind: EventKind
    a: int
    b: int


def named_events(rows) -> list:
    """Event rows ``(step, time, kind, a, b)`` (a list of tuples or an ``EVENT_DTYPE`` array) as
    :class:`Event` tuples with :class:`EventKind` kinds."""
    return [Event(int(r[0]), float(r[1]), EventKind(int(r[2])), int(r[3]), int(r[4])) for r in rows]


#: conductor ids. Case (i): the two electrode planes. Case (ii): the fixed
#: current filament, whose potential varies along z (docs/model.md 'Circuit').
CONDUCTOR_CATHODE = 0
CONDUCTOR_ANODE = 1
CONDUCTOR_FILAMENT = 2
CONDUCTOR_NAMES = {
    CONDUCTOR_CATHODE: "cathode",
    CONDUCTOR_ANODE: "anode",
    CONDUCTOR_FILAMENT: "filament",
}

#: numpy dtype of one event record, as stored in HDF5
EVENT_DTYPE = np.dtype([("step", "<i8"), ("time", "<f8"), ("kind", "<i4"), ("a", "<i8"), ("b", "<i8")])


def event_array(rows):
    """Pack an iterable of ``(step, time, kind, a, b)`` tuples into an ``EVENT_DTYPE`` array."""
    return np.array([tuple(r) for r in rows], dtype=EVENT_DTYPE)
