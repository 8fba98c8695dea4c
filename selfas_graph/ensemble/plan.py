"""One scenario over many seeds: :class:`Ensemble` (what to do with each seed, its tasks, the run and
the summary of its folder) and :class:`SeedPlan`."""

from __future__ import annotations

import dataclasses
import math
import operator
import os
import shlex
import sys
from pathlib import Path

import numpy as np

from .._version import __version__
from ..io.checkpoint import (
    CheckpointError,
    checkpoint_path,
    read_checkpoint,
)
from ..io.h5md import HDF5_READ_ERRORS, RunFile, RunFileError, hdf5_damage
from ..io.h5md_format import FileInUseError
from ..io.scenario import Scenario, ScenarioError, load_scenario, scenario_from_text
from ..lifecycle import ContinuationError, continuation
from ..model.operations import frame_steps, steps_between
from ..model.parameter_match import parameter_differences
from ..model.parameter_match import value_at as _get
from ..parallel import task_pool
from ..provenance import older_version, version_key
from .folder import EnsembleError, FolderLock, make_folder, seed_path
from .pool import run_tasks
from .summary import summarise
from .tasks import run_seed


def scenario_source(scenario, overrides=(), t_end=None):
    """``(path, overrides, t_end)`` of an ensemble's scenario, given as a file's path or as a
    :class:`~selfas_graph.io.scenario.Scenario` loaded from a file (``load_scenario(path, overrides,
    t_end)``): its file, its overrides before ``overrides``, and its end time unless ``t_end`` is given.
    Each seed runs from the file, so a scenario built from text alone is refused."""
    if isinstance(scenario, Scenario):
        if scenario.path is None:
            raise EnsembleError(
                "the scenario was built from text and has no file each seed can run from: "
                "give the scenario file's path, or a Scenario from load_scenario(path)"
            )
        try:  # each seed runs from the file and the overrides: params changed after loading would be dropped
            again = scenario_from_text(scenario.text, scenario.path, scenario.overrides, scenario.params.run.t_end)
            same = again.params == scenario.params
        except ScenarioError:
            same = False
        if not same:
            raise EnsembleError(
                "the scenario's params differ from what its file and overrides give (changed after "
                "load_scenario?); each seed runs from the file: give the change as overrides"
            )
        t_end = scenario.params.run.t_end if t_end is None else t_end
        return Path(scenario.path), [*scenario.overrides, *_override_list(overrides)], t_end
    if not isinstance(scenario, (str, os.PathLike)):
        raise EnsembleError(
            f"scenario: a scenario file's path, or a Scenario from load_scenario(path, overrides), got "
            f"{type(scenario).__name__}; each seed runs from the file, with the changes as overrides "
            f"(e.g. Ensemble('scene.toml', seeds, folder, overrides=['rods.count=50']))"
        )
    return Path(scenario), _override_list(overrides), t_end


def _override_list(overrides) -> list:
    """``overrides`` as a list of "key=value" strings; EnsembleError for one string (it was read one
    character at a time) or anything but a sequence of strings."""
    if isinstance(overrides, (str, bytes)) or not all(isinstance(o, str) for o in overrides or ()):
        raise EnsembleError(f"overrides: give a list of 'key=value' strings, e.g. ['rods.count=50'], got {overrides!r}")
    return list(overrides or ())


def check_times(times, t_end, frame_interval=None, also=()) -> list[float]:
    """``times`` of a summary as a list of floats in ``[0, t_end]`` (a single time is taken as a list
    of one), each a frame's time where ``frame_interval`` is given (a multiple of it, ``t_end``, the
    last frame, or one of ``also``, frames every seed file holds off that grid), each once;
    EnsembleError naming the first that is not. A time between two frames would take one of them and
    be labelled with its own value."""
    times = [times] if np.ndim(times) == 0 else list(times)
    for t in times:
        try:
            ok = 0.0 <= float(t) <= t_end * (1 + 1e-12)
        except (TypeError, ValueError):
            ok = False
        if not ok:
            raise EnsembleError(f"times: {t!r} is not a simulated time between 0 and the end time {t_end:g}")
        if frame_interval:
            k = math.floor(float(t) / frame_interval + 0.5)
            tol = 1e-9 * max(1.0, abs(float(t)))
            if abs(k * frame_interval - float(t)) > tol and min(abs(float(t) - x) for x in (t_end, *also)) > tol:
                lo = math.floor(float(t) / frame_interval) * frame_interval
                raise EnsembleError(
                    f"times: no frame at t = {float(t):g}; the frames are every {frame_interval:g} t0 and at the "
                    f"end time {t_end:g}: give frame times (the nearest: {lo:g} and {min(lo + frame_interval, t_end):g})"
                )
    times = [float(t) for t in times]
    for i, t in enumerate(times):  # a time twice would be a column twice, its seeds counted in both
        same = [u for u in times[:i] if math.isclose(u, t, rel_tol=1e-9, abs_tol=1e-12)]
        if same:
            raise EnsembleError(f"times: {same[0]:g} and {t:g} are one time; give each time once")
    return times


