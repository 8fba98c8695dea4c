"""The lifecycle of one run into its run file, shared by ``selfas-graph simulate`` and the ensemble's seeds.

A run is: a run file, new (:func:`new_run_file`: provenance and the file) or reopened
(``RunWriter.reopen``); a checkpointer; the run loop under :class:`StopOnSignal`
(SIGTERM and SIGINT stop it after the current step with a checkpoint); and one of four ends
(:func:`run_to_file`, which returns an :class:`Outcome`):

- ``finished``: the wall time and steps recorded, the file closed "finished";
- ``interrupted`` (a signal): the file closed "interrupted at step N"; the checkpoint continues it;
- ``failed`` (a numerical failure): the events and per-step rows up to the failure written, the
  file closed "failed: <reason>", the last good state and the failed one saved to
  ``RUN.failure.h5`` (:func:`failure_path`);
- ``io_error`` (a write failed: full disk, quota, a vanished folder): the caller ends the file
  with :func:`close_after_io_error` and its own message.

A ``KeyboardInterrupt`` closes the file "interrupted" and is raised again. What each caller says
about an end (messages, exit codes, result dicts) stays with the caller: ``cli/simulate.py``
and ``ensemble.run_seed``.
"""

from __future__ import annotations

import dataclasses
import signal
from pathlib import Path

from .io.checkpoint import failure_meta, write_failure
from .io.h5md import DiskFullError, RunWriter, is_io_error, run_provenance
from .model.simulation import NumericalFailure, RunInterrupted
from .parallel import parent_gone

__all__ = [
    "ABANDONED",
    "Outcome",
    "StopOnSignal",
    "close_after_io_error",
    "failure_path",
    "new_run_file",
    "run_to_file",
]

#: run files whose HDF5 handle failed in this process: kept referenced until the process ends
#: (HDF5 reports every failed handle it frees)
ABANDONED = []


class StopOnSignal:
    """SIGTERM and SIGINT caught for the duration of a ``with`` block.

    As the ``stop`` hook of :meth:`Simulation.run` it is true once a signal arrived, or once the
    launching process of a pool worker died (``parallel.parent_gone``); the run then stops after
    the current step with a checkpoint. ``signum`` is the signal received.

    Parameters
    ----------
    comm : parallel world, optional
        Under MPI the ranks agree on stopping (a collective call, made every ``every`` calls so that
        it costs nothing next to a step): all stop after the same step, with the signal number
        that rank 0 or any other rank received.
    signals : tuple of signal numbers
    interrupt : bool
        Raise ``KeyboardInterrupt`` on a signal instead (in a pool's launching process: SIGTERM
        then winds the pool down as Ctrl-C does); the signals are then ignored to the end of the block,
        so that a repeat (a launcher signals the process and its group) cannot cut the wind-down.

    Outside the main thread no handler can be set: the launcher's own handling applies.
    """

    def __init__(self, comm=None, every=10, signals=(signal.SIGTERM, signal.SIGINT), interrupt=False):
        self.signum, self.old = None, {}
        self.comm, self.every, self.calls = comm, every, 0
        self.signals, self.interrupt = tuple(signals), interrupt

    def __call__(self):
        if self.comm is None or self.comm.size == 1:
            return self.signum is not None or parent_gone()
        self.calls += 1
        if self.calls % self.every:
            return False
        self.signum = max(self.comm.allgather(self.signum or 0)) or None
        return self.signum is not None

    def __enter__(self):
        for sig in self.signals:
            try:
                self.old[sig] = signal.signal(sig, self._handle)
            except ValueError:  # not the main thread
                pass
        return self

    def _handle(self, signum, frame):
        if self.interrupt:
            for sig in self.old:
                signal.signal(sig, signal.SIG_IGN)
            raise KeyboardInterrupt
        self.signum = signum

    def __exit__(self, *exc):
        for sig, handler in self.old.items():
            signal.signal(sig, handler)
        self.old = {}


def new_run_file(sim, scenario, path, run_id, command_line, scenario_path, overwrite, mpi_ranks=1) -> RunWriter:
    """A new run file for ``sim``: its provenance (:func:`~selfas_graph.io.h5md.run_provenance`),
    the tips' and rods' constants, velocities if the scenario saves them. An earlier run's failed state
    beside it (``RUN.failure.h5``) goes with the run this one replaces: beside it, it would be taken for
    this run's (``simulate`` asks for --force first)."""
    provenance = run_provenance(sim, scenario, command_line, run_id, scenario_path=scenario_path, mpi_ranks=mpi_ranks)
    writer = RunWriter(
        path,
        sim.state.n_tips,
        sim.state.tip_charge,
        sim.state.rod_charge,
        provenance,
        overwrite=overwrite,
        velocities=sim.params.output.velocities,
        frame_interval=sim.frame_interval,
        rod_length=sim.state.rod_length,
        rod_resistance=sim.state.rod_resistance,
    )
    stale = failure_path(path)  # once the new file is made: a refused one leaves the old run whole
    if stale.is_file() and not stale.is_symlink():
        stale.unlink()
    return writer


