"""Ensembles: one scenario run over many seeds, one run file per seed, and statistics over the seeds.

One run of a chaotic system is an anecdote (README, "Ensembles"): a claim is the mean and
standard error over seeds. From Python::

    from selfas_graph.ensemble import Ensemble, format_table
    ens = Ensemble("scenarios/quick.toml", seeds=4, folder="quick_ensemble", t_end=1.0)
    ens.run(jobs=2)                       # seeds 1..4 -> quick_ensemble/seed_0001.h5 ...
    summary = ens.summarise(times=[0.5, 1.0])
    print(format_table(summary))

Seeds are ``first_seed, first_seed + 1, ...`` (``first_seed`` defaults to the scenario's
``scenario.seed``); seed ``s`` is written to ``FOLDER/seed_{s:04d}.h5`` exactly as
``selfas-graph simulate SCENARIO --set scenario.seed=s -o FOLDER/seed_{s:04d}.h5`` would
write it (the same run file, checkpoint and provenance), so one seed can be inspected,
plotted or resumed by hand.

Calling :meth:`Ensemble.run` again runs only what is missing: a seed whose file is
finished at (or beyond) the end time is kept; an interrupted one, or one finished at an
earlier end time, is continued from its checkpoint (``RUN.checkpoint.h5``, as
``simulate --resume``); a failed one is reported and kept. A seed file whose stored
parameters differ from the ensemble's (other than ``run.t_end``) is refused, never reused
or overwritten; ``force=True`` replaces the files that cannot be reused.

The runs go to :class:`selfas_graph.parallel.task_pool`: ``jobs`` spawned processes on
one machine (``cores // jobs`` numba threads each), or the ranks of an MPI launcher.
The same runner serves ``selfas-graph bench percolation`` (:func:`run_tasks`, :func:`run_to_short_circuit`).
"""

from __future__ import annotations

import concurrent.futures
import csv
import dataclasses
import functools
import io
import json
import math
import os
import shlex
import signal
import time
import types
import typing
import uuid
from pathlib import Path
from typing import Callable

import numpy as np

from ._version import __version__
from .analysis.claims import frame_claims
from .analysis.diagnostics import flux_through_disc, rod_centres, timeline
from .analysis.ensemble_stats import censored_times, grouped_summary, mean_sem, mean_sem_fits
from .io.checkpoint import (
    Checkpointer,
    CheckpointError,
    checkpoint_meta,
    checkpoint_path,
    read_checkpoint,
)
from .io.frame import SavedFrame
from .io.h5md import RunFile, RunFileError, RunWriter, is_io_error
from .io.scenario import ScenarioError, load_scenario, scenario_from_text
from .lifecycle import StopOnSignal, close_after_io_error, new_run_file, run_to_file
from .model.simulation import NumericalFailure, RunInterrupted, Simulation
from .model.state import PlacementError
from .model.topology import FILAMENT
from .parallel import is_pool_worker, task_pool

__all__ = [
    "Ensemble",
    "EnsembleError",
    "FolderLock",
    "FRAME_MEASURES",
    "Frame",
    "Measure",
    "SeedPlan",
    "carries_current",
    "format_table",
    "run_seed",
    "run_tasks",
    "run_to_short_circuit",
    "seed_path",
    "summarise",
    "write_summary",
]

#: file name of seed ``s`` in the ensemble's folder
SEED_FILE = "seed_{:04d}.h5"
#: parameters a seed file may differ in and still belong to the ensemble
FREE_PARAMETERS = ("run.t_end", "output.file", "output.checkpoint_interval")
#: summary files written into the ensemble's folder (rewritten from the run files on every call)
SUMMARY_JSON, SUMMARY_CSV = "summary.json", "summary.csv"


class EnsembleError(ValueError):
    """Bad input or a seed file that cannot be used (the CLI reports it with exit code 2)."""


def seed_path(folder, seed) -> Path:
    """The run file of ``seed`` in ``folder``: ``folder/seed_0001.h5`` for seed 1."""
    return Path(folder) / SEED_FILE.format(int(seed))


def _flat(d, prefix=""):
    out = {}
    for k, v in d.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict) and v:
            out.update(_flat(v, key + "."))
        else:
            out[key] = v
    return out


def parameter_differences(stored: dict, wanted: dict) -> list[str]:
    """Dotted keys whose values differ between two parameter dicts, except :data:`FREE_PARAMETERS`."""
    a, b = _flat(json.loads(json.dumps(stored))), _flat(json.loads(json.dumps(wanted)))
    return sorted(
        k
        for k in set(a) | set(b)
        if k not in FREE_PARAMETERS and a.get(k) != b.get(k) and not _newer_key_at_default(k, a, b)
    )


def _newer_key_at_default(key, stored_flat, wanted_flat) -> bool:
    """True for a key that a file of an earlier version lacks (the key came later) while the
    wanted value is that key's default: the run used what the default means. A key of a force
    term counts only where the stored file has that term on (an absent term is off)."""
    if key in stored_flat or key not in wanted_flat:
        return False
    if key.startswith("forces."):
        term = ".".join(key.split(".")[:2]) + "."
        if not any(k.startswith(term) for k in stored_flat):
            return False
    return _DEFAULTS_FLAT().get(key, _MISSING) == wanted_flat[key]


_MISSING = object()


@functools.lru_cache(maxsize=1)
def _DEFAULTS_FLAT():
    """Every key's default, dotted, including the keys of the optional tables (force terms,
    ``[circuit]`` ...) that are off by default: a key added to such a table later has a default
    too, and a file of an earlier version that has the table on used it."""
    from .model.params import Parameters

    flat = _flat(json.loads(json.dumps(Parameters().to_dict())))
    flat.update(_optional_table_defaults(Parameters, ""))
    return flat


