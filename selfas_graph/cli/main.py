"""``selfas-graph`` command line: a table of subcommands, each in its own module.

Exit codes: 0 success, 2 bad input (scenario, arguments, files), 3 numerical
failure of a run, 4 an I/O error while writing (full disk, quota, a vanished
folder), 128 + the signal's number when a signal stopped a run (130 Ctrl-C, 143 SIGTERM; 130 where the
signal is not known). Under ``mpiexec`` every rank exits with the
same code and only rank 0 prints the error; an unexpected error on one rank
aborts them all (no rank is left waiting for the others).
"""

from __future__ import annotations

import argparse
import importlib
import sys

from .._version import __version__

#: subcommand -> (module, one-line help)
COMMANDS = {
    "simulate": ("selfas_graph.cli.simulate", "run a scenario and write an HDF5 run file"),
    "topology": ("selfas_graph.cli.topology", "structures, filaments, currents and events of a saved frame"),
    "analyze": ("selfas_graph.cli.analyze", "magnetic moment, fractal dimensions and loops of a saved frame or series"),
    "plot": (
        "selfas_graph.cli.plot",
        "figures of a saved run: snapshot, density, field, flux, timeline, moment, fractal, skeleton (PNG, PDF or SVG)",
    ),
    "ensemble": ("selfas_graph.cli.ensemble", "run a scenario over many seeds; mean and standard error over them"),
    "study": (
        "selfas_graph.cli.study",
        "the results page from runs: list, run and summarise the studies of docs/studies.toml, write the page",
    ),
    "export": ("selfas_graph.cli.export", "a run as GSD (OVITO, HOOMD-blue, MDAnalysis) or extended XYZ (ASE, OVITO)"),
    "compare": ("selfas_graph.cli.compare", "whether two run files hold the same data, bit for bit"),
    "bench": (
        "selfas_graph.cli.bench",
        "benchmarks and tools (selfas_graph.bench): bench NAME ARGS runs one, bench alone lists them",
    ),
}

#: the commands that only read run files: an HDF5 error while they run is a damaged input
READERS = ("topology", "analyze", "plot", "export", "compare")

EXIT_USAGE = 2
EXIT_NUMERICAL = 3
EXIT_IO = 4
#: the exit code of an interruption whose signal is not known (that of Ctrl-C, 128 + SIGINT)
EXIT_INTERRUPTED = 130


class CliError(Exception):
    """A user error the CLI reports in one line with exit code 2 (no traceback)."""

    code = EXIT_USAGE


class CliIOError(CliError):
    """Writing failed (full disk, quota, a vanished folder): one line, exit code 4.

    ``hard_exit``: an HDF5 file of the process is left in a failed state, which the HDF5
    library may crash on when the interpreter shuts down; the console command then ends at
    once (``os._exit``) after its message, leaving the files as they were last flushed.
    """

    code = EXIT_IO

    def __init__(self, message, hard_exit=False):
        super().__init__(message)
        self.hard_exit = hard_exit


def write_failed(message, exc) -> CliError:
    """The error of a failed write, one rule for every command: exit 4 (:class:`CliIOError`) where the
    system could not store the bytes (full disk, quota, an I/O error), 2 where the target is wrong (a
    missing folder, no permission, a folder in the file's place). ``message`` names the file."""
    from ..io.h5md_format import is_io_error

    wrong_target = isinstance(exc, (FileNotFoundError, PermissionError, IsADirectoryError, NotADirectoryError))
    why = " ".join(str(getattr(exc, "strerror", None) or exc).split())  # one line, also for HDF5's messages
    return (CliIOError if is_io_error(exc) and not wrong_target else CliError)(f"{message}: {why}")


def add_run_and_frame(p):
    """The run-file argument and the ``--frame K | --time T`` choice that the commands reading a
    saved frame share; returns the mutually exclusive group for more choices (e.g. ``--series``)."""
    p.add_argument("run", help="run file written by selfas-graph simulate")
    which = p.add_mutually_exclusive_group()
    which.add_argument("--frame", type=int, help="frame number (negative counts from the end; default: last)")
    which.add_argument(
        "--time",
        type=float,
        help="the frame nearest to this simulated time (at most one frame spacing outside the run's)",
    )
    return which