def summary_times(times, t_end, interval, dt=None, also=()) -> list[float]:
    """The times of a summary: ``times`` checked (:func:`check_times`; frame times where the time step
    ``dt`` is given, the frames ``interval`` rounded to whole steps, or ``also``), or :func:`default_times`
    when None."""
    frame_interval = frame_steps(interval, dt) * dt if dt else None
    if times is None:  # at the frames, whose interval is whole steps (an interval of 0.0125 at dt = 0.002: 0.012)
        return default_times(t_end, frame_interval or interval)
    return check_times(times, t_end, frame_interval, also)


def check_jobs(jobs) -> None:
    """EnsembleError unless ``jobs`` (worker processes) is an integer >= 1, and for more than one unless
    this is the process that started the script (a worker that imports it would start its own pool)."""
    try:
        ok = operator.index(jobs) >= 1
    except TypeError:
        ok = False
    if not ok:
        raise EnsembleError(f"jobs: the number of worker processes, an integer >= 1, got {jobs!r}")
    mp_main = sys.modules.get("__mp_main__")
    if jobs > 1 and mp_main is not None and mp_main is not sys.modules.get("__main__"):
        # multiprocessing's spawn runs the user's script as __mp_main__ (a module of its own, where the process
        # that started it holds __main__ under that name too) in each worker it starts: a call not under the
        # guard runs again there (it said the folder was locked by another ensemble: the script's own)
        raise EnsembleError(
            "run(jobs > 1) was called in a worker process while it imported your script: each worker starts by "
            'importing it, so put the call under `if __name__ == "__main__":`'
        )


@dataclasses.dataclass
class SeedPlan:
    """What :meth:`Ensemble.run` does with one seed.

    ``action`` is "run" (a new file), "resume" (continue from the checkpoint to the end
    time), "done" (finished at or beyond the end time: kept) or "failed" (the run failed
    numerically before: kept, reported; rerun with ``force``). ``note`` says why.
    ``other_version`` names the version that made a kept file when it is not the running one.
    """

    seed: int
    path: Path
    action: str
    note: str = ""
    other_version: str | None = None


