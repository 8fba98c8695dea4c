"""The verdicts of the results page: each claim against its null model, each numerical knob against
the default it varies, and each sweep of a scene's parameter.

A claim's verdict compares the study with its null model at the paper's end time, or in each seed's
mean over the claim's window, in standard errors of the difference: "reproduced" only for |d| > 3 in
the direction the claim predicts (docs/model.md "Measures of the paper's claims", its Verdicts). One
rule decides the test, as for the convergence table:

* where the two studies start from the same rods (the summaries' values at t = 0 agree seed by seed,
  :func:`.pairing.same_start`; a null model that runs the scene's scenario with a force term changed
  does), the seeds both have are paired: d is the mean of the per-seed differences over its standard
  error s_d / sqrt(n) (a fitted measure's fit errors added), with the paired t-test's p-value,
  n - 1 degrees of freedom, or the exact sign test's 2 / 2^n where every pair differs alike
  (:func:`.pairing.paired_stat`); the verdict says "paired over N seeds";
* otherwise the two sets of seeds are independent: d = (x - x_null) / sqrt(SE^2 + SE_null^2) over
  all the seeds of each, beside Welch's p-value ("Welch p").

A difference with no spread to scale by (infinite d: every pair alike, or every seed of each side the
same) is decided by its exact test, the sign test or :func:`separation_p`, at :data:`EXACT_LEVEL`.

A null model whose value is zero in every seed cannot have what the claim measures (its rods never
touch, say): a difference in the claimed direction is then worded as nonzero where the null model
is zero by construction, not as the claim reproduced. A windowed measure that is zero while a seed's
circuit is open, set against a null model that has some, is split in its row into the share of the
window's times at which the seeds carry current and its mean over those times alone (both sides); the
verdict stays on the window's mean. The statistics are those of :mod:`.stats` and :mod:`.pairing`.
"""

from __future__ import annotations

import math

import numpy as np

from ..provenance import version_key
from .pairing import common_rows, paired_stat, same_start, window_split
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