def _optional_table_defaults(cls, prefix) -> dict:
    """Dotted defaults of the keys of every optional table below the dataclass ``cls``."""
    out = {}
    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):
        tp = hints[f.name]
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        inner = args[0] if typing.get_origin(tp) in (typing.Union, types.UnionType) and len(args) == 1 else tp
        if not dataclasses.is_dataclass(inner):
            continue
        key = f"{prefix}{f.name}"
        if inner is not tp:  # optional: off by default, its keys' defaults from the table's class
            try:
                table = inner()
            except TypeError:  # a table without defaults for every key has no default to offer
                continue
            for k, v in _flat(json.loads(json.dumps(dataclasses.asdict(table)))).items():
                out[f"{key}.{k}"] = v
        out.update(_optional_table_defaults(inner, key + "."))
    return out


@dataclasses.dataclass
class SeedPlan:
    """What :meth:`Ensemble.run` does with one seed.

    ``action`` is "run" (a new file), "resume" (continue from the checkpoint to the end
    time), "done" (finished at or beyond the end time: kept) or "failed" (the run failed
    numerically before: kept, reported; rerun with ``force``). ``note`` says why.
    """

    seed: int
    path: Path
    action: str
    note: str = ""


# ----------------------------------------------------------------------------- one seed
def run_seed(task: dict) -> dict:
    """Run (or continue) one seed of an ensemble to its end time; the pool's task function.

    ``task`` holds ``seed``, ``path`` (the run file), ``action`` ("run" or "resume"),
    ``t_end``, and for "run" also ``text``, ``scenario_path``, ``overrides`` (with the
    seed's) and ``force``; ``command`` is recorded as the run's provenance. Never raises
    for a failing run: returns a dict with ``status`` "finished", "interrupted",
    "failed" (numerical failure; the last good and the failed state go to ``SEED.failure.h5``), "io_error"
    (a write failed: full disk, quota; the file stays resumable, :func:`_stop_on_io_error`) or "error"
    (with ``message``), and ``t`` (simulated time reached), ``steps``, ``wall_seconds``, ``threads``.
    """
    import numba

    path, t_end = Path(task["path"]), float(task["t_end"])
    out = {
        "seed": int(task["seed"]),
        "path": str(path),
        "action": task["action"],
        "status": None,
        "t": None,
        "steps": 0,
        "wall_seconds": 0.0,
        "threads": numba.get_num_threads(),
        "message": None,
    }
    t0 = time.perf_counter()
    sim = writer = end = None
    ckpt = checkpoint_path(path)
    with StopOnSignal() as stop:
        try:
            if task["action"] == "resume":
                snap, meta = read_checkpoint(ckpt)
                with RunFile(path) as run:
                    run_id = run.meta.get("run_id")
                if not run_id or run_id != meta.get("run_id"):
                    raise EnsembleError(
                        f"the checkpoint {ckpt} belongs to another run than {path} (run identity "
                        f"{meta.get('run_id') or 'none'} against {run_id or 'none'})"
                    )
                meta = {**meta, "t_end": t_end}
                scenario = scenario_from_text(
                    meta["scenario_text"], overrides=json.loads(meta["overrides"]), t_end=t_end
                )
                sim = Simulation.from_snapshot(scenario.params, snap)
                writer = RunWriter.reopen(path, int(snap["step"]))
            else:
                scenario = scenario_from_text(
                    task["text"], path=Path(task["scenario_path"]), overrides=task["overrides"], t_end=t_end
                )
                sim = Simulation.from_scenario(scenario)
                run_id = uuid.uuid4().hex
                writer = new_run_file(
                    sim, scenario, path, run_id, task.get("command", ""), task["scenario_path"], bool(task.get("force"))
                )
                meta = checkpoint_meta(scenario, run_id, path.name, t_end, __version__)
            checkpointer = Checkpointer(
                ckpt, scenario.params.output.checkpoint_interval, {k: v for k, v in meta.items() if k != "step"}
            )
            end = run_to_file(sim, writer, checkpointer, stop, path)
            out["status"] = end.status
            if end.status == "interrupted":
                out["message"] = f"stopped at step {end.error.step}; checkpoint {ckpt}"
            elif end.status == "failed":
                out["message"] = f"{end.error} (failed state in {end.failure})"
            elif end.status == "io_error":
                out["message"] = _stop_on_io_error(end.error, writer, sim, path, task)
        except Exception as exc:  # noqa: BLE001 - one broken seed must not lose the others; reported
            # not a numerical failure: the file stays resumable from its last checkpoint
            if is_io_error(exc):
                out["status"], out["message"] = "io_error", _stop_on_io_error(exc, writer, sim, path, task)
            else:
                out["status"], out["message"] = "error", f"{type(exc).__name__}: {exc}"
                if writer is not None and getattr(writer, "f", None):
                    writer.close(status=f"error: {type(exc).__name__}: {exc}")
    if end is not None and end.failure_not_saved is not None:
        raise end.failure_not_saved  # the failed state could not be saved: the pool reports the seed's error
    if sim is not None:
        out["t"], out["steps"] = float(sim.state.time), int(sim.state.step)
    out["wall_seconds"] = time.perf_counter() - t0
    return out


