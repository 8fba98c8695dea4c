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
* ``fractal``  -- the mass-radius and box-counting dimensions of the largest structure and
  the R_g ~ N^(1/D) dimension over all structures vs time, with their uncertainties.
* ``skeleton`` -- the cycle rank of the contact graph (and of the largest structure) vs time.

The last three read :func:`selfas_graph.analysis.claims.claims_series` (``--every K``: every
K-th frame; default at most 200 frames).

The output goes next to the run file as ``RUN_KIND_frameK.png`` (``RUN_timeline.png``
for the timeline) unless ``-o`` says otherwise; an existing file is kept unless
``--force``. Needs matplotlib (``pip install "selfas-graph[plot]"``); draws headless.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..analysis import bz_profile, flux_through_disc, radial_density, rod_centres, timeline
from ..analysis.episodes import circuit_episodes
from ..io.frame import SavedFrame
from ..io.h5md import RunFile, RunFileError
from ..model.graph import DEAD_END, FILAMENT
from .main import CliError, CliIOError, add_run_and_frame
from .paths import check_target

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
#: kinds that need the graph data (contacts, roles, currents) of the run
NEEDS_GRAPH = ("field", "flux", "timeline", "moment", "fractal", "skeleton")
#: above this many rods a snapshot colours the largest structure instead of dead ends (paper Fig. 6)
LARGE_RUN = 3000

# the paper's colours
FILAMENT_COLOUR = "blue"
DEAD_END_COLOUR = "red"
LARGEST_COLOUR = "red"
TOTAL_COLOUR = "green"
OTHER_COLOUR = (0.55, 0.55, 0.55)
ELECTRODE_COLOUR = (0.85, 0.65, 0.15)
PLASMA_STYLE = dict(color=(0.2, 0.6, 0.3), lw=0.9, ls="--", zorder=1)


def add_arguments(p):
    add_run_and_frame(p)
    p.add_argument("--kind", choices=KINDS, default="snapshot", help="which figure (default: snapshot)")
    p.add_argument("-o", "--output", help="PNG file to write (default: RUN_KIND_frameK.png next to the run file)")
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
    p.add_argument("--bins", type=int, default=30, help="radial shells of the density profile (default 30)")
    p.add_argument(
        "--n-phi",
        type=int,
        help="azimuthal samples of the field average (default: one per wire radius of arc "
        "on the largest circle, at least 64)",
    )
    p.add_argument(
        "--z-mext", type=float, help="flux in units of an external dipole's flux 4 pi Z_Mext instead of Phi_0 = 4 pi"
    )
    p.add_argument("--dpi", type=int, default=150, help="resolution of the PNG (default 150; a movie's 80)")
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
        help="moment, fractal, skeleton: every K-th frame (default: at most 200 frames)",
    )


def _matplotlib():
    """Import matplotlib lazily (the package works without it) and pick the headless backend."""
    try:
        import matplotlib
    except ImportError:
        raise CliError('plotting needs matplotlib: pip install "selfas-graph[plot]"') from None
    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    return Figure


def _output_path(args, run_path: Path, frame: int) -> Path:
    if args.output:
        out = Path(args.output)
    elif args.kind in SERIES_KINDS:
        out = run_path.with_name(f"{run_path.stem}_{args.kind}.png")
    else:
        out = run_path.with_name(f"{run_path.stem}_{args.kind}_frame{frame}.png")
    check_target(out, "output file", force=args.force, inputs=[run_path])
    if not out.parent.exists():
        raise CliError(f"the folder {out.parent} of the output file does not exist")
    return out


def _scene(run: RunFile) -> str:
    """The scene's name for titles (a figure names its scene and time, not its file)."""
    name = str((run.parameters.get("scenario") or {}).get("name") or "run")
    return {"fig2": "Fig. 2 scene", "fig6": "Fig. 6 scene", "fig8": "Fig. 8 scene"}.get(name, f"{name} scene")


def _title(run: RunFile, frame: SavedFrame, what: str) -> str:
    return f"{_scene(run)}: {what}, t = {frame.time:.4g} $t_0$"


