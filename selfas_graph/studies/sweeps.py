"""The sweeps of the results page: a scene's physical parameter at several values, the claim measures
at each, the step from one value to the next and the trend over the sweep (docs/model.md "Measures of
the paper's claims").

The table prints each point's statistics as the study tables do (a current-related measure over the
seeds that carry current, with how many of how many do). The tests are over every seed with a value,
a current-related measure's 0 where a seed carries none (:func:`sweep_values`): a test over the seeds
that carry current alone would pick its seeds by the outcome, and how many seeds carry current is
much of what a sweep changes. Where some seeds of a point carry none, its cell also gives the mean
the tests use. A step is paired by seed where its two points start from the same rods
(:func:`.pairing.same_start`), over the seeds both have, else Welch's; its cell gives the pairs (or
the seeds a side) in brackets. The trend is one test per measure, Kendall's tau-b between the
parameter and every seed's value, adjusted by Holm over the sweep's measures.
"""

from __future__ import annotations

import math

import numpy as np

from .pairing import common_rows, paired_stat, same_start
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
)
from .verdicts import welch_p

__all__ = ["sweep_points", "sweep_rows", "sweep_trends", "sweep_values"]


def sweep_values(summary, measure, t, fit_errors=True):
    """``(values, errors)``: the per-seed values a sweep's step and trend test at ``t``: every seed with a
    value; a current-related measure's where the seed's current flag is known (0 where it carries
    none); a fitted dimension's where its fit error is known, with those errors (None for another
    measure, or with ``fit_errors`` false: the spread between seeds alone)."""
    v = values_at(summary, measure, t)
    errors = None
    if measure in FIT_ERRORS:
        e = values_at(summary, FIT_ERRORS[measure], t)
        v = np.where(np.isfinite(e), v, np.nan)
        errors = e if fit_errors else None
    if measure in GROUPED:
        _, known, _ = current_flags(summary, t)
        v = np.where(known, v, np.nan)
    return v, errors


def _cell(summary, measure, t) -> str:
    """A point's cell: the table's statistic, and where some seeds carry no current the mean over every
    seed that the tests use."""
    text = measure_text(summary, measure, t)
    if measure in GROUPED:
        g = grouped_at(summary, measure, t)
        if 0 < g["k"] < g["n"]:
            text += f"; every seed, 0 without current: {pm(plain_stat(sweep_values(summary, measure, t)[0]))}"
    return text


def sweep_rows(studies, summaries, name, figures="figures") -> str:
    """A sweep's table: a row per value of its parameter, the claim measures at the sweep's time, the
    p-value of each step from one value to the next (:func:`_step_p`) and the trend over the sweep;
    its figure linked in ``figures`` (the folder as the page links it)."""
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
        cells = [_cell(s, m, sw.time) for m in CLAIM_MEASURES]
        old = older_runs(s, studies.since(study))
        seeds = f"{s['n_seeds']}" + (f" (runs of {', '.join(old)}: to be run again)" if old else "")
        rows.append(f"| {value:g}{mark} | {seeds} | " + " | ".join(cells) + " |")
    done = [(v, summaries[st]) for v, st in studies.sweep_points(name) if summaries.get(st) is not None]
    if len(done) >= 2:
        paired = _paired_steps(done)
        steps = [_step_p(done, m, sw.time, paired) for m in CLAIM_MEASURES]
        rows.append(f"| {_step_label(done, paired)} | | " + " | ".join(steps) + " |")
        trends = sweep_trends(done, sw.time)
        trend = [_trend_text(x) for x in trends]
        tested = sum(math.isfinite(x["p"]) for x in trends)  # Holm counts the measures with a p-value
        label = (
            "trend over the sweep (Kendall τ over every seed, a current-related measure 0 without current; "
            f"Holm over the sweep's {tested} measures tested)"
        )
        rows.append(f"| {label} | | " + " | ".join(trend) + " |")
        rows.append(f"\n![{sw.title}: the claim measures at t = {sw.time:g}]({figures}/sweep_{name}.png)")
    return "\n".join(rows)


def _p_cell(p) -> str:
    return "n/a" if not math.isfinite(p) else ("< 0.001" if p < 0.001 else f"{p:.2g}")


def _paired_steps(points) -> list:
    """For each step of a sweep, whether its two points start from the same rods (:func:`.pairing.same_start`):
    the one rule of the claims, paired by seed where they do, else Welch's."""
    return [same_start(a, b) for (_, a), (_, b) in zip(points, points[1:])]


