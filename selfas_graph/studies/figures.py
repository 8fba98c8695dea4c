"""The figures of a study: its measures against time over the seeds, its short-circuit episodes at
event time, and a snapshot of one seed's last frame (matplotlib, PNG; one style for every figure)."""

from __future__ import annotations

import math
import textwrap
import warnings
from pathlib import Path

import numpy as np

from .page import has_electrodes
from .stats import CLAIM_MEASURES, FIT_ERRORS, GROUPED, LABELS
from .sweeps import sweep_points

__all__ = ["SERIES_MEASURES", "plot_episodes", "plot_series", "series_panels", "study_figures"]

#: the panels of a study's time-series figure
SERIES_MEASURES = (
    "filament_rods",
    "total_current",
    "inside_R_plas",
    "largest_structure_rods",
    "largest_alignment",
    "midplane_flux",
    "fractal_dimension",
    "cycle_rank",
)
SEED_COLOUR, MEAN_COLOUR, FREE_COLOUR = "#4477aa", "black", "#cc6677"


def _figure(**kw):
    from matplotlib.figure import Figure

    return Figure(layout="constrained", **kw)


def _words_unit(measure):
    """A panel's title in words and its axis unit, as matplotlib draws them."""
    words, unit = LABELS.get(measure, (measure.replace("_", " "), ""))
    words = words[0].upper() + words[1:]
    unit = unit.replace("Phi_0", r"$\Phi_0$").replace("J0", "$J_0$").replace("L^2", "$L^2$")
    return words, unit


def _save(fig, path):
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp.png")
    fig.savefig(tmp, dpi=150)
    tmp.replace(path)
    return path


def series_panels(summary) -> list:
    """The measures of :data:`SERIES_MEASURES` the study has, a value somewhere (no R_plas without a
    plasma filament: the median distance from the axis takes its panel; the alignment panel wherever
    the largest structure's or the free rods' alignment has one)."""

    def present(m):
        return m in summary["measures"] and any(x is not None for row in summary["measures"][m]["values"] for x in row)

    names = [m if present(m) or m != "inside_R_plas" else "median_axis_distance" for m in SERIES_MEASURES]
    # the alignment panel also draws the rods in no structure (all of them where none stick)
    return [m for m in names if present(m) or (m == "largest_alignment" and present("free_alignment"))]


def plot_series(summary, out, title) -> Path:
    """Each measure against time: every seed as a thin line, the mean over seeds and one standard
    error as a band where the measure is not split by the circuit (module :mod:`.page`); a fitted
    dimension's band is the spread between seeds alone, which its panel's title says (the tables add
    each seed's fit error)."""
    names = series_panels(summary)
    electrodes = has_electrodes(summary)
    t = np.asarray(summary["times"], dtype=float)
    ncols = 2
    nrows = math.ceil(len(names) / ncols)
    fig = _figure(figsize=(7.2, 2.0 * nrows + 0.6))
    axes = fig.subplots(nrows, ncols, sharex=True, squeeze=False).ravel()
    for ax, name in zip(axes, names):
        m = summary["measures"][name]
        v = np.array([[np.nan if x is None else x for x in row] for row in m["values"]], dtype=float)
        sparse = np.isfinite(v).sum(axis=1).max(initial=0) < 0.75 * len(t)  # a measure summarised at some times only
        for row in v:
            ok = np.isfinite(row)  # joined over the times it has, not broken at the others
            ax.plot(t[ok], row[ok], color=SEED_COLOUR, lw=0.6, alpha=0.55, marker="." if sparse else None, ms=3)
        if name == "largest_alignment" and "free_alignment" in summary["measures"]:
            f = summary["measures"]["free_alignment"]
            fv = np.array([[np.nan if x is None else x for x in row] for row in f["values"]], dtype=float)
            for row in fv:
                ax.plot(t, row, color=FREE_COLOUR, lw=0.6, alpha=0.55)
            ax.plot([], [], color=SEED_COLOUR, label="largest structure")
            ax.plot([], [], color=FREE_COLOUR, label="rods in no structure")
            ax.legend(fontsize="x-small", frameon=False, loc="best")
        if name not in GROUPED:
            with np.errstate(invalid="ignore", divide="ignore"), warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)  # a time with one seed has no spread
                n = np.isfinite(v).sum(axis=0)
                mean = np.nanmean(np.where(n > 0, v, 0.0), axis=0) if v.size else v
                sem = np.nanstd(v, axis=0, ddof=1) / np.sqrt(np.maximum(n, 1))
            mean = np.where(n > 0, mean, np.nan)
            ok = np.isfinite(mean)
            ax.plot(t[ok], mean[ok], color=MEAN_COLOUR, lw=1.2)
            ax.fill_between(t[ok], (mean - sem)[ok], (mean + sem)[ok], color="0.5", alpha=0.35, lw=0)
        words, unit = _words_unit(name)
        if not electrodes:  # case (ii): the current enters and leaves through the external filament
            words = words.replace("through the gap", "through the network")
        if name in FIT_ERRORS:  # the tables' standard error adds each seed's fit error; the band does not
            words += "\n(band: the spread between seeds)"
        ax.set_title(words, fontsize="small", loc="left")
        if unit:
            ax.set_ylabel(unit, fontsize="small")
        ax.tick_params(labelsize="small")
    for ax in axes[len(names) :]:
        ax.set_visible(False)
    for ax in axes[max(0, len(names) - ncols) : len(names)]:
        ax.set_xlabel("Time ($t_0$)", fontsize="small")
        ax.tick_params(labelbottom=True)
    # wrapped: a study's title and the legend in words outrun the figure's width
    fig.suptitle(
        textwrap.fill(f"{title}: each seed (thin lines); mean and one standard error over seeds (black, grey)", 90),
        fontsize="medium",
    )
    return _save(fig, out)


