"""Measures of the paper's claims: ``selfas-graph analyze RUN.h5 [--frame K | --time T | --series] [--json | --csv]``.

For a saved frame (default the last): the magnetic moment of the largest structure from its
tips' monopoles and from its rod currents, in units of the mean single-rod moment too; the
unpaired monopole charge at its free tips; its mass-radius dimension and
the R_g ~ N^(1/D) dimension over all structures, each with its uncertainty and fit range;
the cycle rank, loop lengths and junction degrees of the contact graph (docs/model.md
"Measures of the paper's claims"). ``--series`` (or ``--csv`` without ``--frame``/``--time``) gives one row per
frame (every K-th and the last with ``--every K``). NaN (null in JSON, empty in CSV) where a measure is
undefined. A thin layer over :func:`selfas_graph.analysis.claims.frame_claims`.
"""

from __future__ import annotations

import csv
import json
import math
import sys

import numpy as np

from ..analysis.claims import CLAIM_KEYS, frame_claims
from ..io.h5md import RunFile, RunFileError
from .main import CliError, add_run_and_frame
from .paths import status_note

#: the columns of the --series table (the full set goes to --csv and --json)
SERIES_COLUMNS = {
    "frame": "frame",
    "time": "t",
    "largest_structure_rods": "rods",
    "largest_moment_q": "|m_q|",
    "largest_moment_ratio": "|m_q|/rod",
    "largest_moment_J_z": "m_J,z",
    "fractal_dimension": "D_mass",
    "rg_dimension": "D_Rg",
    "cycle_rank": "cycle_rank",
}
#: integer columns of --json and --csv
_INTEGER = ("frame", "step")
#: counts, integers in --json and --csv where the frame has them (null or empty where not)
_COUNTS = (
    "structures",
    "largest_structure_rods",
    "rg_n_min",
    "rg_n_max",
    "cycle_rank",
    "cycle_rank_largest",
    "loop_length_max",
    "junctions",
    "junction_degree_max",
)


def add_arguments(p):
    which = add_run_and_frame(p)
    which.add_argument("--series", action="store_true", help="every saved frame (a time series)")
    p.add_argument(
        "--every", type=int, default=1, metavar="K", help="with a series: every K-th frame and the last (default 1)"
    )
    form = p.add_mutually_exclusive_group()
    form.add_argument("--json", action="store_true", help="print JSON for scripts")
    form.add_argument("--csv", action="store_true", help="print CSV (all frames unless --frame or --time is given)")
    p.add_argument("--no-loops", action="store_true", help="skip the loop lengths (a cycle basis; the slowest part)")


def _frames(run, args):
    series = args.series or (args.csv and args.frame is None and args.time is None)
    if args.every != 1 and not series:
        picked = ", and --frame and --time pick one frame" if args.frame is not None or args.time is not None else ""
        raise CliError(
            f"--every {args.every} takes every K-th frame of a series{picked}: give --every with --series, or with "
            f"--csv and no --frame or --time"
        )
    if series:
        if args.every < 1:
            raise CliError(f"--every must be >= 1, got {args.every}")
        if run.n_frames == 0:
            raise RunFileError(f"{run.path}: the run has no saved frames")
        frames = list(range(0, run.n_frames, args.every))
        if frames and frames[-1] != run.n_frames - 1:  # the run's last frame too, as plot --every takes it
            frames.append(run.n_frames - 1)
        return frames, True
    if args.time is not None:
        if not math.isfinite(args.time):
            raise CliError(f"--time {args.time} names no frame; give a finite simulated time")
        return [run.frame_index(t=args.time)], False
    return [run.frame_index(frame=args.frame)], False


def _null(x):
    return None if isinstance(x, float) and not math.isfinite(x) else x


def _cell(x):
    if isinstance(x, float) and not math.isfinite(x):
        return ""
    return f"{x:.10g}" if isinstance(x, float) else x


def _fmt(x):
    if not math.isfinite(x):
        return "n/a"
    return f"{int(x)}" if float(x).is_integer() and abs(x) < 1e15 else f"{x:.4g}"


def run(args):
    try:
        with RunFile(args.run) as f:
            frames, series = _frames(f, args)
            if not f.has_graph:
                print(
                    f"selfas-graph analyze: {f.path} has no contact data (contacts.enabled = false?): "
                    f"every measure is NaN",
                    file=sys.stderr,
                )
            try:
                rows = [frame_claims(f, k, loops=not args.no_loops) | {"frame": float(k)} for k in frames]
            except (KeyError, IndexError, TypeError, ValueError) as exc:
                raise RunFileError(f"{f.path}: inconsistent run data ({type(exc).__name__}: {exc})") from None
            path = str(f.path)
            note = status_note(f.status)
    except RunFileError as exc:
        raise CliError(str(exc)) from None
    keys = ["frame"] + list(CLAIM_KEYS)
    for r in rows:
        r.update({k: int(r[k]) for k in _INTEGER})
        r.update({k: int(r[k]) for k in _COUNTS if math.isfinite(r[k])})
    if args.json:
        data = [{k: _null(r[k]) for k in keys} for r in rows]
        print(json.dumps(data if series else data[0], indent=1, allow_nan=False))
    elif args.csv:
        w = csv.writer(sys.stdout, lineterminator="\n")
        w.writerow(keys)
        for r in rows:
            w.writerow([_cell(r[k]) for k in keys])
    elif series:
        print(
            f"{path}: {len(rows)} frames{note}; largest structure: rods, |m_q| (Z_M0 e L), |m_q| per mean rod moment, "
            f"m_J,z (J0 L^2), mass-radius dimension; D_Rg over all structures"
        )
        print("  ".join(f"{c:>10}" for c in SERIES_COLUMNS.values()))
        for r in rows:
            print("  ".join(f"{_fmt(r[c]):>10}" for c in SERIES_COLUMNS))
    else:
        r = rows[0]
        print(f"{path}: frame {int(r['frame'])}, step {int(r['step'])}, t = {r['time']:.6g}{note}")
        for k, meaning in CLAIM_KEYS.items():
            if k in ("time", "step") or k.endswith(("_err", "_se")) or k in _RANGE_KEYS:
                continue
            value = _fmt(r[k])
            if k + "_err" in r:
                lo, hi = _RANGES[k]
                value += (
                    f" +- {_fmt(r[k + '_err'])} (slope s.e. {_fmt(r[k + '_se'])}, fit over {_fmt(r[lo])}..{_fmt(r[hi])}"
                    f" {_RANGE_UNITS[k]})"
                    if np.isfinite(r[k])
                    else " (not testable at this size)"
                )
            print(f"  {k:<26} {value:<40} {meaning}")
    return 0


_RANGES = {
    "fractal_dimension": ("fractal_r_min", "fractal_r_max"),
    "rg_dimension": ("rg_n_min", "rg_n_max"),
}
_RANGE_KEYS = {k for pair in _RANGES.values() for k in pair}
_RANGE_UNITS = {"fractal_dimension": "L", "rg_dimension": "rods"}