def _step_label(points, paired=None) -> str:
    """The step row's label: how its p-values are made (:func:`_paired_steps`, given or found), and what
    its brackets count."""
    paired = _paired_steps(points) if paired is None else paired
    if all(paired):
        how, counts = "paired p, seed by seed,", "the pairs"
    elif not any(paired):
        how, counts = "Welch p", "the seeds a side"
    else:
        how = "p (" + "; ".join("paired" if x else "Welch" for x in paired) + ")"
        counts = "the pairs, or the seeds a side"
    return (
        f"{how} from each value to the next (each step alone; in brackets {counts}; every seed, a "
        "current-related measure 0 without current)"
    )


def _step(a, b, measure, t, same, fit_errors) -> tuple[float, str]:
    """The two-sided p-value of the step from point ``a`` to point ``b`` and what it counts: paired by seed
    over the seeds both have where ``same`` (the number of pairs), else Welch's (the seeds a side)."""
    x, ex = sweep_values(b, measure, t, fit_errors)
    y, ey = sweep_values(a, measure, t, fit_errors)
    if same:
        ib, ia = common_rows(b, a)
        q = paired_stat(x[ib], y[ia], None if ex is None else ex[ib], None if ey is None else ey[ia])
        return q["p"], f"{q['n']}"
    sa, sb = plain_stat(y, ey), plain_stat(x, ex)
    return welch_p(sb, sa), f"{sa['n']}, {sb['n']}"


def _step_p(points, measure, t, paired=None) -> str:
    """The two-sided p-value of each step of a sweep, from one value to the next (:func:`_step`), each
    with its count in brackets: "0.04 (5); 0.5 (5)", "n/a" for a step without two seeds (pairs) a side.
    A fitted dimension's steps are given twice, with each seed's fit error in the standard error and by
    the spread between seeds alone, as the claims give it."""
    paired = _paired_steps(points) if paired is None else paired
    steps = [(a, b, same) for ((_, a), (_, b)), same in zip(zip(points, points[1:]), paired)]

    def cell(a, b, same, fit_errors, counted=True):
        p, n = _step(a, b, measure, t, same, fit_errors)
        return _p_cell(p) + (f" ({n})" if counted else "")

    text = "; ".join(cell(a, b, same, True) for a, b, same in steps)
    if measure in FIT_ERRORS:
        text += " (seeds alone: " + "; ".join(cell(a, b, same, False, False) for a, b, same in steps) + ")"
    return text


def _kendall(points, measure, t) -> dict:
    """Kendall's tau-b between the parameter and every seed's value, the seeds of every point pooled."""
    from scipy.stats import kendalltau

    x, y = [], []
    for value, s in points:
        v = sweep_values(s, measure, t, fit_errors=False)[0]
        v = v[np.isfinite(v)]
        x += [float(value)] * v.size
        y += v.tolist()
    tau = p = math.nan
    if len(set(x)) >= 2 and len(y) >= 3 and np.ptp(y) > 0:
        res = kendalltau(x, y)
        tau, p = float(res.statistic), float(res.pvalue)
    return {"tau": tau, "p": p, "n": len(y)}


def sweep_trends(points, t) -> list[dict]:
    """The trend of each claim measure over a sweep's points ``[(value, summary), ...]`` at ``t``:
    Kendall's tau-b between the parameter and the per-seed values of :func:`sweep_values` (a
    current-related measure 0 where a seed carries none; a fitted dimension by its seeds' values
    alone, as a rank test cannot carry each fit's own error), every seed of every point pooled, and
    its two-sided p-value (docs/model.md "Measures of the paper's claims"). Where the points start
    from the same rods the seeds are not independent, which only makes the test conservative. One
    test per measure, where the steps of the table are several each: the p-values are adjusted by
    Holm over the measures of the sweep (``holm``). Returns a dict per measure of
    :data:`CLAIM_MEASURES`: ``tau``, ``p``, ``holm``, ``n`` (seeds ranked); NaN where fewer than two
    points have values or the values do not vary."""
    from .convergence import holm  # the convergence table's adjustment

    out = [{"measure": m} | _kendall(points, m, t) for m in CLAIM_MEASURES]
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


def sweep_points(studies, summaries, name, measure, every_seed=False):
    """(value, statistic) of a measure over a sweep's points that have a summary, as the sweep's table
    gives it: for a grouped measure the mean and standard error of the seeds that carry current, with
    their number ``k`` (``n``: those of them with a value; never a mean over both groups), else the
    plain statistic of every seed. With ``every_seed``, the plain statistic of the values the tests
    use (:func:`sweep_values`: a grouped measure's 0 where a seed carries none)."""
    sw = studies.sweeps[name]
    out = []
    for value, study in studies.sweep_points(name):
        s = summaries.get(study)
        if s is None:
            continue
        if every_seed:
            out.append((value, plain_stat(sweep_values(s, measure, sw.time, fit_errors=False)[0])))
        else:
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
