"""Close pairs in a neighbour list: the contact search's pairs and its one-pass check.

:func:`close_pairs` lists the pairs of a compressed-row neighbour list (both directions of every
pair: the neighbours of point ``k`` are ``index[start[k]:start[k + 1]]``) closer than a radius, in
two passes that keep the parallel loop a gather; :func:`contacts_unchanged` answers in one pass
whether a step changes no contact (``model/contacts.py``).
"""

import numpy as np

from ._jit import inline, njit, njit_rows, prange


@inline
def closer(position, k, l, r2max):
    """True when points k and l are closer than sqrt(r2max)."""
    dx = position[k, 0] - position[l, 0]
    dy = position[k, 1] - position[l, 1]
    dz = position[k, 2] - position[l, 2]
    return dx * dx + dy * dy + dz * dz < r2max


@njit_rows
def _close_counts(position, start, index, radius, counts):
    n = position.shape[0]
    r2max = radius * radius
    for k in prange(n):
        c = 0
        for j in range(start[k], start[k + 1]):
            l = index[j]
            if l > k and closer(position, k, l, r2max):
                c += 1
        counts[k] = c


@njit_rows
def _close_fill(position, start, index, radius, offset, out):
    n = position.shape[0]
    r2max = radius * radius
    for k in prange(n):
        c = offset[k]
        for j in range(start[k], start[k + 1]):
            l = index[j]
            if l > k and closer(position, k, l, r2max):
                out[c, 0] = k
                out[c, 1] = l
                c += 1


#: relative margin by which every distance must clear its threshold for :func:`contacts_unchanged`
#: to answer True (its squared distances may differ from the contact tracker's in the last bit)
QUIET_MARGIN = 1e-9


@njit
def contacts_unchanged(
    position,
    start,
    index,
    pairs,
    rstar,
    release,
    z_cathode,
    z_anode,
    on_cathode,
    on_anode,
    filament_radius,
    on_filament,
):
    """True only when the contact tracker's step would find no event: one pass instead of its dozen
    numpy passes on the common step without news (``model/contacts.py::ContactTracker.search``).

    Answers True when, with every distance clear of its threshold by :data:`QUIET_MARGIN`
    (relative; a distance within the margin answers False, and the tracker decides exactly):
    no contact pair is beyond the release radius; the listed pairs closer than r* number as many
    as the contact pairs closer than r* (so every close pair is a contact already); no tip off an
    electrode is within r* of it and none on it beyond the release radius; likewise for the
    plasma filament's surface. A NaN anywhere answers False. False is always safe (the tracker
    then does its full check); True is given only where the full check finds nothing.

    Parameters
    ----------
    position : (n_tips, 3) float64
    start, index : the tip neighbour list (compressed rows, both directions), covering r*
    pairs : (m, 2) int64
        Current contacts.
    rstar, release : float
    z_cathode, z_anode : float
        Electrode planes (NaN: no electrodes).
    on_cathode, on_anode, on_filament : (n_tips,) bool
    filament_radius : float
        Surface radius of the plasma filament about the z axis (NaN: none).
    """
    ok, n_known, n_close = contacts_part(
        position,
        start,
        index,
        pairs,
        0,
        pairs.shape[0],
        0,
        position.shape[0],
        rstar,
        release,
        z_cathode,
        z_anode,
        on_cathode,
        on_anode,
        filament_radius,
        on_filament,
    )
    return ok and n_close == n_known


