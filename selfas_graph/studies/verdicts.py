"""The verdicts of the results page: each claim against its null model, each numerical knob against
the default it varies, and each sweep of a scene's parameter.

A claim's verdict compares the study with its null model at the paper's end time, or in each seed's
mean over the claim's window, by d, the difference in standard errors of the difference, and its test's
two-sided p-value: "reproduced" only where p is below :data:`VERDICT_LEVEL` (0.0027, the chance of 3
SE of a normal variable; lower for a claim read before, :func:`reading_level`) and d lies in the direction the claim predicts (docs/model.md "Measures of the paper's
claims", its Verdicts). One rule decides the test, as for the convergence table:

* where the two studies start from the same rods (the summaries' values at t = 0 agree seed by seed,
  :func:`.pairing.same_start`; a null model that runs the scene's scenario with a force term changed
  does), the seeds both have are paired: d is the mean of the per-seed differences over its standard
  error s_d / sqrt(n) (a fitted measure's fit errors added), with the paired t-test's p-value,
  n - 1 degrees of freedom, or the exact sign test's 2 / 2^n where every pair differs alike
  (:func:`.pairing.paired_stat`); the verdict says "paired over N seeds";
* otherwise the two sets of seeds are independent: d = (x - x_null) / sqrt(SE^2 + SE_null^2) over
  all the seeds of each, beside Welch's p-value ("Welch p").

A difference with no spread to scale by (infinite d: every pair alike, or every seed of each side the
same) is decided by its exact test, the sign test or :func:`separation_p`, at the same level.

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
    measure_label,
    measure_text,
    older_runs,
    plain_stat,
    pm,
    values_at,
    window_times,
    window_values,
)

__all__ = ["CLAIM_MEASURES", "claim_rows", "claim_verdict", "welch_p"]


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


#: the two-sided chance of 3 standard errors of a normal variable, 0.0027: the level a claim's test
#: must pass for a verdict, a t-test's or, where a difference has no spread to scale by (infinite d), an
#: exact test's (docs/model.md "Measures of the paper's claims", its Verdicts)
VERDICT_LEVEL = 2.6997960632601866e-3


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


def _level_text(level=None) -> str:
    """The level a verdict's p-value must pass, in words: "0.0027, the chance of 3 SE", or a claim's
    lower level over its readings (:func:`_looks_note` says why) as a number alone."""
    if level is None or level == VERDICT_LEVEL:
        return f"{VERDICT_LEVEL:.2g}, the chance of 3 SE"
    return f"{level:.2g}"


def _verdict(d, expect, p=math.nan, paired=None, zero=False, level=None):
    """The verdict on a difference of ``d`` standard errors from the null model, decided by its test's
    two-sided p-value ``p`` (Welch's, or the paired test's over ``paired`` seeds; an exact test's where
    ``d`` is infinite): "reproduced" where ``p`` is below ``level`` (:data:`VERDICT_LEVEL`, the chance
    of 3 SE, unless given) and ``d`` lies in the claimed direction, "opposite to the claim" where it
    lies the other way, "not distinguished from the null model" otherwise. One rule for every test, so
    that a few seeds need a larger d (at 2 pairs, 3 SE is p = 0.2). Where the null model's value is
    zero in every seed (``zero``), a difference in the claimed direction is not worded as the claim
    reproduced: the null model cannot have any."""
    if math.isnan(d):
        return "not decided (too few seeds)"
    level = VERDICT_LEVEL if level is None else level
    claimed = (d > 0) == (expect == "greater")
    note = "; the null model's value is zero in every seed" if zero else ""
    if math.isinf(d):  # no spread: every seed of each gives the same value, or every pair differs alike
        if paired:
            what = f"every seed differs from the same seed of the null model by the same amount; sign test over {paired} seeds"
        else:
            what = "every seed differs from every seed of the null model; exact rank test"
        what += f", p = {p:.2g}" if math.isfinite(p) else " without a p-value"
        found = what
    else:
        sign = f"{'−' if round(d, 1) < 0 else '+'}{abs(d):.1f}"  # no −0.0
        test = _test_text(p, paired)
        what = f"{sign} SE{'; ' + test if test else ''}"
        found = f"{sign} SE from the null model{'; ' + test if test else ''}"
    if not p < level:  # a few pairs alike are no evidence: 2 of 2 happen half the time
        return f"not distinguished from the null model ({what}, not below {_level_text(level)}{note})"
    if zero and claimed:
        return f"{ZERO_NULL}; {what.replace('SE;', 'SE,')}"
    return f"{'reproduced' if claimed else 'opposite to the claim'} ({found}{note})"


def _fit_verdict(d, d_seeds, expect, p=math.nan, p_seeds=math.nan, paired=None, level=None):
    """The verdict on a fitted measure, whose standard error carries each seed's fit uncertainty (``d``,
    p-value ``p``) or the spread between seeds alone (``d_seeds``, p-value ``p_seeds``; both paired over
    ``paired`` seeds where given, else Welch's): the two are stated, and where they lead to different
    verdicts the page says that the verdict depends on counting the fits' own errors (docs/model.md
    "Measures of the paper's claims")."""
    with_fits = _verdict(d, expect, p, paired, level=level)
    seeds_alone = _verdict(d_seeds, expect, p_seeds, paired, level=level)
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
        f"depends on the fits' own errors: {with_fits} with each seed's fit error, "
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


def _unpaired_note(s, null, n_pairs) -> str:
    """ "; 8 of the study's 20 seeds have no pair in the null model and are left out" where a paired
    verdict over ``n_pairs`` pairs leaves seeds out (no seed of that number on the other side, or no
    value on either; the row's values are over all of each side's seeds), or ""."""
    left = [(len(x["seeds"]) - n_pairs, len(x["seeds"]), who) for x, who in ((s, "study's"), (null, "null model's"))]
    words = [f"{k} of the {who} {n} seeds" for k, n, who in left if k]
    if not words:
        return ""
    return f"; {' and '.join(words)} have no pair and are left out"


def reading_level(k) -> float:
    """The level of a claim's ``k``-th reading (k = 1, 2, ...): :data:`VERDICT_LEVEL` / (k (k + 1)). As
    1 / (k (k + 1)) = 1 / k - 1 / (k + 1), the levels of all readings, however many, sum to less than
    :data:`VERDICT_LEVEL`: reading the verdict again as seeds are added, and stopping when it turns,
    cannot raise the chance of a false one above it (a level divided by the readings so far would:
    its sum grows as the harmonic series)."""
    return VERDICT_LEVEL / (k * (k + 1))


def _looks_note(looks) -> str:
    """ "; read before at 8/5 (3 times), 12/12 and 16/16 seeds (study/null model): the 6th reading,
    tested at 0.0027 / 42" for a claim whose verdict was read before (its ``looks``), or ""
    (:func:`reading_level`)."""
    if not looks:
        return ""
    counts = {}
    for x in looks:  # in order of first reading
        counts[x] = counts.get(x, 0) + 1
    at = [f"{n}/{m}" + ("" if k == 1 else " (twice)" if k == 2 else f" ({k} times)") for (n, m), k in counts.items()]
    at = at[0] if len(at) == 1 else f"{', '.join(at[:-1])} and {at[-1]}"
    k = 1 + len(looks)
    nth = {1: "st", 2: "nd", 3: "rd"}.get(k % 10 if k % 100 not in (11, 12, 13) else 0, "th")
    return (
        f"; read before at {at} seeds (study/null model): the {k}{nth} reading, tested at "
        f"{VERDICT_LEVEL:.2g} / {k * (k + 1)}"
    )


def claim_verdict(c, s, null, nm) -> str:
    """The verdict of claim ``c`` on study summary ``s`` against its null model's summary ``null``
    (measure ``nm``): paired by seed over the seeds both have where the two start from the same rods
    (:func:`.pairing.same_start`), else Welch's comparison of the two sets of seeds; a fitted measure's
    also by the spread between seeds alone; a null model zero in every seed worded as such. The level
    is that of the claim's reading (:func:`reading_level`, :func:`_looks_note`)."""
    x, ex = _claim_values(s, c.measure, c)
    y, ey = _claim_values(null, nm, c)
    looks = [tuple(x) for x in c.looks]  # the readings before this one, a count read twice there twice
    level = reading_level(1 + len(looks))
    if not np.isfinite(y).any():
        return "not decided (the null model has no value of the measure)"
    fitted = ex is not None or ey is not None
    zero = not fitted and _all_zero(y)
    if same_start(s, null):
        ia, ib = common_rows(s, null)
        ex = None if ex is None else ex[ia]
        ey = None if ey is None else ey[ib]
        q = paired_stat(x[ia], y[ib], ex, ey)
        if not fitted:
            verdict = _verdict(q["d"], c.expect, q["p"], q["n"], zero, level)
        else:
            alone = paired_stat(_fitted_only(x[ia], ex), _fitted_only(y[ib], ey))  # the same pairs, no fit errors
            verdict = _fit_verdict(q["d"], alone["d"], c.expect, q["p"], alone["p"], q["n"], level)
        return verdict + _unpaired_note(s, null, q["n"]) + _looks_note(looks)
    a, b = plain_stat(x, ex), plain_stat(y, ey)
    if not fitted:
        d = _claim_difference(a, b)
        p = separation_p(a, b) if math.isinf(d) else welch_p(a, b)
        return _verdict(d, c.expect, p, zero=zero, level=level) + _looks_note(looks)
    sa, sb = plain_stat(_fitted_only(x, ex)), plain_stat(_fitted_only(y, ey))  # the seeds of a, b
    d_seeds = _claim_difference(sa, sb)
    p_seeds = separation_p(sa, sb) if math.isinf(d_seeds) else welch_p(sa, sb)
    verdict = _fit_verdict(_claim_difference(a, b), d_seeds, c.expect, welch_p(a, b), p_seeds, level=level)
    return verdict + _looks_note(looks)


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
