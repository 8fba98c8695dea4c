"""Contact detection with hysteresis, producing event records (docs/model.md 'Contacts and events').

The contacts themselves are a :class:`~.contactset.ContactSet`; the search reads one and
returns the rows that change it.

Two tips of different rods come into contact when closer than r* and stay in
contact until they are farther apart than ``release_radius`` (default 1.5 r*),
so that a vibrating contact does not flood the event log. A tip touches an
electrode plane when its distance h to the plane is below r*, and leaves it when
h exceeds the release radius.

The search reuses the force field's tip neighbour list (extended to the
release radius): each step costs one pass over the listed pairs plus a sorted
set difference of the (few) close pairs against the current contacts.
"""

from __future__ import annotations

import numpy as np

from ..kernels.contacts import close_pair_count, close_pairs, contact_news, contacts_unchanged
from . import events as ev


class ContactTracker:
    """The contact search: the events that change a set of contacts at given positions.

    The tracker keeps no contacts: :meth:`search` compares a
    :class:`~.contactset.ContactSet` with the positions and returns the event rows, which the
    caller applies to the set (:meth:`.ContactSet.apply`, in a run :class:`~.network.Network`).

    Parameters
    ----------
    n_tips : int
    rstar, release_radius : float
        Contact and release distances (release_radius >= rstar).
    electrodes : (z_cathode, z_anode) or None
        Electrode planes of case (i).
    filament_radius : float or None
        Radius w of the case (ii) filament on the z axis: a tip touches it within
        ``r* + w`` of the axis and leaves it beyond ``release_radius + w``.
    """

    def __init__(self, n_tips, rstar, release_radius, electrodes=None, filament_radius=None):
        self.n_tips = n_tips
        self.rstar = float(rstar)
        self.release = float(release_radius)
        self.electrodes = electrodes
        self.filament_radius = filament_radius

    def _keys(self, pairs):
        return pairs[:, 0] * self.n_tips + pairs[:, 1]

    def search(self, contacts, position, neighbours, step, time):
        """The events that take ``contacts`` to the contacts at ``position``, as rows.

        Parameters
        ----------
        contacts : ContactSet
            The contacts before the step (not changed).
        position : (n_tips, 3) float64
        neighbours : NeighbourList over tips covering at least ``release_radius``
        step, time : int, float
            Stamped on the events.

        Returns
        -------
        list of (step, time, kind, a, b) tuples, releases first, then contacts, each
        sorted by ids (a deterministic order).
        """
        common, fr, on_filament = self._kernel_args(contacts, position, neighbours)
        # [perf] one kernel pass answers the common step without news (kernels/contacts.py::contacts_unchanged)
        if contacts_unchanged(*common, fr, on_filament):
            return []
        return self.search_news(contacts, position, neighbours, step, time, common)

    def _kernel_args(self, contacts, position, neighbours):
        """``(common, filament_radius, on_filament)``: the arguments both kernels take (tips, list, contacts,
        radii, electrodes and the tips on them; NaN planes without electrodes), and the filament's."""
        pairs, on_cathode, on_anode, on_filament = contacts.search_arrays
        el = self.electrodes if self.electrodes is not None else (np.nan, np.nan)
        fr = self.filament_radius if self.filament_radius is not None else np.nan
        common = (position, neighbours.start, neighbours.index, pairs, self.rstar, self.release)
        return common + (float(el[0]), float(el[1]), on_cathode, on_anode), float(fr), on_filament

    def search_news(self, contacts, position, neighbours, step, time, common=None):
        """:meth:`search` on a step its one-pass check is not sure of: one more kernel pass where that is
        sure (``kernels/contacts.py::contact_news``), else :meth:`search_numpy`. ``common``: the kernels'
        arguments, if the caller has them."""
        if common is None:
            common = self._kernel_args(contacts, position, neighbours)[0]
        rows = self._news(common, step, time)
        if rows is not None:
            return self._sorted(rows + self._filament_rows(contacts.search_arrays[3], position, step, time))
        return self.search_numpy(contacts, position, neighbours, step, time)

    def _news(self, common, step, time):
        """The tip-pair and electrode rows by one kernel pass (``kernels/contacts.py::contact_news``, on the
        arguments ``common`` of :meth:`_kernel_args`), or None where it is not sure and :meth:`search_numpy` decides."""
        sure, gone, new, c_off, c_on, a_off, a_on = contact_news(*common)
        if not sure:
            return None
        pairs = common[3]
        rows = [(step, time, ev.TIP_RELEASE, int(k), int(l)) for k, l in pairs[gone].tolist()]
        rows += [(step, time, ev.TIP_CONTACT, int(k), int(l)) for k, l in new.tolist()]
        for tips, kind, cid in (
            (c_off, ev.CONDUCTOR_RELEASE, ev.CONDUCTOR_CATHODE),
            (c_on, ev.CONDUCTOR_CONTACT, ev.CONDUCTOR_CATHODE),
            (a_off, ev.CONDUCTOR_RELEASE, ev.CONDUCTOR_ANODE),
            (a_on, ev.CONDUCTOR_CONTACT, ev.CONDUCTOR_ANODE),
        ):
            rows += [(step, time, kind, int(k), cid) for k in tips.tolist()]
        return rows

    def _filament_rows(self, on_filament, position, step, time):
        """The rows of the case (ii) filament's surface (none without it)."""
        if self.filament_radius is None:
            return []
        h = np.hypot(position[:, 0], position[:, 1]) - self.filament_radius
        return self._surface_rows(on_filament, h, ev.CONDUCTOR_FILAMENT, step, time)

    def _surface_rows(self, flags, h, cid, step, time):
        """The rows of conductor ``cid``: the tips on it (``flags``) now beyond the release radius of its
        surface, the tips off it now within r* (``h``: each tip's distance from the surface)."""
        rows = [(step, time, ev.CONDUCTOR_RELEASE, int(k), cid) for k in np.flatnonzero(flags & (h > self.release))]
        rows += [(step, time, ev.CONDUCTOR_CONTACT, int(k), cid) for k in np.flatnonzero(~flags & (h < self.rstar))]
        return rows

    @staticmethod
    def _sorted(rows):
        """Releases first, then contacts, each sorted by ids (a deterministic order, ``events.SEARCH_ORDER``)."""
        if rows:
            rows.sort(key=lambda r: (ev.SEARCH_ORDER[r[2]], r[3], r[4]))
        return rows

    def search_numpy(self, contacts, position, neighbours, step, time):
        """:meth:`search`'s events by numpy passes over the arrays, without the one-pass kernels: the
        reference of the kernel path, and its path where that is not sure."""
        pairs, on_cathode, on_anode, on_filament = contacts.search_arrays
        rows = []
        # releases: current contacts now farther apart than the release radius
        if len(pairs):
            d = position[pairs[:, 0]] - position[pairs[:, 1]]
            gone = np.einsum("ij,ij->i", d, d) > self.release**2
            if gone.any():
                for k, l in pairs[gone]:
                    rows.append((step, time, ev.TIP_RELEASE, int(k), int(l)))
                pairs = pairs[~gone]
        # new contacts: listed pairs closer than r* that are not in contact yet. Fast path for
        # the common step without news: if the number of close pairs equals the number of
        # current contacts closer than r*, every close pair is already a contact.
        n_close = close_pair_count(position, neighbours.start, neighbours.index, self.rstar)
        if len(pairs):
            d = position[pairs[:, 0]] - position[pairs[:, 1]]
            n_known = int((np.einsum("ij,ij->i", d, d) < self.rstar**2).sum())
        else:
            n_known = 0
        close = close_pairs(position, neighbours.start, neighbours.index, self.rstar) if n_close > n_known else ()
        if len(close):
            new = ~np.isin(self._keys(close), self._keys(pairs), assume_unique=True)
            for k, l in close[new]:
                rows.append((step, time, ev.TIP_CONTACT, int(k), int(l)))
        if self.electrodes is not None:
            z = position[:, 2]
            rows += self._surface_rows(on_cathode, z - self.electrodes[0], ev.CONDUCTOR_CATHODE, step, time)
            rows += self._surface_rows(on_anode, self.electrodes[1] - z, ev.CONDUCTOR_ANODE, step, time)
        return self._sorted(rows + self._filament_rows(on_filament, position, step, time))