def _stop_on_io_error(exc, writer, sim, path, task) -> str:
    """End a seed whose writing failed (full disk, quota, a vanished folder) so that a rerun continues it;
    returns the message.

    A :class:`~selfas_graph.io.h5md.DiskFullError` comes before anything of the write happened:
    the file is closed as "stopped", which the plan resumes from its checkpoint. Any other failed
    write leaves HDF5's handle failed: it is abandoned (the file keeps its last flush; a resume drops
    a torn row), and a pool worker then ends without freeing it (HDF5 may crash on it at exit). A
    file this task created that has no checkpoint yet holds nothing to continue: it is removed, and
    a rerun starts the seed again.
    """
    ckpt = checkpoint_path(path)
    reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else " ".join(str(exc).split())[:300]
    step = f"step {sim.state.step} (t = {sim.state.time:.6g})" if sim is not None else "its start"
    if writer is not None and getattr(writer, "f", None):
        if not close_after_io_error(writer, exc, f"stopped by an I/O error at {step}: {reason}") and is_pool_worker():
            _exit_quietly_at_shutdown()
    if task["action"] == "run" and not ckpt.exists():
        try:
            path.unlink()
        except OSError:
            pass
        return f"I/O error at {step} while writing: {reason}; nothing to continue from, the seed starts again"
    return f"I/O error at {step} while writing: {reason}; last good checkpoint {ckpt}"


def _exit_quietly_at_shutdown():
    import atexit
    import os as _os
    import sys

    def _exit():
        sys.stdout.flush()
        sys.stderr.flush()
        _os._exit(0)

    atexit.register(_exit)  # runs before the interpreter frees the abandoned HDF5 objects


def run_to_short_circuit(task: dict) -> dict:
    """Run one scenario without a file until its first short circuit or ``t_max``; the percolation task.

    ``task`` holds ``text``, ``path`` (the scenario's, for messages), ``overrides`` (with
    the seed's), ``seed``, ``t_max`` and ``chunk`` (simulated time per
    :meth:`Simulation.run` call: the granularity of the stop check; results do not depend
    on it); the task keys named in ``echo`` are copied into the result. Returns ``status`` "short_circuit" (``time``), "censored" (none by ``t_max``),
    "failed" (numerical failure at ``t_end``), "unplaceable" or "error" (``message``),
    with ``t_end``, ``steps``, ``events``, ``filament_rods``, ``wall_seconds``.
    """
    seed, t_max = task["seed"], float(task["t_max"])
    out = {
        **{k: task[k] for k in task.get("echo", ())},
        "seed": seed,
        "status": None,
        "time": None,
        "t_end": 0.0,
        "steps": 0,
        "events": 0,
        "filament_rods": 0,
        "wall_seconds": 0.0,
        "message": None,
    }
    t0 = time.perf_counter()
    sim = None
    try:
        scenario = scenario_from_text(task["text"], path=Path(task["path"]), overrides=task["overrides"], t_end=t_max)
        sim = Simulation.from_scenario(scenario)
        total = sim.steps_for(t_max)
        with StopOnSignal() as signalled:
            stop = lambda: sim.short_circuit_time is not None or signalled()  # noqa: E731
            while sim.short_circuit_time is None and sim.state.step < total and not signalled():
                # run() takes whole steps only: the chunk and the end rounded to steps
                n = min(sim.steps_for(task["chunk"]), total - sim.state.step)
                target = sim.state.time + n * sim.dt
                try:
                    summary = sim.run(t_end=target, stop=stop)
                except RunInterrupted:
                    break
                if summary.steps == 0:  # the chunk rounds to no step: the end is reached
                    break
        if sim.short_circuit_time is not None:
            out["status"], out["time"] = "short_circuit", float(sim.short_circuit_time)
        elif signalled():
            out["status"], out["message"] = "interrupted", f"signal {signalled.signum} at step {sim.state.step}"
        else:
            out["status"] = "censored"
    except PlacementError as exc:
        out["status"], out["message"] = "unplaceable", str(exc)
    except NumericalFailure as exc:
        out["status"], out["message"] = "failed", str(exc)
    except Exception as exc:  # noqa: BLE001 - a bug in one run must not lose the ensemble; reported
        out["status"], out["message"] = "error", f"{type(exc).__name__}: {exc}"
    if sim is not None:
        out["t_end"], out["steps"], out["events"] = float(sim.state.time), int(sim.state.step), len(sim.events)
        if sim.graph is not None:
            out["filament_rods"] = int(sim.graph.topology().n_filament)
    out["wall_seconds"] = time.perf_counter() - t0
    return out


# ----------------------------------------------------------------------------- the runner
def run_tasks(
    fn: Callable[[dict], dict], tasks: list, pool, report=None, stop_statuses=("interrupted", "io_error")
) -> list:
    """Run ``fn(task)`` for every task on ``pool`` (a :class:`~selfas_graph.parallel.task_pool`); results in task order.

    Tasks are handed out in order, one per idle worker (none waits in a queue), and
    ``report(result)`` is called as each ends. In a serial pool they run here, one after
    the other. Once a result's ``status`` is in ``stop_statuses`` (a seed stopped by a
    signal), or on Ctrl-C or SIGTERM here, no further task starts; the local workers get
    SIGTERM (a running seed then stops after its step with a checkpoint) and the running
    tasks' results are collected. Tasks never started are None in the returned list.
    """
    results = [None] * len(tasks)
    report = report or (lambda r: None)
    if pool.serial:
        for i, task in enumerate(tasks):
            results[i] = fn(task)
            report(results[i])
            if results[i].get("status") in stop_statuses:
                break
        return results
    waiting, running, stopping = list(range(len(tasks)))[::-1], {}, False

    def collect(futures):
        nonlocal stopping
        for fut in futures:
            i = running.pop(fut)
            results[i] = _result(fut)
            report(results[i])
            if results[i].get("status") == "io_error" and not stopping and not pool.mpi:
                _terminate_workers()  # the other running seeds stop with a checkpoint while there is room
            stopping |= results[i].get("status") in stop_statuses

    with StopOnSignal(signals=(signal.SIGTERM,), interrupt=True):  # Ctrl-C and SIGTERM wind the pool down alike
        try:
            while waiting or running:
                while waiting and not stopping and len(running) < pool.workers:
                    i = waiting.pop()
                    running[pool.submit(fn, tasks[i])] = i
                if not running:
                    break
                done, _ = concurrent.futures.wait(list(running), return_when=concurrent.futures.FIRST_COMPLETED)
                collect(done)
        except KeyboardInterrupt:
            stopping = True
            if not pool.mpi:
                _terminate_workers()
            collect(list(running))
    return results