__all__ = ["CLAIM_MEASURES", "claim_rows", "claim_verdict", "sweep_points", "sweep_rows", "sweep_trends"]


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
    confidence: 3 SE is p = 0.0027 for a normal variable, p = 0.02 with 7 degrees of freedom). The
    Welch-Satterthwaite degrees of freedom count each side's whole variance as that of its seeds, a
    fitted dimension's fit-error term too: that term has no sample size of its own (docs/model.md
    "Measures of the paper's claims"), and one would only raise the degrees of freedom, so the
    p-value errs high. NaN without two seeds a side or without a spread."""
    if a["n"] < 2 or b["n"] < 2:
        return math.nan
    va, vb = a["sem"] ** 2, b["sem"] ** 2
    if not va + vb > 0:
        return math.nan
    from scipy.stats import t as student

    df = (va + vb) ** 2 / (va**2 / (a["n"] - 1) + vb**2 / (b["n"] - 1))
    return float(2.0 * student.sf(abs(a["mean"] - b["mean"]) / math.sqrt(va + vb), df))


#: the two-sided chance of 3 standard errors of a normal variable, 0.0027: where a difference has no
#: spread to scale by (infinite d), the level its exact test must pass for a verdict (docs/model.md
#: "Measures of the paper's claims", its Verdicts)
EXACT_LEVEL = 2.6997960632601866e-3


def separation_p(a, b) -> float:
    """The two-sided p-value of the exact rank test of two sets of seeds that each give one value, the
    two values different (no spread on either side, infinite d): every seed of one above every seed of
    the other, a chance of ``2 / C(n_a + n_b, n_a)`` under exchangeable seeds; NaN without a seed a side."""
    if a["n"] < 1 or b["n"] < 1:
        return math.nan
    return min(1.0, 2.0 / math.comb(a["n"] + b["n"], a["n"]))


def _test_text(p, paired=None) -> str:
    """The test beside a verdict: "Welch p = 0.002" (two significant digits, "< 1e-6" below), "paired
    over 5 seeds, p = 0.002" for a paired test of ``paired`` seeds (without its p where ``p`` is NaN);
    "" for Welch without a p-value."""
    if not math.isfinite(p):
        return f"paired over {paired} seeds" if paired else ""
    value = "< 1e-6" if p < 1e-6 else f"= {p:.2g}".replace("e-0", "e-")
    return f"paired over {paired} seeds, p {value}" if paired else f"Welch p {value}"


def _p_text(p, paired=None) -> str:
    """``"; "`` and :func:`_test_text`, or "" where that is empty."""
    text = _test_text(p, paired)
    return f"; {text}" if text else ""


#: a verdict's words where the null model's value is zero in every seed (docs/model.md "Measures of the paper's claims", its Verdicts)
ZERO_NULL = (
    "nonzero only with what the null model removes (the null model's value is zero in every seed, by construction)"
)


def _verdict(d, expect, p=math.nan, paired=None, zero=False):
    """The verdict on a difference of ``d`` standard errors from the null model (3 of them in the
    claimed direction), with the test beside it: Welch's p-value ``p``, or the paired test over
    ``paired`` seeds. Where the null model's value is zero in every seed (``zero``), a difference in
    the claimed direction is not worded as the claim reproduced: the null model cannot have any."""
    if math.isnan(d):
        return "not decided (too few seeds)"
    claimed = (d > 0) == (expect == "greater")
    if math.isinf(d):  # no spread: every seed of each gives the same value, or every pair differs alike
        if paired:
            what = f"every seed differs from the same seed of the null model by the same amount; sign test over {paired} seeds"
        else:
            what = "every seed differs from every seed of the null model; exact rank test"
        what += f", p = {p:.2g}" if math.isfinite(p) else " without a p-value"
        if not p < EXACT_LEVEL:  # a few pairs alike are no evidence: 2 of 2 happen half the time
            note = "; the null model's value is zero in every seed" if zero else ""
            return (
                f"not distinguished from the null model ({what}, not below {EXACT_LEVEL:.2g}, the chance of 3 SE{note})"
            )
        if zero and claimed:
            return f"{ZERO_NULL}; {what}"
        return f"{'reproduced' if claimed else 'opposite to the claim'} ({what})"
    sign = f"{'+' if d > 0 else '−'}{abs(d):.1f}"
    if abs(d) > 3 and claimed and zero:
        test = _test_text(p, paired)
        return f"{ZERO_NULL}; {sign} SE{', ' + test if test else ''}"
    note = "; the null model's value is zero in every seed" if zero else ""
    if abs(d) > 3:
        return f"{'reproduced' if claimed else 'opposite to the claim'} ({sign} SE from the null model{_p_text(p, paired)}{note})"
    return f"not distinguished from the null model ({d:+.1f} SE{_p_text(p, paired)}{note})".replace("-", "−")


def _fit_verdict(d, d_seeds, expect, p_seeds=math.nan, paired=None):
    """The verdict on a fitted measure, whose standard error carries each seed's fit uncertainty (``d``)
    or the spread between seeds alone (``d_seeds``, p-value ``p_seeds``; both paired over ``paired``
    seeds where given, else Welch's): the two are stated, and where they lead to different verdicts the
    page says that the verdict depends on counting the fits' own errors (docs/model.md "Measures of the
    paper's claims")."""
    with_fits, seeds_alone = _verdict(d, expect), _verdict(d_seeds, expect, p_seeds, paired)
    if math.isnan(d) and math.isnan(d_seeds):
        return with_fits  # "not decided (too few seeds)"
    if with_fits.split(" (")[0] == seeds_alone.split(" (")[0]:
        if math.isinf(d_seeds):  # no spread between the seeds: their verdict in words
            return f"{with_fits[:-1]}; by the spread between seeds alone: {seeds_alone})"
        return (
            f"{with_fits[:-1]}; {d_seeds:+.1f} SE by the spread between seeds alone{_p_text(p_seeds, paired)})".replace(
                "-", "−"
            )
        )
    return (
        f"depends on the fits' own errors: {_verdict(d, expect, math.nan, paired)} with each seed's fit error, "
        f"{seeds_alone} by the spread between seeds alone"
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


def _claim_values(summary, measure, c):
    """A claim side's per-seed values, each seed's mean over the claim's window or its value at the
    claim's time, and their fit errors (None but for a fitted measure at a time)."""
    if c.window:
        return window_values(summary, measure, *c.window), None
    errs = values_at(summary, FIT_ERRORS[measure], c.time) if measure in FIT_ERRORS else None
    return values_at(summary, measure, c.time), errs


def _all_zero(values) -> bool:
    """Whether every seed with a value has exactly 0 (a null model that cannot have any)."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    return bool(v.size) and bool((v == 0.0).all())


def _fitted_only(values, errors):
    """``values`` with NaN where a fit error is missing (none missing without ``errors``): the seeds a
    statistic with fit errors counts, for the reading by the spread between seeds alone too."""
    return values if errors is None else np.where(np.isfinite(errors), values, np.nan)


def _unpaired_note(s, null, ia) -> str:
    """ "; 8 of the study's 20 seeds have no pair in the null model and are left out" where a paired
    verdict leaves seeds out (the row's values are over all of each side's seeds), or ""."""
    left = [(len(x["seeds"]) - len(ia), len(x["seeds"]), who) for x, who in ((s, "study's"), (null, "null model's"))]
    words = [f"{k} of the {who} {n} seeds" for k, n, who in left if k]
    if not words:
        return ""
    return f"; {' and '.join(words)} have no pair and are left out"


def claim_verdict(c, s, null, nm) -> str:
    """The verdict of claim ``c`` on study summary ``s`` against its null model's summary ``null``
    (measure ``nm``): paired by seed over the seeds both have where the two start from the same rods
    (:func:`.pairing.same_start`), else Welch's comparison of the two sets of seeds; a fitted measure's
    also by the spread between seeds alone; a null model zero in every seed worded as such."""
    x, ex = _claim_values(s, c.measure, c)
    y, ey = _claim_values(null, nm, c)
    fitted = ex is not None or ey is not None
    zero = not fitted and _all_zero(y)
    if same_start(s, null):
        ia, ib = common_rows(s, null)
        ex = None if ex is None else ex[ia]
        ey = None if ey is None else ey[ib]
        q = paired_stat(x[ia], y[ib], ex, ey)
        if not fitted:
            return _verdict(q["d"], c.expect, q["p"], q["n"], zero) + _unpaired_note(s, null, ia)
        alone = paired_stat(_fitted_only(x[ia], ex), _fitted_only(y[ib], ey))  # the same pairs, no fit errors
        return _fit_verdict(q["d"], alone["d"], c.expect, alone["p"], q["n"]) + _unpaired_note(s, null, ia)
    a, b = plain_stat(x, ex), plain_stat(y, ey)
    if not fitted:
        d = _claim_difference(a, b)
        return _verdict(d, c.expect, separation_p(a, b) if math.isinf(d) else welch_p(a, b), zero=zero)
    sa, sb = plain_stat(_fitted_only(x, ex)), plain_stat(_fitted_only(y, ey))  # the seeds of a, b
    d_seeds = _claim_difference(sa, sb)
    return _fit_verdict(
        _claim_difference(a, b), d_seeds, c.expect, separation_p(sa, sb) if math.isinf(d_seeds) else welch_p(sa, sb)
    )


def _split_text(summary, measure, window) -> str:
    """A window's mean of a grouped measure split in two (:func:`.pairing.window_split`): the share of
    the window's times at which the seeds carry current, and the measure over those times alone, each
    mean ± SE over the seeds."""
    sp = window_split(summary, measure, *window)
    what = "carry current" if sp["circuit"] else "span the gap (no circuit)"
    return (
        f"split: share of the window's {sp['times']} times at which the seeds {what}: {pm(plain_stat(sp['fraction']))}; "
        f"the measure over those times alone: {pm(plain_stat(sp['size']))}"
    )


def claim_rows(studies, summaries) -> str:
    """The claims table: each claim's measure at the paper's end time, its null model and the verdict
    (:func:`claim_verdict`); a windowed grouped measure against a null model that has some gives both
    sides' :func:`_split_text`."""
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
                null_value = pm(plain_stat(window_values(null, nm, *c.window)))
            else:
                null_value = measure_text(null, nm, c.time)
            null_text = studies.study(c.null).title
            null_value += "" if nm == c.measure else f" ({measure_label(nm)})"
            verdict = claim_verdict(c, s, null, nm)
            if (
                c.window
                and c.measure in GROUPED
                and nm in GROUPED
                and not _all_zero(window_values(null, nm, *c.window))
            ):
                value += f"; {_split_text(s, c.measure, c.window)}"
                null_value += f"; {_split_text(null, nm, c.window)}"
        verdict += _older_note(summaries, (c.study, c.null), studies)
        rows.append(
            f"| {c.claim} | {c.paper} | {measure_label(c.measure)}, {where} | {value} | {null_text} | "
            f"{null_value} | {verdict} |"
        )
    return "\n".join(rows)


def sweep_rows(studies, summaries, name) -> str:
    """A sweep's table: a row per value of its parameter, the claim measures at the sweep's time, the
    p-value of each step from one value to the next (:func:`_step_p`) and the trend over the sweep."""
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
        paired = _paired_steps(done)
        steps = [_step_p(done, m, sw.time, paired) for m in CLAIM_MEASURES]
        rows.append(f"| {_step_label(done, paired)} | | " + " | ".join(steps) + " |")
        trends = sweep_trends(done, sw.time)
        trend = [_trend_text(x) for x in trends]
        tested = sum(math.isfinite(x["p"]) for x in trends)  # Holm counts the measures with a p-value
        label = f"trend over the sweep (Kendall τ over every seed; Holm over the {tested} measures tested)"
        rows.append(f"| {label} | | " + " | ".join(trend) + " |")
        rows.append(f"\n![{sw.title}: the claim measures at t = {sw.time:g}](figures/sweep_{name}.png)")
    return "\n".join(rows)


def _p_cell(p) -> str:
    return "n/a" if not math.isfinite(p) else ("< 0.001" if p < 0.001 else f"{p:.2g}")


def _paired_steps(points) -> list:
    """For each step of a sweep, whether its two points start from the same rods (:func:`.pairing.same_start`):
    the one rule of the claims, paired by seed where they do, else Welch's."""
    return [same_start(a, b) for (_, a), (_, b) in zip(points, points[1:])]


def _step_label(points, paired=None) -> str:
    """The step row's label: how its p-values are made (:func:`_paired_steps`, given or found)."""
    paired = _paired_steps(points) if paired is None else paired
    if all(paired):
        how = "paired p, seed by seed,"
    elif not any(paired):
        how = "Welch p"
    else:
        how = "p (" + "; ".join("paired" if x else "Welch" for x in paired) + ")"
    return f"{how} from each value to the next (each step alone)"


def _step_p(points, measure, t, paired=None) -> str:
    """The two-sided p-value of each step of a sweep, from one value to the next: paired by seed where
    the two points start from the same rods (:func:`.convergence.paired_difference`, a grouped measure
    over the seeds that carry current in both), else Welch's of the statistics the table gives (a
    grouped measure's over the seeds that carry current): "0.04; 0.5; < 0.001", "n/a" for a step
    without two seeds (pairs) a side. A fitted dimension's steps are given twice, with each seed's fit
    error in the standard error and by the spread between seeds alone, as the claims give it."""
    from .convergence import paired_difference  # (convergence imports this module)

    def step(a, b, same, fit_errors):
        if same:
            return paired_difference(b, a, measure, t, fit_errors)["p"]
        if fit_errors:
            return welch_p(_stat_at(b, measure, t), _stat_at(a, measure, t))
        return welch_p(plain_stat(_table_values(b, measure, t)), plain_stat(_table_values(a, measure, t)))

    paired = _paired_steps(points) if paired is None else paired
    steps = [(a, b, same) for ((_, a), (_, b)), same in zip(zip(points, points[1:]), paired)]
    text = "; ".join(_p_cell(step(a, b, same, True)) for a, b, same in steps)
    if measure in FIT_ERRORS:
        text += " (seeds alone: " + "; ".join(_p_cell(step(a, b, same, False)) for a, b, same in steps) + ")"
    return text


def _table_values(summary, measure, t) -> np.ndarray:
    """The per-seed values a table's statistic of ``measure`` at ``t`` describes: the seeds that carry
    current for a grouped measure (:func:`_stat_at`), the seeds with a value and a fit error for a
    fitted one, every seed with a value otherwise."""
    v = values_at(summary, measure, t)
    if measure in FIT_ERRORS:
        v = _fitted_only(v, values_at(summary, FIT_ERRORS[measure], t))
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
