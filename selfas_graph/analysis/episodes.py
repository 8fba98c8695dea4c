"""Short-circuit episodes: when the gap closed, how long it stayed closed, and what opened it.

A run's event records (``events.EVENT_DTYPE``: step, time, kind, a, b) hold one SHORT_CIRCUIT
when the network starts to carry a current between the electrodes and one OPEN_CIRCUIT when the
last current-carrying path breaks (docs/model.md 'Contacts and events'). An *episode* is the time
from one to the next. The event that opened it is a release in the same step as the
OPEN_CIRCUIT: a tip-tip contact inside the filament (TIP_RELEASE) or a tip leaving an electrode
or the case (ii) filament (CONDUCTOR_RELEASE). This tells a filament that breaks apart from one
that lets go of an electrode (docs/results.md, section "Fig. 6").

Given the run's circuit log (``model.circuitlog``: the solve's total current and the rods in series
at each SHORT_CIRCUIT, recorded in the step of the event), each episode also gets the current
through the gap when it closed and the number of rods that carried all of it.

Arrays in, arrays out: :func:`circuit_episodes` sees the event array (and the circuit log) and
never opens a file.
"""

import dataclasses

import numpy as np

from ..model.events import CONDUCTOR_RELEASE, OPEN_CIRCUIT, SHORT_CIRCUIT, TIP_RELEASE

#: ``opened_by`` codes besides the release kinds: several releases in the opening step
#: (tip-tip and conductor), none found in that step, and an episode still closed at the end
OPENED_BY_BOTH = -2
OPENED_BY_UNKNOWN = 0
STILL_CLOSED = -1


@dataclasses.dataclass(frozen=True)
class CircuitEpisodes:
    """The short-circuit episodes of one run, in time order.

    Attributes
    ----------
    start, end : (n,) float64
        Times of the SHORT_CIRCUIT and of the OPEN_CIRCUIT that ended it (t0); ``end`` is NaN
        for an episode still closed when the events end.
    filament_rods : (n,) int64
        Rods in current-carrying filaments when the gap closed (the SHORT_CIRCUIT's ``a``).
    opened_by : (n,) int64
        ``TIP_RELEASE`` (2) or ``CONDUCTOR_RELEASE`` (4) when the releases in the opening step
        were all of that kind, ``OPENED_BY_BOTH`` (-2) when both kinds were there,
        ``OPENED_BY_UNKNOWN`` (0) when the step holds no release, ``STILL_CLOSED`` (-1) for an
        episode that has not ended.
    total_current : (n,) float64 or None
        The total current through the gap when it closed (units J0), from the circuit log; NaN for
        an episode the log holds no row of (it closed before a resume from a checkpoint older than
        the log); None when no log was given.
    rods_in_series : (n,) int64 or None
        Rods carrying the whole current when the gap closed, from the circuit log; -1 where the log
        holds no row; None when no log was given.
    """

    start: np.ndarray
    end: np.ndarray
    filament_rods: np.ndarray
    opened_by: np.ndarray
    total_current: np.ndarray | None = None
    rods_in_series: np.ndarray | None = None

    @property
    def duration(self) -> np.ndarray:
        """``end - start`` (NaN for an episode still closed)."""
        return self.end - self.start

    def __len__(self) -> int:
        return self.start.shape[0]


def circuit_episodes(events, circuit_log=None) -> CircuitEpisodes:
    """Split a run's events into short-circuit episodes.

    Parameters
    ----------
    events : structured array with fields ``step``, ``time``, ``kind``, ``a``
        The run's event records in order (``RunFile.events()``).
    circuit_log : structured array with fields ``step``, ``kind``, ``total_current``, ``rods_in_series``, optional
        The run's circuit log (``RunFile.circuit_log()``); each episode takes the row of the
        SHORT_CIRCUIT that opened it (same step).

    Returns
    -------
    CircuitEpisodes

    Raises
    ------
    ValueError
        If a field is missing, or an OPEN_CIRCUIT comes without a SHORT_CIRCUIT before it, or
        two SHORT_CIRCUITs follow each other without an OPEN_CIRCUIT between them (the network
        emits them alternately).
    """
    names = getattr(getattr(events, "dtype", None), "names", None) or ()
    missing = [f for f in ("step", "time", "kind", "a") if f not in names]
    if missing:
        raise ValueError(f"events must be a structured array with fields step, time, kind, a; missing {missing}")
    step = np.asarray(events["step"], dtype=np.int64)
    time = np.asarray(events["time"], dtype=np.float64)
    kind = np.asarray(events["kind"], dtype=np.int64)
    a = np.asarray(events["a"], dtype=np.int64)
    start, start_step, end, rods, opened = [], [], [], [], []
    for i in np.flatnonzero((kind == SHORT_CIRCUIT) | (kind == OPEN_CIRCUIT)):
        if kind[i] == SHORT_CIRCUIT:
            if len(start) > len(end):
                raise ValueError(f"two SHORT_CIRCUIT events without an OPEN_CIRCUIT between them (step {step[i]})")
            start.append(time[i])
            start_step.append(step[i])
            rods.append(a[i])
            continue
        if len(start) == len(end):
            raise ValueError(f"an OPEN_CIRCUIT without a SHORT_CIRCUIT before it (step {step[i]})")
        end.append(time[i])
        released = set(kind[(step == step[i]) & ((kind == TIP_RELEASE) | (kind == CONDUCTOR_RELEASE))].tolist())
        opened.append(released.pop() if len(released) == 1 else (OPENED_BY_BOTH if released else OPENED_BY_UNKNOWN))
    if len(start) > len(end):
        end.append(np.nan)
        opened.append(STILL_CLOSED)
    total_current = rods_in_series = None
    if circuit_log is not None:
        total_current, rods_in_series = _at_closing(circuit_log, np.array(start_step, dtype=np.int64))
    return CircuitEpisodes(
        start=np.array(start, dtype=np.float64),
        end=np.array(end, dtype=np.float64),
        filament_rods=np.array(rods, dtype=np.int64),
        opened_by=np.array(opened, dtype=np.int64),
        total_current=total_current,
        rods_in_series=rods_in_series,
    )


def _at_closing(circuit_log, steps):
    """The total current and rods in series of the circuit log's SHORT_CIRCUIT rows at ``steps``
    ((n,) int64), NaN and -1 where the log holds no such row."""
    names = getattr(getattr(circuit_log, "dtype", None), "names", None) or ()
    missing = [f for f in ("step", "kind", "total_current", "rods_in_series") if f not in names]
    if missing:
        raise ValueError(
            "circuit_log must be a structured array with fields step, kind, total_current, rods_in_series; "
            f"missing {missing}"
        )
    closing = np.asarray(circuit_log["kind"]) == SHORT_CIRCUIT
    log_step = np.asarray(circuit_log["step"], dtype=np.int64)[closing]
    log_current = np.asarray(circuit_log["total_current"], dtype=np.float64)[closing]
    log_series = np.asarray(circuit_log["rods_in_series"], dtype=np.int64)[closing]
    current = np.full(steps.shape, np.nan)
    series = np.full(steps.shape, -1, dtype=np.int64)
    for i, s in enumerate(steps):
        hit = np.flatnonzero(log_step == s)
        if hit.size:
            current[i] = log_current[hit[0]]
            series[i] = log_series[hit[0]]
    return current, series