class Ensemble:
    """One scenario over many seeds, each in its own run file in ``folder``.

    Parameters
    ----------
    scenario : path-like or Scenario
        Scenario file (TOML), or a scenario loaded from one (``load_scenario``: its overrides and end
        time are kept, before ``overrides`` and unless ``t_end`` is given).
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
        Replace the seed files that cannot be reused (other parameters, failed, incomplete
        without a checkpoint, or older than ``older_than``); files that can be reused are still kept.
    older_than : str
        A version (docs/studies.toml ``trajectories_since``): a seed file made by an older version
        followed other trajectories and cannot be reused ("": any version can).

    Raises
    ------
    EnsembleError
        Bad scenario, overrides, seeds or folder.
    """

    def __init__(self, scenario, seeds, folder, overrides=(), t_end=None, first_seed=None, force=False, older_than=""):
        self.scenario_path, self.overrides, t_end = scenario_source(scenario, overrides, t_end)
        if not isinstance(folder, (str, os.PathLike)):
            raise EnsembleError(f"folder: the path of the folder for the seed files and the summary, got {folder!r}")
        self.folder = Path(folder)
        self.force = bool(force)
        self.older_than = str(older_than or "")
        if self.older_than and version_key(self.older_than) is None:
            raise EnsembleError(f"older_than: a version such as '0.4.0', got {self.older_than!r}")
        own = {
            "scenario.seed": "choose the seeds with first_seed (--first-seed) or a list of seeds",
            "output.file": "each seed's file is FOLDER/seed_SSSS.h5; choose the folder with folder (-o)",
        }
        bad = [o for o in self.overrides if o.split("=", 1)[0].strip() in own]
        if bad:
            key = bad[0].split("=", 1)[0].strip()
            raise EnsembleError(f"overrides (--set) {bad[0]}: the ensemble sets {key} for each run; {own[key]}")
        try:
            self.base = load_scenario(self.scenario_path, overrides=self.overrides, t_end=t_end)
        except ScenarioError as exc:
            raise EnsembleError(str(exc)) from None
        self.t_end = float(self.base.params.run.t_end)
        try:  # as simulate refuses it before any step: each seed would fail at its start
            steps_between(0.0, self.t_end, self.base.params.integrator.dt)
        except ValueError as exc:
            raise EnsembleError(f"t_end (--t-end): {exc}") from None
        if isinstance(seeds, (int, np.integer)) and not isinstance(seeds, bool):
            if seeds < 1:
                raise EnsembleError(f"seeds (--seeds) must be >= 1, got {seeds}")
            first = self.base.params.scenario.seed if first_seed is None else int(first_seed)
            seeds = range(first, first + int(seeds))
        elif first_seed is not None:
            raise EnsembleError(
                f"first_seed (--first-seed) {first_seed!r} goes with a count of seeds; the seeds {seeds!r} are given "
                f"themselves"
            )
        try:
            if isinstance(seeds, (str, bytes)):
                raise TypeError
            self.seeds = [operator.index(s) for s in seeds]
        except TypeError:
            raise EnsembleError(f"seeds: give a count N or a list of integer seeds, got {seeds!r}") from None
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
    def _from_files(self, read) -> list:
        """``read(run)`` of each seed file present that can be read (the plan and the summary name those
        that cannot)."""
        out = []
        for s in self.seeds:
            path = seed_path(self.folder, s)
            if not path.exists():
                continue
            try:
                with RunFile(path) as run:
                    out.append(read(run))
            except (RunFileError, *HDF5_READ_ERRORS, TypeError, ValueError):
                continue
        return out

    def files_end_time(self):
        """The latest end time (``run.t_end``) the seed files in the folder were run to, or None
        where there is no readable one: what a summary of the files present reaches."""
        ends = self._from_files(lambda run: float(run.parameters["run"]["t_end"]))
        return max(ends) if ends else None

    def plan(self, summary_only=False) -> list[SeedPlan]:
        """What :meth:`run` would do with each seed, from the files in the folder (nothing is written).

        With ``summary_only`` (nothing will run) an incomplete seed file, with or without a usable
        checkpoint (one still being written, say, or one run to an earlier end), is planned as
        "partial": summarised up to its last frame.

        Raises
        ------
        EnsembleError
            A seed file that belongs to other parameters, is not a run file, or is
            incomplete without a checkpoint (unless ``force`` or ``summary_only``), listing
            every such seed. With ``summary_only`` ``force`` replaces nothing: a file of other
            parameters or not a run file still stops the plan.
        """
        plans, problems = [], []
        for s in self.seeds:
            try:
                plans.append(self._plan_seed(s, summary_only))
            except EnsembleError as exc:
                problems.append(exc)
        if problems:
            raise EnsembleError(
                "seed files that cannot be used:\n  "
                + "\n  ".join(map(str, problems))
                + self._advice({p.kind for p in problems}, summary_only)
            )
        return plans

    def _advice(self, kinds, summary_only) -> str:
        """What to do about the problems of the ``kinds`` (:class:`EnsembleError` of :meth:`_plan_seed`):
        ``--force`` replaces a seed file and all it holds, so it is not offered for a file another process
        is writing, nor alone for one run past this end time, which a later end time continues or
        ``--no-run`` summarises."""
        if self.force or summary_only:
            return ""
        if kinds == {"in_use"}:
            return "; wait for the processes writing them to end (--force cannot replace a file in use)"
        if "past_end" in kinds:
            return (
                "; a later end time (--t-end) continues a seed run past this one, and --no-run summarises the "
                "files as they are; force=True (--force) would replace them, and all they hold, with new runs"
            )
        return "; pass force=True (--force) to replace them"

    def _plan_seed(self, seed, summary_only=False) -> SeedPlan:
        path = seed_path(self.folder, seed)
        ckpt = checkpoint_path(path)
        # force replaces a file only where seeds will run: a summary takes the files as they are, and one
        # that cannot be used stops it (files of other parameters must not be summarised as these)
        replace = self.force and not summary_only
        if not path.exists():
            if ckpt.exists() and not replace:
                raise EnsembleError(f"{ckpt} exists without its run file {path.name}")
            return SeedPlan(seed, path, "run", "new")
        wanted = self.scenario_for(seed).params
        try:
            with RunFile(path) as run:
                stored, status = run.parameters, str(run.meta.get("status", ""))
                made_by = str(run.meta.get("version") or "unknown")
                t_last = float(run.time[-1]) if run.n_frames else -math.inf
        except (RunFileError, *HDF5_READ_ERRORS) as exc:
            if not isinstance(exc, RunFileError) and hdf5_damage(exc) is None:
                raise
            why = str(exc) if isinstance(exc, RunFileError) else f"{path}: {hdf5_damage(exc)}"
            if replace and not isinstance(exc, FileInUseError):
                return SeedPlan(seed, path, "run", f"replacing: {why}")
            raise EnsembleError(why, "in_use" if isinstance(exc, FileInUseError) else "") from None
        if older_version(made_by, self.older_than):
            why = f"made by version {made_by}, before the trajectories of version {self.older_than}"
            if replace:
                return SeedPlan(seed, path, "run", f"replacing: {why}")
            raise EnsembleError(f"{path} was {why} (docs/studies.toml trajectories_since)")
        diff = parameter_differences(stored, wanted.to_dict())
        if diff:
            if replace:
                return SeedPlan(seed, path, "run", "replacing: other parameters")
            shown = ", ".join(f"{k} = {_get(stored, k)!r} (here {_get(wanted.to_dict(), k)!r})" for k in diff[:4])
            raise EnsembleError(
                f"{path} belongs to other parameters: {shown}" + (f" and {len(diff) - 4} more" if len(diff) > 4 else "")
            )
        half_step = 0.5 * wanted.integrator.dt
        where = f"at t = {t_last:.6g}" if math.isfinite(t_last) else "with no frame"
        if status == "finished" and t_last >= self.t_end - half_step:
            other = made_by if version_key(made_by) != version_key(__version__) else None
            note = f"finished at t = {t_last:.6g}" + (f" by version {other}" if other else "")
            return SeedPlan(seed, path, "done", note, other_version=other)
        if status.startswith("failed"):
            if replace:
                return SeedPlan(seed, path, "run", "replacing a failed run")
            return SeedPlan(seed, path, "failed", status)
        # the checks of simulate --resume (lifecycle.continuation), and a checkpoint not past the end
        why, kind = None, ""
        try:
            snap, meta = read_checkpoint(ckpt)
            continuation(ckpt, path, t_end=self.t_end, read=(snap, meta))
            if float(snap["time"]) > self.t_end + half_step:
                why, kind = f"checkpoint at t = {float(snap['time']):.6g}, after the end time", "past_end"
        except CheckpointError as exc:
            why = str(exc)
        except ContinuationError as exc:  # the reason; the advice is simulate's (here: --force)
            why = exc.reason
        if why is None and summary_only:  # nothing runs: it is summarised to where it ended
            return SeedPlan(seed, path, "partial", f"{status} {where}")
        if why is None:
            return SeedPlan(seed, path, "resume", f"{status} {where}; checkpoint at t = {float(snap['time']):.6g}")
        if summary_only:
            return SeedPlan(seed, path, "partial", f"{status} {where}")
        if replace:
            return SeedPlan(seed, path, "run", f"replacing: {status} {where}, no usable checkpoint")
        raise EnsembleError(
            f"{path} is {status} {where} (end time {self.t_end:g}) and has no usable "
            f"checkpoint {ckpt.name} to continue from ({why})",
            kind,
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
        if pool is None:
            check_jobs(jobs)
        make_folder(self.folder)
        with FolderLock(self.folder):
            tasks = self.tasks(self.plan())
            if pool is None:
                with task_pool(jobs) as own:
                    return run_tasks(run_seed, tasks, own, report)
            return run_tasks(run_seed, tasks, pool, report)

    def shared_frame_times(self) -> list[float]:
        """The frame times off the output grid that every seed file present holds: an earlier end time,
        off the grid, that a later end time continued past (a summary may take them as it takes the
        grid's; a seed run at once to the later end has no frame there, and then none is shared)."""
        p = self.base.params
        step = frame_steps(p.output.interval, p.integrator.dt) * p.integrator.dt
        shared = None
        for t in self._from_files(lambda run: np.asarray(run.time, dtype=float)):
            off = {float(x) for x in t if abs(x / step - round(x / step)) > 1e-9 * max(1.0, x / step)}
            shared = off if shared is None else shared & off
        return sorted(shared or ())

    def summarise(self, times=None, measures=None, flux_radius=None) -> dict:
        """:func:`summarise` over the seed files present (default times: :func:`default_times`, at frames;
        given ``times`` must be frame times, :func:`check_times`, or :meth:`shared_frame_times`)."""
        paths = [seed_path(self.folder, s) for s in self.seeds]
        p = self.base.params
        also = self.shared_frame_times() if times is not None else ()
        times = summary_times(times, self.t_end, p.output.interval, p.integrator.dt, also)
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


def default_times(t_end, interval=None):
    """The times of the summary when none are given: a quarter, half, three quarters and all of ``t_end``,
    each moved to the nearest frame time (a multiple of the output ``interval``, up to ``t_end``) and
    each taken once. A time between two frames used to take one of them and be labelled with its own
    value (frames every 0.5 to t = 1: the 0.25 column was the frame at t = 0)."""
    times = [t_end * k / 4 for k in (1, 2, 3)]
    if interval:
        times = [min(math.floor(t / interval + 0.5) * interval, t_end) for t in times]
    return sorted(set(times + [t_end]))  # the end: the last frame
