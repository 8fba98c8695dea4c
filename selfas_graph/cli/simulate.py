"""Run a scenario: ``selfas-graph simulate SCENARIO [-o OUT] [--set key=value ...] [--t-end T] [--dry-run]``.

Validates the scenario and the output path before anything is written, runs
with a progress bar on a terminal (plain periodic lines otherwise), writes an
HDF5 run file and prints a summary.

Under ``mpiexec -n P`` the ranks share the force work (``selfas_graph.parallel``).
Rank 0 alone checks the input and the files, prints, and writes the run file,
checkpoints and failure snapshots; it sends its verdict to the other ranks, so
that every rank stops together, with one message and the serial exit code.
"""

from __future__ import annotations

import json
import math
import os
import shlex
import signal
import sys
import uuid
from pathlib import Path

from .._version import __version__
from ..io.checkpoint import (
    Checkpointer,
    CheckpointError,
    checkpoint_meta,
    checkpoint_path,
    read_checkpoint,
)
from ..io.h5md import (
    NullWriter,
    RunFile,
    RunFileError,
    RunWriter,
    is_io_error,
    not_replaced,
)
from ..io.h5md_format import RUN_SUFFIXES, is_hdf5
from ..io.scenario import ScenarioError, load_scenario
from ..lifecycle import (
    ContinuationError,
    StopOnSignal,
    close_after_io_error,
    continuation,
    failure_path,
    new_run_file,
    run_to_file,
)
from ..model.accuracy import null_model_notes, short_of_accuracy
from ..model.compiled import python_steps_reason
from ..model.health import stiff_brakes
from ..model.params import plasma_current_text
from ..model.placement import PlacementError
from ..model.simulation import Simulation
from ..model.terms.currents import tree_note, two_trees_note
from ..parallel import abort_job, fit_threads_to_cores, world
from .main import EXIT_NUMERICAL, CliError, CliIOError, counted, write_failed
from .paths import check_folder, check_target, checkpoint_owner, name_max, same_file, through_link
from .progress import Bar, Lines, fmt_time


def add_arguments(p):
    p.add_argument("scenario", nargs="?", help="scenario file (TOML), e.g. scenarios/quick.toml")
    p.add_argument(
        "--resume",
        metavar="RUN_OR_CHECKPOINT",
        help="continue an interrupted run from RUN.h5 (its RUN.checkpoint.h5) or a checkpoint file; "
        "only --t-end may change",
    )
    p.add_argument(
        "-o",
        "--output",
        help="output HDF5 file (default: output.file, or SCENARIO name with .h5); with --resume, the run file "
        "the checkpoint continues (default: the one beside it)",
    )
    p.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override a scenario value, e.g. --set integrator.dt=5e-4 (repeatable)",
    )
    p.add_argument("--t-end", type=float, help="simulated end time (overrides run.t_end)")
    p.add_argument("--dry-run", action="store_true", help="validate and place the rods, print the plan, write nothing")
    p.add_argument(
        "--force",
        action="store_true",
        help="overwrite an existing output file; with --resume from a copy of a checkpoint, wind the run file back to it",
    )
    p.add_argument(
        "--progress",
        choices=("auto", "bar", "lines", "none"),
        default="auto",
        help="progress display (auto: a bar on a terminal, periodic lines otherwise)",
    )


def _new_frames(start, n_steps, every, first):
    """Frames written by ``n_steps`` steps from step ``start``: one at each multiple of ``every``,
    one at the end if that is not one, and (``first``) the initial frame."""
    end = start + n_steps
    return end // every - start // every + int(n_steps > 0 and end % every != 0) + int(first)


def _resume_paths(args):
    """(checkpoint to read, run file to continue) named by ``--resume`` (and ``-o``).

    ``--resume X.h5`` continues X.h5 from the checkpoint beside it, X.checkpoint.h5;
    ``--resume X.checkpoint.h5`` continues the run file beside it that the checkpoint
    names. Both are found relative to the path given, wherever the folder now is:
    nothing is written to a path the user did not name or that does not sit beside it.
    """
    src = Path(args.resume)
    if src.name in ("", ".", "..") or src.is_dir():
        raise CliError(
            f"--resume {args.resume}: give a run file (RUN.h5) or its checkpoint (RUN.checkpoint.h5), not a folder"
        )
    if src.name.endswith(".checkpoint.h5"):
        return src, None
    if src.name.endswith(".failure.h5"):
        run = src.with_name(src.name.removesuffix(".failure.h5") + ".h5")
        raise CliError(
            f"--resume {args.resume}: this is the failed state of the run {run}, which is not resumed (its "
            f"steps would fail again at the same step); start the run again with other settings (e.g. a smaller "
            f"integrator.dt) and --force. read_checkpoint reads the file in Python"
        )
    return checkpoint_path(src), src


