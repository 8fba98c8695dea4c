"""Two studies seed by seed: whether they start from the same rods, the paired difference of per-seed
values, and how a window's mean of a grouped measure splits into how often and how much.

Two studies start from the same rods where the summaries say so at t = 0: every measure both hold has
the same value there, seed by seed, over the seeds both have (a measure one side lacks at t = 0, NaN as
the current of a scene without a circuit, is not compared), and at least one finite value of a measure
of the rods' placement is compared (the others are constants of the scene at t = 0: the rod count, no
structure, no current; two scenes of as many rods would agree in them whatever their rods).
A study without t = 0 among its summarised times, or with no seed in common, starts from other rods as
far as the page can tell. Names, scenario files and overrides are not read: a null model that runs the
same scenario with another force term has the same rods at t = 0, one that places them anew has not.

The paired difference (docs/model.md "Measures of the paper's claims") is that of the convergence
table (:func:`.convergence.paired_difference`), from per-seed values already set side by side: the
mean of ``x_i - y_i`` over the pairs where both have a value, its standard error
``sqrt(s_d^2 / n + mean(ex_i^2 + ey_i^2) / n)`` (``s_d`` the spread of the differences, the fit errors
only for a fitted measure), ``d = diff / sem`` and the two-sided p-value of the paired t-test with
``n - 1`` degrees of freedom (the seeds' alone, also with the fit errors: a fit error has no sample
size of its own, and one would only raise the degrees of freedom, so the p-value errs high); where every pair differs by the same nonzero amount ``d`` is infinite and
the p-value is the exact sign test's, ``2 / 2^n``.
"""

from __future__ import annotations

import math

import numpy as np

from .stats import _in_window, current_flags, plain_stat, reached, values_at

__all__ = ["common_rows", "paired_stat", "same_start", "window_split"]


def common_rows(a, b):
    """``(ia, ib)``: the rows of the seeds both summaries have, in ``a``'s order (integer arrays)."""
    rows_b = {int(x["seed"]): i for i, x in enumerate(b["seeds"]) if "seed" in x}
    pairs = [(i, rows_b[int(x["seed"])]) for i, x in enumerate(a["seeds"]) if "seed" in x and int(x["seed"]) in rows_b]
    ia = np.array([p[0] for p in pairs], dtype=np.int64)
    ib = np.array([p[1] for p in pairs], dtype=np.int64)
    return ia, ib


#: measures whose value at t = 0 depends on where each rod is placed and how it points (the others there
#: are constants of the scene: the number of rods, no structure, no current); two summaries start from
#: the same rods only where one of these is compared
PLACED = ("inside_R_plas", "median_axis_distance", "all_alignment", "free_alignment")


def same_start(a, b, t=0.0) -> bool:
    """Whether two summaries start from the same rods: at ``t`` (0) every measure both hold is equal,
    seed by seed over the seeds both have, where both have a value, and at least one value of a measure
    of the rods' placement (:data:`PLACED`) is compared (module docstring). Equal to 1e-12 relative, as
    the same rods give the same numbers."""
    ia, ib = common_rows(a, b)
    if not ia.size:
        return False
    compared = 0
    for m in sorted(set(a["measures"]) & set(b["measures"])):
        x, y = values_at(a, m, t)[ia], values_at(b, m, t)[ib]
        both = np.isfinite(x) & np.isfinite(y)
        if not np.allclose(x[both], y[both], rtol=1e-12, atol=0.0):
            return False
        compared += int(both.sum()) if m in PLACED else 0
    return compared > 0


def paired_stat(x, y, ex=None, ey=None) -> dict:
    """The paired difference of per-seed values ``x`` and ``y`` (pair i: ``x[i]`` and ``y[i]``), with
    each value's fit error ``ex``, ``ey`` for a fitted measure (module docstring). A pair counts where
    both values, and the errors given, are finite.

    Returns ``n`` pairs; ``a`` and ``b``, the plain statistics of each side over them (with the fit
    errors where given); ``diff`` and ``sem`` of the differences; ``d``, ``diff / sem`` (infinite where
    every pair differs by the same nonzero amount, 0 where none differs, NaN for fewer than 2 pairs);
    ``p``, its two-sided p-value (the sign test's ``2 / 2^n`` where ``d`` is infinite)."""
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    ok = np.isfinite(x) & np.isfinite(y)
    fitted = ex is not None or ey is not None
    ex = np.zeros_like(x) if ex is None else np.asarray(ex, dtype=float)
    ey = np.zeros_like(y) if ey is None else np.asarray(ey, dtype=float)
    ok &= np.isfinite(ex) & np.isfinite(ey)
    n = int(ok.sum())
    x, y, ex, ey = x[ok], y[ok], ex[ok], ey[ok]
    diff = sem = d = p = math.nan
    if n:
        diff = float((x - y).mean())
    if n > 1:
        from scipy.stats import t as student

        sem = math.sqrt(float((x - y).var(ddof=1)) / n + float((ex * ex + ey * ey).mean()) / n)
        d = diff / sem if sem > 0 else (0.0 if diff == 0 else math.copysign(math.inf, diff))
        if math.isinf(d):  # no spread to scale by: the exact sign test of n pairs of one sign
            p = min(1.0, 2.0 * 0.5**n)
        else:
            p = 1.0 if d == 0 else float(2.0 * student.sf(abs(d), n - 1))
    a = plain_stat(x, ex if fitted else None)
    b = plain_stat(y, ey if fitted else None)
    return {"n": n, "a": a, "b": b, "diff": diff, "sem": sem, "d": d, "p": p}


def window_split(summary, measure, lo, hi) -> dict:
    """How a seed's mean of a grouped measure over the summarised times in [lo, hi] (zero while its
    circuit is open) splits: ``fraction``, each seed's share of those times at which it carries current
    (of the times with a value and a current flag), and ``size``, its mean over those times alone (NaN
    for a seed that never does), each a per-seed array, NaN for a seed that stopped before ``hi`` (as in
    :func:`.stats.window_values`); ``times``, how many of the window's times
    hold the measure for some seed; ``circuit``, whether the study has a circuit (without one the flag
    says that filaments span the gap)."""
    times = np.asarray(summary["times"], dtype=float)[_in_window(summary, lo, hi)]
    n = len(summary["seeds"])
    if measure not in summary["measures"] or not times.size:
        nan = np.full(n, np.nan)
        return {"fraction": nan, "size": nan, "times": 0, "circuit": False}
    values, active, known, circuit = [], [], [], False
    for t in times:
        act, kn, circ = current_flags(summary, t)
        v = values_at(summary, measure, t)
        values.append(v)
        active.append(act)
        known.append(kn & np.isfinite(v))
        circuit |= circ
    v, act, kn = np.array(values).T, np.array(active).T, np.array(known).T
    on = act & kn
    whole = reached(summary, hi)  # a seed that stopped inside the window has no split, as it has no mean
    with np.errstate(invalid="ignore", divide="ignore"):
        fraction = np.where(whole & (kn.sum(axis=1) > 0), on.sum(axis=1) / kn.sum(axis=1), np.nan)
        size = np.where(whole & (on.sum(axis=1) > 0), np.where(on, v, 0.0).sum(axis=1) / on.sum(axis=1), np.nan)
    return {"fraction": fraction, "size": size, "times": int(np.isfinite(v).any(axis=0).sum()), "circuit": circuit}
