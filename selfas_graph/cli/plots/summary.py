"""The figure of an ensemble summary: each measure's mean over seeds against time, with a band of one
standard error (:func:`plot_summary`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..main import CliError
from .style import (
    _matplotlib,
    _save_png,
    _series_style,
)


def plot_summary(summary: dict, out, title: str, dpi=150, measures=None) -> Path:
    """The measures of an ensemble summary (:func:`selfas_graph.ensemble.summarise`) against
    time: mean over seeds with a band of one standard error, one panel per measure, the
    number of seeds behind each time in the first (top) panel."""
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
        if "_" not in words.split(" ")[0]:  # a word, not a symbol such as m_J,z
            words = words[0].upper() + words[1:]
        ax.set_title(words, fontsize="small", loc="left")
        if not np.isfinite(mean).any():  # an empty panel says why
            why = "no seed carries current at these times" if "k" in m else "no value at these times"
            ax.text(0.5, 0.5, why, transform=ax.transAxes, ha="center", va="center", fontsize="small", color="0.4")
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
