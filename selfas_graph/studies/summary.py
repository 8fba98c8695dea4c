"""A study's summary: from its run files to one small JSON file that the results page is made from.

The summary holds, for every seed and every time of the study, the value of every measure
(:data:`STUDY_MEASURES`: the ensemble's frame measures, the fits' own uncertainties, the
alignment of the largest structure and of the rods in no structure, the rod currents' moment and
flux), every short-circuit episode of every seed at event time, and the provenance of the runs
(version, commit, CPU, numba target, threads and wall time of each seed). The statistics are
not in it: the page computes them from the per-seed values (:mod:`.page`), so a better estimator
of the spread needs no new runs.
"""

from __future__ import annotations

import dataclasses
import json
import math
import time
from pathlib import Path

import numpy as np

from .._version import __version__
from ..analysis.episodes import circuit_episodes
from ..analysis.moments import monopole_moment
from ..analysis.skeleton import structures
from ..ensemble import FRAME_MEASURES, Measure, seed_path, summarise
from ..io.atomic import write_text_atomic
from ..io.h5md import HDF5_READ_ERRORS, RunFile, RunFileError
from ..provenance import cpu_model, source_commit
from .spec import StudiesError
from .stats import MIN_FREE_RODS

__all__ = ["STUDY_MEASURES", "summarise_study", "write_json_atomic"]


def _contacts(f):
    return None if f.graph is None else np.asarray(f.graph["tip_contacts"], dtype=np.int64).reshape(-1, 2)


def _alignment(f, which):
    """|m_q| over (rods x mean single-rod moment) of the largest structure, of the rods in no
    structure (NaN for fewer than :data:`~.stats.MIN_FREE_RODS`) or of all rods: 1 for rods of the
    mean charge all lined up head to tail along one direction, about 1/sqrt(N) at random. The mean is
    over all rods, one scale for every structure of a frame, so that strong rods lined up exceed 1.
    All rods need no contact data."""
    q = f.run.tip_charge
    n_rods = q.shape[0] // 2
    tc = _contacts(f)
    if tc is None and which != "all":
        return math.nan
    label, size = structures(n_rods, tc) if tc is not None else (None, None)
    mean_rod = float(np.abs(q[0::2]).mean())
    if which == "all":
        rods = np.ones(n_rods, dtype=bool)
    elif which == "largest":
        if not size.size:
            return math.nan
        big = int(np.argmax(size))
        rods = label == big
    else:
        rods = label < 0
    n = int(rods.sum())
    if n == 0 or mean_rod <= 0 or (which == "free" and n < MIN_FREE_RODS):
        return math.nan
    lab = np.where(rods, 0, -1)
    m = monopole_moment(f.position, q, lab, 1)[0]
    return float(np.linalg.norm(m)) / (n * mean_rod)


