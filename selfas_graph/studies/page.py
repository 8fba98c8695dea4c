"""The results page from the studies' summaries: statistics, tables, verdicts and figures.

Every number of docs/results.md between ``<!-- begin generated: KEY -->`` and
``<!-- end generated: KEY -->`` is written by :func:`page_blocks` from the committed summaries
(``docs/results/NAME.json``, :mod:`.summary`); ``tests/cli/test_results_page.py`` checks that the page
holds what this module makes of them. The statistics (docs/model.md "Measures of the paper's claims"):

* a measure every seed has: mean +- standard error over the seeds with a value; for a fitted
  dimension the standard error also carries each fit's own uncertainty,
  ``SE^2 = s^2 / n + mean(err_i^2) / n``;
* a measure that splits the seeds into two groups (the circuit carries current or not):
  "k of n seeds", and the median [range] and mean +- SE of the k seeds it describes, never a mean
  over both groups;
* a claim's verdict compares the study with its null model at the paper's end time in units of the
  combined standard error, d = (x - x_null) / sqrt(SE^2 + SE_null^2): "reproduced" only for
  |d| > 3 in the direction the claim predicts.
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np

from ..analysis.ensemble_stats import grouped_summary, mean_sem, mean_sem_fits
from ..provenance import older_version

__all__ = [
    "GROUPED",
    "LABELS",
    "claim_rows",
    "grouped_stat",
    "has_electrodes",
    "load_summary",
    "page_blocks",
    "plain_stat",
    "replace_blocks",
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
#: fitted measures and their own uncertainty
FIT_ERRORS = {
    "fractal_dimension": "fractal_dimension_err",
    "rg_dimension": "rg_dimension_err",
}
#: words and units of the measures, as the tables and figures show them
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
#: the rows of a study's table, in order
TABLE_MEASURES = (
    "filament_rods",
    "total_current",
    "midplane_flux",
    "flux_over_dipole",
    "moment_J_z",
    "inside_R_plas",
    "median_axis_distance",
    "largest_structure_rods",
    "largest_moment_ratio",
    "largest_alignment",
    "free_alignment",
    "fractal_dimension",
    "rg_dimension",
    "cycle_rank",
)


def load_summary(folder, name):
    """The summary of study ``name`` in ``folder`` (``NAME.json``), or None if it is not there."""
    path = Path(folder) / f"{name}.json"
    if not path.exists():
        return None
    return json.loads(path.read_text(encoding="utf-8"))


def _values(summary, measure, t):
    """Per-seed values of ``measure`` at time ``t`` (NaN where a seed has none)."""
    times = summary["times"]
    k = int(np.argmin([abs(x - t) for x in times]))
    if abs(times[k] - t) > 1e-9 * max(1.0, abs(t)) or measure not in summary["measures"]:
        return np.full(len(summary["seeds"]), np.nan)
    return np.array([np.nan if v[k] is None else v[k] for v in summary["measures"][measure]["values"]], dtype=float)


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


def _fmt(x, digits=3):
    if x is None or not math.isfinite(x):
        return "n/a"
    if 10**digits <= abs(x) < 1e6:  # whole, not 1.04e+03 or 1.3e+02
        return f"{x:.0f}"
    return f"{x:.{digits}g}"


def _pm(s):
    if s["n"] == 0:
        return "n/a"
    if not math.isfinite(s["sem"]):
        return f"{_fmt(s['mean'])} (1 seed)"
    return f"{_fmt(s['mean'])} ± {_fmt(s['sem'], 2)} ({s['n']})"


def measure_text(summary, measure, t) -> str:
    """A measure of a summary at a time as the page prints it (module docstring)."""
    v = _values(summary, measure, t)
    if measure in GROUPED:
        cur = _values(summary, "total_current", t)
        g = grouped_stat(v, np.abs(cur) > 0)
        if g["n"] == 0:
            return "n/a"
        if g["k"] == 0:
            return f"0 of {g['n']} seeds carry current"
        return (
            f"{g['k']} of {g['n']} seeds carry current: median {_fmt(g['median'])} "
            f"[{_fmt(g['min'])} to {_fmt(g['max'])}], mean {_pm(g | {'n': g['k']})}"
        )
    if measure in FIT_ERRORS:
        # a fit over less than a factor 4 in scale is refused (NaN) by the estimator
        # (analysis/fractal.py, MIN_RANGE): where every seed's is, the dimension is not testable
        s = plain_stat(v, _values(summary, FIT_ERRORS[measure], t))
        if s["n"] == 0:
            return "not testable at this size (no fit over a factor 4 in scale)"
        k = len(v) - s["n"]
        return _pm(s) if not k else f"{_pm(s)}; not testable in {k} seed{'' if k == 1 else 's'}"
    return _pm(plain_stat(v))


def _label(measure):
    words, unit = LABELS.get(measure, (measure.replace("_", " "), ""))
    return f"{words} ({unit})" if unit else words


def has_electrodes(summary) -> bool:
    """Whether the study's scene closes its circuit between electrodes (case (i)) rather than through
    the external filament (case (ii)), from its scenario file and overrides; True if that file cannot
    be read here."""
    from ..io.scenario import ScenarioError, load_scenario

    study = summary.get("study", {})
    try:
        params = load_scenario(study["scenario"], overrides=list(study.get("overrides", ()))).params
    except (KeyError, OSError, ScenarioError):  # a summary read away from its scenario file
        return True
    return params.forces.electrodes is not None or params.forces.external_filament is None


def study_table(summary) -> str:
    """The table of a study: a row per measure, a column per table time, and the short circuits
    (between the electrodes, or through the external filament in case (ii))."""
    electrodes = has_electrodes(summary)
    times = summary["study"]["table_times"]
    head = "| measure | " + " | ".join(f"t = {t:g}" for t in times) + " |"
    rows = [head, "|---|" + "---|" * len(times)]
    for m in TABLE_MEASURES:
        if m not in summary["measures"]:
            continue
        cells = [measure_text(summary, m, t) for t in times]
        if all(c == "n/a" for c in cells):
            continue  # a measure the scene does not have (R_plas without a plasma filament)
        label = _label(m)
        if not electrodes:  # case (ii): the current enters and leaves through the external filament
            label = label.replace("through the gap", "through the network")
        rows.append(f"| {label} | " + " | ".join(cells) + " |")
    sc = summary.get("short_circuit") or {}
    n_obs, n = sc.get("n_observed", 0), summary["n_seeds"]
    text = f"{n_obs} of {n} seeds"
    if n_obs:
        text += f", median time (Kaplan-Meier) {_fmt(sc.get('median'))} t0"
        starts = [s["episodes"]["start"] for s in summary["seeds"]]
        text += f"; {sum(len(x) for x in starts)} closings of the {'gap' if electrodes else 'circuit'} in all"
        first = [s["episodes"].get("total_current", [None])[:1] for s in summary["seeds"]]
        first = [x[0] for x in first if x and x[0] is not None]
        series = [s["episodes"].get("rods_in_series", [None])[:1] for s in summary["seeds"]]
        series = [x[0] for x in series if x and x[0] is not None]
        if any(x > 0 for x in first):  # runs with a circuit log that carry current: the first closing, seed by seed
            text += (
                f"; the first closing carries median {_fmt(float(np.median(first)))} J0 "
                f"[{_fmt(min(first))} to {_fmt(max(first))}] through median {_fmt(float(np.median(series)))} "
                f"{'rod' if float(np.median(series)) == 1.0 else 'rods'} in series"
            )
    label = "short circuit of the electrodes" if electrodes else "circuit closed through the external filament"
    rows.append(f"| {label} | {text} |" + " |" * (len(times) - 1))
    return "\n".join(rows)


def percolation_table(summary) -> str:
    """A percolation study's table: per rod count, how many runs short-circuited by t_max (with the 95 %
    Wilson interval of the fraction) and the Kaplan-Meier median [quartiles] of the short-circuit time."""
    t_max = summary["study"]["t_max"]
    rows = [
        f"| rods | short-circuited by t = {t_max:g} (95 % interval) | median short-circuit time [q25 to q75] |",
        "|---|---|---|",
    ]
    for d in summary["densities"]:
        lo, hi = d.get("fraction_ci95") or (math.nan, math.nan)
        q = [">" + f"{t_max:g}" if d.get(k) is None else _fmt(d[k]) for k in ("median", "q25", "q75")]
        rows.append(
            f"| {d['count']} | {d['short_circuited']} of {d['runs']} ({_fmt(lo, 2)} to {_fmt(hi, 2)}) | "
            f"{q[0]} [{q[1]} to {q[2]}] |"
        )
    return "\n".join(rows)


def older_runs(summary, since) -> list:
    """The versions of a summary's runs older than ``since`` (docs/studies.toml ``trajectories_since``,
    the first version whose trajectories the code follows now), an unreadable version counted as older;
    [] when there are none, or ``since`` is ""."""
    if not since or summary is None:
        return []
    seeds = [summary] if summary.get("kind") == "percolation" else summary["seeds"]
    versions = {str(x.get("version") or "unknown") for x in seeds}
    return sorted(v for v in versions if older_version(v, since))


def _older_note(summaries, names, since) -> str:
    """ "; made before the trajectory change of 0.4.0 (NAME: 0.3.0): to be run again" for the studies
    among ``names`` made of runs older than ``since``, or ""."""
    old = {n: older_runs(summaries.get(n), since) for n in dict.fromkeys(names) if n}
    old = {n: v for n, v in old.items() if v}
    if not old:
        return ""
    which = ", ".join(f"{n}: {', '.join(v)}" for n, v in old.items())
    return f"; made before the trajectory change of {since} ({which}): to be run again"


def status_text(studies, summaries) -> str:
    """Which studies are still made of runs older than the trajectories of the code now."""
    since = studies.trajectories_since
    old = {n: older_runs(s, since) for n, s in summaries.items()}
    old = {n: v for n, v in old.items() if v}
    if not old:
        return "Every summarised study is made of runs of the trajectories the code follows now" + (
            f" (version {since} or later)." if since else "."
        )
    return (
        f"**Runs to be made again.** Trajectories changed in version {since} (CHANGELOG); these studies are "
        f"still made of runs of older versions, and their runs lines and every claim, convergence and "
        f"sensitivity row that uses them say so: "
        + ", ".join(f"{n} ({', '.join(v)})" for n, v in old.items())
        + ". `selfas-graph study run NAME --jobs 2 --force` (it replaces the older run files), then "
        "`study summarise NAME` and `study page`, makes each again."
    )


def provenance_text(summary, since="") -> str:
    """Version, commits, CPU, threads and wall time of a study's runs, in one paragraph; marked when
    they are older than version ``since``."""
    seeds = summary["seeds"]
    if not seeds:
        return "No run files were summarised."
    commits = sorted({s.get("commit", "")[:10] or "unknown" for s in seeds})
    cpus = sorted({s.get("cpu_model", "") or "unknown CPU" for s in seeds})
    targets = sorted({s.get("numba_cpu", "") or "unknown" for s in seeds})
    threads = sorted({s.get("numba_threads", 0) for s in seeds})
    wall = [s.get("wall_seconds") for s in seeds if s.get("wall_seconds") is not None]
    wall = [w for w in wall if isinstance(w, (int, float)) and math.isfinite(w)]
    versions = sorted({s.get("version", "") for s in seeds})
    t_ends = [s["t_end"] for s in seeds]
    text = (
        f"{len(seeds)} seeds ({', '.join(str(s['seed']) for s in seeds)}), each to t = {_fmt(min(t_ends))}"
        + (f" to {_fmt(max(t_ends))}" if max(t_ends) > min(t_ends) else "")
        + f"; version {', '.join(versions)}, commit {', '.join(commits)}; {'; '.join(cpus)}, kernels for "
        f"{', '.join(targets)}, {'/'.join(str(t) for t in threads)} numba thread(s) a seed"
    )
    if wall:
        lo, hi = _fmt(min(wall) / 60, 2), _fmt(max(wall) / 60, 2)
        text += f"; wall time a seed {lo if lo == hi else f'{lo}-{hi}'} min"
    if summary.get("missing"):
        text += f". Not yet run: {', '.join(summary['missing'])}"
    return text + "." + _older_text(summary, since)


def _older_text(summary, since) -> str:
    old = older_runs(summary, since)
    if not old:
        return ""
    name = summary["study"]["name"]
    return (
        f" **Runs of version {', '.join(old)}, made before the trajectory change of version {since} (CHANGELOG): "
        f"to be run again (`selfas-graph study run {name} --force`).**"
    )


def _claim_difference(a, b):
    """(x - x_null) / sqrt(SE^2 + SE_null^2); infinite where both spreads are zero and the means differ
    (every seed of both the same, e.g. no filament in any seed of the null model and the same count in
    every seed of the scene), NaN without a spread estimate (one seed)."""
    if not (a["n"] and b["n"]) or not (math.isfinite(a["sem"]) and math.isfinite(b["sem"])):
        return math.nan
    den = math.sqrt(a["sem"] ** 2 + b["sem"] ** 2)
    if den == 0.0:
        return 0.0 if a["mean"] == b["mean"] else math.copysign(math.inf, a["mean"] - b["mean"])
    return (a["mean"] - b["mean"]) / den


def _verdict(d, expect):
    if math.isnan(d):
        return "not decided (too few seeds)"
    if math.isinf(d):  # no spread in either: every seed of each gives the same value
        same = (d > 0) == (expect == "greater")
        return f"{'reproduced' if same else 'opposite to the claim'} (every seed differs from every seed of the null model)"
    if (d > 3 and expect == "greater") or (d < -3 and expect == "less"):
        return f"reproduced ({'+' if d > 0 else '−'}{abs(d):.1f} SE from the null model)"
    if abs(d) > 3:
        return f"opposite to the claim ({'+' if d > 0 else '−'}{abs(d):.1f} SE from the null model)"
    return f"not distinguished from the null model ({d:+.1f} SE)".replace("-", "−")


def _window_values(summary, measure, lo, hi):
    """Each seed's mean of ``measure`` over the summarised times in [lo, hi] (NaN: none there)."""
    times = np.asarray(summary["times"], dtype=float)
    pick = (times >= lo - 1e-9) & (times <= hi + 1e-9)
    if measure not in summary["measures"] or not pick.any():
        return np.full(len(summary["seeds"]), np.nan)
    v = np.array([[np.nan if x is None else x for x in row] for row in summary["measures"][measure]["values"]])
    v = v[:, pick]
    n = np.isfinite(v).sum(axis=1)
    return np.where(n > 0, np.nansum(v, axis=1) / np.maximum(n, 1), np.nan)


