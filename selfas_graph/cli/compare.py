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


def run(args):
    for path in (args.a, args.b):
        if not Path(path).is_file():
            raise CliError(f"no such run file: {path}")
    try:
        return same_run.run(args)
    except BrokenPipeError:
        raise  # the reader of the output went away (`| head`): the command line ends quietly
    except OSError as exc:  # h5py: not an HDF5 file, or unreadable
        raise CliError(f"cannot read the run files: {exc}") from None