def _terminate_workers():
    import multiprocessing

    for child in multiprocessing.active_children():
        child.terminate()  # SIGTERM: a running seed stops after its step with a checkpoint


def _result(fut):
    try:
        return fut.result()
    except Exception as exc:  # noqa: BLE001 - a worker process died (killed, out of memory): reported
        return {"status": "error", "message": f"{type(exc).__name__}: {exc}"}


# ----------------------------------------------------------------------------- the ensemble
class Ensemble:
    """One scenario over many seeds, each in its own run file in ``folder``.

    Parameters
    ----------
    scenario : path-like
        Scenario file (TOML).
    seeds : int or sequence of int
        A count ``N`` (seeds ``first_seed .. first_seed + N - 1``) or the seeds themselves.
    folder : path-like
        Where the run files and the summary go; created if missing.
    overrides : sequence of "key=value"
        Scenario overrides for every seed (``scenario.seed`` is the ensemble's to set).
    t_end : float, optional
        End time of every seed (default: the scenario's ``run.t_end``).
    first_seed : int, optional
        Default: the scenario's ``scenario.seed``.
    force : bool
        Replace the seed files that cannot be reused (other parameters, failed, or
        incomplete without a checkpoint); files that can be reused are still kept.

    Raises
    ------
    EnsembleError
        Bad scenario, overrides, seeds or folder.
    """

    def __init__(self, scenario, seeds, folder, overrides=(), t_end=None, first_seed=None, force=False):
        self.scenario_path = Path(scenario)
        self.overrides = list(overrides)
        self.folder = Path(folder)
        self.force = bool(force)
        bad = [o for o in self.overrides if o.split("=", 1)[0].strip() == "scenario.seed"]
        if bad:
            raise EnsembleError(
                f"--set {bad[0]}: the ensemble sets scenario.seed for each run; choose the seeds with --first-seed"
            )
        try:
            self.base = load_scenario(self.scenario_path, overrides=self.overrides, t_end=t_end)
        except ScenarioError as exc:
            raise EnsembleError(str(exc)) from None
        self.t_end = float(self.base.params.run.t_end)
        if isinstance(seeds, (int, np.integer)):
            if seeds < 1:
                raise EnsembleError(f"--seeds must be >= 1, got {seeds}")
            first = self.base.params.scenario.seed if first_seed is None else int(first_seed)
            seeds = range(first, first + int(seeds))
        self.seeds = [int(s) for s in seeds]
        if not self.seeds or min(self.seeds) < 0 or len(set(self.seeds)) != len(self.seeds):
            raise EnsembleError(f"seeds must be distinct integers >= 0, got {self.seeds}")
        for s in (self.seeds[0], self.seeds[-1]):  # the seeds differ only in scenario.seed
            try:
                self.scenario_for(s)
            except ScenarioError as exc:
                raise EnsembleError(f"seed {s}: {exc}") from None
        if self.folder.exists() and not self.folder.is_dir():
            raise EnsembleError(f"the output folder {self.folder} is a file")

    def scenario_for(self, seed):
        """The :class:`~selfas_graph.io.scenario.Scenario` of one seed."""
        return scenario_from_text(
            self.base.text, path=self.base.path, overrides=self._overrides(seed), t_end=self.t_end
        )

    def _overrides(self, seed):
        return [*self.overrides, f"scenario.seed={seed}"]

    def command_for(self, seed) -> str:
        """The ``selfas-graph simulate`` command that writes the same run file as this seed."""
        args = ["selfas-graph", "simulate", str(self.scenario_path)]
        for o in self._overrides(seed):
            args += ["--set", o]
        return shlex.join(args + ["--t-end", repr(self.t_end), "-o", str(seed_path(self.folder, seed))])

    # ------------------------------------------------------------------ planning
    def plan(self, summary_only=False) -> list[SeedPlan]:
        """What :meth:`run` would do with each seed, from the files in the folder (nothing is written).

        With ``summary_only`` (nothing will run) an incomplete seed file without a usable
        checkpoint (one still being written, say) is planned as "partial": summarised up to
        its last frame.

        Raises
        ------
        EnsembleError
            A seed file that belongs to other parameters, is not a run file, or is
            incomplete without a checkpoint (unless ``force`` or ``summary_only``), listing
            every such seed.
        """
        plans, problems = [], []
        for s in self.seeds:
            try:
                plans.append(self._plan_seed(s, summary_only))
            except EnsembleError as exc:
                problems.append(str(exc))
        if problems:
            hint = "; pass --force to replace them" if not self.force else ""
            raise EnsembleError("seed files that cannot be used:\n  " + "\n  ".join(problems) + hint)
        return plans

    def _plan_seed(self, seed, summary_only=False) -> SeedPlan:
        path = seed_path(self.folder, seed)
        ckpt = checkpoint_path(path)
        if not path.exists():
            if ckpt.exists() and not self.force:
                raise EnsembleError(f"{ckpt} exists without its run file {path.name}")
            return SeedPlan(seed, path, "run", "new")
        wanted = self.scenario_for(seed).params
        try:
            with RunFile(path) as run:
                stored, status = run.parameters, str(run.meta.get("status", ""))
                t_last = float(run.time[-1]) if run.n_frames else -math.inf
                scenario_text = run.scenario_text
        except RunFileError as exc:
            if self.force:
                return SeedPlan(seed, path, "run", f"replacing: {exc}")
            raise EnsembleError(str(exc)) from None
        diff = parameter_differences(stored, wanted.to_dict())
        if diff:
            if self.force:
                return SeedPlan(seed, path, "run", "replacing: other parameters")
            shown = ", ".join(f"{k} = {_get(stored, k)!r} (here {_get(wanted.to_dict(), k)!r})" for k in diff[:4])
            raise EnsembleError(
                f"{path} belongs to other parameters: {shown}" + (f" and {len(diff) - 4} more" if len(diff) > 4 else "")
            )
        half_step = 0.5 * wanted.integrator.dt
        if status == "finished" and t_last >= self.t_end - half_step:
            return SeedPlan(seed, path, "done", f"finished at t = {t_last:.6g}")
        if status.startswith("failed"):
            if self.force:
                return SeedPlan(seed, path, "run", "replacing a failed run")
            return SeedPlan(seed, path, "failed", status)
        try:
            snap, meta = read_checkpoint(ckpt)
            usable = meta.get("scenario_text") == scenario_text and float(snap["time"]) <= self.t_end + half_step
        except CheckpointError:
            usable = False
        if usable:
            return SeedPlan(
                seed, path, "resume", f"{status} at t = {t_last:.6g}; checkpoint at t = {float(snap['time']):.6g}"
            )
        if summary_only:
            return SeedPlan(seed, path, "partial", f"{status} at t = {t_last:.6g}")
        if self.force:
            return SeedPlan(seed, path, "run", f"replacing: {status} at t = {t_last:.6g}, no usable checkpoint")
        raise EnsembleError(
            f"{path} is {status} at t = {t_last:.6g} (end time {self.t_end:g}) and has no usable "
            f"checkpoint {ckpt.name} to continue from"
        )

    # ------------------------------------------------------------------ running
    def tasks(self, plans) -> list[dict]:
        """The :func:`run_seed` tasks of the plans that need a run."""
        return [
            {
                "seed": p.seed,
                "path": str(p.path),
                "action": p.action,
                "t_end": self.t_end,
                "text": self.base.text,
                "scenario_path": str(self.base.path),
                "overrides": self._overrides(p.seed),
                "force": self.force,
                "command": self.command_for(p.seed),
            }
            for p in plans
            if p.action in ("run", "resume")
        ]

    def run(self, jobs=1, report=None, pool=None) -> list[dict]:
        """Run every seed that is not done; returns :func:`run_seed`'s results (None: never started).

        ``pool`` is an entered :class:`~selfas_graph.parallel.task_pool`; by default one of
        ``jobs`` workers is made here. The folder is created and locked (:class:`FolderLock`:
        EnsembleError if another ensemble runs in it); nothing is run for seeds whose files are
        done or failed.
        """
        make_folder(self.folder)
        with FolderLock(self.folder):
            tasks = self.tasks(self.plan())
            if pool is None:
                with task_pool(jobs) as own:
                    return run_tasks(run_seed, tasks, own, report)
            return run_tasks(run_seed, tasks, pool, report)

    def summarise(self, times=None, measures=None, flux_radius=None) -> dict:
        """:func:`summarise` over the seed files present (default times: quarters of the end time)."""
        paths = [seed_path(self.folder, s) for s in self.seeds]
        times = default_times(self.t_end) if times is None else times
        out = summarise(
            [p for p in paths if p.exists()], times, t_end=self.t_end, measures=measures, flux_radius=flux_radius
        )
        out.update(
            scenario=str(self.scenario_path),
            overrides=self.overrides,
            folder=str(self.folder),
            seeds_requested=self.seeds,
            missing=[str(p) for p in paths if not p.exists()],
        )
        return out