def claim_rows(studies, summaries) -> str:
    """The claims table: each claim's measure at the paper's end time, its null model and the verdict."""
    rows = [
        "| claim | what the paper shows | measure at t | selfas-graph | null model | null model's value | verdict |",
        "|---|---|---|---|---|---|---|",
    ]
    for c in studies.claims:
        s = summaries.get(c.study)
        if s is None:
            rows.append(f"| {c.claim} | {c.paper} | {_label(c.measure)} | not run yet | | | |")
            continue
        if c.window:
            lo, hi = c.window
            where = f"mean over t = {lo:g}-{hi:g}"
            value = _pm(plain_stat(_window_values(s, c.measure, lo, hi)))
            value += f"; at t = {c.time:g}: {measure_text(s, c.measure, c.time)}"
        else:
            where = f"t = {c.time:g}"
            value = measure_text(s, c.measure, c.time)
        also = "; ".join(f"{_label(m)}: {measure_text(s, m, c.time)}" for m in c.also)
        if also:
            value += f"; {also}"
        null = summaries.get(c.null) if c.null else None
        if not c.null:
            null_text, null_value, verdict = "none yet", "", "not yet set against a null model"
        elif null is None:
            null_text, null_value, verdict = studies.study(c.null).title, "not run yet", "not yet set against its null"
        else:
            nm = c.null_measure or c.measure
            if c.window:
                a = plain_stat(_window_values(s, c.measure, *c.window))
                b = plain_stat(_window_values(null, nm, *c.window))
                null_value = _pm(b)
            else:  # a fitted measure's standard error carries each seed's fit uncertainty, as the tables show
                ea = _values(s, FIT_ERRORS[c.measure], c.time) if c.measure in FIT_ERRORS else None
                eb = _values(null, FIT_ERRORS[nm], c.time) if nm in FIT_ERRORS else None
                a = plain_stat(_values(s, c.measure, c.time), ea)
                b = plain_stat(_values(null, nm, c.time), eb)
                null_value = measure_text(null, nm, c.time)
            d = _claim_difference(a, b)
            null_text = studies.study(c.null).title
            null_value += "" if nm == c.measure else f" ({_label(nm)})"
            verdict = _verdict(d, c.expect)
        verdict += _older_note(summaries, (c.study, c.null), studies.trajectories_since)
        rows.append(
            f"| {c.claim} | {c.paper} | {_label(c.measure)}, {where} | {value} | {null_text} | "
            f"{null_value} | {verdict} |"
        )
    return "\n".join(rows)