def _finished_at(path):
    """The end time of the finished run in ``path``, or None (no file, not a run file, not finished)."""
    try:
        with RunFile(path) as run:
            return float(run.time[-1]) if run.status == "finished" and run.n_frames else None
    except (OSError, RunFileError, KeyError, ValueError):
        return None


def _load_resume(args):
    """(scenario, snapshot, run file, checkpoint file read, run identity) of a run to continue
    (the checks: :func:`~selfas_graph.lifecycle.continuation`)."""
    if args.scenario or args.overrides:
        raise CliError("--resume continues a run exactly: give no SCENARIO and no --set (only --t-end may change)")
    ckpt, out = _resume_paths(args)
    if out is not None and not out.exists() and not ckpt.exists():
        raise CliError(f"cannot resume {out}: neither the run file nor its checkpoint {ckpt} exists")
    try:
        snap, meta = read_checkpoint(ckpt)
    except CheckpointError as exc:
        raise CliError(f"cannot resume: {exc}") from None
    if out is None:
        name = str(meta.get("run_name") or ckpt.name[: -len(".checkpoint.h5")] + ".h5")
        if Path(name).name != name or name in (".", ".."):
            raise CliError(f"cannot resume: {ckpt} names its run file {name!r}, which is not a file name")
        out = ckpt.with_name(name)
    if args.output:
        out = Path(args.output)
    _check_output_name(out, resuming=True)
    if args.t_end is not None and args.t_end < float(snap["time"]):
        raise CliError(
            f"--t-end (run.t_end) {args.t_end:g} is before the checkpoint's time {float(snap['time']):.6g}; "
            f"give a later end time"
        )
    if not out.exists():
        if args.output:
            raise CliError(
                f"cannot resume into {out}: with --resume, -o names the run file to continue, which must exist "
                f"(a checkpoint continues its run file; to continue into a new file, copy the run file first)"
            )
        raise CliError(
            f"cannot resume: the run file {out} of checkpoint {ckpt} does not exist (give the run file with -o)"
        )
    try:
        cont = continuation(ckpt, out, t_end=args.t_end, read=(snap, meta))
    except ContinuationError as exc:
        raise CliError(str(exc)) from None
    for note in cont.notes:
        print(f"note: {note}", file=sys.stderr)
    _check_frames_after(out, ckpt, float(snap["time"]), args.force)
    return cont.scenario, snap, out, ckpt, cont.run_id


def _check_frames_after(out, ckpt, t_ckpt, force):
    """The frames of ``out`` after the checkpoint's time ``t_ckpt`` are dropped by the resume and computed
    again (those of a run stopped between two checkpoints): said in a note. From a checkpoint that is
    not the one beside the run file (an older copy), refused without ``--force``: the run file, and its
    own later checkpoint, would be wound back to the copy's time."""
    try:
        with RunFile(out) as run:
            later = [float(t) for t in run.time if float(t) > t_ckpt]
    except (OSError, RunFileError, KeyError, ValueError):
        return  # continuation() has read the file; a frame table it cannot show is trimmed by the writer
    if not later:
        return
    frames = (
        f"{len(later)} frame{'s' if len(later) > 1 else ''} of {out} after t = {t_ckpt:.6g} (to t = {later[-1]:.6g})"
    )
    own = checkpoint_path(out)
    if not (own.exists() and same_file(own, ckpt)) and not force:
        raise CliError(
            f"resuming {out} from {ckpt}, not from its own checkpoint {own.name}, drops the {frames} and "
            f"replaces {own.name}: pass --force to wind the run back to t = {t_ckpt:.6g}, or resume {out}"
        )
    print(f"note: the {frames} are dropped and computed again from the checkpoint {ckpt}", file=sys.stderr)


