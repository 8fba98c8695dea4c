"""Statistics over the seeds of an ensemble (README, "Ensembles: a claim over many seeds").

One run of a chaotic system is an anecdote: a claim is reported as the mean and the
standard error over seeds. Arrays in, arrays out; no files:

* :func:`mean_sem` -- mean, standard error of the mean and count over seeds, leaving out
  the seeds that have no value (NaN, e.g. a run that stopped before the time asked for);
* :func:`kaplan_meier` -- the distribution of a time that some seeds never reach (the
  short-circuit time of runs that ended without one is *censored* at their end time: it
  is later than that, not unknown, and not to be averaged in);
* :func:`km_quantile` -- a quantile (e.g. the median) of that distribution, NaN when the
  curve does not reach it;
* :func:`wilson_interval` -- the 95 % Wilson score interval of a fraction m / n;
* :func:`censored_times` -- the whole summary of censored times: counts, mean and standard
  error of the observed times alone (labelled so), and the Kaplan-Meier quartiles.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["censored_times", "kaplan_meier", "km_quantile", "mean_sem", "wilson_interval"]

#: 95 % two-sided normal quantile
Z95 = 1.959963984540054


def mean_sem(values, axis=0):
    """Mean, standard error of the mean and count along ``axis``, ignoring NaN.

    The standard error is ``s / sqrt(n)`` with ``s`` the sample standard deviation
    (``ddof = 1``) of the ``n`` finite values; it is NaN for ``n < 2``, and the mean is
    NaN for ``n = 0``.

    Parameters
    ----------
    values : array_like of float
        One row per seed along ``axis`` (NaN: no value for that seed).
    axis : int

    Returns
    -------
    mean, sem : float64 arrays of ``values``' shape without ``axis``
    n : int64 array of the same shape
    """
    v = np.asarray(values, dtype=np.float64)
    if v.ndim == 0:
        raise ValueError("values must have at least one axis (the seeds)")
    finite = np.isfinite(v)
    n = finite.sum(axis=axis)
    z = np.where(finite, v, 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = z.sum(axis=axis) / n
        dev = np.where(finite, v - np.expand_dims(mean, axis), 0.0)
        var = (dev * dev).sum(axis=axis) / (n - 1)
        sem = np.sqrt(var / n)
    mean = np.where(n > 0, mean, np.nan)
    sem = np.where(n > 1, sem, np.nan)
    return mean, sem, n.astype(np.int64)


def kaplan_meier(times, observed):
    """Kaplan-Meier estimate of ``F(t) = P(T <= t)`` from censored times.

    Parameters
    ----------
    times : (n,) float
        For each seed, the time of its event (``observed``) or the time its run ended
        without one (censored: the event, if any, comes later).
    observed : (n,) bool
        True where the event happened at ``times``.

    Returns
    -------
    t : (k,) float64
        The distinct event times, increasing.
    F : (k,) float64
        ``F`` just after each of them. A seed censored at the very time of an event
        counts as still at risk then.
    """
    times = np.asarray(times, dtype=np.float64)
    observed = np.asarray(observed, dtype=bool)
    if times.ndim != 1 or observed.shape != times.shape:
        raise ValueError(f"times and observed must be 1-D of equal length, got {times.shape}, {observed.shape}")
    if not np.all(np.isfinite(times)):
        raise ValueError("times must be finite (a censored seed has the time its run ended)")
    t_event = np.unique(times[observed])
    surv, out = 1.0, np.empty(t_event.shape[0])
    for i, t in enumerate(t_event):
        at_risk = np.count_nonzero(times >= t)  # events at t and censored at or after t
        d = np.count_nonzero(observed & (times == t))
        surv *= 1.0 - d / at_risk
        out[i] = 1.0 - surv
    return t_event, out


def km_quantile(t, F, q):
    """Smallest ``t`` with ``F(t) >= q`` on a Kaplan-Meier curve; NaN if the curve stays below ``q``."""
    t = np.asarray(t, dtype=np.float64)
    F = np.asarray(F, dtype=np.float64)
    if not 0.0 < q <= 1.0:
        raise ValueError(f"q must be in (0, 1], got {q}")
    hit = np.flatnonzero(F >= q - 1e-12)  # 1e-12: F is a product of ratios, q = 0.5 must match 1 - 1/2
    return float(t[hit[0]]) if hit.size else math.nan


def wilson_interval(m, n, z=Z95):
    """Wilson score interval ``(lo, hi)`` of a binomial fraction ``m / n`` (``(0, 1)`` for ``n = 0``)."""
    if n == 0:
        return (0.0, 1.0)
    if not 0 <= m <= n:
        raise ValueError(f"need 0 <= m <= n, got m = {m}, n = {n}")
    p = m / n
    den = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / den
    half = z * math.sqrt(p * (1.0 - p) / n + z * z / (4 * n * n)) / den
    return (max(0.0, centre - half), min(1.0, centre + half))


def censored_times(times, observed):
    """Summary of a time that some seeds never reached (e.g. the short circuit).

    Parameters
    ----------
    times, observed
        As in :func:`kaplan_meier`.

    Returns
    -------
    dict with
        ``n`` seeds, ``n_observed``, ``n_censored``; ``fraction`` observed and its 95 %
        Wilson interval ``fraction_ci95``; ``mean_observed``, ``sem_observed`` over the
        observed times alone (biased low when seeds are censored: read it with
        ``n_censored``); ``q25``, ``median``, ``q75`` from the Kaplan-Meier curve (NaN if
        not reached); ``km_t``, ``km_F`` the curve; ``censored_at`` the censoring times.
    """
    times = np.asarray(times, dtype=np.float64)
    observed = np.asarray(observed, dtype=bool)
    t, F = kaplan_meier(times, observed)
    n, m = int(times.shape[0]), int(observed.sum())
    mean, sem, _ = mean_sem(times[observed])
    return {
        "n": n,
        "n_observed": m,
        "n_censored": n - m,
        "fraction": m / n if n else math.nan,
        "fraction_ci95": wilson_interval(m, n),
        "mean_observed": float(mean),
        "sem_observed": float(sem),
        "q25": km_quantile(t, F, 0.25),
        "median": km_quantile(t, F, 0.5),
        "q75": km_quantile(t, F, 0.75),
        "km_t": t,
        "km_F": F,
        "censored_at": np.sort(times[~observed]),
    }
