"""Run a scenario over many seeds and summarise them: ``selfas-graph ensemble SCENARIO --seeds N [--jobs J]``.

Seeds S .. S+N-1 (S: ``--first-seed``, default the scenario's ``scenario.seed``) each go
to their own run file ``DIR/seed_SSSS.h5``, written as ``selfas-graph simulate`` writes
it. Seeds finished at the end time are not run again; interrupted ones (or ones
finished at an earlier end time) continue from their checkpoint. A seed file of other
parameters is refused (``--force`` replaces such files). Then the summary, mean and
standard error over seeds at the chosen times, is printed and written to
``DIR/summary.json`` and ``DIR/summary.csv`` (both rewritten from the run files on every
call).

On one machine the seeds run in ``--jobs`` processes with ``cores // jobs`` numba
threads each. On a cluster allocation, ``mpiexec -n P selfas-graph ensemble ...`` (or
``mpiexec -n P python -m mpi4py.futures -m selfas_graph.cli.main ensemble ...``) runs
them on the P - 1 ranks other than rank 0, which hands them out and writes the summary.
The Python API is :mod:`selfas_graph.ensemble`.
"""

from __future__ import annotations

import math
import sys
import time
from pathlib import Path

from .._version import __version__
from ..ensemble import SUMMARY_CSV, SUMMARY_JSON, Ensemble, EnsembleError, format_table, write_summary
from ..ensemble.folder import own_file
from ..ensemble.plan import summary_times
from ..parallel import task_pool
from .main import EXIT_NUMERICAL, CliError, CliIOError, counted, interrupted_code, write_failed


def _default_times_note(times, t_end, interval) -> str | None:
    """Why the default times gave fewer than four columns (frames too far apart), or None."""
    if len(times) >= 4:
        return None
    return (
        f"the default times (a quarter, half, three quarters and all of t = {t_end:g}) fall on "
        f"{len(times)} frame{'s' if len(times) != 1 else ''} of the output every {interval:g}: give --times, "
        f"or a shorter output.interval, for more columns"
    )


def _times(text):
    import argparse

    try:
        values = [float(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"{text!r}: give simulated times separated by commas, e.g. 100,300,600"
        ) from None
    if not values or not all(math.isfinite(v) and v >= 0 for v in values):
        raise argparse.ArgumentTypeError(f"{text!r}: give finite simulated times >= 0, separated by commas")
    return values


def _positive_int(text):
    import argparse

    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"{text} must be >= 1")
    return v


def add_arguments(p):
    p.add_argument("scenario", help="scenario file (TOML), e.g. scenarios/quick.toml")
    p.add_argument("--seeds", type=_positive_int, required=True, metavar="N", help="number of seeds")
    p.add_argument(
        "--first-seed", type=int, metavar="S", help="seeds S .. S+N-1 (default: the scenario's scenario.seed)"
    )
    p.add_argument(
        "--jobs",
        type=_positive_int,
        default=1,
        metavar="J",
        help="seeds run at once on this machine, each with cores // J numba threads (default 1; "
        "under mpiexec the ranks are the workers)",
    )
    p.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override a scenario value for every seed, as in simulate (repeatable)",
    )
    p.add_argument("--t-end", type=float, help="simulated end time of every seed (overrides run.t_end)")
    p.add_argument(
        "-o",
        "--output",
        metavar="DIR",
        help="folder of the run files and summary (default: SCENARIO name + '_ensemble'); created if missing",
    )
    p.add_argument(
        "--times",
        type=_times,
        metavar="T1,T2,...",
        help="times of the summary, each a frame time (a multiple of output.interval, or the end time) (default: a quarter, half, three quarters and all of the end time, each at its nearest frame)",
    )
    p.add_argument(
        "--flux-radius",
        type=float,
        metavar="R",
        help="disc radius of the mid-plane flux (default: the placement box's half-diagonal in x-y)",
    )
    p.add_argument(
        "--grid",
        action="append",
        metavar="KEY=V1,V2,...",
        help="run the seeds at every value of a scenario key (repeatable: the product of the grids); each "
        "point in DIR/KEY=V/, the combined summary in DIR/grid_summary.json and .csv",
    )
    p.add_argument("--no-run", action="store_true", help="summarise the seed files present; run nothing")
    p.add_argument(
        "--plot",
        action="store_true",
        help="also draw DIR/summary.png: each measure against time, mean and a band of one standard error",
    )
    p.add_argument(
        "--force",
        action="store_true",
        help="replace seed files that cannot be reused (other parameters, failed, or incomplete without "
        "a checkpoint); finished ones are kept",
    )