def _check_output_name(out: Path, resuming=False):
    if "\x00" in str(out):
        raise CliError(f"the output path {str(out)!r} contains a NUL character")
    if out.name not in ("", ".", ".."):
        check_target(out, "run file" if resuming else "output file", force=True, resuming=resuming)  # devices, names
    if out.name in ("", ".", "..") or out.is_dir():
        raise CliError(f"the output path {out} names a folder, not a file; give a file name such as run.h5")


def _check_files_beside(out: Path, ckpt: Path):
    """Refuse a run whose checkpoint another run file beside it shares (the same name before another run
    suffix: ``c.h5`` and ``c.hdf5`` both checkpoint to ``c.checkpoint.h5``), or whose checkpoint's
    temporary file would have a longer name than the folder takes (found at the first checkpoint, it
    would end the run as an I/O error)."""
    for suffix in ("", *RUN_SUFFIXES):
        other = out.with_name(out.stem + suffix)
        if other.name != out.name and other.is_file() and is_hdf5(other):
            raise CliError(
                f"{other} beside {out.name} has the same name before its suffix: the two would share the "
                f"checkpoint {ckpt.name} and the failure file; choose another name with -o"
            )
    tmp = ckpt.name + ".tmp"  # io/checkpoint.py writes aside, then renames
    room = name_max(out.parent)
    if len(tmp.encode("utf-8", "surrogateescape")) > room:
        raise CliError(
            f"the output name {out.name[:40]}... is too long: its checkpoint's temporary file would have "
            f"{len(tmp)} characters, more than the file system's {room}; give a name of at most "
            f"{room - (len(tmp) - len(out.stem))} characters before the suffix"
        )


class _PeerFailed(SystemExit):
    """Rank 0 failed with an unexpected error (it prints the traceback): the other ranks exit quietly."""


def _on_root(fn, share=True):
    """Call ``fn()`` on rank 0 only; every rank returns its result (``share``) or raises the same CliError.

    What rank 0 alone can find out (files, the output folder, a checkpoint) is decided once,
    so the ranks cannot disagree; without ``share`` the other ranks get None (e.g. for an
    open file). Serially this is ``fn()``.
    """
    if world.size == 1:
        return fn()
    result, status = None, ("ok", None)
    if world.rank == 0:
        try:
            result = fn()
        except CliError as exc:
            status = ("error", str(exc))
        except BaseException:
            world.bcast((("crash", None), None), root=0)
            raise
    status, shared = world.bcast((status, result if share else None), root=0)
    if status[0] == "error":
        raise CliError(status[1])
    if status[0] == "crash":
        raise _PeerFailed(1)
    return result if world.rank == 0 else shared