#: lock file of a running ensemble in its folder
LOCK_FILE = ".ensemble.lock"


class FolderLock:
    """The exclusive lock of an ensemble's folder, held while an ensemble runs seeds in it (a context manager).

    An OS lock on ``FOLDER/.ensemble.lock`` (``flock``; ``msvcrt.locking`` on Windows): the
    kernel drops it when the process ends, however it ends, so a lock file left by a crash is
    stale and simply taken over. Its text names the holder (process id, host, start time) for the
    message of a second ensemble, which is refused at once. The file is removed on release.
    """

    def __init__(self, folder):
        self.folder = Path(folder)
        self.path = self.folder / LOCK_FILE
        self.fd = None

    def acquire(self) -> "FolderLock":
        """Take the lock; EnsembleError naming the folder and the holder if another process has it."""
        while True:
            try:
                fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
            except OSError as exc:
                raise EnsembleError(f"cannot lock the output folder {self.folder}: {exc.strerror or exc}") from None
            if not _try_lock(fd):
                holder = _read_holder(fd)
                os.close(fd)
                raise EnsembleError(
                    f"the output folder {self.folder} is in use by another ensemble ({holder}); wait for it to "
                    f"end (or stop it), or give another folder with -o"
                )
            try:  # the holder before may have removed the file after this opened it: lock the file there now
                same = os.path.samestat(os.fstat(fd), os.stat(self.path))
            except OSError:
                same = False
            if same:
                break
            os.close(fd)
        import socket

        text = f"pid {os.getpid()} on {socket.gethostname()}, since {time.strftime('%Y-%m-%d %H:%M:%S')}\n"
        os.ftruncate(fd, 0)
        os.lseek(fd, 0, os.SEEK_SET)
        os.write(fd, text.encode())
        self.fd = fd
        return self

    def release(self) -> None:
        if self.fd is None:
            return
        try:
            os.unlink(self.path)  # while still held: a waiting process then finds it gone and retries
        except OSError:
            pass
        os.close(self.fd)
        self.fd = None

    def __enter__(self):
        return self.acquire()

    def __exit__(self, *exc):
        self.release()
        return False


