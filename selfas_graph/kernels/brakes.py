"""Brakes between tips closer than r* (docs/model.md 'Term 2'): the force over the tip neighbour
list (:func:`tip_brake`) and the exact brake of close pairs used by the split step.

Neighbour lists are in compressed-row form and hold both directions of every pair: the neighbours
of tip ``k`` are ``index[start[k]:start[k + 1]]``. The list may hold pairs beyond r* (a Verlet
skin); the kernels test the distance.
"""

import math

from ._jit import PARALLEL_ROWS, inline, njit, njit_parallel, prange
from .contacts import close_pairs, closer


@njit_parallel
def tip_brake(position, velocity, start, index, rstar, k_br, out):
    """Friction between tips of different rods closer than r* (docs/model.md 'Term 2', paper Eq. 12).

    ``F_k -= k_br (v_k - v_l)`` for every neighbour l with ``|x_k - x_l| < r*``.

    Parameters
    ----------
    position, velocity : (n_tips, 3) float64
    start : (n_tips + 1,) int64
    index : (n_pairs * 2,) int32 or int64 (``cells.list_dtype``)
        Tip neighbour list (tips of the same rod excluded by the caller).
    rstar, k_br : float
        Range of the brake and its coefficient (units m / t0).
    out : (n_tips, 3) float64
        Overwritten with the brake force on each tip.
    """
    n = position.shape[0]
    for k in prange(n):
        _tip_brake_row(position, velocity, start, index, rstar, k_br, k, out)


@inline
def _tip_brake_row(position, velocity, start, index, rstar, k_br, k, out):
    """Row ``k`` of :func:`tip_brake`."""
    rs2 = rstar * rstar
    fx = 0.0
    fy = 0.0
    fz = 0.0
    for j in range(start[k], start[k + 1]):
        l = index[j]
        dx = position[k, 0] - position[l, 0]
        dy = position[k, 1] - position[l, 1]
        dz = position[k, 2] - position[l, 2]
        if dx * dx + dy * dy + dz * dz < rs2:
            fx -= k_br * (velocity[k, 0] - velocity[l, 0])
            fy -= k_br * (velocity[k, 1] - velocity[l, 1])
            fz -= k_br * (velocity[k, 2] - velocity[l, 2])
    out[k, 0] = fx
    out[k, 1] = fy
    out[k, 2] = fz


@njit
def tip_brake_rows(position, velocity, start, index, rstar, k_br, lo, hi, out):
    """:func:`tip_brake` of the tips ``lo`` to ``hi`` only, serial."""
    for k in range(lo, hi):
        _tip_brake_row(position, velocity, start, index, rstar, k_br, k, out)


@njit
def _brake_pair(velocity, k, l, decay):
    """Brake one pair exactly (velocity in place: the mean kept, the difference times ``decay``);
    returns ``|v_k - v_l|^2`` before the brake, from which the callers take the work."""
    rel2 = 0.0
    for d in range(3):
        diff = velocity[k, d] - velocity[l, d]
        rel2 += diff * diff
        mean = 0.5 * (velocity[k, d] + velocity[l, d])
        half = 0.5 * diff * decay
        velocity[k, d] = mean + half
        velocity[l, d] = mean - half
    return rel2


@njit
def brake_pairs_exact(velocity, pairs, k_br, dt):
    """Exact brake of each listed tip pair over ``dt``, pair after pair (a Shardlow-type splitting).

    For one pair of unit masses, ``dv_k/dt = -k_br (v_k - v_l)`` and the opposite for l keep
    the mean velocity and damp the difference as ``exp(-2 k_br t)``; applying this exact
    solution to each pair in turn is stable for any dt, keeps momentum, and never adds
    energy. Pairs are processed in the given (sorted) order, so the result is deterministic.

    Parameters
    ----------
    velocity : (n_tips, 3) float64, modified in place
    pairs : (m, 2) int64
    k_br, dt : float

    Returns
    -------
    float
        The work done: the change of kinetic energy (unit masses), summed pair by pair,
        ``-(1 - decay^2) |v_k - v_l|^2 / 4`` for each pair as met.
    """
    decay = math.exp(-2.0 * k_br * dt)
    work = 0.0
    for j in range(pairs.shape[0]):
        k = pairs[j, 0]
        l = pairs[j, 1]
        work -= 0.25 * (1.0 - decay * decay) * _brake_pair(velocity, k, l, decay)
    return work