#: the measures of the convergence and sensitivity tables: one per claim
CLAIM_MEASURES = (
    "filament_rods",
    "inside_R_plas",
    "midplane_flux",
    "largest_alignment",
    "fractal_dimension",
    "cycle_rank",
)


def _difference(a, b):
    """(x_a - x_b) / sqrt(SE_a^2 + SE_b^2) of two plain statistics (NaN without a spread)."""
    den = math.sqrt(a["sem"] ** 2 + b["sem"] ** 2) if a["n"] and b["n"] else math.nan
    return (a["mean"] - b["mean"]) / den if den > 0 else math.nan


def convergence_rows(studies, summaries) -> str:
    """For each variant of a numerical knob, each claim measure at the variant's end time against the
    study it varies (same time): both means with their standard errors, the difference in combined
    standard errors, and what follows for a user."""
    rows = [
        "| setting | measure | default | this setting | difference (combined SE) | conclusion |",
        "|---|---|---|---|---|---|",
    ]
    for st in studies.studies.values():
        if st.section != "convergence":
            continue
        s, base = summaries.get(st.name), summaries.get(st.null_of)
        if s is None or base is None:
            missing = st.name if s is None else st.null_of
            rows.append(f"| {st.title} | | | | | not run yet (`selfas-graph study run {missing}`) |")
            continue
        t = st.t_end
        ds = []
        cells = []
        for m in CLAIM_MEASURES:
            errs = _values(s, FIT_ERRORS[m], t) if m in FIT_ERRORS else None
            berrs = _values(base, FIT_ERRORS[m], t) if m in FIT_ERRORS else None
            a, b = plain_stat(_values(s, m, t), errs), plain_stat(_values(base, m, t), berrs)
            d = _difference(a, b)
            ds.append(d)
            cells.append((m, b, a, d))
        finite = [abs(d) for d in ds if math.isfinite(d)]
        if not finite:
            verdict = "not decided (too few seeds)"
        elif max(finite) > 3:
            verdict = "moves these statistics: not safe for them"
        elif max(finite) > 2:
            verdict = "marginal (a difference of 2-3 SE)"
        else:
            verdict = "safe for these statistics (every difference within 2 SE)"
        verdict += _older_note(summaries, (st.name, st.null_of), studies.trajectories_since)
        for k, (m, b, a, d) in enumerate(cells):
            name = st.title if k == 0 else ""
            text = "n/a" if not math.isfinite(d) else f"{d:+.1f}".replace("-", "−")
            rows.append(
                f"| {name} | {_label(m)}, t = {t:g} | {_pm(b)} | {_pm(a)} | {text} | {verdict if k == 0 else ''} |"
            )
    return "\n".join(rows)