def build_parser():
    parser = _Parser(prog="selfas-graph", description=__doc__.splitlines()[0])
    parser.add_argument("--version", action="version", version=f"selfas-graph {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name, (module, help_text) in COMMANDS.items():
        mod = importlib.import_module(module)
        p = sub.add_parser(name, help=help_text, description=mod.__doc__)
        mod.add_arguments(p)
        p.set_defaults(_run=mod.run)
    return parser


def parse_args(parser, argv=None):
    """``parser.parse_args(argv)``, but names given after options still count for a command whose
    trailing positional list is named by its ``_rest`` default (``study run fig2 --jobs 2 fig6``);
    an unknown option is refused as by argparse."""
    args, extra = parser.parse_known_args(argv)
    rest = getattr(args, "_rest", None)
    if extra and rest and not any(a.startswith("-") for a in extra):
        getattr(args, rest).extend(extra)
    elif extra:
        parser.error(f"unrecognized arguments: {' '.join(extra)}")
    return args


def __getattr__(name):
    # raised_in_hdf5 lives in io/h5md_format.py; imported from here as before, without loading h5py at start
    if name == "raised_in_hdf5":
        from ..io.h5md_format import raised_in_hdf5

        return raised_in_hdf5
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def interrupted_code(results) -> int:
    """The exit code of a command whose seeds a signal stopped: 128 + the signal's number, as ``simulate``
    and a shell give it (130 for Ctrl-C, 143 for SIGTERM), from the first seed result (a dict or None) that
    names it (``signum``); :data:`EXIT_INTERRUPTED` where none does (under ``mpiexec`` the signal stays
    with rank 0)."""
    for r in results:
        if r is not None and r.get("signum"):
            return 128 + int(r["signum"])
    return EXIT_INTERRUPTED


def counted(n, one, many=None) -> str:
    """``n`` things as the commands print them, in the singular for one: ``counted(2, "seed")``."""
    return f"{n} {one if n == 1 else many or one + 's'}"


def _launcher_rank() -> int:
    """This process's rank as an MPI launcher states it (0 outside ``mpiexec``), read before MPI starts."""
    import os

    for var in ("PMI_RANK", "OMPI_COMM_WORLD_RANK", "PMIX_RANK"):
        if os.environ.get(var, "").isdigit():
            return int(os.environ[var])
    return 0


class _Parser(argparse.ArgumentParser):
    """argparse's parser, whose usage errors are printed by rank 0 alone under ``mpiexec`` (every rank
    parses the same command line and exits with 2 alike)."""

    def error(self, message):
        if _launcher_rank() != 0:
            sys.exit(2)
        super().error(message)


def _interrupted(who) -> int:
    """Ctrl-C or SIGTERM that reached the command line outside a run's own handling (while a command
    starts, or a command without any): one line, exit 130. Under ``mpiexec`` the other ranks may wait
    in a collective call for this one, where no signal reaches Python: the job is ended (MPI_Abort),
    never left hanging."""
    world = getattr(sys.modules.get("selfas_graph.parallel"), "world", None)
    size = getattr(world, "size", 1)
    if size == 1 or world.rank == 0:
        print(f"{who}: interrupted", file=sys.stderr)
    if size > 1:
        from ..parallel import abort_job

        abort_job(EXIT_INTERRUPTED, world)
    return EXIT_INTERRUPTED


class _ReaderMayGo:
    """Standard output that outlives its reader: once a write or flush finds the pipe closed (``| head``),
    the rest goes to /dev/null and the command carries on, so that the files it writes after its
    printed lines (an ensemble's summary after its table) are written all the same."""

    def __init__(self, stream):
        self._stream = stream

    def _gone(self):
        import os

        try:
            os.dup2(os.open(os.devnull, os.O_WRONLY), self._stream.fileno())
        except (OSError, ValueError, AttributeError):  # no descriptor (captured output): nothing to redirect
            pass

    def write(self, text):
        try:
            return self._stream.write(text)
        except BrokenPipeError:
            self._gone()
            return len(text)

    def flush(self):
        try:
            self._stream.flush()
        except BrokenPipeError:
            self._gone()
            try:  # what the buffer held now goes to /dev/null
                self._stream.flush()
            except (BrokenPipeError, ValueError):
                pass

    def __getattr__(self, name):
        return getattr(self._stream, name)


def main(argv=None) -> int:
    stdout = sys.stdout
    sys.stdout = _ReaderMayGo(stdout)
    try:
        return _main(argv)
    except KeyboardInterrupt:  # Ctrl-C while the command starts (MPI, the parser): no traceback
        return _interrupted("selfas-graph")
    finally:
        sys.stdout = stdout


def _main(argv) -> int:
    from ..parallel import world

    parser = build_parser()
    args = parse_args(parser, argv)
    try:
        if world.size > 1 and args.command in READERS:
            # every rank would run the whole command: the same lines printed once per rank, and
            # the ranks racing to write the same figure or export
            raise CliError(
                f"{args.command} reads run files in one process: run it without mpiexec "
                f"(under mpiexec, simulate and the bench tools share the work between ranks)"
            )
        return int(args._run(args) or 0)
    except CliError as exc:
        if world.rank == 0:
            print(f"selfas-graph {args.command}: error: {exc}", file=sys.stderr)
        if getattr(exc, "hard_exit", False) and argv is None:
            import os

            sys.stdout.flush()
            sys.stderr.flush()
            os._exit(exc.code)
        return exc.code
    except KeyboardInterrupt:
        return _interrupted(f"selfas-graph {args.command}")
    except BrokenPipeError:
        # the reader went away (e.g. `| head`): stop quietly, as command-line tools do
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except (OSError, RuntimeError) as exc:
        from ..io.h5md import raised_in_hdf5

        if args.command not in READERS or not raised_in_hdf5(exc):
            raise
        # a damaged run file (bytes overwritten in its metadata): HDF5 says so only when the part is read
        files = " or ".join(str(getattr(args, a)) for a in ("run", "a", "b") if getattr(args, a, None))
        print(f"selfas-graph {args.command}: error: cannot read {files}: {exc} (a damaged file?)", file=sys.stderr)
        return EXIT_USAGE
    except Exception:
        if world.size == 1:
            raise
        import traceback

        from ..parallel import abort_job

        traceback.print_exc()
        abort_job(1, world)


if __name__ == "__main__":  # pragma: no cover
    # `python -m selfas_graph.cli.main`: call the package's module, whose CliError the
    # subcommands raise (this file's own copy, __main__, has a different CliError class)
    from selfas_graph.cli.main import main as package_main

    sys.exit(package_main())