def _outside_legend(fig, handles=None, ncols=2):
    """A legend below the axes, off the data and clear of the title (constrained layout makes room for it)."""
    kw = {} if handles is None else {"handles": handles}
    fig.legend(loc="outside lower center", ncols=ncols, fontsize="small", frameon=False, **kw)


def _num(x, fmt=".4g"):
    """A number for a label, negative with a typographic minus sign (as the tick labels have)."""
    return format(x, fmt).replace("-", "\N{MINUS SIGN}")


#: a time series with more points than this is drawn as a thin line without markers
MARKERS_UP_TO = 40


def _series_style(n):
    return dict(lw=1.0) if n > MARKERS_UP_TO else dict(lw=1.2, marker="o", ms=2.5)


# --------------------------------------------------------------------------- kinds
def _snapshot(fig, run, frame, args):
    from matplotlib.lines import Line2D
    from mpl_toolkits.mplot3d.art3d import Line3DCollection, Poly3DCollection

    ax = fig.add_subplot(projection="3d")
    # draw in the order given: the translucent electrode planes first, the rods over them (the
    # depth sort of mplot3d would otherwise let a plane veil every rod behind it)
    ax.computed_zorder = False
    seg = frame.position.reshape(frame.n_rods, 2, 3)
    role = frame.role
    large = frame.n_rods > LARGE_RUN
    groups = []  # (mask, colour, width, label)
    if role is None:
        groups.append((np.ones(frame.n_rods, dtype=bool), OTHER_COLOUR, 0.8, "rods (no graph data)"))
    else:
        fil = role == FILAMENT
        if large:
            red, red_label = frame.largest_mask, "largest structure"
            fil = fil & ~red
        else:
            # the paper's red: "dead ends within the network of short-circuited filaments", i.e.
            # DEAD_END rods of a structure that holds filament rods; dead ends of structures that
            # touch only one electrode stay grey
            networks = np.unique(frame.structure[role == FILAMENT])
            red = (role == DEAD_END) & np.isin(frame.structure, networks)
            red_label = "dead ends of filament networks"
        rest = ~(fil | red)
        groups += [
            (rest, OTHER_COLOUR, 0.6, "other rods"),
            (fil, FILAMENT_COLOUR, 1.6, "current-carrying filaments"),
            (red, DEAD_END_COLOUR if not large else LARGEST_COLOUR, 1.6, red_label),
        ]
    handles = []
    for mask, colour, width, label in groups:
        alpha = 0.6 if colour is OTHER_COLOUR and role is not None else 1.0
        if mask.any():
            ax.add_collection3d(Line3DCollection(seg[mask], colors=[colour], linewidths=width, alpha=alpha, zorder=2))
        handles.append(Line2D([], [], color=colour, lw=2, alpha=alpha, label=f"{label} ({int(mask.sum())})"))
    lo, hi = frame.position.min(axis=0), frame.position.max(axis=0)
    plasma = frame.plasma
    if plasma:  # the R_plas cylinder is drawn: the box holds it
        (px, py), r_p = plasma.get("axis", (0.0, 0.0)), float(plasma["radius"])
        lo[:2] = np.minimum(lo[:2], [px - r_p, py - r_p])
        hi[:2] = np.maximum(hi[:2], [px + r_p, py + r_p])
    if frame.gap is not None:
        lo[2], hi[2] = min(lo[2], -frame.gap / 2), max(hi[2], frame.gap / 2)
        x0, x1, y0, y1 = lo[0] - 0.5, hi[0] + 0.5, lo[1] - 0.5, hi[1] + 0.5
        for z, name in ((-frame.gap / 2, "cathode"), (frame.gap / 2, "anode")):
            rect = [[(x0, y0, z), (x1, y0, z), (x1, y1, z), (x0, y1, z)]]
            ax.add_collection3d(
                Poly3DCollection(
                    rect, facecolors=[ELECTRODE_COLOUR], edgecolors=[ELECTRODE_COLOUR], alpha=0.12, zorder=0
                )
            )
        handles.append(
            Line2D([], [], color=ELECTRODE_COLOUR, lw=6, alpha=0.4, label=f"electrodes z = $\\pm${frame.gap / 2:g} L")
        )
    if plasma:
        # the plasma filament: a dashed cylinder of radius R_plas about its axis, between the electrodes
        (ax0, ay0), r_p = plasma.get("axis", (0.0, 0.0)), float(plasma["radius"])
        z_lo, z_hi = (-frame.gap / 2, frame.gap / 2) if frame.gap is not None else (lo[2], hi[2])
        phi = np.linspace(0.0, 2 * np.pi, 97)
        for z in (z_lo, z_hi):
            ax.plot(ax0 + r_p * np.cos(phi), ay0 + r_p * np.sin(phi), np.full_like(phi, z), **PLASMA_STYLE)
        for a in (0.25 * np.pi, 1.25 * np.pi):
            ax.plot([ax0 + r_p * np.cos(a)] * 2, [ay0 + r_p * np.sin(a)] * 2, [z_lo, z_hi], **PLASMA_STYLE)
        handles.append(Line2D([], [], label=f"plasma filament, $R_{{plas}}$ = {r_p:g} L", **PLASMA_STYLE))
    if frame.dipole is not None or frame.external_filament:
        if frame.dipole is not None:
            half = frame.dipole[1] / 2
            ax.plot([0, 0], [0, 0], [-half, half], color="black", lw=3, zorder=1)
            handles.append(
                Line2D([], [], color="black", lw=3, label=f"external dipole, $Z_{{Mext}}$ = {frame.dipole[0]:g}")
            )
            lo[2], hi[2] = min(lo[2], -half), max(hi[2], half)
        if frame.external_filament:
            ax.plot([0, 0], [0, 0], [lo[2], hi[2]], color="black", lw=0.8, ls="--", zorder=1)
            handles.append(Line2D([], [], color="black", lw=0.8, ls="--", label="current filament (z axis)"))
    if getattr(args, "bounds", None) is not None:  # a movie: the same box in every frame
        lo, hi = (np.array(b, dtype=np.float64) for b in args.bounds)
    span = np.maximum(hi - lo, 1e-6)
    pad = 0.02 * span.max()
    ax.set_xlim(lo[0] - pad, hi[0] + pad)
    ax.set_ylim(lo[1] - pad, hi[1] + pad)
    ax.set_zlim(lo[2] - pad, hi[2] + pad)
    # framed on the rods: the box has the scene's proportions and fills the figure, whose shape
    # run() chooses from the same proportions (a tall case (ii) column gets a tall figure)
    # a tall box (the Fig. 6 column) is drawn small inside its axes by mplot3d's projection: zoom
    # it so that it fills the figure's height (the figure's own shape follows the same ratio)
    tall = float(span[2] / max(span[0], span[1]))
    ax.set_box_aspect(tuple(span + 2 * pad), zoom=0.95 * min(1.25, max(1.0, tall**0.17)))
    ax.set_xlabel("x (L)")
    ax.set_ylabel("y (L)")
    ax.set_zlabel("z (L)", labelpad=10)
    # labels clear of the tick marks, so that the minus signs of negative ticks stay visible
    ax.tick_params(axis="z", pad=6)
    ax.tick_params(axis="x", pad=2)
    ax.tick_params(axis="y", pad=2)
    fig.legend(handles=handles, loc="outside lower center", ncols=2, fontsize="small", frameon=False)
    fig.suptitle(_title(run, frame, f"{frame.n_rods} rods"), fontsize="medium")


