"""The convergence table of the results page: each setting of a numerical knob against the default it
varies, seed by seed.

A setting runs seeds that the study it varies runs too (its ``null_of`` in docs/studies.toml), so each
pair of runs starts from the same rods. Two such runs part within a few t0 (their first short circuits
fall at other times), yet their outcomes at the table's time can stay correlated: the rods' placement
decides much of where a network forms. Two independent sets of seeds would count that shared part as
noise on both sides; the table compares the pairs instead (docs/model.md "Measures of the paper's
claims"):

* the difference of a measure is the mean over the seeds both runs have of ``x_i - x_default,i``,
  its standard error ``s_d / sqrt(n)`` (``s_d`` the spread of the per-seed differences), and for a
  fitted dimension ``sqrt(s_d^2 / n + mean(err_i^2 + err_default,i^2) / n)`` as for the claims; its
  two-sided p-value is that of the paired t-test, ``n - 1`` degrees of freedom; where every pair
  differs by the same nonzero amount (a count can) the t-test is undefined, and the p-value is the
  exact two-sided sign test's, ``2 / 2^n``: 5 pairs alike give 0.0625, not 0;
* a grouped measure (zero while a seed's circuit is open) pairs every seed with a current flag in both
  runs, 0 where one carries none: pairing only the seeds that carry current in both picked them by the
  outcome, and would not see a setting that changes whether current flows;
* a setting "moves these statistics" when one of its measures differs at a family-wise level of 5 %
  over the measures compared (Holm's step-down adjustment of the p-values): with 6 measures and 5
  seeds, a single difference of 3-4 SE is what chance gives one setting in ten or more;
* "detectable" is the difference that test finds 4 times in 5 when it is the setting's only one
  (:func:`detectable_se`), in % of the default's mean over the same seeds;
* a fitted dimension is given twice, with each seed's fit error and by the spread between seeds alone
  (two runs of one seed share much of the bend that makes the fit error), and where the conclusions
  the two give differ the table says that it depends on the fits' own errors.
"""

from __future__ import annotations

import functools
import math

import numpy as np

from .pairing import common_rows, paired_stat
from .stats import CLAIM_MEASURES, FIT_ERRORS, GROUPED, current_flags, fmt, measure_label, plain_stat, pm, values_at
from .verdicts import _older_note

__all__ = ["LEVEL", "convergence_rows", "detectable_se", "holm", "paired_difference"]


#: the family-wise level of a setting's comparisons (module docstring)
LEVEL = 0.05


@functools.lru_cache(maxsize=256)
def detectable_se(df, measures=1, level=LEVEL, power=0.8) -> float:
    """The true difference, in standard errors, that the paired t-test with ``df`` degrees of freedom
    finds with probability ``power`` at level ``level / measures`` (two-sided; Holm's first step over
    ``measures`` comparisons): the noncentrality of the noncentral t distribution where the chance
    beyond the critical value reaches ``power``. About 2.8 for many degrees of freedom and one
    measure; 3.76 for 4 degrees of freedom and one measure, 6.17 with 6 measures; 65 for one degree
    of freedom (two pairs) and 4 measures. Infinite past 10^6."""
    from scipy.optimize import brentq
    from scipy.stats import nct
    from scipy.stats import t as student

    crit = float(student.isf(level / (2 * measures), df))

    def missed(delta):  # chance beyond the critical value, less the power; nct gives NaN far in its tails
        p = nct.sf(crit, df, delta) + nct.cdf(-crit, df, delta)
        return float(np.nan_to_num(p, nan=1.0 if delta > crit else 0.0)) - power

    hi = 50.0  # with few degrees of freedom and many measures the critical value itself passes 50
    while missed(hi) < 0.0:
        if hi > 1e6:
            return math.inf
        hi *= 4.0
    return float(brentq(missed, 0.0, hi))


