"""The lifecycle of one run into its run file, shared by ``selfas-graph simulate`` and the ensemble's seeds.

A run is: a run file, new (:func:`new_run_file`: provenance and the file) or reopened
(``RunWriter.reopen``, once :func:`continuation` has found the file and its checkpoint fit to
continue); a checkpointer; the run loop under :class:`StopOnSignal`
(SIGTERM and SIGINT stop it after the current step with a checkpoint); and one of four ends
(:func:`run_to_file`, which returns an :class:`Outcome`):

- ``finished``: the wall time and steps recorded, the file closed "finished";
- ``interrupted`` (a signal): the file closed "interrupted at step N"; the checkpoint continues it;
- ``failed`` (a numerical failure): the events and per-step rows up to the failure written, the
  file closed "failed: <reason>", the last good state and the failed one saved to
  ``RUN.failure.h5`` (:func:`failure_path`);
- ``io_error`` (a write failed: full disk, quota, a vanished folder, or HDF5 failed on the file's
  damaged metadata): the caller ends the file
  with :func:`close_after_io_error` and its own message.

A ``KeyboardInterrupt`` closes the file "interrupted" and is raised again. What each caller says
about an end (messages, exit codes, result dicts) stays with the caller: ``cli/simulate.py``
and ``ensemble.run_seed``.
"""

from __future__ import annotations

import dataclasses
import json
import signal
from pathlib import Path

import numpy as np

from ._version import __version__
from .io import layout
from .io.checkpoint import CheckpointError, failure_meta, read_checkpoint, write_failure
from .io.h5md import (
    HDF5_READ_ERRORS,
    DiskFullError,
    RunFile,
    RunFileError,
    RunWriter,
    appendable_problems,
    hdf5_damage,
    is_io_error,
    raised_in_hdf5,
    run_provenance,
)
from .io.scenario import ScenarioError, scenario_from_text
from .model.parameter_match import described_differences
from .model.simulation import NumericalFailure, RunInterrupted
from .parallel import parent_gone
from .provenance import version_key