def pool_text(pool) -> str:
    """Where the seeds run, as the commands print it."""
    if pool.mpi:
        return counted(pool.workers, "MPI worker rank")
    if pool.serial:
        import numba

        return f"this process ({counted(numba.get_num_threads(), 'numba thread')})"
    return f"{counted(pool.workers, 'process', 'processes')} x {counted(pool.threads, 'numba thread')}"


class SeedReport:
    """The ``report`` of :func:`~selfas_graph.ensemble.run_tasks` of the commands: one line as each
    seed ends, ``[k/total] [FOLDER ]seed S: what at t = T (W s): message`` (``folders``: the seed
    file's folder first, for seeds of several ensembles). ``total`` may be set once known."""

    WORDS = {"io_error": "stopped by an I/O error"}

    def __init__(self, total=0, folders=False):
        self.done, self.total, self.folders = 0, total, folders

    def __call__(self, r):
        self.done += 1
        what = self.WORDS.get(r.get("status"), str(r.get("status")))
        extra = f": {r['message']}" if r.get("message") else ""
        t = f" at t = {r['t']:.6g}" if r.get("t") is not None else ""
        where = f"{Path(r.get('path', '?')).parent.name} " if self.folders else ""
        print(
            f"[{self.done}/{self.total}] {where}seed {r.get('seed', '?')}: {what}{t} "
            f"({r.get('wall_seconds', 0.0):.1f} s){extra}",
            flush=True,
        )


def run(args):
    with task_pool(args.jobs) as pool:
        if pool.is_worker:
            return 0  # an MPI rank that ran seeds for rank 0
        return _run(args, pool)


def _make(folder):
    from ..ensemble import make_folder

    try:
        make_folder(folder)
    except EnsembleError as exc:
        raise CliError(str(exc)) from None


class _Locks:
    """The folder locks this process holds: one per folder, taken once, all released at the end."""

    def __init__(self):
        self._held = {}

    def hold(self, folder):
        """Lock ``folder`` for this process (again: nothing); another ensemble there is refused (exit 2)."""
        from ..ensemble import FolderLock

        key = Path(folder).resolve()
        if key in self._held:
            return
        try:
            self._held[key] = FolderLock(folder).acquire()
        except EnsembleError as exc:
            raise CliError(str(exc)) from None

    def release_all(self):
        for lock in self._held.values():
            lock.release()
        self._held.clear()


def _run(args, pool):
    locks = _Locks()
    try:
        if args.grid:
            return _run_grid(args, pool, locks)
        return _run_ensemble(args, pool, locks)
    finally:
        locks.release_all()


def _check_summary_args(args, t_end, params, also=()):
    """``--flux-radius`` and ``--times`` against the scene, before anything runs (a bad one ended a
    grid with a traceback after all its seeds had run)."""
    if args.flux_radius is not None and not (math.isfinite(args.flux_radius) and args.flux_radius > 0):
        raise CliError(f"--flux-radius must be a positive length, got {args.flux_radius}")
    times = args.times
    if times is None:
        return
    if max(times) > t_end:
        raise CliError(f"--times {max(times):g} is after the end time {t_end:g}; give times up to it")
    try:  # frame times only
        summary_times(times, t_end, params.output.interval, params.integrator.dt, also)
    except EnsembleError as exc:
        raise CliError(f"--{exc}") from None


def _own_files(folder, *names) -> list[Path]:
    """The files ``names`` of ``folder`` an ensemble writes, refused (CliError) where one is a symbolic
    link or not a file (:func:`~selfas_graph.ensemble.folder.own_file`): checked before any seed runs,
    or its run would end without a summary, and again before each is written."""
    try:
        return [own_file(Path(folder) / name) for name in names]
    except EnsembleError as exc:
        raise CliError(str(exc)) from None


def _exit_code(results, kept_failed) -> int:
    """The exit code of an ensemble or a grid from its seeds' results (None: never started) and the
    count of failed seeds the plan kept from an earlier run."""
    statuses = [r.get("status") for r in results if r is not None]
    if "interrupted" in statuses or any(r is None for r in results):
        print(
            "selfas-graph ensemble: interrupted; rerun the same command to continue "
            "(finished seeds are kept, interrupted ones resume from their checkpoints)",
            file=sys.stderr,
        )
        return interrupted_code(results)
    if "error" in statuses:
        print("selfas-graph ensemble: some seeds stopped with an error (above)", file=sys.stderr)
        return 1
    if "failed" in statuses or kept_failed:
        return EXIT_NUMERICAL
    return 0