def sweep_rows(studies, summaries, name) -> str:
    """A sweep's table: a row per value of its parameter, the claim measures at the sweep's time."""
    sw = studies.sweeps[name]
    head = f"| {sw.parameter} | seeds | " + " | ".join(_label(m) for m in CLAIM_MEASURES) + " |"
    rows = [head, "|---|---|" + "---|" * len(CLAIM_MEASURES)]
    for value, study in studies.sweep_points(name):
        s = summaries.get(study)
        mark = " (the paper's)" if study == sw.base else ""
        if s is None:
            rows.append(
                f"| {value:g}{mark} | not run yet (`selfas-graph study run {study}`) |" + " |" * len(CLAIM_MEASURES)
            )
            continue
        cells = [measure_text(s, m, sw.time) for m in CLAIM_MEASURES]
        old = older_runs(s, studies.trajectories_since)
        seeds = f"{s['n_seeds']}" + (f" (runs of {', '.join(old)}: to be run again)" if old else "")
        rows.append(f"| {value:g}{mark} | {seeds} | " + " | ".join(cells) + " |")
    if sum(summaries.get(study) is not None for _, study in studies.sweep_points(name)) >= 2:
        rows.append(f"\n![{sw.title}: the claim measures at t = {sw.time:g}](figures/sweep_{name}.png)")
    return "\n".join(rows)