def _try_lock(fd) -> bool:
    try:
        import fcntl
    except ImportError:  # Windows
        import msvcrt

        try:
            msvcrt.locking(fd, msvcrt.LK_NBLCK, 1)
            return True
        except OSError:
            return False
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        return True
    except OSError:
        return False


def _read_holder(fd) -> str:
    try:
        os.lseek(fd, 0, os.SEEK_SET)
        text = os.read(fd, 200).decode("utf-8", "replace").strip()
    except OSError:
        text = ""
    return text or "a process that has not written its name yet"


def make_folder(folder) -> Path:
    """Create ``folder`` (and its parents) if missing; EnsembleError if that is impossible."""
    folder = Path(folder)
    if folder.is_symlink() and not folder.exists():
        raise EnsembleError(
            f"the output folder {folder} is a symbolic link to {os.readlink(folder)}, which does not exist; "
            f"create that folder or give another one"
        )
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise EnsembleError(f"cannot create the output folder {folder}: {exc.strerror or exc}") from None
    return folder


def _get(d, dotted):
    for k in dotted.split("."):
        if not isinstance(d, dict) or k not in d:
            return None
        d = d[k]
    return d


def default_times(t_end):
    """The times of the summary when none are given: a quarter, half, three quarters and all of ``t_end``."""
    return [t_end * k / 4 for k in (1, 2, 3, 4)]


# ----------------------------------------------------------------------------- per-frame measures


class Frame(SavedFrame):
    """One saved frame of a run file (:class:`~selfas_graph.io.frame.SavedFrame`), with what the
    measures need computed once (lazily).

    Adds to the saved frame: ``centres`` (rod centres), ``rho`` (their distance from the plasma
    axis, or the z axis), ``flux_radius``, ``claims`` (``frame_claims(run, index)``).
    """

    def __init__(self, run, index, params, flux_radius=None):
        super().__init__(run, index, params)
        self._flux_radius = flux_radius

    @functools.cached_property
    def centres(self):
        return rod_centres(self.position)

    @functools.cached_property
    def rho(self):
        ax = self.plasma["axis"] if self.plasma else (0.0, 0.0)
        return np.hypot(self.centres[:, 0] - ax[0], self.centres[:, 1] - ax[1])

    @property
    def flux_radius(self):
        """Disc radius of the mid-plane flux: given, or the half-diagonal of the placement box in x-y."""
        if self._flux_radius is not None:
            return float(self._flux_radius)
        (x0, x1), (y0, y1) = self.params["placement"]["box"][:2]
        return float(np.hypot(max(abs(x0), abs(x1)), max(abs(y0), abs(y1))))

    @functools.cached_property
    def claims(self):
        return frame_claims(self.run, self.index)


@dataclasses.dataclass(frozen=True)
class Measure:
    """A number per frame: ``fn(frame) -> float`` (NaN when it does not apply), with its unit and meaning.

    ``err(frame) -> float``, if given, is the value's own uncertainty (a fit's): the standard
    error over seeds then adds it (:func:`~selfas_graph.analysis.ensemble_stats.mean_sem_fits`).
    ``grouped``: the measure describes seeds whose circuit carries a current (:func:`carries_current`);
    its mean, standard error and count are those of that group alone, with its median and range
    (:func:`~selfas_graph.analysis.ensemble_stats.grouped_summary`).
    """

    name: str
    unit: str
    doc: str
    fn: Callable[[Frame], float]
    err: Callable[[Frame], float] | None = None
    grouped: bool = False


def carries_current(f) -> float:
    """1.0 if a current flows through the circuit at the frame (rods in current-carrying filaments,
    or a nonzero total current where the frame has no graph), 0.0 if not, NaN if unknown."""
    rods = _filament_rods(f)
    if math.isfinite(rods):
        return float(rods > 0)
    j = _total_current(f)
    return float(j != 0.0) if math.isfinite(j) else math.nan


def _filament_rods(f):
    return math.nan if f.graph is None else float(np.count_nonzero(f.graph["role"] == FILAMENT))


def _total_current(f):
    try:
        t, v = f.run.observable("total_current")
    except RunFileError:
        return math.nan
    k = int(np.argmin(np.abs(t - f.time)))
    return float(v[k])


def _inside_plasma(f):
    return float(np.mean(f.rho < f.plasma["radius"])) if f.plasma else math.nan


def _midplane_flux(f):
    if f.graph is None:
        return math.nan
    current = np.asarray(f.graph["current"], dtype=np.float64)
    if not np.any(current):
        return 0.0
    w = 0.5 * f.params["rods"]["diameter"]
    return float(flux_through_disc([f.flux_radius], 0.0, f.position, None, current, w)[0])