def _r_max(args, points):
    if args.r_max is not None:
        if not args.r_max > 0:
            raise CliError(f"--r-max must be > 0, got {args.r_max}")
        return float(args.r_max)
    r = float(np.hypot(points[:, 0], points[:, 1]).max()) if len(points) else 0.0
    return r if r > 0 else 1.0


def _density(fig, run, frame, args):
    ax = fig.add_subplot()
    centre = rod_centres(frame.position)
    if frame.gap is not None:
        z_range = (-frame.gap / 2, frame.gap / 2)
    else:
        z_range = (float(centre[:, 2].min()), float(centre[:, 2].max()))
        if z_range[1] <= z_range[0]:
            z_range = (z_range[0] - 0.5, z_range[0] + 0.5)
    if args.bins < 1:
        raise CliError(f"--bins must be >= 1, got {args.bins}")
    r_max = _r_max(args, centre)
    curves = [("total", None, TOTAL_COLOUR)]
    if frame.role is not None:
        curves += [
            ("in current-carrying filaments", frame.role == FILAMENT, FILAMENT_COLOUR),
            ("in the largest structure", frame.largest_mask, LARGEST_COLOUR),
        ]
    for label, mask, colour in curves:
        edges, dens = radial_density(centre, r_max, args.bins, z_range, mask=mask)
        n = len(centre) if mask is None else int(mask.sum())
        ax.plot(0.5 * (edges[1:] + edges[:-1]), dens, "-o", ms=2.5, lw=1.2, color=colour, label=f"{label} ({n} rods)")
    ax.set_xlim(0, r_max)
    ax.set_ylim(bottom=0)
    ax.set_xlabel("distance from the z axis r (L)")
    ax.set_ylabel("rod density (rods / $L^3$)")
    _outside_legend(fig, ncols=3)
    note = "" if frame.role is not None else " (no graph data: total only)"
    ax.set_title(
        _title(run, frame, "radial density")
        + note
        + f"\naveraged over {_num(z_range[0], '.3g')} $\\leq$ z $\\leq$ {_num(z_range[1], '.3g')} L and azimuth",
        fontsize="medium",
    )