#: what the plan of a seed can say (ensemble.plan.SeedPlan.action)
_ACTIONS = ("run", "resume", "done", "failed", "partial")


def _counts(plans) -> dict:
    return {a: sum(p.action == a for p in plans) for a in _ACTIONS}


def _count_text(count, no_run=False) -> str:
    """The plan's counts in words; with ``--no-run`` a seed without a file is missing, not to run."""
    first = f"{count['run']} missing" if no_run else f"{count['run']} to run, {count['resume']} to resume"
    return f"{first}, {count['done']} done, {count['failed']} failed" + (
        f", {count['partial']} partial (summarised to their last frame)" if count["partial"] else ""
    )


def _run_ensemble(args, pool, locks):
    """One ensemble: plan its seeds, run those left, summarise the files."""
    try:
        name_source = Path(args.scenario).stem
        folder = Path(args.output) if args.output else Path(f"{name_source}_ensemble")

        def ensemble(t_end):
            return Ensemble(
                args.scenario,
                args.seeds,
                folder,
                overrides=args.overrides,
                t_end=t_end,
                first_seed=args.first_seed,
                force=args.force,
            )

        ens = ensemble(args.t_end)
        if not args.no_run and folder.is_dir():  # before its files are read: they may be another ensemble's
            locks.hold(folder)
        if args.no_run and args.t_end is None:  # the files present, to where they were run (not the scene's end)
            ran_to = ens.files_end_time()
            if ran_to is not None and not math.isclose(ran_to, ens.t_end, rel_tol=1e-12):
                print(f"summarising to t = {ran_to:g}, the end time of the seed files (--t-end chooses another)")
                ens = ensemble(ran_to)
        plans = ens.plan(summary_only=args.no_run)
    except EnsembleError as exc:
        raise CliError(str(exc)) from None
    _check_summary_args(args, ens.t_end, ens.base.params, ens.shared_frame_times() if args.times else ())
    _own_files(folder, SUMMARY_JSON, SUMMARY_CSV, *(("summary.png",) if args.plot else ()))
    times = args.times
    count = _counts(plans)
    runs = not args.no_run and count["run"] + count["resume"]
    if runs:  # a folder that cannot be made is refused before the plan is printed
        _make(folder)
        locks.hold(folder)
    p = ens.base.params
    print(
        f"{p.scenario.name}: seeds {ens.seeds[0]}..{ens.seeds[-1]} to t = {ens.t_end:g} in {folder}/: "
        + _count_text(count, args.no_run)
        + ("" if args.no_run else f"; on {pool_text(pool)}"),
        flush=True,
    )
    for plan in plans:
        if plan.action == "failed":
            print(f"  seed {plan.seed}: {plan.note} (kept; --force reruns it)", flush=True)
        elif plan.action == "done" and plan.other_version:  # kept, but the model may have changed since
            print(
                f"  seed {plan.seed}: {plan.note}, not this version {__version__} (kept; see the CHANGELOG)", flush=True
            )
    results = []
    if runs:
        tasks = ens.tasks(plans)
        report = SeedReport(len(tasks))
        t0 = time.perf_counter()
        from ..ensemble import run_seed, run_tasks

        results = run_tasks(run_seed, tasks, pool, report)
        print(
            f"ran {sum(r is not None for r in results)} of {counted(len(tasks), 'seed')} in {time.perf_counter() - t0:.1f} s",
            flush=True,
        )
        io = [r for r in results if r is not None and r.get("status") == "io_error"]
        if io:  # no summary: there is no room for it either
            from ..lifecycle import ABANDONED

            what = "; ".join(f"seed {r['seed']}: {r['message']}" for r in io)
            raise CliIOError(
                f"writing into {folder} failed ({what}). "
                f"Every seed file keeps its frames and checkpoint; free some space (or fix the folder) and "
                f"run the same command again to continue",
                hard_exit=bool(ABANDONED),
            )
    summary = ens.summarise(times=times, flux_radius=args.flux_radius)
    stopped = sum(r is not None and r.get("status") == "interrupted" for r in results)
    never = sum(r is None for r in results)
    if summary["n_seeds"]:
        print()
        if stopped or never:
            print(
                f"partial: {counted(stopped, 'seed')} stopped before t = {ens.t_end:g} and {never} never "
                f"started; each seed counts at the times it reached"
            )
        print(format_table(summary))
        if times is None:
            note = _default_times_note(summary["times"], ens.t_end, ens.base.params.output.interval)
            if note:
                print(f"note: {note}")
        try:
            js, cs = write_summary(summary, folder)
        except (EnsembleError, OSError) as exc:
            raise write_failed(f"cannot write the summary into {folder}", exc) from None
        print(f"\nwrote {js} and {cs}")
        if args.plot:
            from .plot import plot_summary

            (png,) = _own_files(folder, "summary.png")
            print(f"wrote {plot_summary(summary, png, title=f'{p.scenario.name} ensemble')}")
    else:
        print("no seed file to summarise")
    return _exit_code(results, count["failed"])


