"""Figures of a saved run: ``selfas-graph plot RUN.h5 --kind KIND [--frame K | --time T] [-o FILE.png]``.

Kinds, after the paper's figures (docs/model.md 'Figure diagnostics'):

* ``snapshot`` -- the rods in 3-D: current-carrying filaments blue, dead ends within
  the filament networks red (the dead-end rods of structures that hold filament
  rods), the rest grey (Figs. 2, 8); with more than 3000 rods the largest structure
  is red instead of the dead ends (Fig. 6). Electrode planes are translucent rectangles.
* ``density``  -- rods per unit volume vs distance r from the z axis, averaged over
  z between the electrodes (or over the rods' extent) and azimuth: total (green),
  in current-carrying filaments (blue), in the largest structure (red) (Figs. 3, 7, 9).
* ``field``    -- B_z of the rod currents only vs r, averaged over azimuth, one
  curve per plane (``--planes``; default the two electrode planes and z = 0, Fig. 4).
* ``flux``     -- flux of that B_z through discs of radius R, in units of
  Phi_0 = 4 pi (Fig. 5), or of an external dipole's flux with ``--z-mext`` (Fig. 11).
* ``timeline`` -- rods in filaments and total current vs time, the short-circuit
  time marked.
* ``moment``   -- the largest structure's magnetic moment vs time: |m_q| in units of the
  mean single-rod moment, and m_J,z of its rod currents (docs/model.md "Measures of the paper's claims").
* ``fractal``  -- the mass-radius dimension of the largest structure and
  the R_g ~ N^(1/D) dimension over all structures vs time, with their uncertainties.
* ``skeleton`` -- the cycle rank of the contact graph (and of the largest structure) vs time.

The last three read :func:`selfas_graph.analysis.claims.claims_series` (``--every K``: every
K-th frame and the last; default at most 201 frames).

The output goes next to the run file as ``RUN_KIND_frameK.png`` (``RUN_KIND.png`` for the
kinds over time: timeline, moment, fractal, skeleton) unless ``-o`` says otherwise; an existing file is kept unless
``--force``. Needs matplotlib (``pip install "selfas-graph[plot]"``); draws headless.

This module holds the command (its options, their checks, the table of kinds); the figures are
drawn in :mod:`selfas_graph.cli.plots`: one frame (``plots/frame.py``), over time
(``plots/series.py``), an ensemble summary (``plots/summary.py``, :func:`plot_summary`), and what
they share (``plots/style.py``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..io.h5md import RunFile, RunFileError
from .main import CliError, add_run_and_frame
from .paths import check_folder, check_target
from .plots.frame import LARGE_RUN as LARGE_RUN
from .plots.frame import _density, _field_or_flux, _figsize, _snapshot
from .plots.series import _fractal, _moment, _skeleton, _timeline
from .plots.style import _matplotlib, _save_png, plot_format
from .plots.summary import plot_summary as plot_summary

KINDS = ("snapshot", "density", "field", "flux", "timeline", "moment", "fractal", "skeleton")
#: kinds drawn over time (one file per run, not per frame)
SERIES_KINDS = ("timeline", "moment", "fractal", "skeleton")
#: bounds of the size-like options: a density profile of 10^4 shells is finer than any run's
#: rods resolve; 10^5 azimuthal samples per radius resolve a wire of radius 0.03 on a circle
#: of radius 500; more planes than 50 do not fit one figure
MAX_BINS = 10_000
MAX_N_PHI = 100_000
MAX_PLANES = 50
#: profiles reach at most this radius (L): the shipped scenes span tens of L, and the default
#: azimuthal sampling at this radius is MAX_N_PHI samples for the wires of D = 0.06
MAX_R_MAX = 500.0
#: kinds drawn from one frame (--frame / --time pick it)
FRAME_KINDS = ("snapshot", "density", "field", "flux")
#: the options that shape some figures only, and those figures ("movie": ``--movie``); any other is refused
KIND_OPTIONS = {
    "frame": FRAME_KINDS,
    "time": FRAME_KINDS,
    "every": ("moment", "fractal", "skeleton", "movie"),
    "bins": ("density",),
    "r_max": ("density", "field", "flux"),
    "planes": ("field", "flux"),
    "n_phi": ("field", "flux"),
    "z_mext": ("flux",),
}
#: the density profile's radial shells when --bins is not given
DEFAULT_BINS = 30
#: kinds that need the graph data (contacts, roles, currents) of the run
NEEDS_GRAPH = ("field", "flux", "timeline", "moment", "fractal", "skeleton")
#: the kinds drawn over the run's frames rather than of one frame
OVER_TIME = ("timeline", "moment", "fractal", "skeleton")


#: the resolution of a PNG when --dpi is not given (a movie has its own, cli/movie.py MOVIE_DPI)
PNG_DPI = 150


def add_arguments(p):
    add_run_and_frame(p)
    p.add_argument("--kind", choices=KINDS, default="snapshot", help="which figure (default: snapshot)")
    p.add_argument(
        "-o",
        "--output",
        help="PNG, PDF or SVG file to write, by its suffix, PNG without one (default next to the run file: RUN_KIND_frameK.png, or RUN_KIND.png for the "
        "kinds over time: timeline, moment, fractal, skeleton)",
    )
    p.add_argument("--force", action="store_true", help="overwrite an existing output file")
    p.add_argument(
        "--planes",
        type=float,
        nargs="+",
        metavar="Z",
        help="planes z = const for field and flux (default: the electrode planes and z = 0; in case (ii) "
        "z = +-(L_ext/2 - 0.02) and 0 as in Figs. 10-11; otherwise "
        "the lowest tip, 0 and the highest tip)",
    )
    p.add_argument(
        "--r-max", type=float, help="largest radius of the profiles (default: the farthest rod from the axis)"
    )
    p.add_argument("--bins", type=int, help=f"radial shells of the density profile (default {DEFAULT_BINS})")
    p.add_argument(
        "--n-phi",
        type=int,
        help="azimuthal samples of the field average (default: one per wire radius of arc "
        "on the largest circle, at least 64)",
    )
    p.add_argument(
        "--z-mext", type=float, help="flux in units of an external dipole's flux 4 pi Z_Mext instead of Phi_0 = 4 pi"
    )
    p.add_argument(
        "--dpi",
        type=int,
        default=None,
        help=f"resolution of a PNG (default {PNG_DPI}; a movie's 80); a PDF or SVG takes none",
    )
    p.add_argument(
        "--movie",
        metavar="OUT.gif|OUT.mp4",
        help="render the snapshot of every frame (or of every K-th, --every) into a movie: GIF with Pillow, "
        'MP4 with ffmpeg (pip install "selfas-graph[movie]" or a system ffmpeg)',
    )
    p.add_argument(
        "--every",
        type=int,
        metavar="K",
        help="moment, fractal, skeleton: every K-th frame and the last (default: at most 201 frames); --movie: every "
        "K-th frame and the last (default: every frame)",
    )


def _output_path(args, run_path: Path, frame: int) -> Path:
    if args.output:
        out = Path(args.output)
    elif args.kind in SERIES_KINDS:
        out = run_path.with_name(f"{run_path.stem}_{args.kind}.png")
    else:
        out = run_path.with_name(f"{run_path.stem}_{args.kind}_frame{frame}.png")
    check_target(out, "output file", force=True, inputs=[run_path], keep_hdf5=True)  # never written
    if plot_format(out) != "png" and args.dpi is not None:  # before whether it exists, as the suffix
        raise CliError(f"--dpi sets a PNG's resolution; {out.name} is drawn in vectors: leave --dpi out")
    check_target(out, "output file", force=args.force, inputs=[run_path], keep_hdf5=True)
    check_folder(out, "output file")
    return out


DRAW = {
    "snapshot": _snapshot,
    "density": _density,
    "field": _field_or_flux,
    "flux": _field_or_flux,
    "timeline": _timeline,
    "moment": _moment,
    "fractal": _fractal,
    "skeleton": _skeleton,
}


def _option_name(dest: str) -> str:
    return "--" + dest.replace("_", "-")


def _check_applies(args):
    """Refuse an option the figure asked for does not use (it would be ignored without a word)."""
    figure = "movie" if args.movie else args.kind
    if args.movie and args.output:
        raise CliError(f"-o names a figure's file; a movie is written to its --movie name ({args.movie}): leave -o out")
    for dest, kinds in KIND_OPTIONS.items():
        if getattr(args, dest) is None or figure in kinds:
            continue
        named = [k for k in kinds if k != "movie"]
        uses = f"--kind {', '.join(named[:-1])}{' or ' if len(named) > 1 else ''}{named[-1]}"
        uses += " and by --movie" if "movie" in kinds else ""
        asked = "--movie" if args.movie else f"--kind {args.kind}"
        hint = " (a figure over time draws every frame)" if dest in ("frame", "time") and not args.movie else ""
        raise CliError(f"{_option_name(dest)} is used by {uses}, not by {asked}{hint}; leave it out")


def _check_options(args):
    if args.dpi is not None and not 10 <= args.dpi <= 1200:
        raise CliError(f"--dpi must be between 10 and 1200, got {args.dpi}")
    # size-like options are bounded: a figure is drawn in seconds, not minutes
    if args.bins is not None and not 1 <= args.bins <= MAX_BINS:
        raise CliError(f"--bins must be between 1 and {MAX_BINS}, got {args.bins}")
    if args.n_phi is not None and not 1 <= args.n_phi <= MAX_N_PHI:
        raise CliError(f"--n-phi must be between 1 and {MAX_N_PHI}, got {args.n_phi}")
    if args.planes and len(args.planes) > MAX_PLANES:
        raise CliError(f"--planes takes at most {MAX_PLANES} planes, got {len(args.planes)}")
    if args.r_max is not None and not (np.isfinite(args.r_max) and 0 < args.r_max <= MAX_R_MAX):
        raise CliError(f"--r-max must be a radius > 0 and at most {MAX_R_MAX:g} L, got {args.r_max}")
    if args.planes and not all(np.isfinite(z) for z in args.planes):
        raise CliError(f"--planes must be finite numbers, got {args.planes}")
    if args.every is not None and args.every < 1:
        raise CliError(f"--every must be >= 1, got {args.every}")
    if args.time is not None and not np.isfinite(args.time):
        raise CliError(f"--time {args.time} names no frame; give a finite simulated time")
    _check_applies(args)
    if args.bins is None:
        args.bins = DEFAULT_BINS


def run(args):
    _check_options(args)
    Figure = _matplotlib()
    if args.movie:
        from .movie import render_movie

        return render_movie(args, Figure)
    try:
        with RunFile(args.run) as f:
            try:
                frame = f.frame(args.frame, t=args.time)
                if args.kind in OVER_TIME:  # any frame's graph data: a frame without (a torn record) is a gap
                    if not f.has_graph:
                        f.graph_frame_index(frame.index)  # raises the reader's explanation
                elif args.kind in NEEDS_GRAPH:
                    frame.require_graph(args.kind)
                out = _output_path(args, f.path, frame.index)
                fig = Figure(figsize=_figsize(args.kind, frame), layout="constrained")
                DRAW[args.kind](fig, f, frame, args)
            except RunFileError:
                raise  # the reader's own explanation (a frame or time the run does not have)
            except (KeyError, IndexError, TypeError, AttributeError, ValueError) as exc:
                # a file with the run layout but inconsistent contents (foreign or damaged; a
                # parameters_json that is not JSON is a ValueError)
                raise RunFileError(f"{f.path}: inconsistent run data ({type(exc).__name__}: {exc})") from None
    except RunFileError as exc:
        raise CliError(str(exc)) from None
    _save_png(fig, out, PNG_DPI if args.dpi is None else args.dpi)
    print(f"wrote {out}")
    return 0