#: the per-frame measures of a summary, in table order; a new one is one more line
FRAME_MEASURES = [
    Measure("filament_rods", "rods", "rods in current-carrying filaments", _filament_rods, grouped=True),
    Measure(
        "total_current", "J0", "current through the circuit (observable total_current)", _total_current, grouped=True
    ),
    Measure("inside_R_plas", "fraction", "fraction of rod centres within R_plas of the plasma axis", _inside_plasma),
    Measure(
        "median_axis_distance", "L", "median distance of rod centres from the axis", lambda f: float(np.median(f.rho))
    ),
    Measure(
        "midplane_flux",
        "Phi_0",
        "flux of the rod currents' B_z through the disc z = 0 of radius flux_radius "
        "(default: the placement box's half-diagonal)",
        _midplane_flux,
        grouped=True,
    ),
    Measure(
        "moment_J_z",
        "J0 L^2",
        "m_J,z of all rod currents about the z axis",
        lambda f: float(f.claims["moment_J_z"]),
        grouped=True,
    ),
]
FRAME_MEASURES += [
    Measure(
        k, u, d, lambda f, k=k: float(f.claims[k]), err=(lambda f, k=k: float(f.claims[k + "_err"])) if fit else None
    )
    for k, u, d, fit in (
        ("largest_structure_rods", "rods", "rods in the largest structure", False),
        ("largest_moment_ratio", "1", "largest structure's |m_q| over the mean single-rod moment", False),
        (
            "fractal_dimension",
            "1",
            "mass-radius dimension of the largest structure (NaN, not testable, while its R_g < 4 L)",
            True,
        ),
        ("rg_dimension", "1", "R_g ~ N^(1/D) dimension over the structures of the frame", True),
        ("cycle_rank", "loops", "cycle rank of the contact graph (E - V + C)", False),
    )
]


# ----------------------------------------------------------------------------- summary
def summarise(paths, times, t_end=None, measures=None, flux_radius=None) -> dict:
    """Mean and standard error over seed files of the short-circuit time and of per-frame measures.

    Parameters
    ----------
    paths : sequence of path-like
        Run files, one per seed.
    times : sequence of float
        Simulated times; each seed's nearest saved frame within half an output interval
        is used, a seed that has no such frame (it ended earlier) is left out there.
    t_end : float, optional
        Short circuits later than this count as censored at ``t_end`` (default: none).
    measures : list of :class:`Measure`, optional
        Default :data:`FRAME_MEASURES`.
    flux_radius : float, optional
        Disc radius of the mid-plane flux (see :class:`Frame`).

    Returns
    -------
    dict (JSON-ready) with ``seeds`` (per seed: path, seed, status, end time, short-circuit
    time or None; files that cannot be read are left out and listed in ``unreadable``), ``short_circuit`` (:func:`~selfas_graph.analysis.ensemble_stats.censored_times`:
    seeds without one are censored at their end time, counted, not averaged in),
    ``times`` and ``measures`` (name -> unit, doc, per time mean, sem, n, and ``values``
    per seed and time, NaN as None). A measure with a fit uncertainty also has ``fit_err``
    (per seed and time), ``sem_between`` and ``fit_err_rms`` per time, and its ``sem`` is
    ``sqrt(sem_between^2 + fit_err_rms^2 / n)`` (docs/model.md "Measures of the paper's
    claims"). A grouped measure (a current flows or not) has ``group`` (what the group is),
    ``k`` (seeds in the group), ``n_seeds`` (seeds with a value), ``median``, ``min``,
    ``max`` per time, and its ``mean``, ``sem`` and ``n`` are the group's alone; ``current``
    per seed and time says which seeds carry a current.
    """
    measures = FRAME_MEASURES if measures is None else measures
    times = [float(t) for t in times]
    seeds, values = [], np.full((len(measures), len(paths), len(times)), np.nan)
    errs = np.full_like(values, np.nan)
    current = np.full((len(paths), len(times)), np.nan)
    grouped = any(m.grouped for m in measures)
    sc_t, sc_obs, unreadable = [], [], []
    for j, path in enumerate(paths):
        try:
            run = RunFile(path)
        except RunFileError as exc:  # e.g. still being written by a running seed: left out, named
            unreadable.append({"path": str(path), "reason": str(exc)})
            continue
        with run:
            params = run.parameters
            interval = float(params["output"]["interval"])
            t_run = run.time
            end = float(t_run[-1]) if t_run.size else 0.0
            t_sc = timeline(t_run, np.zeros_like(t_run), events=run.events()).short_circuit_time
            cens = end if t_end is None else min(end, float(t_end))
            seen = t_sc is not None and t_sc <= cens
            sc_t.append(t_sc if seen else cens)
            sc_obs.append(seen)
            seeds.append(
                {
                    "path": str(path),
                    "seed": int(params["scenario"]["seed"]),
                    "status": str(run.meta.get("status", "")),
                    "t_end": end,
                    "short_circuit_time": t_sc if seen else None,
                }
            )
            for k, t in enumerate(times):
                if not t_run.size:
                    break
                idx = int(np.argmin(np.abs(t_run - t)))
                if abs(t_run[idx] - t) > 0.5 * interval + 1e-9:
                    continue
                frame = Frame(run, idx, params, flux_radius)
                for m, measure in enumerate(measures):
                    values[m, j, k] = measure.fn(frame)
                    if measure.err is not None:
                        errs[m, j, k] = measure.err(frame)
                if grouped:
                    current[j, k] = carries_current(frame)
    keep = [j for j, p in enumerate(paths) if str(p) not in {u["path"] for u in unreadable}]
    values, errs, current = values[:, keep], errs[:, keep], current[keep]
    sc = censored_times(sc_t, sc_obs) if seeds else None
    out = {
        "version": __version__,
        "n_seeds": len(seeds),
        "times": times,
        "t_end": t_end,
        "seeds": seeds,
        "unreadable": unreadable,
        "short_circuit": None if sc is None else {k: _plain(v) for k, v in sc.items()},
        "measures": {},
    }
    if grouped:
        out["current"] = _plain(current)
    for m, measure in enumerate(measures):
        extra = {}
        if measure.grouped:
            g = [grouped_summary(values[m][:, k], current[:, k] == 1.0) for k in range(len(times))]
            mean, sem, n = (np.array([x[key] for x in g]) for key in ("mean", "sem", "k"))
            extra = {"group": "seeds whose circuit carries a current"}
            extra.update({key: _plain(np.array([x[key] for x in g])) for key in ("k", "median", "min", "max")})
            extra["n_seeds"] = [x["n"] for x in g]
        elif measure.err is not None:
            mean, sem, between, rms, n = mean_sem_fits(values[m], errs[m], axis=0)
            extra = {"sem_between": _plain(between), "fit_err_rms": _plain(rms), "fit_err": _plain(errs[m])}
        else:
            mean, sem, n = mean_sem(values[m], axis=0)
        out["measures"][measure.name] = {
            "unit": measure.unit,
            "doc": measure.doc,
            "mean": _plain(mean),
            "sem": _plain(sem),
            "n": np.asarray(n).astype(int).tolist(),
            "values": _plain(values[m]),
            **extra,
        }
    return out