def _prepare(args):
    """(scenario, snapshot or None, output path, checkpoint path, run id, checkpoint read or None), every
    input and file checked; new checkpoints go to the checkpoint path, beside the output."""
    snap = None
    if args.resume:
        scenario, snap, out, read_from, run_id = _load_resume(args)
        out = through_link(out)
        ckpt = checkpoint_path(out)  # new checkpoints go beside the run file continued
        check_target(out, "run file", force=True, resuming=True)
        check_target(ckpt, "checkpoint file", force=True, resuming=True)
        if ckpt.exists() and not same_file(ckpt, read_from):
            try:
                other = read_checkpoint(ckpt)[1].get("run_id")
            except CheckpointError:
                other = None
            if other != run_id:
                raise CliError(
                    f"cannot resume into {out}: the file {ckpt} beside it, where its checkpoints go, "
                    f"is not a checkpoint of this run; move it away first"
                )
    else:
        run_id = uuid.uuid4().hex
        if not args.scenario:
            raise CliError("give a SCENARIO file, or --resume RUN.h5 to continue a run")
        try:
            scenario = load_scenario(args.scenario, overrides=args.overrides, t_end=args.t_end)
        except ScenarioError as exc:
            raise CliError(str(exc)) from None
        out = through_link(Path(args.output) if args.output else scenario.output_path)
        _check_output_name(out)
        ckpt = checkpoint_path(out)
        _check_files_beside(out, ckpt)
        check_target(out, "output file", force=True, inputs=[args.scenario])
        check_target(ckpt, "checkpoint file", force=True, inputs=[args.scenario])
        refused = not_replaced(out)  # a scene, a checkpoint or an export is not replaced, even with --force
        if refused:
            raise CliError(refused)
        owner = checkpoint_owner(ckpt)
        if owner is not None and owner != out.name and (ckpt.parent / owner).is_file():
            # run files of other suffixes share the checkpoint's name (run.txt and run.h5: run.checkpoint.h5)
            raise CliError(
                f"the checkpoint file {ckpt} beside {out.name} is that of the run file {owner}: this run would "
                f"replace it, even with --force, and {owner} could no longer be resumed; choose another name with -o"
            )
        if ckpt.exists() and not args.force:
            ended = _finished_at(out)
            if ended is not None:  # nothing left to continue: only a later end time extends it
                raise CliError(
                    f"{out} exists and finished at t = {ended:.6g} (its checkpoint {ckpt} beside it); pass --force "
                    f"to run it again, -o to choose another name, or --resume {out} --t-end LATER to extend it"
                )
            raise CliError(
                f"checkpoint file {ckpt} exists (from an earlier run?); pass --force to overwrite it, "
                f"or --resume {out} to continue that run"
            )
    if snap is None:  # a dry run checks these too: it says whether the run would start
        if out.exists() and not args.force:
            raise CliError(f"output file {out} exists; pass --force to overwrite it or -o to choose another name")
        if out.exists() and out.is_dir():
            raise CliError(f"output path {out} is a directory")
        check_folder(out, "output file")
        stale = failure_path(out)  # an earlier run's failed state: beside this run it would be taken for its own
        if stale.exists() and not args.force:
            raise CliError(
                f"{stale} exists (an earlier run's failed state); pass --force to remove it with the run, or -o "
                f"to choose another name"
            )
    return scenario, snap, out, ckpt, run_id, (read_from if snap is not None else None)


def run(args):
    scenario, snap, out, ckpt, run_id, read_from = _on_root(lambda: _prepare(args))
    p = scenario.params
    try:
        sim = (
            Simulation.from_scenario(scenario, comm=world)
            if snap is None
            else Simulation.from_snapshot(p, snap, comm=world)
        )
    except PlacementError as exc:
        raise CliError(str(exc)) from None
    fit_threads_to_cores()
    try:
        n_steps = sim.steps_to(p.run.t_end)
    except ValueError as exc:
        raise CliError(f"run.t_end: {exc}") from None
    plan = _plan(args, sim, snap, read_from, out, n_steps)
    if world.rank == 0:
        _announce(sim, plan)
    if args.dry_run:
        return _dry_run(sim, snap, read_from, out, plan)

    writer = _on_root(lambda: _open_writer(args, sim, scenario, snap, out, read_from, run_id), share=False)
    checkpointer = None
    if world.size > 1:
        # the other ranks take the frames' calls too (their energies are sums over all ranks)
        n_frames = world.bcast(writer.n_frames if writer is not None else 0, root=0)
        if world.rank != 0:
            writer = NullWriter(n_frames)
    if world.rank == 0:
        checkpointer = Checkpointer(
            ckpt, p.output.checkpoint_interval, checkpoint_meta(scenario, run_id, out.name, p.run.t_end, __version__)
        )
    mode = args.progress
    if mode == "auto":
        mode = "bar" if sys.stderr.isatty() else "lines"
    reporter = None
    if world.rank == 0 and mode != "none":
        reporter = Bar(n_steps, p.run.t_end, sim.state.step) if mode == "bar" else Lines(sys.stderr)
    with StopOnSignal(comm=world) as stop:
        end = run_to_file(sim, writer, checkpointer, stop, out, progress=reporter, keeps_files=world.rank == 0)
    return _ended(end, stop, sim, writer, out, ckpt)


def _plan(args, sim, snap, ckpt, out, n_steps) -> dict:
    """What the run will do, as printed by ``--dry-run``: scene, size, terms, steps, frames, output, threads."""
    import numba

    p = sim.params
    start = sim.state.step
    return {
        "scenario": None if args.scenario is None else str(args.scenario),
        **({"resume": str(ckpt), "from_step": start, "from_t": sim.state.time} if snap is not None else {}),
        "rods": p.rods.count,
        "terms": p.forces.active(),
        "dt": p.integrator.dt,
        "t_end": p.run.t_end,
        "steps": n_steps,
        "frames": _new_frames(start, n_steps, sim.frame_steps, first=snap is None),
        "output": str(out),
        "threads": numba.get_num_threads(),
        "mpi_ranks": world.size,
        "fast_steps": "compiled" if sim.compiled is not None else f"in Python: {python_steps_reason(sim)}",
        **{k: v for k, v in sim.force_field.describe().items() if k != "terms"},
    }