@njit
def contacts_part(
    position,
    start,
    index,
    pairs,
    p_lo,
    p_hi,
    k_lo,
    k_hi,
    rstar,
    release,
    z_cathode,
    z_anode,
    on_cathode,
    on_anode,
    filament_radius,
    on_filament,
):
    """The tests of :func:`contacts_unchanged` on the contacts ``p_lo`` to ``p_hi`` and the tips ``k_lo``
    to ``k_hi``: ``(ok, n_known, n_close)``, ``ok`` False when one of them fails, else the contacts among
    them closer than r* and the listed pairs ``k < l`` from those tips closer than r*. Over any split of
    the contacts and the tips into parts, :func:`contacts_unchanged` is True exactly when every part is
    ok and the counts add up to the same number."""
    lo = 1.0 - QUIET_MARGIN
    hi = 1.0 + QUIET_MARGIN
    r2 = rstar * rstar
    n_known = 0
    for p in range(p_lo, p_hi):
        k = pairs[p, 0]
        l = pairs[p, 1]
        dx = position[k, 0] - position[l, 0]
        dy = position[k, 1] - position[l, 1]
        dz = position[k, 2] - position[l, 2]
        d2 = dx * dx + dy * dy + dz * dz
        if not d2 <= release * release * lo:
            return False, 0, 0
        if d2 < r2 * lo:
            n_known += 1
        elif d2 <= r2 * hi:
            return False, 0, 0
    n_close = 0
    # the tips' own rows through slices from k_lo (loops from 0: `kernels/tips.py::tip_tip_fast_rows`)
    own, s = position[k_lo:k_hi], start[k_lo : k_hi + 1]
    for i in range(k_hi - k_lo):
        k = k_lo + i
        for j in range(s[i], s[i + 1]):
            l = index[j]
            if l > k:
                dx = own[i, 0] - position[l, 0]
                dy = own[i, 1] - position[l, 1]
                dz = own[i, 2] - position[l, 2]
                d2 = dx * dx + dy * dy + dz * dz
                if d2 < r2 * lo:
                    n_close += 1
                elif not d2 > r2 * hi:  # within the margin, or NaN
                    return False, 0, 0
    if z_cathode == z_cathode:
        c, a = on_cathode[k_lo:k_hi], on_anode[k_lo:k_hi]
        for i in range(k_hi - k_lo):
            z = own[i, 2]
            # the tracker's differences, z - z_cathode and z_anode - z, computed alike (no margin needed)
            hc = z - z_cathode
            ha = z_anode - z
            if c[i]:
                if not hc <= release:
                    return False, 0, 0
            elif not hc >= rstar:
                return False, 0, 0
            if a[i]:
                if not ha <= release:
                    return False, 0, 0
            elif not ha >= rstar:
                return False, 0, 0
    if filament_radius == filament_radius:
        f = on_filament[k_lo:k_hi]
        for i in range(k_hi - k_lo):
            rho = np.sqrt(own[i, 0] * own[i, 0] + own[i, 1] * own[i, 1])
            h = rho - filament_radius
            tol = QUIET_MARGIN * (rho + abs(filament_radius) + release)  # the tracker takes np.hypot
            if f[i]:
                if not h <= release - tol:
                    return False, 0, 0
            elif not h >= rstar + tol:
                return False, 0, 0
    return True, n_known, n_close


def close_pair_count(position, start, index, radius):
    """Number of distinct pairs in the list closer than ``radius`` (each pair once)."""
    counts = np.zeros(position.shape[0], dtype=np.int64)
    _close_counts(position, start, index, radius, counts)
    return int(counts.sum())


def close_pairs(position, start, index, radius):
    """All listed pairs ``(k, l)``, ``k < l``, closer than ``radius``: by k, and for each k in the order of its list.

    Two passes (count, then fill at prefix-sum offsets) keep the parallel loop a
    gather with no shared counter and no fixed capacity to overflow.

    Parameters
    ----------
    position : (n, 3) float64
    start, index : the compressed-row neighbour list, int64 offsets and int32 or int64 entries (``cells.list_dtype``)
    radius : float

    Returns
    -------
    (m, 2) int64
    """
    n = position.shape[0]
    counts = np.zeros(n, dtype=np.int64)
    _close_counts(position, start, index, radius, counts)
    offset = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(counts, out=offset[1:])
    out = np.empty((offset[-1], 2), dtype=np.int64)
    _close_fill(position, start, index, radius, offset, out)
    return out


#: new tip contacts :func:`contact_news` holds in one call; more answer "not sure" (the tracker's numpy path)
NEWS_CAPACITY = 512


