"""The summary over seed files: mean and standard error of the short-circuit time and of the
per-frame measures (:func:`summarise`)."""

from __future__ import annotations

import math
import os

import numpy as np

from .._version import __version__
from ..analysis.diagnostics import timeline
from ..analysis.ensemble_stats import censored_times, grouped_summary, mean_sem, mean_sem_fits
from ..io.h5md import HDF5_READ_ERRORS, RunFile, RunFileError, hdf5_damage
from ..model.parameter_match import parameter_differences, value_at
from .folder import EnsembleError
from .measures import FRAME_MEASURES, Frame, Measure, carries_current


def _each_file_once(paths):
    """EnsembleError where two of ``paths`` name one file (also through a link): it would count as two
    seeds, and shrink the standard errors."""
    seen = {}
    for path in paths:
        try:
            st = os.stat(path)
            key = (st.st_dev, st.st_ino)
        except OSError:  # not there: named as unreadable below
            continue
        if key in seen:
            raise EnsembleError(f"{path} and {seen[key]} are one file: give each seed file once")
        seen[key] = path


def _one_sample(first, path, params, seeds) -> tuple:
    """The path and parameters every seed file is held to (``first``; the file's own for the first one
    read), EnsembleError where ``params`` differ from them in more than the seed or repeat a seed of
    ``seeds`` (those read before): a mean over other parameters, or one seed counted twice, would pass
    for one ensemble's."""
    seed = value_at(params, "scenario.seed")
    twice = [s["path"] for s in seeds if s["seed"] == seed]
    if twice:
        raise EnsembleError(f"{path} and {twice[0]} are both seed {seed}: one sample, give it once")
    if first is None:
        return path, params
    # both ways: a key a file of an earlier version lacks counts at its default, whichever file lacks it
    diff = sorted(set(parameter_differences(first[1], params)) & set(parameter_differences(params, first[1])))
    diff = [k for k in diff if k != "scenario.seed"]
    if diff:
        shown = "; ".join(f"{k} is {value_at(first[1], k)!r} there and {value_at(params, k)!r} here" for k in diff[:3])
        more = f" (and {len(diff) - 3} more keys)" if len(diff) > 3 else ""
        raise EnsembleError(
            f"{path} is of other parameters than {first[0]}: {shown}{more}; summarise one parameter set at a time"
        )
    return first


def _measures(measures) -> list:
    """``measures`` as :class:`Measure` objects (:data:`FRAME_MEASURES` for None; a name stands for the
    measure of :data:`FRAME_MEASURES` it names); EnsembleError naming the valid names otherwise."""
    if measures is None:
        return FRAME_MEASURES
    known = {m.name: m for m in FRAME_MEASURES}
    out = []
    for m in [measures] if isinstance(measures, (str, Measure)) else measures:
        if isinstance(m, str) and m in known:
            m = known[m]
        if not isinstance(m, Measure):
            raise EnsembleError(
                f"measures: {m!r} is not a measure; give Measure objects or names of FRAME_MEASURES: {', '.join(known)}"
            )
        out.append(m)
    return out


def summarise(paths, times, t_end=None, measures=None, flux_radius=None) -> dict:
    """Mean and standard error over seed files of the short-circuit time and of per-frame measures.

    Parameters
    ----------
    paths : sequence of path-like
        Run files, one per seed, of one parameter set but for the seed and the end time
        (EnsembleError naming the keys otherwise).
    times : sequence of float
        Simulated times; each seed's nearest saved frame within half an output interval
        is used, a seed that has no such frame (it ended earlier) is left out there.
    t_end : float, optional
        Short circuits later than this count as censored at ``t_end`` (default: none).
    measures : list of :class:`Measure` or of their names, optional
        Default :data:`FRAME_MEASURES`; a name stands for the measure of that list it names.
    flux_radius : float, optional
        Disc radius of the mid-plane flux (see :class:`Frame`).

    Returns
    -------
    dict (JSON-ready) with ``seeds`` (per seed: path, seed, status, end time, short-circuit
    time or None; files that cannot be read are left out and listed in ``unreadable``), ``short_circuit`` (:func:`~selfas_graph.analysis.ensemble_stats.censored_times`:
    seeds without one are censored at their end time, counted, not averaged in),
    ``times`` and ``measures`` (name -> unit, doc, per time mean, sem, n, and ``values``
    per seed and time, NaN as None). A measure with a fit uncertainty also has ``fit_err``
    (per seed and time), ``sem_between`` and ``fit_err_rms`` per time, and its ``sem`` is
    ``sqrt(sem_between^2 + fit_err_rms^2 / n)`` (docs/model.md "Measures of the paper's
    claims"). A grouped measure (a current flows or not) has ``group`` (what the group is),
    ``k`` (seeds in the group), ``n_seeds`` (seeds with a value), ``median``, ``min``,
    ``max`` per time, and its ``mean``, ``sem`` and ``n`` are the group's alone; ``current``
    per seed and time says which seeds carry a current.
    """
    measures = _measures(measures)
    times = [float(t) for t in times]
    grouped = any(m.grouped for m in measures)
    _each_file_once(paths)
    seeds, unreadable, rows = [], [], []
    first = None  # the path and parameters of the first file read, which every other must share
    for path in paths:
        try:
            run = RunFile(path)
        except RunFileError as exc:  # e.g. still being written by a running seed: left out, named
            unreadable.append({"path": str(path), "reason": str(exc)})
            continue
        try:
            with run:
                first = _one_sample(first, path, run.parameters, seeds)
                seed, row = _read_seed(run, path, times, t_end, measures, flux_radius, grouped)
        except HDF5_READ_ERRORS as exc:  # damaged metadata: HDF5 says so only when the part is read
            if hdf5_damage(exc) is None:
                raise
            unreadable.append({"path": str(path), "reason": f"{path}: {hdf5_damage(exc)}"})
            continue
        seeds.append(seed)
        rows.append(row)
    # (measure, seed, time) arrays over the readable seeds; a seed with no frame near a time has NaN there
    shape = (len(measures), len(seeds), len(times))
    values = np.stack([r[0] for r in rows], axis=1) if rows else np.full(shape, np.nan)
    errs = np.stack([r[1] for r in rows], axis=1) if rows else np.full(shape, np.nan)
    current = np.stack([r[2] for r in rows]) if rows else np.full(shape[1:], np.nan)
    sc = censored_times([r[3] for r in rows], [r[4] for r in rows]) if seeds else None
    out = {
        "version": __version__,
        "n_seeds": len(seeds),
        "times": times,
        "t_end": t_end,
        "seeds": seeds,
        "unreadable": unreadable,
        "short_circuit": None if sc is None else {k: _plain(v) for k, v in sc.items()},
        "measures": {},
    }
    if grouped:
        out["current"] = _plain(current)
    for m, measure in enumerate(measures):
        out["measures"][measure.name] = _measure_summary(measure, values[m], errs[m], current)
    return out