def _free_rods(f):
    tc = _contacts(f)
    if tc is None:
        return math.nan
    label, _ = structures(f.run.tip_charge.shape[0] // 2, tc)
    return float(np.count_nonzero(label < 0))


def _flux(f):
    """The rod currents' mid-plane flux of a frame, computed once (the ensemble's measure,
    analysis.diagnostics.flux_through_rim)."""
    if "_study_flux" not in f.__dict__:
        f.__dict__["_study_flux"] = FRAME_BY_NAME["midplane_flux"].fn(f)
    return f.__dict__["_study_flux"]


def _flux_over_external(f):
    """The rod currents' mid-plane flux over the flux of B_ext through the same disc."""
    b = f.params["forces"].get("uniform_field")
    if not b or not b["B"][2]:
        return math.nan
    flux = _flux(f)
    # Phi_0 = 4 pi B0 L^2 (docs/model.md 'Reduced units'): B_z pi R^2 in units of Phi_0 is B_z R^2 / 4
    phi_ext = b["B"][2] * f.flux_radius**2 / 4.0
    return flux / phi_ext


def _flux_over_dipole(f):
    """Case (ii): the rod currents' mid-plane flux over the external dipole's flux 4 pi |Z_Mext|
    (the paper's Phi_ext of Fig. 11; docs/model.md 'Figure diagnostics'); NaN without the dipole."""
    d = f.params["forces"].get("external_dipole")
    if not d or not d["magnetic_charge"]:
        return math.nan
    # Phi_0 = 4 pi B0 L^2 (docs/model.md 'Reduced units'): 4 pi |Z_Mext| is |Z_Mext| Phi_0
    return _flux(f) / abs(d["magnetic_charge"])


FRAME_BY_NAME = {m.name: m for m in FRAME_MEASURES}

#: the measures of a study's summary: the ensemble's, the fits' uncertainties and the alignment measures
STUDY_MEASURES = [dataclasses.replace(m, fn=_flux) if m.name == "midplane_flux" else m for m in FRAME_MEASURES] + [
    Measure(k, u, d, lambda f, k=k: float(f.claims[k]), grouped=grouped)
    for k, u, d, grouped in (
        ("fractal_dimension_err", "1", "uncertainty of that mass-radius fit", False),
        ("rg_dimension_err", "1", "uncertainty of the R_g fit", False),
        ("largest_moment_J_z", "J0 L^2", "m_J,z of the largest structure's rod currents", True),
        ("cycle_rank_largest", "loops", "independent loops of the largest structure", False),
        ("structures", "1", "structures (rods joined by tip contacts)", False),
    )
]
STUDY_MEASURES += [
    Measure("free_rods", "rods", "rods in no structure (no tip contact)", _free_rods),
    Measure(
        "largest_alignment",
        "1",
        "|m_q| of the largest structure over its rods times the mean single-rod moment",
        lambda f: _alignment(f, "largest"),
    ),
    Measure(
        "free_alignment",
        "1",
        "|m_q| of the rods in no structure over their number times the mean single-rod moment",
        lambda f: _alignment(f, "free"),
    ),
    Measure(
        "all_alignment",
        "1",
        "|m_q| of all rods over their number times the mean single-rod moment",
        lambda f: _alignment(f, "all"),
    ),
    Measure(
        "flux_over_external",
        "1",
        "rod currents' flux through the mid-plane disc over B_ext's flux through it",
        _flux_over_external,
        grouped=True,
    ),
    Measure(
        "flux_over_dipole",
        "1",
        "case (ii): rod currents' flux through the mid-plane disc over the external dipole's flux 4 pi |Z_Mext|",
        _flux_over_dipole,
        grouped=True,
    ),
]


def _seed_record(path):
    """The continuations (``resumed_with``) and short-circuit episodes of one seed file (None if it cannot be
    read); its provenance is in the ensemble's seed entry (:func:`~selfas_graph.ensemble.summary.seed_provenance`)."""
    try:
        run = RunFile(path)
    except RunFileError:
        return None
    with run:
        meta = run.meta
        ep = circuit_episodes(run.events(), run.circuit_log())
        return {
            "path": Path(path).name,
            "seed": int(run.parameters["scenario"]["seed"]),
            "status": str(meta.get("status", "")),
            "t_end": float(run.time[-1]) if run.n_frames else 0.0,
            "resumed_with": json.loads(meta.get("resumed_with", "[]")),
            "episodes": {
                "start": [float(x) for x in ep.start],
                "end": [None if not math.isfinite(x) else float(x) for x in ep.end],
                "filament_rods": [int(x) for x in ep.filament_rods],
                "opened_by": [int(x) for x in ep.opened_by],
                # at each closing (runs with a circuit log, since 0.4): the current through the gap and
                # the rods that carry all of it; NaN and -1 (an episode the log has no row for) as None
                **(
                    {
                        "total_current": [None if not math.isfinite(x) else float(x) for x in ep.total_current],
                        "rods_in_series": [None if x < 0 else int(x) for x in ep.rods_in_series],
                    }
                    if ep.total_current is not None
                    else {}
                ),
            },
        }


#: the flux measures are summarised at the table times and every FLUX_EVERY t0 only (their cost:
#: 0.1-0.8 s a frame for 600-1000 current-carrying rods, analysis.diagnostics.flux_through_rim)
FLUX_EVERY = 20.0
FLUX_MEASURES = ("midplane_flux", "flux_over_external", "flux_over_dipole")


def _sparse(measure, times):
    """``measure`` evaluated at ``times`` only (NaN at the other frames)."""

    def fn(f):
        return measure.fn(f) if any(abs(f.time - t) <= 1e-9 * max(1.0, t) for t in times) else math.nan

    return dataclasses.replace(measure, fn=fn)


def study_measures(study, compared_times=()) -> list:
    """:data:`STUDY_MEASURES` for ``study``: the flux measures only at its table times, every
    :data:`FLUX_EVERY` t0, its end time and ``compared_times`` (where other studies are set against
    it, :meth:`~.spec.Studies.compared_times`) that fall on its summarised times."""
    every = max(FLUX_EVERY, study.every)
    on_frames = [t for t in compared_times if any(abs(t - u) <= 1e-9 * max(1.0, t) for u in study.times)]
    flux_times = sorted(
        set(study.table_times)
        | {study.t_end}
        | {k * every for k in range(int(study.t_end // every) + 1)}
        | set(on_frames)
    )
    return [_sparse(m, flux_times) if m.name in FLUX_MEASURES else m for m in STUDY_MEASURES]


def _check_frames(study, paths, also=()):
    """StudiesError where a summarised time of ``study`` (or one of ``also``, the times other entries set
    it against) is no frame of its run files, up to each file's last: the summary would give the
    nearest frame's values under that time's label (frames every 0.5 summarised at 0.3, say)."""
    for path in paths:
        try:
            with RunFile(path) as run:
                frames = np.asarray(run.time, dtype=float)
        except (RunFileError, *HDF5_READ_ERRORS):
            continue  # the summary names a file it cannot read
        if not frames.size:
            continue
        tol = 1e-9 * max(1.0, float(frames[-1]))
        off = [t for t in (*study.times, *also) if t <= frames[-1] + tol and not (np.abs(frames - t) <= tol).any()]
        if off:
            raise StudiesError(
                f"study {study.name}: t = {off[0]:g} is no frame of {Path(path).name} (frames at "
                f"{', '.join(f'{x:g}' for x in frames[:4])}, ...): give every, table_times and the times of the "
                "claims and sweeps on it as frame times (multiples of the scenario's output.interval, or t_end)"
            )
        return


def summarise_study(study, runs, studies=None) -> dict:
    """The summary of ``study`` (a :class:`~.spec.Study`) from its run files in ``runs/study.name``;
    with ``studies`` (the :class:`~.spec.Studies` it belongs to), the flux measures also at the
    times other studies are set against it.

    Seeds whose file is missing or unreadable are listed in ``missing``; the statistics of the page
    count only seeds with a frame at each time.
    """
    folder = Path(runs) / study.name
    seeds = list(range(study.first_seed, study.first_seed + study.seeds))
    paths = [seed_path(folder, s) for s in seeds]
    present = [p for p in paths if p.exists()]
    started = time.perf_counter()
    compared = studies.compared_times(study.name) if studies else ()
    _check_frames(study, present, compared)
    out = summarise(present, study.times, t_end=study.t_end, measures=study_measures(study, compared))
    # the ensemble's seed entries (short-circuit time, provenance) with the continuations and episodes,
    # joined by file: a file the ensemble summary could not read is in neither
    records = {r["path"]: r for r in (_seed_record(p) for p in present) if r is not None}
    lost = [Path(s["path"]).name for s in out["seeds"] if Path(s["path"]).name not in records]
    if lost:
        raise StudiesError(
            f"{', '.join(lost)} in {folder}: read for its frames but not for its events (is a run still "
            "writing it?); summarise again once no run writes the study's files"
        )
    out["seeds"] = [s | records[Path(s["path"]).name] for s in out["seeds"]]
    for s in out["seeds"]:
        s["path"] = Path(s["path"]).name
    out["unreadable"] = [{"path": Path(u["path"]).name, "reason": u["reason"]} for u in out["unreadable"]]
    out["study"] = {
        "name": study.name,
        "title": study.title,
        "scenario": study.scenario,
        "overrides": list(study.overrides),
        "seeds": seeds,
        "t_end": study.t_end,
        "table_times": list(study.table_times),
    }
    out["missing"] = [p.name for p in paths if not p.exists()]
    out["summarised_by"] = {
        "version": __version__,
        "commit": source_commit(),
        "cpu_model": cpu_model(),
        "seconds": round(time.perf_counter() - started, 1),
    }
    return out


def write_json_atomic(data, path) -> Path:
    """Write ``data`` as JSON to ``path`` through a temporary file renamed into place."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    return write_text_atomic(path, json.dumps(data, indent=1, allow_nan=False) + "\n")


def percolation_summary(study, path) -> dict:
    """The summary of a percolation study from ``selfas-graph bench percolation``'s result file: the
    statistics per rod count (runs, short-circuited, the Wilson 95 % interval of the fraction,
    Kaplan-Meier quartiles of the short-circuit time), what they are made of (the Kaplan-Meier curve
    ``km`` and each run's ``run_times``: seed, status, and the short-circuit time or the time it was
    censored at), and the provenance of the runs."""
    raw = json.loads(Path(path).read_text(encoding="utf-8"))
    keep = ("count", "density", "fraction_volume", "phi", "runs", "short_circuited", "censored", "failed", "decided")
    keep += ("fraction", "fraction_ci95", "q25", "median", "q75", "km")
    runs = raw.get("runs", [])

    def run_times(count):
        return [
            {
                "seed": r["seed"],
                "status": r["status"],
                "time": r["time"] if r["status"] == "short_circuit" else r["t_end"],
            }
            for r in runs
            if r["count"] == count
        ]

    return {
        "kind": "percolation",
        "study": {
            "name": study.name,
            "title": study.title,
            "scenario": study.scenario,
            "overrides": list(study.overrides),
            "t_max": raw["t_max"],
            "fields": raw["fields"],
        },
        "densities": [
            {**{k: d[k] for k in keep if k in d}, "run_times": run_times(d["count"])} for d in raw["densities"]
        ],
        "seeds": raw["seeds"],
        "version": raw.get("version", ""),
        "commit": raw.get("commit", ""),
        "cpu_model": raw.get("cpu_model", ""),
        "numba_cpu": raw.get("numba_cpu", ""),
        "workers": raw.get("workers"),
        "wall_seconds": raw.get("wall_seconds"),
    }
