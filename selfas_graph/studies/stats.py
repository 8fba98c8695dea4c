"""The statistics of the results page: a measure of a study's summary at a time, over its seeds.

docs/model.md "Measures of the paper's claims":

* a measure every seed has: mean +- standard error over the seeds with a value; for a fitted
  dimension the standard error also carries each fit's own uncertainty,
  ``SE^2 = s^2 / n + mean(err_i^2) / n``;
* a measure that splits the seeds into two groups (the circuit carries current or not):
  "k of n seeds", and the median [range] and mean +- SE of the k seeds it describes, never a mean
  over both groups.

The summaries are those of :mod:`.summary` (``docs/results/NAME.json``).
"""

from __future__ import annotations

import math

import numpy as np

from ..analysis.ensemble_stats import grouped_summary, mean_sem, mean_sem_fits
from ..provenance import older_version

__all__ = [
    "CLAIM_MEASURES",
    "FIT_ERRORS",
    "GROUPED",
    "LABELS",
    "MIN_FREE_RODS",
    "UNSHOWN_UNITS",
    "current_flags",
    "fmt",
    "grouped_at",
    "grouped_stat",
    "measure_label",
    "measure_text",
    "older_runs",
    "plain_stat",
    "pm",
    "values_at",
    "window_values",
    "with_minimum_counts",
]

#: measures that are zero in a seed whose circuit is open: reported as "k of n seeds" (module docstring)
GROUPED = (
    "filament_rods",
    "total_current",
    "midplane_flux",
    "flux_over_external",
    "flux_over_dipole",
    "moment_J_z",
    "largest_moment_J_z",
)


#: the measures of the convergence and sensitivity tables: one per claim
CLAIM_MEASURES = (
    "filament_rods",
    "inside_R_plas",
    "midplane_flux",
    "largest_alignment",
    "fractal_dimension",
    "cycle_rank",
)


#: fitted measures and their own uncertainty
FIT_ERRORS = {
    "fractal_dimension": "fractal_dimension_err",
    "rg_dimension": "rg_dimension_err",
}


#: units of a measure (``Measure.unit``) that the page does not show: counts and pure numbers
UNSHOWN_UNITS = ("1", "rods", "loops", "fraction")

#: words and units of the measures, as the tables and figures show them: each unit is the measure's
#: own (``Measure.unit``, selfas_graph/ensemble/measures.py and studies/summary.py), or "" for one of
#: :data:`UNSHOWN_UNITS` (a test holds the two together)
LABELS = {
    "filament_rods": ("rods in current-carrying filaments", ""),
    "total_current": ("current through the gap", "J0"),
    "inside_R_plas": ("fraction of rods within R_plas", ""),
    "median_axis_distance": ("median distance of rods from the axis", "L"),
    "midplane_flux": ("flux of the rod currents through the mid-plane", "Phi_0"),
    "flux_over_external": ("that flux over the flux of B_ext", ""),
    "flux_over_dipole": ("that flux over the external dipole's flux Phi_ext = 4 pi Z_Mext", ""),
    "largest_structure_rods": ("rods in the largest structure", ""),
    "largest_moment_ratio": ("largest structure's monopole moment, magnitude", "rod moments"),
    "largest_alignment": ("alignment of the largest structure's rods", ""),
    "free_alignment": ("alignment of the rods in no structure", ""),
    "all_alignment": ("alignment of all rods", ""),
    "free_rods": ("rods in no structure", ""),
    "moment_J_z": ("moment of the rod currents m_J,z", "J0 L^2"),
    "largest_moment_J_z": ("m_J,z of the largest structure", "J0 L^2"),
    "fractal_dimension": ("mass-radius dimension of the largest structure", ""),
    "rg_dimension": ("dimension from R_g ~ N^(1/D) over the structures", ""),
    "cycle_rank": ("independent loops (cycle rank)", ""),
    "cycle_rank_largest": ("independent loops of the largest structure", ""),
    "structures": ("structures", ""),
}


def reached(summary, t) -> np.ndarray:
    """Which seeds ran to time ``t`` (their ``t_end``, to 1e-9 relative; a seed entry without one
    counts as having reached it). A seed that stopped before ``t`` has no value there, though the
    ensemble summary may hold its last frame within half an output interval of ``t``: one rule for every
    statistic of the page."""
    tol = 1e-9 * max(1.0, abs(t))
    return np.array([float(x.get("t_end", math.inf)) >= t - tol for x in summary["seeds"]], dtype=bool)