def _announce(sim, plan):
    """The run's first line (scene, rods, terms, steps, threads and ranks), and a note when the output
    interval is not a whole number of steps."""
    p = sim.params
    print(
        f"selfas-graph {__version__}: {p.scenario.name}: {p.rods.count} rods, terms "
        f"{', '.join(plan['terms']) or 'none'}; dt = {p.integrator.dt:g}, t_end = {p.run.t_end:g} "
        f"({plan['steps']} steps); {counted(plan['threads'], 'thread')} x {counted(world.size, 'rank')}",
        flush=True,
    )
    if not math.isclose(sim.frame_interval, p.output.interval, rel_tol=1e-9):
        print(
            f"note: output.interval = {p.output.interval:g} is {p.output.interval / p.integrator.dt:.6g} steps of "
            f"integrator.dt = {p.integrator.dt:g}: a frame every {sim.frame_steps} steps "
            f"(t = {sim.frame_interval:.6g}), and one at the end",
            flush=True,
        )


def _dry_run(sim, snap, ckpt, out, plan) -> int:
    """``--dry-run``: the placement or checkpoint checked, the notes and the plan printed, nothing
    written; the numerical-failure exit code when the brakes are too stiff for the time step."""
    p = sim.params
    if world.rank == 0:
        if snap is None:
            print("dry run: placement succeeded, nothing written")
        else:
            print(
                f"dry run: checkpoint {ckpt} read and verified against {out} (step {sim.state.step}, "
                f"t = {sim.state.time:.6g}); {counted(plan['steps'], 'step')} to take, nothing written"
            )
        if plasma_current_text(p):
            print(plasma_current_text(p))
        for text in [*null_model_notes(p), two_trees_note(p)]:
            if text:
                print(f"note: {text}")
        for rule in short_of_accuracy(p):
            print(f"faster than accurate: {rule.key} = {rule.value(p)}; the stated accuracy needs {rule.stated}")
        print(json.dumps(plan, indent=2))
    if stiff := stiff_brakes(p, p.integrator.dt):  # the run would stop at its first contacts, or at once
        if world.rank == 0:
            print(f"selfas-graph simulate: the run would stop with a numerical failure: {stiff}", file=sys.stderr)
        return EXIT_NUMERICAL
    return 0


def _open_writer(args, sim, scenario, snap, out, ckpt, run_id):
    """The run file: reopened after its checkpoint on ``--resume`` (what came after is dropped), or
    new; a new file that cannot be written is removed and reported as a CliError or CliIOError."""
    if snap is not None:
        try:
            writer = RunWriter.reopen(
                out,
                int(snap["step"]),
                t_end=scenario.params.run.t_end,
                frame_interval=sim.frame_interval,
                mpi_ranks=world.size,
                drop_later=True,  # what came after the checkpoint is computed again
            )
        except RunFileError as exc:
            raise CliError(f"cannot resume: {exc}") from None
        print(
            f"resuming at step {int(snap['step'])} (t = {float(snap['time']):.6g}) from {ckpt}; "
            f"{writer.n_frames} frames kept in {out}",
            flush=True,
        )
        return writer
    existed = os.path.lexists(out)
    try:
        return new_run_file(
            sim, scenario, out, run_id, shlex.join(sys.argv), args.scenario, args.force, mpi_ranks=world.size
        )
    except OSError as exc:
        if not existed:  # a failed run leaves no output file behind
            try:
                out.unlink()
            except OSError:
                pass
        raise write_failed(f"cannot write the output file {out}", exc) from None


