"""The verdicts of the results page: each claim against its null model, each numerical knob against
the default it varies, and each sweep of a scene's parameter.

A claim's verdict compares the study with its null model at the paper's end time in units of the
combined standard error, d = (x - x_null) / sqrt(SE^2 + SE_null^2): "reproduced" only for |d| > 3 in
the direction the claim predicts (docs/model.md "Measures of the paper's claims"). The statistics are
those of :mod:`.stats`.
"""

from __future__ import annotations

import math

import numpy as np

from ..provenance import version_key
from .stats import (
    CLAIM_MEASURES,
    FIT_ERRORS,
    GROUPED,
    current_flags,
    grouped_at,
    measure_label,
    measure_text,
    older_runs,
    plain_stat,
    pm,
    values_at,
    window_times,
    window_values,
)

__all__ = ["CLAIM_MEASURES", "claim_rows", "sweep_points", "sweep_rows", "sweep_trends"]


def _combined_sem(a, b):
    """sqrt(SE_a^2 + SE_b^2) of two plain statistics; NaN where either has no value or no spread."""
    return math.sqrt(a["sem"] ** 2 + b["sem"] ** 2) if a["n"] and b["n"] else math.nan


def _claim_difference(a, b):
    """(x - x_null) / sqrt(SE^2 + SE_null^2); infinite where both spreads are zero and the means differ
    (every seed of both the same, e.g. no filament in any seed of the null model and the same count in
    every seed of the scene), NaN without a spread estimate (one seed)."""
    den = _combined_sem(a, b)
    if not math.isfinite(den):
        return math.nan
    if den == 0.0:
        return 0.0 if a["mean"] == b["mean"] else math.copysign(math.inf, a["mean"] - b["mean"])
    return (a["mean"] - b["mean"]) / den


def welch_p(a, b) -> float:
    """The two-sided p-value of Welch's t-test of two plain statistics (mean, standard error, count): the
    chance of a difference at least this large in combined standard errors between two sets of seeds of
    one distribution, for the few seeds a study has (a normal reading of the difference overstates the
    confidence: 3 SE is p = 0.0027 for a normal variable, p = 0.02 with 7 degrees of freedom). NaN
    without two seeds a side or without a spread."""
    if a["n"] < 2 or b["n"] < 2:
        return math.nan
    va, vb = a["sem"] ** 2, b["sem"] ** 2
    if not va + vb > 0:
        return math.nan
    from scipy.stats import t as student

    df = (va + vb) ** 2 / (va**2 / (a["n"] - 1) + vb**2 / (b["n"] - 1))
    return float(2.0 * student.sf(abs(a["mean"] - b["mean"]) / math.sqrt(va + vb), df))


def _p_text(p) -> str:
    """``"; Welch p = 0.002"`` (two significant digits, ``< 1e-6`` below), or "" for NaN."""
    if not math.isfinite(p):
        return ""
    return "; Welch p < 1e-6" if p < 1e-6 else f"; Welch p = {p:.2g}".replace("e-0", "e-")


def _verdict(d, expect, p=math.nan):
    """The verdict on a difference of ``d`` combined standard errors from the null model (3 of them in the
    claimed direction), with the Welch p-value ``p`` beside it where given."""
    if math.isnan(d):
        return "not decided (too few seeds)"
    if math.isinf(d):  # no spread in either: every seed of each gives the same value
        same = (d > 0) == (expect == "greater")
        return f"{'reproduced' if same else 'opposite to the claim'} (every seed differs from every seed of the null model)"
    if (d > 3 and expect == "greater") or (d < -3 and expect == "less"):
        return f"reproduced ({'+' if d > 0 else '−'}{abs(d):.1f} SE from the null model{_p_text(p)})"
    if abs(d) > 3:
        return f"opposite to the claim ({'+' if d > 0 else '−'}{abs(d):.1f} SE from the null model{_p_text(p)})"
    return f"not distinguished from the null model ({d:+.1f} SE{_p_text(p)})".replace("-", "−")


def _fit_verdict(d, d_seeds, expect, p_seeds=math.nan):
    """The verdict on a fitted measure, whose standard error carries each seed's fit uncertainty (``d``)
    or the spread between seeds alone (``d_seeds``, Welch p ``p_seeds``): the two are stated, and where
    they lead to different verdicts the page says that the verdict depends on counting the fits' own
    errors (docs/model.md "Measures of the paper's claims")."""
    with_fits, seeds_alone = _verdict(d, expect), _verdict(d_seeds, expect, p_seeds)
    if with_fits.split(" (")[0] == seeds_alone.split(" (")[0]:
        return f"{with_fits[:-1]}; {d_seeds:+.1f} SE by the spread between seeds alone{_p_text(p_seeds)})".replace(
            "-", "−"
        )
    return (
        f"depends on the fits' own errors: {with_fits} with each seed's fit error, {seeds_alone} by the "
        f"spread between seeds alone"
    )