def holm(pvalues) -> list:
    """Holm's step-down adjustment of p-values (NaN stays NaN and is not counted): the smallest of m
    times m, the next times m - 1 and no smaller than the one before, each at most 1."""
    order = sorted((p, k) for k, p in enumerate(pvalues) if not math.isnan(p))
    m, out, running = len(order), [math.nan] * len(pvalues), 0.0
    for j, (p, k) in enumerate(order):
        running = max(running, min(1.0, (m - j) * p))
        out[k] = running
    return out


def paired_difference(setting, default, measure, t, fit_errors=True) -> dict:
    """A measure at time ``t`` of ``setting`` against ``default``, paired by seed (module docstring;
    the arithmetic of :func:`.pairing.paired_stat`).

    Returns a dict: ``n`` pairs compared; ``a`` and ``b``, the plain statistics (mean, sem, n) of the
    setting and the default over those pairs; ``diff`` and ``sem`` of the per-seed differences; ``d``,
    ``diff / sem`` (infinite where every pair differs by the same nonzero amount, 0 where none differs,
    NaN for fewer than 2 pairs) and ``p``, its two-sided p-value with ``n - 1`` degrees of freedom
    (the sign test's ``2 / 2^n`` where ``d`` is infinite); for a grouped measure also ``k_a``,
    ``k_b``, the seeds of each side that carry current, of ``of`` pairs with a value and a flag on
    both sides. A fitted dimension carries each seed's fit error unless ``fit_errors`` is false (the
    spread between seeds alone); a pair lacking a fit error is left out either way.
    """
    ia, ib = common_rows(setting, default)
    a, b = values_at(setting, measure, t)[ia], values_at(default, measure, t)[ib]
    ok = np.isfinite(a) & np.isfinite(b)
    ea = eb = None
    if measure in FIT_ERRORS:  # a value without its fit error is left out, as in mean_sem_fits
        ea, eb = values_at(setting, FIT_ERRORS[measure], t)[ia], values_at(default, FIT_ERRORS[measure], t)[ib]
        ok &= np.isfinite(ea) & np.isfinite(eb)
    out = {}
    if measure in GROUPED:  # every pair with a flag on both sides, 0 where a seed carries none (not only
        # the pairs that carry current in both: that picked the seeds by the outcome)
        act_a, known_a, _ = current_flags(setting, t)
        act_b, known_b, _ = current_flags(default, t)
        ok &= known_a[ia] & known_b[ib]
        out |= {"k_a": int((ok & act_a[ia]).sum()), "k_b": int((ok & act_b[ib]).sum()), "of": int(ok.sum())}
        if not (out["k_a"] or out["k_b"]):  # no current on either side: nothing to compare, not a 0 = 0
            ok = np.zeros_like(ok)
    if ea is not None and not fit_errors:
        ea, eb = np.zeros_like(ea), np.zeros_like(eb)
    pick = np.where(ok, 0.0, np.nan)  # the pairs kept: NaN elsewhere, which paired_stat leaves out
    stat = paired_stat(a + pick, b + pick, None if ea is None else ea, None if eb is None else eb)
    if ea is not None and not fit_errors:  # both sides as the tables give them by the seeds alone
        stat["a"], stat["b"] = plain_stat(a[ok]), plain_stat(b[ok])
    return out | stat


def _side(p, key) -> str:
    """One side's cell: "mean ± SE (n)", for a grouped measure after how many of the paired seeds
    carry current, the mean over every one of them where some carry none."""
    s = p["a" if key == "k_a" else "b"]
    if key not in p:
        return pm(s)
    group = f"{p[key]} of {p['of']} carry current"
    if not p["n"]:
        return group
    return f"{group}: {pm(s)}" if p[key] == p["of"] else f"{group}; every seed, 0 without current: {pm(s)}"


def _difference(p) -> str:
    """The paired difference as "x ± SE (d SE; p = ...)"; "n/a" without two pairs."""
    if math.isnan(p["d"]):
        return "n/a"
    if math.isinf(p["d"]):
        return f"{fmt(p['diff'])} in every pair (sign test p = {fmt(p['p'], 2)})".replace("-", "−")
    return f"{fmt(p['diff'])} ± {fmt(p['sem'], 2)} ({p['d']:+.1f} SE; p = {fmt(p['p'], 2)})".replace("-", "−")


