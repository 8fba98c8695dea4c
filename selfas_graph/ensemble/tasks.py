"""The pool's task functions: one seed into its run file (:func:`run_seed`), and one run without a
file to its first short circuit (:func:`run_to_short_circuit`, the percolation benchmark's task)."""

from __future__ import annotations

import time
import uuid
from pathlib import Path

from .._version import __version__
from ..io.checkpoint import (
    Checkpointer,
    checkpoint_meta,
    checkpoint_path,
)
from ..io.h5md import RunWriter, is_io_error
from ..io.scenario import scenario_from_text
from ..lifecycle import StopOnSignal, close_after_io_error, continuation, new_run_file, run_to_file
from ..model.placement import PlacementError
from ..model.simulation import NumericalFailure, RunInterrupted, Simulation
from ..parallel import is_pool_worker


def run_seed(task: dict) -> dict:
    """Run (or continue) one seed of an ensemble to its end time; the pool's task function.

    ``task`` holds ``seed``, ``path`` (the run file), ``action`` ("run" or "resume"),
    ``t_end``, and for "run" also ``text``, ``scenario_path``, ``overrides`` (with the
    seed's) and ``force``; ``command`` is recorded as the run's provenance. Never raises
    for a failing run: returns a dict with ``status`` "finished", "interrupted",
    "failed" (numerical failure; the last good and the failed state go to ``SEED.failure.h5``), "io_error"
    (a write failed: full disk, quota; the file stays resumable, :func:`_stop_on_io_error`) or "error"
    (with ``message``), and ``t`` (simulated time reached), ``steps``, ``wall_seconds``, ``threads``,
    ``signum`` (the signal that stopped an interrupted seed, else None).
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
        "signum": None,
    }
    t0 = time.perf_counter()
    sim = writer = end = None
    ckpt = checkpoint_path(path)
    with StopOnSignal() as stop:
        try:
            if task["action"] == "resume":
                cont = continuation(ckpt, path, t_end=t_end)  # the checks of simulate --resume
                scenario, snap = cont.scenario, cont.snapshot
                # the checkpoints from here on, as simulate --resume writes them: this version, the scenario
                # continued (an old run's brake among its overrides)
                meta = checkpoint_meta(scenario, cont.run_id, path.name, t_end, __version__)
                sim = Simulation.from_snapshot(scenario.params, snap)
                writer = RunWriter.reopen(
                    path,
                    int(snap["step"]),
                    t_end=scenario.params.run.t_end,
                    frame_interval=sim.frame_interval,
                    drop_later=True,  # what came after the checkpoint is computed again
                )
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
                out["signum"] = stop.signum  # None when the launching process ended
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
    "failed" (numerical failure at ``t_end``), "interrupted" (a signal, ``message``; its number in ``signum``),
    "unplaceable" or "error" (``message``),
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
        "signum": None,
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
            out["signum"] = signalled.signum
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
        if sim.network is not None:
            out["filament_rods"] = int(sim.network.topology().n_filament)
    out["wall_seconds"] = time.perf_counter() - t0
    return out