def _older_note(summaries, names, studies) -> str:
    """ "; made before the trajectory change of 0.4.0 (NAME: 0.3.0): to be run again" for the studies
    among ``names`` made of runs older than their ``trajectories_since`` (``studies.since``), or ""."""
    old = {n: older_runs(summaries.get(n), studies.since(n)) for n in dict.fromkeys(names) if n}
    old = {n: v for n, v in old.items() if v}
    if not old:
        return ""
    since = sorted({studies.since(n) for n in old}, key=version_key)
    which = ", ".join(f"{n}: {', '.join(v)}" for n, v in old.items())
    return f"; made before the trajectory change of {' and '.join(since)} ({which}): to be run again"


def claim_rows(studies, summaries) -> str:
    """The claims table: each claim's measure at the paper's end time, its null model and the verdict."""
    rows = [
        "| claim | what the paper shows | measure at t | selfas-graph | null model | null model's value | verdict |",
        "|---|---|---|---|---|---|---|",
    ]
    for c in studies.claims:
        s = summaries.get(c.study)
        if s is None:
            rows.append(f"| {c.claim} | {c.paper} | {measure_label(c.measure)} | not run yet | | | |")
            continue
        if c.window:
            lo, hi = c.window
            where = f"mean over t = {lo:g}-{hi:g} ({window_times(s, c.measure, lo, hi)} summarised times)"
            value = pm(plain_stat(window_values(s, c.measure, lo, hi)))
            value += f"; at t = {c.time:g}: {measure_text(s, c.measure, c.time)}"
        else:
            where = f"t = {c.time:g}"
            value = measure_text(s, c.measure, c.time)
        also = "; ".join(f"{measure_label(m)}: {measure_text(s, m, c.time)}" for m in c.also)
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
                a = plain_stat(window_values(s, c.measure, *c.window))
                b = plain_stat(window_values(null, nm, *c.window))
                null_value = pm(b)
            else:  # a fitted measure's standard error carries each seed's fit uncertainty, as the tables show
                ea = values_at(s, FIT_ERRORS[c.measure], c.time) if c.measure in FIT_ERRORS else None
                eb = values_at(null, FIT_ERRORS[nm], c.time) if nm in FIT_ERRORS else None
                a = plain_stat(values_at(s, c.measure, c.time), ea)
                b = plain_stat(values_at(null, nm, c.time), eb)
                null_value = measure_text(null, nm, c.time)
            d = _claim_difference(a, b)
            null_text = studies.study(c.null).title
            null_value += "" if nm == c.measure else f" ({measure_label(nm)})"
            verdict = _verdict(d, c.expect, welch_p(a, b))
            if not c.window and (ea is not None or eb is not None):
                sa, sb = plain_stat(values_at(s, c.measure, c.time)), plain_stat(values_at(null, nm, c.time))
                verdict = _fit_verdict(d, _claim_difference(sa, sb), c.expect, welch_p(sa, sb))
        verdict += _older_note(summaries, (c.study, c.null), studies)
        rows.append(
            f"| {c.claim} | {c.paper} | {measure_label(c.measure)}, {where} | {value} | {null_text} | "
            f"{null_value} | {verdict} |"
        )
    return "\n".join(rows)


def sweep_rows(studies, summaries, name) -> str:
    """A sweep's table: a row per value of its parameter, the claim measures at the sweep's time, and
    the Welch p-value of each step from one value to the next."""
    sw = studies.sweeps[name]
    head = f"| {sw.parameter} | seeds | " + " | ".join(measure_label(m) for m in CLAIM_MEASURES) + " |"
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
        old = older_runs(s, studies.since(study))
        seeds = f"{s['n_seeds']}" + (f" (runs of {', '.join(old)}: to be run again)" if old else "")
        rows.append(f"| {value:g}{mark} | {seeds} | " + " | ".join(cells) + " |")
    done = [(v, summaries[st]) for v, st in studies.sweep_points(name) if summaries.get(st) is not None]
    if len(done) >= 2:
        steps = [_step_p(done, m, sw.time) for m in CLAIM_MEASURES]
        rows.append("| Welch p from each value to the next (each step alone) | | " + " | ".join(steps) + " |")
        trend = [_trend_text(x) for x in sweep_trends(done, sw.time)]
        label = f"trend over the sweep (Kendall τ over every seed; Holm over the {len(CLAIM_MEASURES)} measures)"
        rows.append(f"| {label} | | " + " | ".join(trend) + " |")
        rows.append(f"\n![{sw.title}: the claim measures at t = {sw.time:g}](figures/sweep_{name}.png)")
    return "\n".join(rows)