def plot_episodes(summary, out, title) -> Path:
    """When the gap was closed (case (ii): the circuit through the external filament), seed by seed, at
    the times of the events (not of the frames)."""
    seeds = summary["seeds"]
    fig = _figure(figsize=(7.2, 0.35 * len(seeds) + 1.3))
    ax = fig.subplots()
    t_end = float(summary["study"]["t_end"])
    for k, s in enumerate(seeds):
        ep = s["episodes"]
        spans = [(a, (b if b is not None else s["t_end"]) - a) for a, b in zip(ep["start"], ep["end"])]
        # an episode shorter than the line width is still drawn, as a tick
        spans = [(a, max(w, 2e-3 * t_end)) for a, w in spans]
        ax.broken_barh(spans, (k - 0.35, 0.7), facecolors=SEED_COLOUR)
        ax.text(t_end * 1.005, k, f"{len(spans)}", va="center", fontsize="x-small")
    ax.set_yticks(range(len(seeds)), [f"seed {s['seed']}" for s in seeds], fontsize="small")
    ax.set_xlim(0, t_end)
    ax.set_ylim(-0.6, len(seeds) - 0.4)
    ax.invert_yaxis()
    ax.set_xlabel("Time ($t_0$)", fontsize="small")
    closed = "electrodes short-circuited" if has_electrodes(summary) else "circuit closed through the external filament"
    ax.set_title(
        textwrap.fill(f"{title}: {closed} (bars; number of closings at the right)", 80, break_on_hyphens=False),
        fontsize="medium",
    )
    return _save(fig, out)


def study_figures(study, summary, folder) -> list:
    """The figures of a study made from its summary, into ``folder``: ``NAME_series.png`` and
    ``NAME_episodes.png`` (the snapshot of a run file is drawn by ``selfas-graph plot``)."""
    folder = Path(folder)
    return [
        plot_series(summary, folder / f"{study.name}_series.png", study.title),
        plot_episodes(summary, folder / f"{study.name}_episodes.png", study.title),
    ]


def plot_sweep(studies, summaries, name, out) -> Path:
    """The claim measures at the sweep's time against its parameter: mean and one standard error over
    the seeds of each point, as the sweep's table gives them (:func:`.sweeps.sweep_points`: for a
    measure of the current, the seeds that carry it, "k/n" beside each point, and dashed grey the mean
    over every seed, 0 where one carries none, which the step and trend rows test). A point of one
    seed, without a spread, is drawn hollow."""
    sw = studies.sweeps[name]
    ncols = 2
    nrows = math.ceil(len(CLAIM_MEASURES) / ncols)
    fig = _figure(figsize=(7.2, 2.0 * nrows + 0.6))
    axes = fig.subplots(nrows, ncols, squeeze=False).ravel()
    for ax, m in zip(axes, CLAIM_MEASURES):
        pts = [(v, st) for v, st in sweep_points(studies, summaries, name, m) if st["n"]]
        if pts:
            x = [v for v, _ in pts]
            y = [st["mean"] for _, st in pts]
            e = [0.0 if not math.isfinite(st["sem"]) else st["sem"] for _, st in pts]
            ax.errorbar(x, y, yerr=e, marker="o", ms=3.5, capsize=3, lw=1.0, color=SEED_COLOUR)
            alone = [(xv, yv) for xv, yv, (_, st) in zip(x, y, pts) if st["n"] < 2]
            if alone:  # one seed: no spread to draw, which a bar of zero length would hide; a hollow mark
                ax.plot(*zip(*alone), ls="none", marker="o", ms=7, mfc="white", mec=SEED_COLOUR, zorder=3)
            for xv, yv, (_, st) in zip(x, y, pts):
                if "of" in st:  # grouped: how many seeds the point describes
                    ax.annotate(f"{st['n']}/{st['of']}", (xv, yv), textcoords="offset points", xytext=(4, 4),
                                fontsize="x-small", color="0.35")  # fmt: skip
        if m in GROUPED:  # what the step and trend rows test: every seed, 0 where it carries no current
            every = [(v, st) for v, st in sweep_points(studies, summaries, name, m, every_seed=True) if st["n"]]
            if every:
                ax.errorbar(
                    [v for v, _ in every], [st["mean"] for _, st in every],
                    yerr=[0.0 if not math.isfinite(st["sem"]) else st["sem"] for _, st in every],
                    marker="s", ms=3, capsize=2, lw=0.8, ls="--", color="0.55", label="every seed, 0 without current",
                )  # fmt: skip
                ax.legend(fontsize="x-small", frameon=False, loc="best")
        ax.axvline(sw.base_value, color="0.6", lw=0.8, ls=":")
        words, unit = _words_unit(m)
        ax.set_title(words, fontsize="small", loc="left")
        if unit:
            ax.set_ylabel(unit, fontsize="small")
        ax.set_xlabel(sw.parameter, fontsize="small")
        ax.tick_params(labelsize="small")
    for ax in axes[len(CLAIM_MEASURES) :]:
        ax.set_visible(False)
    fig.suptitle(f"{sw.title}\n(t = {sw.time:g}; the paper's value dotted)", fontsize="medium")
    return _save(fig, out)