@njit
def contact_news(position, start, index, pairs, rstar, release, z_cathode, z_anode, on_cathode, on_anode):
    """The tip-pair and electrode events of a step in one serial pass, for the contact tracker's step
    with news (``model/contacts.py::ContactTracker.search``; its numpy path is the reference).

    Returns ``(sure, gone, new, cathode_off, cathode_on, anode_off, anode_on)``: ``gone`` the indices
    of the contacts beyond the release radius (in the order of ``pairs``), ``new`` (m, 2) the listed
    pairs ``k < l`` closer than r* that are not contacts (row by row, each row in list order), and the
    tips that leave or touch each electrode (ascending). The close pairs are those of
    :func:`close_pairs` (the same arithmetic); a contact's distance is taken as the tracker's numpy
    path takes it only to the last bit, so ``sure`` is False (and the caller takes the numpy path)
    when one lies within :data:`QUIET_MARGIN` of r* or of the release radius, is NaN, or when more than
    :data:`NEWS_CAPACITY` new pairs are found. The electrodes' heights are the tracker's differences,
    computed alike. ``z_cathode`` NaN: no electrodes (empty arrays).

    Parameters
    ----------
    position : (n_tips, 3) float64
    start, index : the tip neighbour list (compressed rows, both directions), covering the release radius
    pairs : (m, 2) int64
        Current contacts, sorted by ``k n_tips + l`` (``ContactSet.search_arrays``).
    rstar, release, z_cathode, z_anode : float
    on_cathode, on_anode : (n_tips,) bool
    """
    n = position.shape[0]
    m = pairs.shape[0]
    lo = 1.0 - QUIET_MARGIN
    hi = 1.0 + QUIET_MARGIN
    r2 = rstar * rstar
    rel2 = release * release
    empty = np.zeros(0, dtype=np.int64)
    none = np.zeros((0, 2), dtype=np.int64)
    gone = np.empty(m, dtype=np.int64)
    n_gone = 0
    keys = np.empty(m, dtype=np.int64)
    for p in range(m):
        k = pairs[p, 0]
        l = pairs[p, 1]
        keys[p] = k * n + l
        dx = position[k, 0] - position[l, 0]
        dy = position[k, 1] - position[l, 1]
        dz = position[k, 2] - position[l, 2]
        d2 = dx * dx + dy * dy + dz * dz
        if not (d2 < rel2 * lo or d2 > rel2 * hi) or (r2 * lo <= d2 <= r2 * hi):
            return False, empty, none, empty, empty, empty, empty
        if d2 > rel2:
            gone[n_gone] = p
            n_gone += 1
    new = np.empty((NEWS_CAPACITY, 2), dtype=np.int64)
    n_new = 0
    for k in range(n):
        for j in range(start[k], start[k + 1]):
            l = index[j]
            if l > k and closer(position, k, l, r2):
                key = k * n + np.int64(l)  # int64 with JIT off too (l may be an int32 entry)
                at = np.searchsorted(keys, key)
                if at < m and keys[at] == key:
                    continue
                if n_new == NEWS_CAPACITY:
                    return False, empty, none, empty, empty, empty, empty
                new[n_new, 0] = k
                new[n_new, 1] = l
                n_new += 1
    if not z_cathode == z_cathode:
        return True, gone[:n_gone].copy(), new[:n_new].copy(), empty, empty, empty, empty
    flags = np.zeros(n, dtype=np.int8)  # bit 0 leaves the cathode, 1 touches it, 2 leaves the anode, 3 touches it
    for k in range(n):
        hc = position[k, 2] - z_cathode
        ha = z_anode - position[k, 2]
        if on_cathode[k]:
            if hc > release:
                flags[k] |= 1
        elif hc < rstar:
            flags[k] |= 2
        if on_anode[k]:
            if ha > release:
                flags[k] |= 4
        elif ha < rstar:
            flags[k] |= 8
    return (
        True,
        gone[:n_gone].copy(),
        new[:n_new].copy(),
        np.flatnonzero(flags & 1),
        np.flatnonzero(flags & 2),
        np.flatnonzero(flags & 4),
        np.flatnonzero(flags & 8),
    )
