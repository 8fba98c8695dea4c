"""The circuit log: the current through the gap at each short circuit, recorded when it happens.

Frames are written every output interval and miss a short circuit that closes and opens between
two of them; the event log (:mod:`.events`) holds every SHORT_CIRCUIT and OPEN_CIRCUIT but not the
current. The circuit log holds one row per such event, made in the step of the event from the
circuit solve of that step (docs/model.md 'Contacts and events'):

==================  ===============================================================
field               meaning
==================  ===============================================================
step, time          of the event
kind                ``SHORT_CIRCUIT`` or ``OPEN_CIRCUIT`` (:mod:`.events`)
total_current       the solve's total current (units J0); 0 at an OPEN_CIRCUIT and
                    without a ``[circuit]`` table
rods_in_series      rods that carry the whole current, ``| |J_i| - J | <= 1e-9 J``
                    (every current-carrying path passes through them); 0 when J = 0
filament_rods       rods in current-carrying filaments (the SHORT_CIRCUIT's ``a``);
                    0 at an OPEN_CIRCUIT
==================  ===============================================================

Re-solves while the gap stays closed (contacts inside the filament, case (ii) heights) add no row.
"""

import numpy as np

from .events import OPEN_CIRCUIT, SHORT_CIRCUIT

#: numpy dtype of one circuit-log row, as the simulation keeps it and its checkpoints store it
CIRCUIT_LOG_DTYPE = np.dtype(
    [
        ("step", "<i8"),
        ("time", "<f8"),
        ("kind", "<i4"),
        ("total_current", "<f8"),
        ("rods_in_series", "<i8"),
        ("filament_rods", "<i8"),
    ]
)

#: relative tolerance of "carries the whole current": the solve's round-off is about 1e-14 relative
#: (its Kirchhoff residual), a rod on one of two parallel branches carries at most 1 - 1/n_rods of it
SERIES_TOLERANCE = 1e-9


def rods_in_series(current, total_current) -> int:
    """Rods whose current is the whole current through the gap.

    Parameters
    ----------
    current : (n_rods,) float64
        Rod currents J_i (units J0; sign = direction).
    total_current : float
        The solve's total current J >= 0.

    Returns
    -------
    int
        The number of rods with ``| |J_i| - J | <= SERIES_TOLERANCE * J``; 0 when ``J`` is 0.
    """
    total = float(total_current)
    if not total > 0.0:
        return 0
    return int(
        np.count_nonzero(np.abs(np.abs(np.asarray(current, dtype=np.float64)) - total) <= SERIES_TOLERANCE * total)
    )


def circuit_rows(events, total_current, current) -> list:
    """The circuit-log rows of one step's events.

    Parameters
    ----------
    events : list of (step, time, kind, a, b)
        The step's event rows (the SHORT_CIRCUIT / OPEN_CIRCUIT row, if any, is among them).
    total_current : float
        The total current of the step's solve (0 without a solve).
    current : (n_rods,) float64
        The rod currents after the step's solve.

    Returns
    -------
    list of (step, time, kind, total_current, rods_in_series, filament_rods)
    """
    rows = []
    for step, time, kind, a, _ in events:
        if kind == SHORT_CIRCUIT:
            j = float(total_current)
            rows.append((int(step), float(time), int(kind), j, rods_in_series(current, j), int(a)))
        elif kind == OPEN_CIRCUIT:
            rows.append((int(step), float(time), int(kind), 0.0, 0, 0))
    return rows


def circuit_log_array(rows) -> np.ndarray:
    """Pack circuit-log rows (tuples) into a ``CIRCUIT_LOG_DTYPE`` array."""
    return np.array([tuple(r) for r in rows], dtype=CIRCUIT_LOG_DTYPE)