__all__ = [
    "ABANDONED",
    "Continuation",
    "ContinuationError",
    "Outcome",
    "StopOnSignal",
    "close_after_io_error",
    "continuation",
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
        self.signum = signum
        if self.interrupt:  # the pool hands the signal on to its workers
            for sig in self.old:
                signal.signal(sig, signal.SIG_IGN)
            raise KeyboardInterrupt

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
    writer = RunWriter.for_simulation(sim, path, overwrite=overwrite, provenance=provenance)
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
        # a failed write of the system, or any failed HDF5 operation on the run's files (damaged metadata)
        if not (is_io_error(exc) or raised_in_hdf5(exc)):
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
            if not (is_io_error(exc) or raised_in_hdf5(exc)):
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


class ContinuationError(Exception):
    """A run file and checkpoint that cannot be continued together; the message says why.

    ``reason`` is the why alone and ``advice`` what a user of ``simulate --resume`` does about it (or
    ""); the message is both. An ensemble's plan, which advises otherwise, quotes the reason.
    """

    def __init__(self, reason: str, advice: str = ""):
        super().__init__(f"{reason}; {advice}" if advice else reason)
        self.reason, self.advice = reason, advice


@dataclasses.dataclass(frozen=True)
class Continuation:
    """A run to continue from its checkpoint (:func:`continuation`).

    Attributes
    ----------
    scenario : Scenario
        The scenario the run started with (its text and ``--set`` overrides, as the checkpoint holds
        them), ending at the end time asked for.
    snapshot, meta : dict
        The checkpoint's state and metadata (:func:`~selfas_graph.io.checkpoint.read_checkpoint`).
    run_id : str
        The run's identity, the same in the run file and the checkpoint.
    notes : tuple of str
        What the user should know and nothing stops: another version continues the run, or the
        scenario file has changed since the run started.
    """

    scenario: object
    snapshot: dict
    meta: dict
    run_id: str
    notes: tuple = ()


def _scenario_refusal(meta, overrides, stored, t_end, exc) -> str:
    """Why the checkpoint's scenario does not validate: the end time asked for (when the scenario validates
    with the run's own), or the checkpoint's scenario itself."""
    if t_end is not None:
        try:
            scenario_from_text(meta["scenario_text"], overrides=overrides, t_end=stored)
        except (ScenarioError, ValueError, TypeError):
            pass
        else:
            return f"cannot resume to the end time {t_end!r} asked for (--t-end, run.t_end): {exc}"
    return f"cannot resume: the checkpoint's scenario no longer validates: {exc}"


def continuation(checkpoint, run_path, t_end=None, read=None) -> Continuation:
    """Check that the run file ``run_path`` continues from the checkpoint file ``checkpoint`` and
    return what a resume needs; nothing is written. The one rule of ``simulate --resume``, an
    ensemble's plan and its seeds.

    Refused (:class:`ContinuationError`): a checkpoint that cannot be read or whose scenario no longer
    validates; a run file that cannot be read (damaged metadata among these), cannot be appended to (a row
    of the frames or observables torn by a kill is dropped on reopening; other damage is not), ended in a
    numerical failure (the same steps would fail again),
    is another run's (run identity, scenario or rod count), has no frame at or before the
    checkpoint's step or states other parameters than the scenario continued (its ``parameters_json``,
    the end time, output file and checkpoint interval aside: :mod:`.model.parameter_match`). A run started when ``integrator.brake``'s default was ``explicit`` continues
    with it.

    Parameters
    ----------
    checkpoint, run_path : path
    t_end : float, optional
        The end time; None: the run's own (the checkpoint's ``t_end``, else the scenario's).
    read : (snapshot, meta), optional
        The checkpoint as already read, so that it is not read twice.
    """
    checkpoint, run_path = Path(checkpoint), Path(run_path)
    if read is None:
        try:
            read = read_checkpoint(checkpoint)
        except CheckpointError as exc:
            raise ContinuationError(f"cannot resume: {exc}") from None
    snap, meta = read
    stored, asked = (float(meta["t_end"]) if "t_end" in meta else None), t_end
    t_end = stored if t_end is None else t_end
    overrides = json.loads(meta["overrides"])
    try:
        scenario = scenario_from_text(meta["scenario_text"], overrides=overrides, t_end=t_end)
    except (ScenarioError, ValueError, TypeError) as exc:
        raise ContinuationError(_scenario_refusal(meta, overrides, stored, asked, exc)) from None
    facts = _run_file_facts(run_path)  # read-only, before anything in it is changed
    _refuse(facts, snap, meta, checkpoint, run_path)
    if facts.brake is not None and facts.brake != scenario.params.integrator.brake:
        # a scene without integrator.brake, started when the default was explicit: continue as it ran
        try:
            scenario = scenario_from_text(
                meta["scenario_text"], t_end=t_end, overrides=overrides + [f"integrator.brake={facts.brake}"]
            )
        except (ScenarioError, ValueError, TypeError) as exc:
            raise ContinuationError(_scenario_refusal(meta, overrides, stored, asked, exc)) from None
    _refuse_other_parameters(facts, scenario, run_path)
    return Continuation(scenario, snap, meta, str(facts.run_id), _notes(meta, facts.source, checkpoint))


@dataclasses.dataclass(frozen=True)
class _RunFacts:
    """What :func:`continuation` reads of a run file (read-only)."""

    n_tips: int
    scenario_text: str
    steps: np.ndarray  # the frames' steps
    brake: str | None  # integrator.brake the run started with (None: unreadable)
    run_id: str | None
    source: str  # the scenario file's path as the run recorded it ("" if none)
    problems: list  # why it cannot be appended to (none: it can)
    status: str
    parameters: dict | None  # parameters_json (None: unreadable)
    last_row: int | None  # the last step of the per-step rows (-1: none yet; None: a file without them)


def _run_file_facts(run_path) -> _RunFacts:
    try:
        with RunFile(run_path) as run_file:
            return _RunFacts(
                n_tips=run_file.n_tips,
                scenario_text=run_file.scenario_text,
                steps=run_file.step,
                brake=_started_brake(run_file),
                run_id=run_file.meta.get("run_id"),
                source=str(run_file.meta.get("scenario_path") or ""),
                problems=appendable_problems(run_file.f),
                status=run_file.status,
                parameters=_stored_parameters(run_file),
                last_row=_last_step_row(run_file.f),
            )
    except RunFileError as exc:
        raise ContinuationError(f"cannot resume into {run_path}: {exc}") from None
    except HDF5_READ_ERRORS as exc:
        why = hdf5_damage(exc)
        if why is None:
            raise
        raise ContinuationError(f"cannot resume into {run_path}: {why}") from None


def _last_step_row(f) -> int | None:
    """The step of the last per-step row of an open run file (:data:`~.io.layout.BOND_ERROR_PER_STEP`;
    a run writes one for every step and hands them on before each checkpoint): -1 before any, None for a
    file without them."""
    try:
        steps = f[layout.OBSERVABLES][layout.BOND_ERROR_PER_STEP]["step"]
        return int(steps[-1]) if steps.shape[0] else -1
    except (KeyError, OSError, ValueError):
        return None


def _refuse(facts, snap, meta, checkpoint, run_path) -> None:
    """Raise ContinuationError if the run file ``run_path`` (``facts``) cannot continue from the checkpoint
    (``snap``, ``meta``): the rules of :func:`continuation`, in the order they are told."""
    status = facts.status
    if status.startswith("failed: numerical failure"):  # not a full disk, which a resume with room overcomes
        raise ContinuationError(
            f"cannot resume: the run of {run_path} ended in a {status.removeprefix('failed: ')} (its "
            f"state is in {failure_path(run_path)}); a resume would take the same steps from the checkpoint and "
            f"fail again",
            "start the run again with other settings (e.g. a smaller integrator.dt) and --force",
        )
    if facts.problems:
        raise ContinuationError(f"cannot resume into {run_path}: it cannot be continued: {'; '.join(facts.problems)}")
    run_id = facts.run_id
    if not run_id or run_id != meta.get("run_id"):
        raise ContinuationError(
            f"cannot resume: the checkpoint {checkpoint} belongs to another run than the run file {run_path} "
            f"(run identity {meta.get('run_id') or 'none'} in the checkpoint, {run_id or 'none'} in the "
            f"run file)",
            "give the run file's own checkpoint",
        )
    if facts.n_tips != np.asarray(snap["position"]).shape[0] or facts.scenario_text != meta["scenario_text"]:
        raise ContinuationError(
            f"cannot resume: {run_path} is not the run of checkpoint {checkpoint} (different scenario or rod count)"
        )
    step, steps = int(snap["step"]), facts.steps
    if (len(steps) and steps[0] > step) or (not len(steps) and step != 0):
        raise ContinuationError(f"cannot resume: {run_path} has no frame at or before the checkpoint's step {step}")
    if step > 0 and facts.last_row is not None and facts.last_row < step:
        # a run hands its per-step rows to the file before each checkpoint: a file that ends before the
        # checkpoint's step is an older copy of the run file, or one cut back, and the steps between
        # would be missing from it for good
        ends = f"step {facts.last_row}" if facts.last_row >= 0 else "before its first step"
        raise ContinuationError(
            f"cannot resume: {run_path} ends at {ends}, its checkpoint {checkpoint} is at step {step}: the "
            f"steps in between are not in the run file, and a resume would leave that gap in it",
            "resume the run file its checkpoint was written with, or continue from a checkpoint the file reaches",
        )


def _refuse_other_parameters(facts, scenario, run_path) -> None:
    """ContinuationError when the run file states other parameters than ``scenario``, the one continued:
    checked before the file is reopened, which changes it (and on every MPI rank alike)."""
    if facts.parameters is None:
        return
    differs = described_differences(facts.parameters, scenario.params.to_dict(), "the run file", "its checkpoint")
    if differs:
        shown = "; ".join(differs[:4]) + (f" and {len(differs) - 4} more" if len(differs) > 4 else "")
        raise ContinuationError(
            f"cannot resume: {run_path} states other parameters than the run its checkpoint continues ({shown})",
            "resume a run file with its own checkpoint, or start a new run",
        )


def _notes(meta, source, checkpoint) -> tuple:
    """What the user should know of a continuation and nothing stops (:attr:`Continuation.notes`)."""
    notes = []
    made_by = str(meta.get("version") or "unknown")
    if version_key(made_by) != version_key(__version__):
        notes.append(
            f"{checkpoint} was written by version {made_by} and version {__version__} continues it: where the model "
            f"changed between them (CHANGELOG), the rest of the run follows {__version__}; the run file records the "
            f"continuation (resumed_with)"
        )
    if source and _changed_since(source, meta["scenario_text"]):
        notes.append(
            f"the scenario file {source} differs from the scenario this run started with; --resume continues "
            f"the run as it started (its files hold that scenario): start a new run to use the file as it is now"
        )
    return tuple(notes)


def _changed_since(path, text) -> bool:
    """True if the scenario file at ``path`` (as the run recorded it) now reads other than ``text``."""
    try:
        return Path(path).read_text(encoding="utf-8") != text
    except (OSError, UnicodeDecodeError):
        return False


def _stored_parameters(run_file) -> dict | None:
    """The resolved parameters a run file states (``parameters_json``; None if absent or unreadable)."""
    try:
        params = json.loads(run_file.meta["parameters_json"])
    except (ValueError, TypeError, KeyError):
        return None
    return params if isinstance(params, dict) else None


def _started_brake(run_file):
    """The integrator.brake a run was started with, from its resolved parameters (None if unreadable)."""
    try:
        brake = json.loads(run_file.meta["parameters_json"])["integrator"]["brake"]
    except (ValueError, TypeError, KeyError, IndexError):
        return None
    return brake if brake in ("explicit", "split") else None