def _rows_at(summary, rows, t):
    """Column ``t`` of per-seed rows over the summary's times (NaN where a seed has none or did not
    reach ``t``, :func:`reached`, or where ``rows`` is None or ``t`` is not a summarised time)."""
    times = summary["times"]
    k = int(np.argmin([abs(x - t) for x in times]))
    if abs(times[k] - t) > 1e-9 * max(1.0, abs(t)) or rows is None:
        return np.full(len(summary["seeds"]), np.nan)
    out = np.array([np.nan if v[k] is None else v[k] for v in rows], dtype=float)
    return np.where(reached(summary, t), out, np.nan) if len(out) == len(summary["seeds"]) else out


#: the fewest rods in no structure whose alignment the page gives: N rods at random align to about
#: 1/sqrt(N) (0.18 at 30), and below that the measure follows the count of those rods, which falls
#: as they join structures, more than their alignment (docs/model.md "Measures of the paper's claims")
MIN_FREE_RODS = 30


def with_minimum_counts(summary):
    """``summary`` with the alignment of the rods in no structure removed (None) where fewer than
    :data:`MIN_FREE_RODS` were in no structure: the rule of :mod:`.summary`'s measure, applied to
    summaries made before it (their per-seed counts ``free_rods`` are kept). Changes ``summary`` in
    place and returns it."""
    m, counts = summary.get("measures", {}).get("free_alignment"), summary.get("measures", {}).get("free_rods")
    if m is None or counts is None:
        return summary
    m["values"] = [
        [None if c is None or v is None or c < MIN_FREE_RODS else v for v, c in zip(row, crow)]
        for row, crow in zip(m["values"], counts["values"])
    ]
    return summary


def values_at(summary, measure, t):
    """Per-seed values of ``measure`` at time ``t`` (NaN where a seed has none)."""
    m = summary["measures"].get(measure)
    return _rows_at(summary, None if m is None else m["values"], t)


def current_flags(summary, t):
    """``(active, known, circuit)`` at time ``t``: which seeds the grouped measures describe, those with
    rods in gap-spanning filaments or a nonzero current through the gap (the summary's ``current``,
    docs/model.md "Measures of the paper's claims"; a summary without it: a nonzero total current);
    which seeds have a flag at all (a seed with a value but no flag counts in neither group, not as one
    without current); and whether the study has a circuit at all (some seed's total current is a
    number). Without a circuit the filaments span the gap but carry no current."""
    cur = values_at(summary, "total_current", t)
    circuit = bool(np.isfinite(cur).any())
    if "current" in summary:
        flag = _rows_at(summary, summary.get("current"), t)
        known = np.isfinite(flag)
    else:  # an older summary: the total current is the flag
        flag = np.abs(cur)
        known = np.isfinite(cur) | (not circuit)  # a bool array (``~`` of a Python bool is an int)
    return np.nan_to_num(flag) > 0, known, circuit


def grouped_at(summary, measure, t) -> dict:
    """A grouped measure at time ``t``: :func:`grouped_stat` of the seeds the summary flags as
    carry current, with ``circuit``; a seed whose flag is unknown counts in neither group."""
    active, known, circuit = current_flags(summary, t)
    v = values_at(summary, measure, t)
    return grouped_stat(np.where(known, v, np.nan), active) | {"circuit": circuit}


def plain_stat(values, errors=None) -> dict:
    """Mean, standard error and count over the finite values
    (:func:`~selfas_graph.analysis.ensemble_stats.mean_sem`); with ``errors``, each value's own
    fit uncertainty, the standard error is sqrt(s^2 / n + mean(err^2) / n)
    (:func:`~selfas_graph.analysis.ensemble_stats.mean_sem_fits`)."""
    v = np.asarray(values, dtype=float).reshape(-1, 1)
    if errors is None:
        mean, sem, n = mean_sem(v)
    else:
        mean, sem, _, _, n = mean_sem_fits(v, np.asarray(errors, dtype=float).reshape(-1, 1))
    return {"n": int(n[0]), "mean": float(mean[0]), "sem": float(sem[0])}


def grouped_stat(values, active) -> dict:
    """:func:`~selfas_graph.analysis.ensemble_stats.grouped_summary`: k of n seeds, and the median,
    range, mean and standard error of the k seeds where ``active`` holds."""
    return grouped_summary(values, active)


def fmt(x, digits=3):
    """``x`` with ``digits`` significant digits as the page prints it: whole from 10^digits to 10^6,
    "n/a" for None or a value that is not finite."""
    if x is None or not math.isfinite(x):
        return "n/a"
    if 10**digits <= abs(x) < 1e6:  # whole, not 1.04e+03 or 1.3e+02
        return f"{x:.0f}"
    return f"{x:.{digits}g}"


