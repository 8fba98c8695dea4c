"""What the figures of ``selfas-graph plot`` share: the paper's colours, titles and legends, the
style of time series, matplotlib imported lazily (headless) and PNGs written atomically."""

from __future__ import annotations

from pathlib import Path

from ...analysis.frame_topology import filament_words, has_circuit
from ...io.atomic import atomic_write
from ...io.frame import SavedFrame
from ...io.h5md import RunFile
from ..main import CliError, write_failed

# the paper's colours
FILAMENT_COLOUR = "blue"
DEAD_END_COLOUR = "red"
LARGEST_COLOUR = "red"
TOTAL_COLOUR = "green"
OTHER_COLOUR = (0.55, 0.55, 0.55)
ELECTRODE_COLOUR = (0.85, 0.65, 0.15)
PLASMA_STYLE = dict(color=(0.2, 0.6, 0.3), lw=0.9, ls="--", zorder=1)


def _matplotlib():
    """Import matplotlib lazily (the package works without it) and pick the headless backend."""
    try:
        import matplotlib
    except ImportError:
        raise CliError('plotting needs matplotlib: pip install "selfas-graph[plot]"') from None
    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    return Figure


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


#: the formats a plot is written in, by the output's suffix (PNG without one)
PLOT_FORMATS = ("png", "pdf", "svg")


def plot_format(out: Path) -> str:
    """The format of a plot written to ``out``: its suffix's, PNG without one; CliError for another suffix."""
    suffix = out.suffix.lower().lstrip(".")
    if suffix and suffix not in PLOT_FORMATS:
        raise CliError(f"{out}: a plot is written as PNG, PDF or SVG; give a name ending in .png, .pdf or .svg")
    return suffix or "png"


def _save_png(fig, out: Path, dpi):
    """Draw aside in the format of :func:`plot_format` and rename into place: a failed write (full disk)
    leaves no partial file."""
    fmt = plot_format(out)
    try:  # through a symbolic link the file it names is replaced, as for every file written (io/atomic.py)
        atomic_write(out, lambda tmp: fig.savefig(tmp, dpi=dpi, format=fmt))
    except OSError as exc:
        raise write_failed(f"cannot write {out}", exc) from None


def filament_label(run) -> str:
    """What a figure calls the rods of the FILAMENT role (:func:`~selfas_graph.analysis.frame_topology.filament_words`)."""
    return filament_words(has_circuit(run))
