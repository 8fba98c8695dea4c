"""The figures over time, one per run: ``timeline`` (rods in filaments, total current), ``moment``,
``fractal`` and ``skeleton`` (the claims' measures, :func:`selfas_graph.analysis.claims.claims_series`)."""

from __future__ import annotations

import numpy as np

from ...analysis import timeline
from ...analysis.episodes import circuit_episodes
from ..main import CliError
from .style import (
    FILAMENT_COLOUR,
    LARGEST_COLOUR,
    TOTAL_COLOUR,
    _outside_legend,
    _scene,
    _series_style,
)


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
    from ...analysis.claims import claims_series

    every = args.every if args.every is not None else max(1, -(-run.n_frames // 200))
    if every < 1:
        raise CliError(f"--every must be >= 1, got {every}")
    frames = list(range(0, run.n_frames, every))
    if frames and frames[-1] != run.n_frames - 1:  # the run's last frame too, as a movie shows it
        frames.append(run.n_frames - 1)
    return claims_series(run, frames, loops=False)


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
    from matplotlib.ticker import MaxNLocator

    ax.yaxis.set_major_locator(MaxNLocator(integer=True))  # a count of loops: no half-integer ticks
    ax.set_xlabel("time t ($t_0$)")
    ax.set_ylabel("cycle rank E - V + C (independent loops)")
    _outside_legend(fig, ncols=2)
    ax.set_title(f"{_scene(run)}: loops of the rod network", fontsize="medium")