def _run_grid(args, pool, locks):
    """``--grid``: an ensemble at every grid point, all seeds in one pool, the combined summary."""
    from ..ensemble import run_seed, run_tasks, write_summary
    from ..grid import GRID_CSV, GRID_JSON, GRID_PNG, Grid, parse_grid, plot_grid, write_grid_summary

    folder = Path(args.output) if args.output else Path(f"{Path(args.scenario).stem}_grid")
    try:
        grid = Grid(
            args.scenario,
            parse_grid(args.grid),
            args.seeds,
            folder,
            overrides=args.overrides,
            t_end=args.t_end,
            first_seed=args.first_seed,
            force=args.force,
        )
    except EnsembleError as exc:
        raise CliError(str(exc)) from None
    _check_summary_args(args, grid.t_end, grid.ensembles[0].base.params)
    _own_files(folder, GRID_JSON, GRID_CSV, *((GRID_PNG,) if args.plot else ()))
    for ens in grid.ensembles:
        _own_files(ens.folder, SUMMARY_JSON, SUMMARY_CSV)
    try:
        if not args.no_run and folder.is_dir():
            locks.hold(folder)
        plans = grid.plans(summary_only=args.no_run)
    except EnsembleError as exc:
        raise CliError(str(exc)) from None
    tasks = [] if args.no_run else grid.tasks(plans)
    if tasks:  # folders that cannot be made are refused before the plan is printed
        _make(folder)
        locks.hold(folder)
        for ens in grid.ensembles:
            _make(ens.folder)
            locks.hold(ens.folder)  # each point's folder too: an ensemble run there alone takes its lock
    kept_failed = 0
    for ens, plan in zip(grid.ensembles, plans):
        count = _counts(plan)
        kept_failed += count["failed"]
        print(
            f"{ens.folder}/: seeds {ens.seeds[0]}..{ens.seeds[-1]} to t = {grid.t_end:g}: {_count_text(count, args.no_run)}",
            flush=True,
        )
    resumed = sum(t["action"] == "resume" for t in tasks)
    print(
        f"grid of {len(grid.points)} points x {len(grid.ensembles[0].seeds)} seeds: {len(tasks) - resumed} to run"
        + (f", {resumed} to resume" if resumed else ""),
        flush=True,
    )
    results = []
    if tasks:
        results = run_tasks(run_seed, tasks, pool, SeedReport(len(tasks), folders=True))
        io = [r for r in results if r is not None and r.get("status") == "io_error"]
        if io:
            from ..lifecycle import ABANDONED

            raise CliIOError(
                f"writing into {folder} failed ({io[0]['message']}); free some space and run the same command again",
                hard_exit=bool(ABANDONED),
            )
    table = grid.summarise(times=args.times, flux_radius=args.flux_radius)
    if not tasks and not any(point["summary"]["n_seeds"] for point in table["points"]):
        print("no seed file to summarise")  # as for one ensemble: nothing written
        return 0
    if args.times is None:
        note = _default_times_note(table["times"], grid.t_end, grid.ensembles[0].base.params.output.interval)
        if note:
            print(f"note: {note}")
    try:
        for point in table["points"]:
            if point["summary"]["n_seeds"]:
                write_summary(point["summary"], folder / point["folder"])
        js, cs = write_grid_summary(table, folder)
    except (EnsembleError, OSError) as exc:
        raise write_failed(f"cannot write the grid summary into {folder}", exc) from None
    print(f"wrote {js} and {cs}")
    if args.plot:
        (png,) = _own_files(folder, GRID_PNG)
        print(f"wrote {plot_grid(table, png, title=f'{Path(args.scenario).stem} grid')}")
    return _exit_code(results, kept_failed)
