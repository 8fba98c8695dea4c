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
  error of the observed times alone (labelled so), and the Kaplan-Meier quartiles;
* :func:`mean_sem_fits` -- mean over seeds of a fitted quantity (a fractal dimension) whose
  standard error combines the spread between seeds with each seed's own fit uncertainty;
* :func:`grouped_summary` -- a quantity whose seeds split into two groups (a current flows
  or not): "k of n seeds", with the median, range, mean and standard error of the active
  group only, never a mean over both groups.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = [
    "censored_times",
    "grouped_summary",
    "kaplan_meier",
    "km_quantile",
    "mean_sem",
    "mean_sem_fits",
    "wilson_interval",
]

#: 95 % two-sided normal quantile
Z95 = 1.959963984540054


def mean_sem(values, axis=0):
    """Mean, standard error of the mean and count along ``axis``, over the finite values only.

    The standard error is ``s / sqrt(n)`` with ``s`` the sample standard deviation
    (``ddof = 1``) of the ``n`` finite values; it is NaN for ``n < 2``, and the mean is
    NaN for ``n = 0``. NaN (no value) and +-inf (no finite value, e.g. an infinite
    resistance) are left out alike and not counted in ``n``.

    Parameters
    ----------
    values : array_like of float
        One row per seed along ``axis`` (NaN or inf: no finite value for that seed).
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


def mean_sem_fits(values, fit_err, axis=0):
    """Mean over seeds of a fitted quantity, its standard error with each fit's uncertainty added.

    ``SE_total^2 = s^2 / n + mean(err_i^2) / n``: ``s^2`` the sample variance between the ``n``
    seeds with a finite value and a finite ``err_i`` (the spread of the ensemble), ``err_i``
    each seed's own fit uncertainty. Each seed has the same weight (no inverse-variance
    weighting: a seed whose structure fits a straight line better is not a likelier sample of
    the ensemble). The between-seed variance already holds the random part of the fit errors,
    so the sum counts that part twice: an upper bound on the random error. Most of a fit's
    uncertainty on these structures is the bend of the curve over the fitted range, alike from
    seed to seed; such a part is not reduced by averaging at all, so the results page also
    states its verdicts by ``sem_between`` alone (``studies/verdicts.py``). A bias common to
    every seed is bounded by the anchors of ``tests/unit/test_fractal.py``.

    Parameters
    ----------
    values, fit_err : array_like of float, same shape
        One row per seed along ``axis`` (NaN or inf: no finite value for that seed).
    axis : int

    Returns
    -------
    mean, sem_total, sem_between, fit_err_rms : float64 arrays of ``values``' shape without ``axis``
        ``sem_between = s / sqrt(n)``, ``fit_err_rms = sqrt(mean(err_i^2))``; ``sem_total`` is
        NaN for ``n < 2`` as ``sem_between`` is.
    n : int64 array
    """
    v = np.asarray(values, dtype=np.float64)
    e = np.asarray(fit_err, dtype=np.float64)
    if v.shape != e.shape:
        raise ValueError(f"values and fit_err must have the same shape, got {v.shape}, {e.shape}")
    v = np.where(np.isfinite(e), v, np.nan)  # a value without its uncertainty is left out
    mean, sem_between, n = mean_sem(v, axis=axis)
    finite = np.isfinite(v)
    with np.errstate(invalid="ignore", divide="ignore"):
        ms = np.where(finite, e * e, 0.0).sum(axis=axis) / n
        fit_rms = np.where(n > 0, np.sqrt(ms), np.nan)
        total = np.sqrt(sem_between**2 + ms / n)
    return mean, np.where(n > 1, total, np.nan), sem_between, fit_rms, n


def grouped_summary(values, active_mask):
    """A quantity whose seeds split into an active group and the rest: "k of n seeds", the active group alone.

    For a current-related quantity (total current, rods in current-carrying filaments, the rod
    currents' flux or moment) seeds whose circuit is open give 0 and the others a value of
    their own; the mean over both groups describes no seed. Reported instead: how many seeds
    are active, and the median, range, mean and standard error (``s / sqrt(k)``, ``ddof = 1``)
    over the active seeds only.

    Parameters
    ----------
    values : (n,) float
        One value per seed (NaN: no value, e.g. the run ended earlier; such a seed counts in
        neither group).
    active_mask : (n,) bool
        True for the seeds of the active group (e.g. a current flows at that time).

    Returns
    -------
    dict with ``k`` (active seeds with a value), ``n`` (seeds with a value), ``median``,
    ``min``, ``max``, ``mean``, ``sem`` of the active group (NaN when ``k = 0``; ``sem`` NaN
    when ``k < 2``).
    """
    v = np.asarray(values, dtype=np.float64).reshape(-1)
    active = np.asarray(active_mask, dtype=bool).reshape(-1)
    if v.shape != active.shape:
        raise ValueError(f"values and active_mask must have the same length, got {v.shape}, {active.shape}")
    has = np.isfinite(v)
    group = v[has & active]
    k = int(group.shape[0])
    nan = math.nan
    mean, sem, _ = mean_sem(group) if k else (nan, nan, 0)
    return {
        "k": k,
        "n": int(has.sum()),
        "median": float(np.median(group)) if k else nan,
        "min": float(group.min()) if k else nan,
        "max": float(group.max()) if k else nan,
        "mean": float(mean),
        "sem": float(sem),
    }