def _p_cell(p) -> str:
    return "n/a" if not math.isfinite(p) else ("< 0.001" if p < 0.001 else f"{p:.2g}")


def _step_p(points, measure, t) -> str:
    """The two-sided Welch p-value of each step of a sweep, from one value to the next, of the statistic
    the table gives (a grouped measure's over the seeds that carry current): "0.04; 0.5; < 0.001", "n/a"
    for a step without two seeds a side. A fitted dimension's steps are given twice, with each seed's
    fit error in the standard error and by the spread between seeds alone, as the claims give it."""
    stats = [_stat_at(s, measure, t) for _, s in points]
    text = "; ".join(_p_cell(welch_p(b, a)) for a, b in zip(stats, stats[1:]))
    if measure in FIT_ERRORS:
        alone = [plain_stat(_table_values(s, measure, t)) for _, s in points]
        text += " (seeds alone: " + "; ".join(_p_cell(welch_p(b, a)) for a, b in zip(alone, alone[1:])) + ")"
    return text


def _table_values(summary, measure, t) -> np.ndarray:
    """The per-seed values a table's statistic of ``measure`` at ``t`` describes: the seeds that carry
    current for a grouped measure (:func:`_stat_at`), every seed with a value otherwise."""
    v = values_at(summary, measure, t)
    if measure in GROUPED:
        active, known, _ = current_flags(summary, t)
        v = v[active & known]
    return v[np.isfinite(v)]


def sweep_trends(points, t) -> list[dict]:
    """The trend of each claim measure over a sweep's points ``[(value, summary), ...]`` at ``t``:
    Kendall's tau-b between the parameter and the per-seed values the table describes, every seed of
    every point pooled, and its two-sided p-value (docs/model.md "Measures of the paper's claims"). One
    test per measure, where the steps of the table are several each: the p-values are adjusted by Holm
    over the measures (``holm``). A fitted dimension is ranked by its seeds' values alone (a rank test
    cannot carry each fit's own error). Returns a dict per measure of :data:`CLAIM_MEASURES`:
    ``tau``, ``p``, ``holm``, ``n`` (seeds ranked); NaN where fewer than two points have values or
    the values do not vary."""
    from scipy.stats import kendalltau

    from .convergence import holm  # the convergence table's adjustment (convergence imports this module)

    out = []
    for m in CLAIM_MEASURES:
        x, y = [], []
        for value, s in points:
            v = _table_values(s, m, t)
            x += [float(value)] * v.size
            y += v.tolist()
        tau = p = math.nan
        if len(set(x)) >= 2 and len(y) >= 3 and np.ptp(y) > 0:
            res = kendalltau(x, y)
            tau, p = float(res.statistic), float(res.pvalue)
        out.append({"measure": m, "tau": tau, "p": p, "n": len(y)})
    for row, q in zip(out, holm([r["p"] for r in out])):
        row["holm"] = q
    return out


def _trend_text(r) -> str:
    """A trend cell: "rises: τ = +0.80, p < 0.001 (< 0.001 after Holm)", "falls: ...", or "none shown:
    ..." where the adjusted p-value is not under the family-wise 5 %."""
    if not math.isfinite(r["p"]):
        return "n/a"
    word = "none shown" if not r["holm"] < 0.05 else ("rises" if r["tau"] > 0 else "falls")
    return f"{word}: τ = {r['tau']:+.2f}, p = {_p_cell(r['p'])} ({_p_cell(r['holm'])} after Holm)".replace(
        "= <", "<"
    ).replace("-", "−")


def sweep_points(studies, summaries, name, measure):
    """(value, statistic) of a measure over a sweep's points that have a summary, as the sweep's table
    gives it: for a grouped measure the mean and standard error of the seeds that carry current, with
    their number ``k`` (``n``: those of them with a value; never a mean over both groups), else the
    plain statistic of every seed."""
    sw = studies.sweeps[name]
    out = []
    for value, study in studies.sweep_points(name):
        s = summaries.get(study)
        if s is None:
            continue
        out.append((value, _stat_at(s, measure, sw.time)))
    return out


def _stat_at(summary, measure, t) -> dict:
    """A measure's statistic at ``t`` as the tables give it: for a grouped measure the mean and
    standard error of the ``n`` seeds that carry current, of ``of`` with a value (never a mean over
    both groups); for a fitted one with each seed's fit error in the standard error; else over every
    seed."""
    if measure in GROUPED:
        g = grouped_at(summary, measure, t)
        return {"n": g["k"], "mean": g["mean"], "sem": g["sem"], "of": g["n"]}
    errs = values_at(summary, FIT_ERRORS[measure], t) if measure in FIT_ERRORS else None
    return plain_stat(values_at(summary, measure, t), errs)