def _planes(args, frame):
    if args.planes:
        return sorted(args.planes)
    if frame.gap is not None:
        return [-frame.gap / 2, 0.0, frame.gap / 2]
    if frame.dipole is not None:
        # paper Figs. 10-11: planes just inside the dipole's ends (z = +-9.98 for L_ext = 20)
        half = frame.dipole[1] / 2 - 0.02
        return [-half, 0.0, half]
    z = frame.position[:, 2]
    return [float(z.min()), 0.0, float(z.max())]


def _plane_colours(planes):
    """The paper's blue / black / red for three planes (lowest to highest); a colormap otherwise."""
    if len(planes) == 3:
        return ["blue", "black", "red"]
    if len(planes) <= 2:
        return ["blue", "red"][: len(planes)]
    import matplotlib

    cmap = matplotlib.colormaps["coolwarm"]
    return [cmap(i / (len(planes) - 1)) for i in range(len(planes))]


def _field_or_flux(fig, run, frame, args):
    frame.require_graph(args.kind)
    if args.n_phi is not None and args.n_phi < 1:
        raise CliError(f"--n-phi must be >= 1, got {args.n_phi}")
    if args.z_mext is not None and not (np.isfinite(args.z_mext) and args.z_mext != 0):
        raise CliError(f"--z-mext must be a nonzero number, got {args.z_mext}")
    if args.z_mext is None and frame.dipole is not None and args.kind == "flux":
        args.z_mext = frame.dipole[0]  # case (ii): flux in units of the dipole's 4 pi Z_Mext (paper Fig. 11)
    current = frame.graph["current"]
    r_max = _r_max(args, frame.position)
    planes = _planes(args, frame)
    ax = fig.add_subplot()
    if args.kind == "field":
        r = np.linspace(0.0, r_max, 201)
    else:
        r = np.linspace(0.0, r_max, 101)
    for z, colour in zip(planes, _plane_colours(planes)):
        if args.kind == "field":
            y = bz_profile(r, z, frame.position, None, current, frame.wire_radius, n_phi=args.n_phi)
        else:
            y = flux_through_disc(
                r, z, frame.position, None, current, frame.wire_radius, n_phi=args.n_phi, z_mext=args.z_mext
            )
        ax.plot(r, y, color=colour, label=f"plane z = {_num(z)} L")
    ax.axhline(0.0, color="0.7", lw=0.8, zorder=0)
    ax.set_xlim(0, r_max)
    n_active = int(np.count_nonzero(current))
    if n_active:
        note = f"{n_active} rods carry current"
    else:
        closed = len(circuit_episodes(run.events(until_step=frame.step)))
        note = (
            "no rod carries current (the electrodes have not been short-circuited yet)"
            if closed == 0
            else f"no rod carries current at this frame (the gap closed {closed} time{'s' if closed > 1 else ''} before)"
        )
    if args.kind == "field":
        ax.set_xlabel("distance from the z axis r (L)")
        ax.set_ylabel("$B_z$ of the rod currents ($B_0$), azimuthal mean")
        ax.set_title(_title(run, frame, "$B_z$ of the rod currents") + f"\n{note}", fontsize="medium")
    else:
        ax.set_xlabel("disc radius R (L)")
        if args.z_mext is None:
            unit = "$\\Phi_0 = 4\\pi B_0 L^2$"
        else:
            unit = f"$4\\pi Z_{{Mext}}$, $Z_{{Mext}}$ = {args.z_mext:g}"
        ax.set_ylabel(f"flux of the rod currents' $B_z$ (units of {unit})")
        ax.set_title(_title(run, frame, "magnetic flux through discs") + f"\n{note}", fontsize="medium")
    _outside_legend(fig, ncols=min(len(planes), 4))


