"""The figures of one saved frame: ``snapshot`` (the rods in 3-D), ``density`` (rods per unit volume
against r), ``field`` and ``flux`` (B_z of the rod currents and its flux through discs), and the
figure size a frame asks for."""

from __future__ import annotations

import numpy as np

from ...analysis import bz_profile, flux_through_disc, radial_density, rod_centres
from ...analysis.episodes import circuit_episodes
from ...model.graph import DEAD_END, FILAMENT
from ..main import CliError
from .style import (
    DEAD_END_COLOUR,
    ELECTRODE_COLOUR,
    FILAMENT_COLOUR,
    LARGEST_COLOUR,
    OTHER_COLOUR,
    PLASMA_STYLE,
    TOTAL_COLOUR,
    _num,
    _outside_legend,
    _title,
    filament_label,
)

#: above this many rods a snapshot colours the largest structure instead of dead ends (paper Fig. 6)
LARGE_RUN = 3000


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
        # the dead ends that are not red (topology counts every dead end): named in the grey rods' count
        grey_dead = int(((role == DEAD_END) & rest).sum())
        other = (
            f"other rods ({{n}}; {grey_dead} of them dead ends off the filament networks)"
            if grey_dead
            else "other rods"
        )
        groups += [
            (rest, OTHER_COLOUR, 0.6, other),
            (fil, FILAMENT_COLOUR, 1.6, filament_label(run)),
            (red, DEAD_END_COLOUR if not large else LARGEST_COLOUR, 1.6, red_label),
        ]
    handles = []
    for mask, colour, width, label in groups:
        alpha = 0.6 if colour is OTHER_COLOUR and role is not None else 1.0
        if mask.any():
            ax.add_collection3d(Line3DCollection(seg[mask], colors=[colour], linewidths=width, alpha=alpha, zorder=2))
        text = label.format(n=int(mask.sum())) if "{n}" in label else f"{label} ({int(mask.sum())})"
        handles.append(Line2D([], [], color=colour, lw=2, alpha=alpha, label=text))
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
    if args.r_max is None:  # the shells are half-open: the farthest rod, at r_max, falls in the last one
        r_max = float(np.nextafter(r_max, np.inf))
    curves = [("total", None, TOTAL_COLOUR)]
    if frame.role is not None:
        curves += [
            (f"in {filament_label(run)}", frame.role == FILAMENT, FILAMENT_COLOUR),
            ("in the largest structure", frame.largest_mask, LARGEST_COLOUR),
        ]
    for label, mask, colour in curves:
        edges, dens = radial_density(centre, r_max, args.bins, z_range, mask=mask)
        n = len(centre) if mask is None else int(mask.sum())
        counted = int(np.rint(np.sum(dens * np.pi * np.diff(edges**2) * (z_range[1] - z_range[0]))))
        rods = f"{n} rods" if counted == n else f"{counted} of {n} rods within r_max"
        ax.plot(0.5 * (edges[1:] + edges[:-1]), dens, "-o", ms=2.5, lw=1.2, color=colour, label=f"{label} ({rods})")
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
            "no rod carries current (no filament has joined two conductors yet)"
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
