"""Export a run for viewers: ``selfas-graph export RUN.h5 --format gsd|xyz [--frames ...] [-o OUT] [--force]``.

GSD (OVITO, HOOMD-blue, MDAnalysis, freud) holds the tips as particles typed by their rod's
role, one bond per rod, the currents; extended XYZ (ASE, OVITO) the same per tip, without
bonds. The run file is only read; the output never replaces it, and an existing output
only with --force (docs/output.md).
"""

from __future__ import annotations

import sys
import warnings
from pathlib import Path

from ..io.export import FORMATS, ExportError, ExportExistsError, MissingGraphWarning, export_run
from ..io.h5md import RunFileError, raised_in_hdf5
from .main import CliError, counted, write_failed


def add_arguments(p):
    p.add_argument("run", help="run file written by selfas-graph simulate")
    p.add_argument(
        "--format",
        choices=FORMATS,
        required=True,
        help="gsd (OVITO, HOOMD-blue, MDAnalysis) or xyz (extended XYZ: ASE, OVITO)",
    )
    p.add_argument(
        "--frames",
        default="all",
        help="all (default), K, A:B[:S] (a Python slice) or K1,K2,... "
        "(negative numbers count from the end; write --frames=-1)",
    )
    p.add_argument(
        "-o", "--output", help="output file, ending in .gsd or .xyz (.extxyz) (default: RUN with .gsd or .xyz)"
    )
    p.add_argument("--force", action="store_true", help="overwrite an existing output file")


def run(args):
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", MissingGraphWarning)
            path, n = export_run(args.run, args.format, out=args.output, frames=args.frames, force=args.force)
    except ExportExistsError as exc:
        raise CliError(
            f"output file {exc.path} exists; pass --force to overwrite it or -o to choose another name"
        ) from None
    except (RunFileError, ExportError) as exc:
        raise CliError(str(exc)) from None
    except OSError as exc:  # named by the file asked for, not the temporary file it is written to first
        if raised_in_hdf5(exc):  # reading the run file
            raise
        target = args.output or Path(args.run).with_suffix("." + args.format)
        raise write_failed(f"cannot write the export {target}", exc) from None
    print(f"wrote {path} ({counted(n, 'frame')}, {args.format})")
    for w in caught:
        if issubclass(w.category, MissingGraphWarning):
            print(f"note: {w.message}", file=sys.stderr)
        else:  # any other warning as Python would have shown it
            warnings.showwarning(w.message, w.category, w.filename, w.lineno)
    return 0