def _figsize(kind, frame):
    """Figure size in inches: snapshots take the proportions of the rods' extent (height over width)."""
    if kind != "snapshot":
        return (7.0, 5.5)
    lo, hi = frame.position.min(axis=0), frame.position.max(axis=0)
    width = max(float(max(hi[0] - lo[0], hi[1] - lo[1])), 1e-6)
    height = float(hi[2] - lo[2])
    if frame.gap is not None:
        height = max(height, frame.gap)
    if frame.dipole is not None:
        height = max(height, frame.dipole[1])
    ratio = min(max(height / width, 0.6), 2.2)
    return (7.0, 7.0 * ratio**0.6 + 0.8) if ratio > 1 else (8.0, 7.0)


def _timeline(fig, run, frame, args):
    if "rods/filament" not in run.observable_names():
        raise CliError(f"{run.path}: no 'rods/filament' observable, which the timeline plot needs")
    t, n_fil = run.observable("rods/filament")
    total = run.observable("total_current")[1] if "total_current" in run.observable_names() else None
    tl = timeline(t, n_fil, total, run.events())
    ax = fig.add_subplot()
    style = _series_style(len(tl.time))
    lines = ax.plot(tl.time, tl.n_filament, color=FILAMENT_COLOUR, label="rods in filaments", **style)
    ax.set_xlabel("time t ($t_0$)")
    ax.set_ylabel("rods in current-carrying filaments", color=FILAMENT_COLOUR)
    ax.set_ylim(bottom=0)
    if tl.total_current is not None and np.nanmax(np.abs(tl.total_current), initial=0.0) > 0:
        ax2 = ax.twinx()
        lines += ax2.plot(
            tl.time,
            tl.total_current,
            color="black",
            label="total current",
            **(style | ({"marker": "s"} if "marker" in style else {})),
        )
        ax2.set_ylabel("total current ($J_0$)")
        ax2.set_ylim(bottom=min(0.0, float(np.nanmin(tl.total_current))))
    # the episodes of a closed gap at the times of their events, not of the frames: a closing
    # shorter than the frame interval is drawn too (at least 0.3 % of the time axis wide)
    ep = circuit_episodes(run.events())
    t_last = float(run.time[-1]) if run.n_frames else 0.0
    width = 3e-3 * max(t_last, 1e-9)
    for k, (a, b) in enumerate(zip(ep.start, ep.end)):
        b = t_last if not np.isfinite(b) else b
        span = ax.axvspan(a, max(b, a + width), color=FILAMENT_COLOUR, alpha=0.15, lw=0)
        if k == 0:
            span.set_label("electrodes short-circuited")
            lines.append(span)
    _outside_legend(fig, lines, ncols=3)
    if len(ep) == 0:
        sc = "the gap never closed"
    else:
        sc = f"first short circuit at t = {ep.start[0]:.4g} $t_0$, {len(ep)} closing{'s' if len(ep) > 1 else ''}"
    ax.set_title(f"{_scene(run)}: filaments over time ({sc})", fontsize="medium")