def seed_provenance(meta) -> dict:
    """What made a seed file (its run's provenance attributes): version, commit, CPU, the CPU numba compiled
    for, threads a seed and the wall time of all its segments (None where the file does not say)."""
    wall = float(meta.get("wall_seconds_total", math.nan))
    return {
        "version": str(meta.get("version", "")),
        "commit": str(meta.get("commit", "")),
        "cpu_model": str(meta.get("cpu_model", "")),
        "numba_cpu": str(meta.get("numba_cpu", "")),
        "numba_threads": int(meta.get("numba_threads", 0)),
        "wall_seconds": wall if math.isfinite(wall) else None,
    }


def _read_seed(run, path, times, t_end, measures, flux_radius, grouped):
    """One seed's entry of ``seeds`` and its row: (values, fit errors) per measure and time, whether
    it carries a current per time, its short-circuit time or censoring time, and whether it was seen."""
    params = run.parameters
    interval = float(params["output"]["interval"])
    t_run = run.time
    end = float(t_run[-1]) if t_run.size else 0.0
    t_sc = timeline(t_run, np.zeros_like(t_run), events=run.events()).short_circuit_time
    cens = end if t_end is None else min(end, float(t_end))
    seen = t_sc is not None and t_sc <= cens
    seed = {
        "path": str(path),
        "seed": int(params["scenario"]["seed"]),
        "status": run.status,
        "t_end": end,
        "short_circuit_time": t_sc if seen else None,
        **seed_provenance(run.meta),
    }
    values = np.full((len(measures), len(times)), np.nan)
    errs = np.full_like(values, np.nan)
    current = np.full(len(times), np.nan)
    for k, t in enumerate(times):
        if not t_run.size:
            break
        idx = int(np.argmin(np.abs(t_run - t)))
        if abs(t_run[idx] - t) > 0.5 * interval + 1e-9:
            continue
        frame = Frame(run, idx, params, flux_radius)
        for m, measure in enumerate(measures):
            values[m, k] = measure.fn(frame)
            if measure.err is not None:
                errs[m, k] = measure.err(frame)
        if grouped:
            current[k] = carries_current(frame)
    return seed, (values, errs, current, t_sc if seen else cens, seen)


def _measure_summary(measure, values, errs, current) -> dict:
    """The entry of one measure in ``measures`` from its (seed, time) values and fit errors."""
    extra = {}
    if measure.grouped:
        g = [grouped_summary(values[:, k], current[:, k] == 1.0) for k in range(values.shape[1])]
        mean, sem, n = (np.array([x[key] for x in g]) for key in ("mean", "sem", "k"))
        extra = {"group": "seeds whose circuit carries a current"}
        extra.update({key: _plain(np.array([x[key] for x in g])) for key in ("k", "median", "min", "max")})
        extra["n_seeds"] = [x["n"] for x in g]
    elif measure.err is not None:
        mean, sem, between, rms, n = mean_sem_fits(values, errs, axis=0)
        extra = {"sem_between": _plain(between), "fit_err_rms": _plain(rms), "fit_err": _plain(errs)}
    else:
        mean, sem, n = mean_sem(values, axis=0)
    return {
        "unit": measure.unit,
        "doc": measure.doc,
        "mean": _plain(mean),
        "sem": _plain(sem),
        "n": np.asarray(n).astype(int).tolist(),
        "values": _plain(values),
        **extra,
    }


def _plain(v):
    """JSON-ready: arrays to lists, NaN and +-inf to None (standard JSON has neither; a measure that is
    not finite, such as a flux over the flux of a zero B_ext, has no value)."""
    if isinstance(v, np.ndarray):
        return [_plain(x) for x in v.tolist()]
    if isinstance(v, (list, tuple)):
        return [_plain(x) for x in v]
    if isinstance(v, (float, np.floating)):
        return None if not math.isfinite(v) else float(v)
    if isinstance(v, np.integer):
        return int(v)
    return v
