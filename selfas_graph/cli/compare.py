"""Whether two run files hold the same data, bit for bit: ``selfas-graph compare RUN_A RUN_B [--ignore-attrs]``.

Compares every dataset (shape, dtype and bytes; NaN equals NaN at the same place) and, unless
``--ignore-attrs``, every attribute except those that record the wall clock, the software, how the run
was launched (MPI ranks, threads, the scene file's folder) or the random run identity. Prints the
differences; exit code 1 if there are any, 0 if the files agree.
Attributes that only describe what a dataset holds, added by a later version, are named but not counted.
The same as ``python -m selfas_graph.bench.same_run`` (``selfas_graph/bench/same_run.py``).
"""

from __future__ import annotations

from pathlib import Path

from ..bench import same_run
from .main import CliError


def add_arguments(p):
    same_run.add_arguments(p)


def _check(path):
    """A clear error naming ``path`` where it cannot be compared: missing, a folder, not HDF5, or a file
    another process is writing."""
    from ..io.h5md_format import is_hdf5

    p = Path(path)
    if p.is_dir():
        raise CliError(f"{path} is a folder, not a run file")
    if not p.is_file():
        raise CliError(f"no such run file: {path}")
    if not is_hdf5(p):
        raise CliError(f"{path} is not an HDF5 file, as a selfas-graph run file is")


def _kind(path):
    """ "checkpoint" for a checkpoint file, "run file" for anything else that opens (None where it does not:
    locked or damaged, named by the comparison itself)."""
    import h5py

    from ..io.h5md_format import HDF5_READ_ERRORS

    try:
        with h5py.File(path, "r") as f:
            fmt = f.attrs.get("format", "")
    except HDF5_READ_ERRORS:
        return None
    fmt = fmt.decode(errors="replace") if isinstance(fmt, bytes) else str(fmt)
    return "checkpoint" if "checkpoint" in fmt else "run file"


def run(args):
    for path in (args.a, args.b):
        _check(path)
    kinds = [_kind(args.a), _kind(args.b)]
    if None not in kinds and kinds[0] != kinds[1]:  # every dataset would differ: a list of no use
        raise CliError(f"{args.a} is a {kinds[0]} and {args.b} a {kinds[1]}: compare two run files, or two checkpoints")
    try:
        return same_run.run(args)
    except BrokenPipeError:
        raise  # the reader of the output went away (`| head`): the command line ends quietly
    except OSError as exc:  # h5py: unreadable, or locked by a writer
        from ..io.h5md_format import in_use
        from ..io.run_reader import locked_message

        busy = [p for p in (args.a, args.b) if in_use(p)]
        if busy:
            raise CliError("; ".join(locked_message(p) for p in busy)) from None
        raise CliError(f"cannot read {args.a} or {args.b}: {exc}") from None