def _ended(end, stop, sim, writer, out, ckpt) -> int:
    """The exit code of a run that ended (``run_to_file``'s end), with its message or summary."""
    exc = end.error
    if end.status == "interrupted":
        if world.rank == 0:
            print(
                f"selfas-graph simulate: {signal.Signals(stop.signum).name} received: stopped at step {exc.step} "
                f"(t = {sim.state.time:.6g}); checkpoint {ckpt}; continue with: selfas-graph simulate --resume {out}",
                file=sys.stderr,
            )
        return 128 + stop.signum
    if end.status == "failed":
        if world.rank != 0:  # every rank fails at the same step (same state); rank 0 reports it
            return EXIT_NUMERICAL
        if end.failure_not_saved is not None:
            print(
                f"selfas-graph simulate: the failed state could not be saved ({end.failure_not_saved})", file=sys.stderr
            )
        print(f"selfas-graph simulate: {exc}", file=sys.stderr)
        print(
            f"frames up to the last output interval are in {out}; the last good state and the failed one "
            f"are in {end.failure} (read_checkpoint reads the first; the second is its group 'failed')",
            file=sys.stderr,
        )
        return EXIT_NUMERICAL
    if end.status == "io_error":
        _io_failure(exc, writer, out, ckpt, sim)
    if world.rank == 0:
        _print_summary(end.summary, out, sim)
    return 0


def _io_failure(exc, writer, out, ckpt, sim):
    """End a run whose writing failed (full disk, quota, a vanished folder): exit code 4.

    A :class:`DiskFullError` is raised before anything of the write happened, so the run file
    is closed as usual; any other failed write leaves HDF5's handle in a failed state, which
    is abandoned: the file keeps what its last flush wrote, and ``--resume`` drops a torn row.
    """
    clean = close_after_io_error(writer, exc, f"failed: {getattr(exc, 'strerror', None) or exc}")
    last = "none"
    if ckpt.exists():
        try:
            last = f"{ckpt} (step {int(read_checkpoint(ckpt)[0]['step'])})"
        except CheckpointError:
            last = str(ckpt)
    reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else " ".join(str(exc).split())[:300]
    advice = (
        "Free some space (or fix the folder) and continue with"
        if is_io_error(exc)
        else "HDF5 failed on the file (a damaged file?); check it, then try"
    )
    msg = (
        f"I/O error at step {sim.state.step} (t = {sim.state.time:.6g}) while writing: {reason}. "
        f"The frames flushed before it are in {out}; last good checkpoint: {last}. {advice}: "
        f"selfas-graph simulate --resume {out}"
    )
    if world.size > 1:
        print(f"selfas-graph simulate: error: {msg}", file=sys.stderr, flush=True)
        abort_job(4, world)  # every rank ends (the others wait in a collective call)
    raise CliIOError(msg, hard_exit=not clean) from None


def _balance_note(rel, sim) -> str:
    """The balance over the energy turned over; a finished run above its energy_tolerance passed the
    check by the round-off floor of the energies (model/health.py), so its ratio says nothing."""
    if not math.isfinite(rel):
        return "(no energy turned over)"
    if abs(rel) > sim.params.integrator.energy_tolerance:
        return "(round-off of the energies: almost no energy turned over)"
    return f"({rel:.2g} of kinetic energy + |work|)"


def _print_summary(s, out, sim):
    rel = s.energy_balance / s.energy_scale if s.energy_scale > 0 else float("nan")
    speed = (
        f"{s.steps_per_second:.0f} steps/s, {1e3 / s.steps_per_second:.2f} ms/step" if s.steps else "no step to take"
    )
    lines = [
        f"done: {s.steps} steps, t = {s.t_start:.4g} -> {s.t_end:.4g} in {fmt_time(s.wall_seconds)} ({speed})",
        f"  max bond-length error after constraint: {s.max_bond_error:.3g}",
        f"  energy balance E - E0 - W: {s.energy_balance:.3g} " + _balance_note(rel, sim),
        f"  contacts (tip pairs closer than r*): {sim.contact_count()}",
    ]
    st = sim.status()
    if sim.params.circuit is not None:
        sc = st["short_circuit_time"]
        lines.append(
            (
                f"  short circuit: the conductors were first joined at t = {sc:.6g}"
                if sc is not None
                else "  short circuit: never"
            )
            + f"; at the end {st['current_rods']} rods carry current, total {st['total_current']:.4g} J0"
        )
        note = tree_note(sim.params, st["current_rods"])
        if note:
            lines.append(f"  note: {note}")
    lines.append(f"  output: {out} ({s.frames} frames); checkpoint {checkpoint_path(out)}")
    print("\n".join(lines))