@njit
def brake_close_pairs_exact(position, velocity, start, index, radius, k_br, dt):
    """:func:`close_pairs` and :func:`brake_pairs_exact` in one serial pass, without the pair array.

    The listed pairs ``k < l`` closer than ``radius`` are braked exactly over ``dt`` in the order
    :func:`close_pairs` lists them (row k by row k, each row in list order), with the same
    arithmetic: the velocities and the work are those of the two calls, bit for bit. The search
    reads only positions, the brake writes only velocities, so they may share the pass.

    Parameters
    ----------
    position : (n_tips, 3) float64
    velocity : (n_tips, 3) float64, modified in place
    start, index : the compressed-row neighbour list, int64 offsets and int32 or int64 entries (``cells.list_dtype``)
    radius, k_br, dt : float

    Returns
    -------
    (float, int)
        The work done (as :func:`brake_pairs_exact`) and the number of pairs braked.
    """
    decay = math.exp(-2.0 * k_br * dt)
    r2max = radius * radius
    work = 0.0
    m = 0
    for k in range(position.shape[0]):
        for j in range(start[k], start[k + 1]):
            l = index[j]
            if l > k and closer(position, k, l, r2max):
                m += 1
                work -= 0.25 * (1.0 - decay * decay) * _brake_pair(velocity, k, l, decay)
    return work, m


@njit
def close_pairs_rows(position, start, index, radius, lo, hi, pair_k, pair_l, offset):
    """The listed pairs ``k < l`` closer than ``radius`` with ``k`` from ``lo`` to ``hi``, in the order
    :func:`brake_close_pairs_exact` meets them, written from ``offset`` on into ``pair_k``, ``pair_l``;
    returns how many. (``offset = start[lo]`` leaves room for all: a row's pairs are at most its entries.)"""
    r2max = radius * radius
    m = offset
    # the tips' own rows through slices from lo (loops from 0: `kernels/tips.py::tip_tip_fast_rows`)
    own, s = position[lo:hi], start[lo : hi + 1]
    for i in range(hi - lo):
        k = lo + i
        for j in range(s[i], s[i + 1]):
            l = index[j]
            if l > k:
                dx = own[i, 0] - position[l, 0]
                dy = own[i, 1] - position[l, 1]
                dz = own[i, 2] - position[l, 2]
                if dx * dx + dy * dy + dz * dz < r2max:  # contacts.py::closer
                    pair_k[m] = k
                    pair_l[m] = l
                    m += 1
    return m - offset


@inline
def brake_found_pairs(velocity, pair_k, pair_l, offset, count, k_br, dt, work):
    """The exact brake of the pairs :func:`close_pairs_rows` found (``count`` from ``offset`` on), added
    to ``work`` and returned, with the arithmetic of :func:`brake_close_pairs_exact`, pair after pair."""
    decay = math.exp(-2.0 * k_br * dt)
    for j in range(offset, offset + count):
        work -= 0.25 * (1.0 - decay * decay) * _brake_pair(velocity, pair_k[j], pair_l[j], decay)
    return work


def brake_close_pairs(position, velocity, start, index, radius, k_br, dt):
    """The exact brake of every listed pair closer than ``radius`` (velocity in place): (work, pairs braked).

    Bit for bit ``brake_pairs_exact(velocity, close_pairs(position, start, index, radius), k_br, dt)``:
    one serial pass (:func:`brake_close_pairs_exact`) below :data:`~._jit.PARALLEL_ROWS` tips, where
    the numpy glue of the two calls costs more than the pass; above it the pair search runs on all
    threads first.
    """
    if position.shape[0] < PARALLEL_ROWS:
        return brake_close_pairs_exact(position, velocity, start, index, radius, k_br, dt)
    pairs = close_pairs(position, start, index, radius)
    if not len(pairs):
        return 0.0, 0
    return brake_pairs_exact(velocity, pairs, k_br, dt), len(pairs)