def _detectable(p, measures) -> str:
    """:func:`detectable_se` standard errors of the paired difference in % of the default's mean over
    the pairs ("n/a" without a spread or a mean)."""
    if not (p["n"] > 1 and math.isfinite(p["sem"]) and p["sem"] > 0 and p["b"]["mean"]):
        return "n/a"
    delta = detectable_se(p["n"] - 1, measures)
    return "n/a" if math.isinf(delta) else f"±{fmt(100 * delta * p['sem'] / abs(p['b']['mean']), 2)} %"


def _conclusion(pairs) -> str:
    """A setting's conclusion from the Holm-adjusted p-values of its measures (module docstring)."""
    ps = [x["p"] for x in pairs]
    adjusted = holm(ps)
    compared = [k for k, q in enumerate(adjusted) if not math.isnan(q)]
    if not compared:
        return "not decided (too few seeds)"
    k = min(compared, key=lambda j: (adjusted[j], ps[j]))  # Holm ties several: the smallest raw p
    m = len(compared)
    what = f"{measure_label(CLAIM_MEASURES[k])}: p = {fmt(ps[k], 2)}, {fmt(adjusted[k], 2)} after Holm over {m}"
    if adjusted[k] < LEVEL:
        verdict = f"moves these statistics ({what})"
    else:
        verdict = f"no difference detected at this size (smallest: {what})"
    if m < len(pairs):
        verdict += f"; {len(pairs) - m} of {len(pairs)} measures not compared (n/a)"
    return verdict


def convergence_rows(studies, summaries) -> str:
    """For each variant of a numerical knob, each claim measure at the variant's end time against the
    study it varies (same time, same seeds): both sides over the seeds compared, their paired
    difference in its standard errors, the difference the comparison would find, and what follows."""
    rows = [
        "| setting | measure | default, same seeds | this setting | difference, paired by seed | detectable "
        "| conclusion |",
        "|---|---|---|---|---|---|---|",
    ]
    for st in studies.studies.values():
        if st.section != "convergence":
            continue
        s, base = summaries.get(st.name), summaries.get(st.null_of)
        if s is None or base is None:
            missing = st.name if s is None else st.null_of
            rows.append(f"| {st.title} | | | | | | not run yet (`selfas-graph study run {missing}`) |")
            continue
        t = st.t_end
        pairs = [paired_difference(s, base, m, t) for m in CLAIM_MEASURES]
        alone = [
            paired_difference(s, base, m, t, fit_errors=False) if m in FIT_ERRORS else p
            for m, p in zip(CLAIM_MEASURES, pairs)
        ]
        verdict = _fit_conclusion(pairs, alone) + _older_note(summaries, (st.name, st.null_of), studies)
        measures = sum(not math.isnan(p["d"]) for p in pairs)
        for k, (m, p) in enumerate(zip(CLAIM_MEASURES, pairs, strict=True)):
            diff, detect = _difference(p), _detectable(p, measures)
            if m in FIT_ERRORS:
                diff += f"; seeds alone: {_difference(alone[k])}"
                detect += f" (seeds alone: {_detectable(alone[k], measures)})"
            rows.append(
                f"| {st.title if k == 0 else ''} | {measure_label(m)}, t = {t:g} | {_side(p, 'k_b')} | "
                f"{_side(p, 'k_a')} | {diff} | {detect} | {verdict if k == 0 else ''} |"
            )
    return "\n".join(rows)


def _fit_conclusion(pairs, alone) -> str:
    """:func:`_conclusion` with each seed's fit error in a fitted dimension's pairs, and, where the
    conclusion by the spread between seeds alone (``alone``) differs, both, as the claims give a
    fitted measure (docs/model.md "Measures of the paper's claims")."""
    with_fits, seeds_alone = _conclusion(pairs), _conclusion(alone)
    if with_fits.split(" (")[0] == seeds_alone.split(" (")[0]:
        return with_fits
    return (
        f"depends on the fits' own errors: {with_fits} with each seed's fit error; {seeds_alone} by the "
        "spread between seeds alone"
    )