def _plain(v):
    """JSON-ready: arrays to lists, NaN to None."""
    if isinstance(v, np.ndarray):
        return [_plain(x) for x in v.tolist()]
    if isinstance(v, (list, tuple)):
        return [_plain(x) for x in v]
    if isinstance(v, (float, np.floating)):
        return None if not math.isfinite(v) else float(v)
    if isinstance(v, np.integer):
        return int(v)
    return v


def _pm(mean, sem, n):
    if mean is None:
        return "n/a"
    return f"{mean:.4g} +- {sem:.2g} ({n})" if sem is not None else f"{mean:.4g} ({n})"


def _group_cell(m, i):
    k, n = m["k"][i], m["n_seeds"][i]
    if not k:
        return f"0/{n}"
    f = lambda v: "n/a" if v is None else f"{v:.4g}"  # noqa: E731
    return f"{k}/{n}: {f(m['median'][i])} [{f(m['min'][i])}, {f(m['max'][i])}], {_pm(m['mean'][i], m['sem'][i], k)}"


def format_table(summary) -> str:
    """The summary as a Markdown table: one row per measure, one column per time, ``mean +- sem (seeds)``."""
    lines = []
    sc = summary.get("short_circuit")
    if sc:
        f = lambda v: "not reached" if v is None else f"{v:.4g}"  # noqa: E731
        mean = (
            "n/a"
            if sc["mean_observed"] is None
            else f"{sc['mean_observed']:.4g}"
            + (f" +- {sc['sem_observed']:.2g}" if sc["sem_observed"] is not None else "")
        )
        lines.append(
            f"short circuit: {sc['n_observed']} of {sc['n']} seeds "
            f"({sc['n_censored']} without one, censored at their end time); "
            f"Kaplan-Meier median {f(sc['median'])} (quartiles {f(sc['q25'])}, {f(sc['q75'])}); "
            f"mean over the {sc['n_observed']} that short-circuited {mean}"
        )
    times = summary["times"]
    head = "| measure | unit | " + " | ".join(f"t = {t:g}" for t in times) + " |"
    lines += [
        "",
        "mean +- standard error over seeds (seeds with a frame at that time)",
        "",
        head,
        "|" + "---|" * (len(times) + 2),
    ]
    for name, m in summary["measures"].items():
        if "k" in m:
            cells = [_group_cell(m, i) for i in range(len(times))]
        else:
            cells = [_pm(a, b, n) for a, b, n in zip(m["mean"], m["sem"], m["n"])]
        lines.append(f"| {name} | {m['unit']} | " + " | ".join(cells) + " |")
    if any("k" in m for m in summary["measures"].values()):
        lines += [
            "",
            "current-related measures: k/n seeds carrying a current, the median [min, max] and "
            "mean +- standard error of those k only",
        ]
    if any("fit_err_rms" in m for m in summary["measures"].values()):
        lines += ["fitted dimensions: the standard error adds each seed's fit uncertainty to the spread between seeds"]
    for u in summary.get("unreadable", ()):
        lines += [f"left out: {u['reason']}"]
    if summary.get("note"):
        lines += ["", f"note: {summary['note']}"]
    return "\n".join(lines)


#: columns of summary.csv after measure, unit, time, mean, sem, n (empty where a measure has none):
#: a fitted measure's standard error between seeds and rms fit uncertainty; a grouped measure's
#: seeds in the group (k; its mean, sem and n are the group's), seeds with a value, median, min, max
CSV_EXTRA = ("sem_between", "fit_err_rms", "k", "n_seeds", "median", "min", "max")


def write_summary(summary, folder) -> tuple[Path, Path]:
    """Write ``summary.json`` (everything) and ``summary.csv`` (one row per measure and time) into ``folder``."""
    folder = make_folder(folder)
    js, cs = folder / SUMMARY_JSON, folder / SUMMARY_CSV
    js.write_text(json.dumps(summary, indent=1, allow_nan=False) + "\n")
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["measure", "unit", "time", "mean", "sem", "n", *CSV_EXTRA])
    sc = summary.get("short_circuit")
    if sc:
        w.writerow(
            [
                "short_circuit_time_observed",
                "t0",
                "",
                _csv(sc["mean_observed"]),
                _csv(sc["sem_observed"]),
                sc["n_observed"],
                *[""] * len(CSV_EXTRA),
            ]
        )
        w.writerow(["short_circuit_time_km_median", "t0", "", _csv(sc["median"]), "", sc["n"], *[""] * len(CSV_EXTRA)])
        w.writerow(["seeds_without_short_circuit", "seeds", "", sc["n_censored"], "", sc["n"], *[""] * len(CSV_EXTRA)])
    for name, m in summary["measures"].items():
        for i, (t, a, b, n) in enumerate(zip(summary["times"], m["mean"], m["sem"], m["n"])):
            w.writerow([name, m["unit"], t, _csv(a), _csv(b), n, *(_csv(m[c][i]) if c in m else "" for c in CSV_EXTRA)])
    cs.write_text(buf.getvalue())
    return js, cs


def _csv(v):
    return "" if v is None else repr(v) if isinstance(v, float) else v