def failure_path(path) -> Path:
    """Where a numerical failure's states go: ``RUN.h5`` -> ``RUN.failure.h5``."""
    path = Path(path)
    return path.with_name(path.stem + ".failure.h5")


@dataclasses.dataclass
class Outcome:
    """How a run ended: ``status`` "finished", "interrupted", "failed" or "io_error".

    ``summary`` is the run's :class:`RunSummary` when finished; ``error`` the ``RunInterrupted``,
    ``NumericalFailure`` or I/O error that ended it; ``failure`` the failure file (when failed);
    ``failure_not_saved`` the error that kept the failed state from being saved, if one did.
    """

    status: str
    summary: object = None
    error: BaseException | None = None
    failure: Path | None = None
    failure_not_saved: Exception | None = None


def run_to_file(sim, writer, checkpointer, stop, path, progress=None, keeps_files=True) -> Outcome:
    """Run ``sim`` to its end time into ``writer`` and close the file as the run ended.

    Parameters
    ----------
    sim : Simulation
    writer : RunWriter, or NullWriter on the MPI ranks other than 0 (or None)
    checkpointer : Checkpointer or None
    stop : callable, the stop hook (:class:`StopOnSignal`), entered by the caller
    path : path-like, the run file (the failure file goes beside it)
    progress : the progress display (closed at every end), optional
    keeps_files : bool
        False on the MPI ranks other than 0: a numerical failure writes nothing there.

    Errors other than I/O errors propagate, the file and the display left as they were;
    ``KeyboardInterrupt`` closes both (the file "interrupted") and is raised again.
    """
    try:
        if checkpointer is not None and checkpointer.due():
            # the first checkpoint (due at once) before the first step (and the compilation of its kernels, a minute
            # on a cold cache): a run whose file exists can always be resumed
            checkpointer.write(sim)
        # the stop hook and the checkpointer are asked at the slow steps: the fast steps between run in one call
        summary = sim.run(
            writer=writer,
            progress=progress,
            checkpointer=checkpointer,
            stop=stop,
            check_every=sim.params.integrator.slow_every,
        )
    except RunInterrupted as exc:
        if progress:
            progress.close()
        if writer:
            writer.close(status=f"interrupted at step {exc.step}")
        return Outcome("interrupted", error=exc)
    except NumericalFailure as exc:
        if progress:
            progress.close()
        out = Outcome("failed", error=exc, failure=failure_path(path))
        if keeps_files and writer:
            sim.flush_output(writer)  # the events and per-step rows up to the failure
            writer.close(status=f"failed: {exc}")
            # the failed state goes to its own file for inspection, never into the run file: beside the
            # last state that passed the checks, its non-finite entries coded apart (no NaN is stored)
            try:
                write_failure(out.failure, sim.last_good_snapshot, sim.snapshot(), failure_meta(checkpointer, sim, exc))
            except (OSError, RuntimeError) as io:
                out.failure_not_saved = io
        return out
    except KeyboardInterrupt:
        if progress:
            progress.close()
        if writer:
            writer.close(status="interrupted")
        raise
    except (OSError, RuntimeError) as exc:
        if not is_io_error(exc):
            raise
        if progress:
            progress.close()
        return Outcome("io_error", error=exc)
    if progress:
        progress.close()
    if writer:
        try:
            writer.set_attrs(wall_seconds=summary.wall_seconds, steps_done=summary.steps)
            writer.close(status="finished")
        except (OSError, RuntimeError) as exc:
            if not is_io_error(exc):
                raise
            return Outcome("io_error", summary=summary, error=exc)
    return Outcome("finished", summary=summary)


def close_after_io_error(writer, exc, status) -> bool:
    """End the run file of a run whose writing failed; True when it was closed cleanly (as ``status``).

    A :class:`DiskFullError` is raised before anything of the write happened, so the file is
    closed as usual. Any other failed write leaves HDF5's handle in a failed state, which is
    abandoned (kept in :data:`ABANDONED`): the file keeps what its last flush wrote, and a resume
    drops a torn row.
    """
    clean = isinstance(exc, DiskFullError)
    if clean and writer:
        try:
            writer.close(status=status)
        except (OSError, RuntimeError):
            clean = False
    if not clean:
        ABANDONED.append(writer)
    return clean
