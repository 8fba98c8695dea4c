"""What a writer of a run holds between frames (:class:`PendingRows`: the per-step rows, the events and
circuit-log rows written), and :class:`NullWriter`, the writer that keeps nothing (MPI ranks other than 0)."""

from __future__ import annotations

import numpy as np

__all__ = ["PendingRows", "NullWriter"]


class PendingRows:
    """What a writer holds between frames: the per-step rows a simulation hands over every step,
    and how many of the run's events and circuit-log rows are written. Shared by :class:`~.run_writer.RunWriter` and :class:`NullWriter`."""

    n_frames = 0
    #: why the last run written stopped early ("failed: ...", "interrupted (Ctrl-C)"), None if it did not:
    #: set by the run (``model/operations.py::FrameWriter.stopped``), the status a plain ``close()`` records
    stopped_by = None
    events_written = 0
    circuit_rows_written = 0
    _pending = (np.empty(0, dtype=np.int64), np.empty(0))
    _n_pending = 0

    def reserve_per_step(self, n: int) -> None:
        """Start a buffer of up to ``n`` per-step rows (at most one output interval, +1); rows
        not handed on by :meth:`flush_pending` are dropped."""
        self._pending = (np.empty(n, dtype=np.int64), np.empty(n))
        self._n_pending = 0

    def buffer_per_step(self, step: int, value: float) -> None:
        """Keep one per-step row (the step's bond error) until the next :meth:`flush_pending`."""
        steps, values = self._pending
        steps[self._n_pending] = step
        values[self._n_pending] = value
        self._n_pending += 1

    def flush_pending(self, events=None, circuit_log=None) -> None:
        """Write the buffered per-step rows and, given the run's whole event log ``events`` (and its
        ``circuit_log``), the rows of each not written yet (their datasets are created at the first call)."""
        if self._n_pending:
            steps, values = self._pending
            self.write_per_step(steps[: self._n_pending], values[: self._n_pending])
            self._n_pending = 0
        if events is not None:
            self.write_events(events[self.events_written :])
            self.events_written = len(events)
        if circuit_log is not None:
            self.write_circuit_log(circuit_log[self.circuit_rows_written :])
            self.circuit_rows_written = len(circuit_log)

    def run_to(self, t_end) -> None:
        """The end time of the run writing from now on (a :class:`~.run_writer.RunWriter` states it in the file)."""

    def state_dict(self) -> dict:
        """Frames, events and circuit-log rows written, and the per-step rows not written yet."""
        steps, values = self._pending
        return {
            "n_frames": int(self.n_frames),
            "events_written": int(self.events_written),
            "circuit_rows_written": int(self.circuit_rows_written),
            "pending_step": steps[: self._n_pending].copy(),
            "pending_value": values[: self._n_pending].copy(),
        }

    def load_state_dict(self, d: dict) -> None:
        """Restore :meth:`state_dict` (the per-step buffer keeps at least the rows given)."""
        self.n_frames = int(d["n_frames"])
        self.events_written = int(d["events_written"])
        self.circuit_rows_written = int(d.get("circuit_rows_written", 0))
        steps = np.asarray(d["pending_step"], dtype=np.int64)
        n = steps.shape[0]
        if self._pending[0].shape[0] < n:
            self.reserve_per_step(n)
        self._pending[0][:n] = steps
        self._pending[1][:n] = np.asarray(d["pending_value"], dtype=np.float64)
        self._n_pending = n


class NullWriter(PendingRows):
    """Takes every call a :class:`~.run_writer.RunWriter` takes and keeps nothing: the writer of MPI ranks other than 0.

    With it every rank makes the same calls in the run loop, in particular the frames'
    observables, whose energies are sums over all ranks. ``n_frames`` counts like the
    real writer's, starting from rank 0's count.
    """

    def __init__(self, n_frames=0):
        self.n_frames = int(n_frames)
        self.events_written = 0
        self.circuit_rows_written = 0

    def write_frame(self, step, t, position, velocity, observables):
        self.n_frames += 1

    def write_per_step(self, steps, values):
        pass

    def write_events(self, rows):
        pass

    def write_circuit_log(self, rows):
        pass

    def write_graph(self, step, t, arrays, role, current, potential, conductor_potential):
        pass

    def set_attrs(self, **attrs):
        pass

    def flush(self):
        pass

    def close(self, status=None):
        pass