def sweep_points(studies, summaries, name, measure):
    """(value, plain statistic) of a measure over a sweep's points that have a summary."""
    sw = studies.sweeps[name]
    out = []
    for value, study in studies.sweep_points(name):
        s = summaries.get(study)
        if s is not None:
            errs = _values(s, FIT_ERRORS[measure], sw.time) if measure in FIT_ERRORS else None
            out.append((value, plain_stat(_values(s, measure, sw.time), errs)))
    return out


def page_blocks(studies, folder) -> dict:
    """Every generated block of the results page, keyed by its marker name: ``claims``, and for
    each study ``table NAME``, ``runs NAME`` and ``figures NAME`` (a study without a summary
    yet says how to make it)."""
    summaries = {name: load_summary(folder, name) for name in studies.studies}
    summaries = {k: v for k, v in summaries.items() if v is not None}
    blocks = {
        "claims": claim_rows(studies, summaries),
        "convergence": convergence_rows(studies, summaries),
        "status": status_text(studies, summaries),
    }
    for name in studies.sweeps:
        blocks[f"sensitivity {name}"] = sweep_rows(studies, summaries, name)
    for name, study in studies.studies.items():
        s = summaries.get(name)
        if s is None:
            todo = (
                f"Not run at this version yet: `selfas-graph study run {name} --jobs 2`, then `study summarise {name}`."
            )
            blocks[f"table {name}"] = blocks[f"runs {name}"] = todo
            blocks[f"figures {name}"] = ""
            continue
        if s.get("kind") == "percolation":
            blocks[f"table {name}"] = percolation_table(s)
            blocks[f"runs {name}"] = (
                f"{len(s['seeds'])} seeds a count to t = {_fmt(s['study']['t_max'])}; version {s['version']}, commit "
                f"{(s['commit'] or 'unknown')[:10]}; {s['cpu_model'] or 'unknown CPU'}, kernels for {s['numba_cpu']}, "
                f"{s['workers']} worker(s) of one numba thread; {_fmt((s['wall_seconds'] or 0) / 60, 2)} min in all."
                + _older_text(s, studies.trajectories_since)
            )
            blocks[f"figures {name}"] = ""
            continue
        blocks[f"table {name}"] = study_table(s)
        blocks[f"runs {name}"] = provenance_text(s, studies.trajectories_since)
        blocks[f"figures {name}"] = (
            f"| {study.title}: every measure over time | short-circuit episodes | seed {s['seeds'][0]['seed']} at "
            f"t = {_fmt(s['seeds'][0]['t_end'])} |\n|---|---|---|\n"
            f"| ![](figures/{name}_series.png) | ![](figures/{name}_episodes.png) | ![](figures/{name}_snapshot.png) |"
        )
        if study.section in ("paper", "contrast"):
            blocks[f"figures {name}"] += (
                f"\n\nA movie of seed {s['seeds'][0]['seed']}: [`figures/{name}_movie.mp4`](figures/{name}_movie.mp4) "
                f"(`selfas-graph plot RUN.h5 --movie OUT.mp4`)."
            )
    return blocks


_BLOCK = re.compile(
    r"(<!-- begin generated: (?P<key>[^>]+?) -->\n)(?P<body>.*?)(<!-- end generated: (?P=key) -->)", re.S
)


def replace_blocks(text, blocks) -> tuple[str, list]:
    """``text`` with every generated block replaced by ``blocks[key]``; also the keys found in the
    text that ``blocks`` has no entry for (left as they were)."""
    missing = []

    def sub(m):
        key = m.group("key")
        if key not in blocks:
            missing.append(key)
            return m.group(0)
        return m.group(1) + blocks[key].rstrip("\n") + "\n" + m.group(4)

    return _BLOCK.sub(sub, text), missing


def page_blocks_in(text) -> dict:
    """The generated blocks a page holds now, by key."""
    return {m.group("key"): m.group("body").rstrip("\n") for m in _BLOCK.finditer(text)}