def pm(s):
    """A :func:`plain_stat` as "mean ± SE (n)" ("(1 seed)" without a spread, "n/a" with no value)."""
    if s["n"] == 0:
        return "n/a"
    if not math.isfinite(s["sem"]):
        return f"{fmt(s['mean'])} (1 seed)"
    return f"{fmt(s['mean'])} ± {fmt(s['sem'], 2)} ({s['n']})"


def measure_text(summary, measure, t) -> str:
    """A measure of a summary at a time as the page prints it (module docstring)."""
    v = values_at(summary, measure, t)
    if measure in GROUPED:
        g = grouped_at(summary, measure, t)
        what = "carry current" if g["circuit"] else "span the gap (no circuit)"
        if g["n"] == 0:
            return "n/a"
        if g["k"] == 0:
            return f"0 of {g['n']} seeds {what}"
        return (
            f"{g['k']} of {g['n']} seeds {what}: median {fmt(g['median'])} "
            f"[{fmt(g['min'])} to {fmt(g['max'])}], mean {pm(g | {'n': g['k']})}"
        )
    if measure in FIT_ERRORS:
        # a fit over less than a factor 4 in scale is refused (NaN) by the estimator
        # (analysis/fractal.py, MIN_RANGE): where every seed's is, the dimension is not testable
        err = values_at(summary, FIT_ERRORS[measure], t)
        # only seeds that reached t (values_at): a seed stopped before it has no frame there
        there = reached(summary, t)
        if there.shape == v.shape:
            v, err = v[there], err[there]
        if not v.size:
            return "n/a"
        s = plain_stat(v, err)
        if s["n"] == 0:
            return "not testable at this size (no fit over a factor 4 in scale)"
        k = len(v) - s["n"]
        return pm(s) if not k else f"{pm(s)}; not testable in {k} seed{'' if k == 1 else 's'}"
    if measure == "free_alignment":  # say which seeds the rule of MIN_FREE_RODS leaves out
        few = int((values_at(summary, "free_rods", t) < MIN_FREE_RODS).sum())
        if few:
            if not np.isfinite(v).any():
                return f"n/a (fewer than {MIN_FREE_RODS} such rods in {'every' if few == len(v) else few} seed{'s' if few > 1 and few < len(v) else ''})"
            return f"{pm(plain_stat(v))}; {few} seed{'' if few == 1 else 's'} with fewer than {MIN_FREE_RODS} such rods left out"
    return pm(plain_stat(v))


def measure_label(measure):
    """The words and unit of a measure as the tables show them (:data:`LABELS`)."""
    words, unit = LABELS.get(measure, (measure.replace("_", " "), ""))
    return f"{words} ({unit})" if unit else words


def _in_window(summary, lo, hi):
    """Which summarised times lie in [lo, hi] (to 1e-9: the times are sums of the summary's step)."""
    times = np.asarray(summary["times"], dtype=float)
    return (times >= lo - 1e-9) & (times <= hi + 1e-9)


def window_values(summary, measure, lo, hi):
    """Each seed's mean of ``measure`` over the summarised times in [lo, hi] (NaN: none there, or the
    seed stopped before ``hi``: a mean over the window's early part alone is not the window's)."""
    pick = _in_window(summary, lo, hi)
    if measure not in summary["measures"] or not pick.any():
        return np.full(len(summary["seeds"]), np.nan)
    v = np.array([[np.nan if x is None else x for x in row] for row in summary["measures"][measure]["values"]])
    v = v[:, pick]
    n = np.isfinite(v).sum(axis=1)
    return np.where((n > 0) & reached(summary, hi), np.nansum(v, axis=1) / np.maximum(n, 1), np.nan)


def window_times(summary, measure, lo, hi) -> int:
    """How many summarised times in [lo, hi] hold ``measure`` for some seed: the times a window's mean
    is over (the costly flux is summarised at fewer times than the counts)."""
    pick = _in_window(summary, lo, hi)
    if measure not in summary["measures"] or not pick.any():
        return 0
    rows = summary["measures"][measure]["values"]
    return sum(any(row[k] is not None for row in rows) for k in np.flatnonzero(pick))


def older_runs(summary, since) -> list:
    """The versions of a summary's runs older than ``since`` (docs/studies.toml ``trajectories_since``,
    the first version whose trajectories the code follows now), an unreadable version counted as older;
    [] when there are none, or ``since`` is ""."""
    if not since or summary is None:
        return []
    seeds = [summary] if summary.get("kind") == "percolation" else summary["seeds"]
    versions = {str(x.get("version") or "unknown") for x in seeds}
    return sorted(v for v in versions if older_version(v, since))