def _series(run, args):
    from ..analysis.claims import claims_series

    every = args.every if args.every is not None else max(1, -(-run.n_frames // 200))
    if every < 1:
        raise CliError(f"--every must be >= 1, got {every}")
    return claims_series(run, range(0, run.n_frames, every), loops=False)


def _moment(fig, run, frame, args):
    s = _series(run, args)
    ax = fig.add_subplot()
    style = _series_style(len(s["time"]))  # markers on short series: a value between NaNs stays visible
    lines = ax.plot(
        s["time"], s["largest_moment_ratio"], **style, color=LARGEST_COLOUR, label="$|m_q|$ / mean rod moment"
    )
    ax.set_xlabel("time t ($t_0$)")
    ax.set_ylabel("$|m_q|$ of the largest structure / mean $|q|$")
    ax.set_ylim(bottom=0)
    m_j = s["largest_moment_J_z"]
    note = ""
    if np.nanmax(np.abs(m_j), initial=0.0) > 0:  # a second axis only for a series that is not all zero
        ax2 = ax.twinx()
        lines += ax2.plot(s["time"], m_j, **style, color=FILAMENT_COLOUR, label="$m_{J,z}$ of its rod currents")
        ax2.set_ylabel("$m_{J,z}$ of the rod currents ($J_0 L^2$)")
        ax2.axhline(0.0, color="0.8", lw=0.8, zorder=0)
    else:
        note = " (no rod current in these frames)"
    _outside_legend(fig, lines, ncols=2)
    ax.set_title(f"{_scene(run)}: magnetic moment of the largest structure{note}", fontsize="medium")


def _fractal(fig, run, frame, args):
    s = _series(run, args)
    ax = fig.add_subplot()
    for key, colour, label in (
        ("fractal_dimension", LARGEST_COLOUR, "mass-radius, largest structure"),
        ("rg_dimension", TOTAL_COLOUR, r"$R_g \sim N^{1/D}$ over all structures"),
    ):
        y, err = s[key], s[key + "_err"]
        ax.plot(s["time"], y, **_series_style(len(y)), color=colour, label=label)
        ax.fill_between(s["time"], y - err, y + err, color=colour, alpha=0.1, lw=0)
    for d in (1, 2, 3):
        ax.axhline(d, color="0.85", lw=0.8, zorder=0)
    finite = np.concatenate([s[k][np.isfinite(s[k])] for k in ("fractal_dimension", "rg_dimension")])
    ax.set_ylim(0, max(3.5, float(finite.max()) + 0.2) if finite.size else 3.5)
    ax.set_xlabel("time t ($t_0$)")
    ax.set_ylabel("dimension D (bands: uncertainty)")
    _outside_legend(fig, ncols=2)
    ax.set_title(f"{_scene(run)}: fractal dimensions", fontsize="medium")


def _skeleton(fig, run, frame, args):
    s = _series(run, args)
    ax = fig.add_subplot()
    style = _series_style(len(s["time"]))
    ax.plot(s["time"], s["cycle_rank"], **style, color="black", label="contact graph")
    ax.plot(s["time"], s["cycle_rank_largest"], **style, color=LARGEST_COLOUR, label="largest structure")
    ax.set_ylim(bottom=0)
    ax.set_xlabel("time t ($t_0$)")
    ax.set_ylabel("cycle rank E - V + C (independent loops)")
    _outside_legend(fig, ncols=2)
    ax.set_title(f"{_scene(run)}: loops of the rod network", fontsize="medium")


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


def _check_options(args):
    if not 10 <= args.dpi <= 1200:
        raise CliError(f"--dpi must be between 10 and 1200, got {args.dpi}")
    # size-like options are bounded: a figure is drawn in seconds, not minutes
    if not 1 <= args.bins <= MAX_BINS:
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
                if args.kind in NEEDS_GRAPH:
                    frame.require_graph(args.kind)
                out = _output_path(args, f.path, frame.index)
                fig = Figure(figsize=_figsize(args.kind, frame), layout="constrained")
                DRAW[args.kind](fig, f, frame, args)
            except (KeyError, IndexError, TypeError, AttributeError, ValueError) as exc:
                # a file with the run layout but inconsistent contents (foreign or damaged; a
                # parameters_json that is not JSON is a ValueError)
                raise RunFileError(f"{f.path}: inconsistent run data ({type(exc).__name__}: {exc})") from None
    except RunFileError as exc:
        raise CliError(str(exc)) from None
    _save_png(fig, out, args.dpi)
    print(f"wrote {out}")
    return 0


# --------------------------------------------------------------------------- ensembles
def _save_png(fig, out: Path, dpi):
    """Draw aside and rename into place: a failed write (full disk) leaves no partial PNG."""
    tmp = out.with_name(out.name + ".tmp")
    try:
        fig.savefig(tmp, dpi=dpi, format="png")
        os.replace(tmp, out)
    except OSError as exc:
        try:
            tmp.unlink()
        except OSError:
            pass
        raise CliIOError(f"cannot write {out}: {exc.strerror or exc}") from None


def plot_summary(summary: dict, out, title: str, dpi=150, measures=None) -> Path:
    """The measures of an ensemble summary (:func:`selfas_graph.ensemble.summarise`) against
    time: mean over seeds with a band of one standard error, one panel per measure, the
    number of seeds behind each time in the lowest panel's labels."""
    Figure = _matplotlib()
    names = [m for m in (measures or summary["measures"]) if m in summary["measures"]]
    if not names:
        raise CliError("the ensemble summary holds none of the measures to plot")
    times = np.asarray(summary["times"], dtype=np.float64)
    ncols = 2 if len(names) > 3 else 1
    nrows = -(-len(names) // ncols)
    fig = Figure(figsize=(4.2 * ncols, 2.0 * nrows + 0.8), layout="constrained")
    axes = fig.subplots(nrows, ncols, sharex=True, squeeze=False).ravel()
    style = _series_style(len(times))
    for ax, name in zip(axes, names):
        m = summary["measures"][name]
        mean = np.array([np.nan if v is None else v for v in m["mean"]], dtype=np.float64)
        sem = np.array([np.nan if v is None else v for v in m["sem"]], dtype=np.float64)
        ax.plot(times, mean, color="black", **style)
        ax.fill_between(times, mean - sem, mean + sem, color="0.6", alpha=0.5, lw=0)
        unit = m.get("unit") or ""
        words = (m.get("doc") or name.replace("_", " ")).split(" (")[0]
        ax.set_title(words[0].upper() + words[1:], fontsize="small", loc="left")
        if unit not in ("", "1"):
            ax.set_ylabel(unit.replace("Phi_0", r"$\Phi_0$").replace("J0", "$J_0$"), fontsize="small")
    for ax in axes[len(names) :]:
        ax.set_visible(False)
    for ax in axes[max(0, len(names) - ncols) : len(names)]:
        ax.set_xlabel("t [$t_0$]")
        ax.tick_params(labelbottom=True)
    # seeds behind each time: where the count changes (shorter runs end), a dotted line, and
    # the count after it in the first panel
    n = np.asarray(summary["measures"][names[0]]["n"])
    starts = [0] + [k for k in range(1, len(n)) if n[k] != n[k - 1]]
    for j, k in enumerate(starts):
        if n[k] == 0:
            continue
        for ax in axes[: len(names)]:
            if k:
                ax.axvline(times[k], color="0.5", lw=0.6, ls=":")
        axes[0].annotate(
            f"{n[k]} seed{'s' if n[k] != 1 else ''}",
            (times[k], 1.0),
            xycoords=("data", "axes fraction"),
            xytext=(2, -2 - 8 * (j % 2)),
            textcoords="offset points",
            ha="left",
            va="top",
            fontsize="x-small",
            color="0.3",
        )
    fig.suptitle(
        f"{title}: mean \N{PLUS-MINUS SIGN} one standard error over the seeds with a frame at each time",
        fontsize="medium",
    )
    out = Path(out)
    _save_png(fig, out, dpi)
    return out
