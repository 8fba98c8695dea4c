"""The results page from the studies' summaries: tables, provenance and the generated blocks.

Every number of docs/results.md between ``<!-- begin generated: KEY -->`` and
``<!-- end generated: KEY -->`` is written by :func:`page_blocks` from the committed summaries
(``docs/results/NAME.json``, :mod:`.summary`); ``tests/cli/test_results_page.py`` checks that the page
holds what this module makes of them. The statistics of a measure over the seeds are those of
:mod:`.stats`, the claims', convergence and sweep tables those of :mod:`.verdicts`.
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np

from ..analysis.ensemble_stats import wilson_interval
from ..provenance import version_key
from .convergence import convergence_rows
from .spec import StudiesError
from .stats import fmt, measure_label, measure_text, older_runs, with_minimum_counts
from .sweeps import sweep_rows
from .verdicts import claim_rows

__all__ = ["has_electrodes", "load_summary", "page_blocks", "page_blocks_in", "replace_blocks", "study_table"]

#: the rows of a study's table, in order
TABLE_MEASURES = (
    "filament_rods",
    "total_current",
    "midplane_flux",
    "flux_over_dipole",
    "moment_J_z",
    "inside_R_plas",
    "median_axis_distance",
    "largest_structure_rods",
    "largest_moment_ratio",
    "largest_alignment",
    "free_alignment",
    "fractal_dimension",
    "rg_dimension",
    "cycle_rank",
)


def load_summary(folder, name):
    """The summary of study ``name`` in ``folder`` (``NAME.json``), or None if it is not there."""
    path = Path(folder) / f"{name}.json"
    if not path.exists():
        return None
    try:
        raw = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise StudiesError(
            f"{path}: not a readable study summary ({exc}); make it again with study summarise"
        ) from None
    return with_minimum_counts(raw) if isinstance(raw, dict) else raw


def has_electrodes(summary) -> bool:
    """Whether the study's scene closes its circuit between electrodes (case (i)) rather than through
    the external filament (case (ii)), from its scenario file and overrides.

    The scenario path is read as the studies file gives it, from the working directory (as
    ``study run`` reads it); :class:`~.spec.StudiesError` if the file cannot be read there, since a
    guess would word case (ii)'s closings of the circuit as short circuits of the electrodes."""
    from ..io.scenario import ScenarioError, load_scenario

    study = summary.get("study", {})
    if "scenario" not in study:
        raise StudiesError("the summary names no scenario file (its 'study' entry has no 'scenario')")
    try:
        params = load_scenario(study["scenario"], overrides=list(study.get("overrides", ()))).params
    except ScenarioError as exc:
        raise StudiesError(
            f"{study['scenario']}: cannot read the study's scenario file from {Path.cwd()} ({'; '.join(exc.problems)}); "
            "run the command from the folder the studies file's scenario paths are relative to "
            "(the repository's root for docs/studies.toml)"
        ) from None
    return params.forces.electrodes is not None or params.forces.external_filament is None


def study_table(summary) -> str:
    """The table of a study: a row per measure, a column per table time, and the short circuits
    (between the electrodes, or through the external filament in case (ii))."""
    electrodes = has_electrodes(summary)
    times = summary["study"]["table_times"]
    head = "| measure | " + " | ".join(f"t = {t:g}" for t in times) + " |"
    rows = [head, "|---|" + "---|" * len(times)]
    for m in TABLE_MEASURES:
        if m not in summary["measures"]:
            continue
        cells = [measure_text(summary, m, t) for t in times]
        if all(c == "n/a" for c in cells):
            continue  # a measure the scene does not have (R_plas without a plasma filament)
        label = measure_label(m)
        if not electrodes:  # case (ii): the current enters and leaves through the external filament
            label = label.replace("through the gap", "through the network")
        rows.append(f"| {label} | " + " | ".join(cells) + " |")
    sc = summary.get("short_circuit") or {}
    n_obs, n = sc.get("n_observed", 0), summary["n_seeds"]
    text = f"{n_obs} of {n} seeds"
    if n_obs:
        text += f", median time (Kaplan-Meier: where its estimate reaches 1/2) {fmt(sc.get('median'))} t0"
        starts = [s["episodes"]["start"] for s in summary["seeds"]]
        text += f"; {sum(len(x) for x in starts)} closings of the {'gap' if electrodes else 'circuit'} in all"
        first = [s["episodes"].get("total_current", [None])[:1] for s in summary["seeds"]]
        first = [x[0] for x in first if x and x[0] is not None]
        series = [s["episodes"].get("rods_in_series", [None])[:1] for s in summary["seeds"]]
        series = [x[0] for x in series if x and x[0] is not None]
        if any(x > 0 for x in first):  # runs with a circuit log that carry current: the first closing, seed by seed
            text += (
                f"; the first closing carries median {fmt(float(np.median(first)))} J0 "
                f"[{fmt(min(first))} to {fmt(max(first))}] through median {fmt(float(np.median(series)))} "
                f"{'rod' if float(np.median(series)) == 1.0 else 'rods'} in series"
            )
            if len(first) < n_obs:  # seeds whose runs kept no circuit log: said, not silently left out
                text += f" ({len(first)} of the {n_obs} seeds that closed it have a circuit log)"
    label = "short circuit of the electrodes" if electrodes else "circuit closed through the external filament"
    rows.append(f"| {label} | {text} |" + " |" * (len(times) - 1))
    return "\n".join(rows)


def percolation_table(summary) -> str:
    """A percolation study's table: per rod count, how many runs short-circuited by t_max (with the 95 %
    Wilson interval of the fraction) and the Kaplan-Meier median [quartiles] of the short-circuit time."""
    t_max = summary["study"]["t_max"]
    rows = [
        f"| rods | short-circuited by t = {t_max:g} (Wilson 95 % interval) | median short-circuit time [q25 to q75] "
        "(Kaplan-Meier) |",
        "|---|---|---|",
    ]
    for d in summary["densities"]:
        q = [">" + f"{t_max:g}" if d.get(k) is None else fmt(d[k]) for k in ("median", "q25", "q75")]
        # failed runs stopped before t_max: out of the fraction, in the Kaplan-Meier curve (censored); the
        # interval is taken here, as a summary made before `decided` holds one over every run
        failed = d.get("failed", 0)
        decided = d.get("decided", d["runs"] - failed)
        lo, hi = wilson_interval(d["short_circuited"], decided) if decided else (math.nan, math.nan)
        also = f"; {failed} failed before t = {t_max:g}" if failed else ""
        rows.append(
            f"| {d['count']} | {d['short_circuited']} of {decided} ({fmt(lo, 2)} to {fmt(hi, 2)}){also} | "
            f"{q[0]} [{q[1]} to {q[2]}] |"
        )
    return "\n".join(rows)


def status_text(studies, summaries) -> str:
    """Which studies are still made of runs older than the trajectories of the code now (the file's
    ``trajectories_since``, or a study's own later one)."""
    since = studies.trajectories_since
    old = {n: older_runs(s, studies.since(n)) for n, s in summaries.items()}
    old = {n: v for n, v in old.items() if v}
    if not old:
        later = sorted({studies.since(n) for n in summaries} - {since}, key=version_key)
        versions = ([f"version {since} or later"] if since else []) + [
            f"{', '.join(later)} or later for the studies that name it in docs/studies.toml"
        ] * bool(later)
        return "Every summarised study is made of runs of the trajectories the code follows now" + (
            f" ({'; '.join(versions)})." if versions else "."
        )
    return (
        "**Runs to be made again.** These studies are still made of runs of versions older than the "
        "trajectories the code follows now (CHANGELOG), and their runs lines and every claim, convergence "
        "and sensitivity row that uses them say so: "
        + ", ".join(f"{n} (runs of {', '.join(v)}; trajectories since {studies.since(n)})" for n, v in old.items())
        + ". `selfas-graph study run NAME --jobs 2 --force` (it replaces the older run files), then "
        "`study summarise NAME` and `study page`, makes each again."
    )


def provenance_text(summary, since="") -> str:
    """Version, commits, CPU, threads and wall time of a study's runs, in one paragraph; marked when
    they are older than version ``since``."""
    seeds = summary["seeds"]
    if not seeds:
        return "No run files were summarised."
    commits = sorted({s.get("commit", "")[:10] or "unknown" for s in seeds})
    cpus = sorted({s.get("cpu_model", "") or "unknown CPU" for s in seeds})
    targets = sorted({s.get("numba_cpu", "") or "unknown" for s in seeds})
    threads = sorted({s.get("numba_threads", 0) for s in seeds})
    wall = [s.get("wall_seconds") for s in seeds if s.get("wall_seconds") is not None]
    wall = [w for w in wall if isinstance(w, (int, float)) and math.isfinite(w)]
    versions = sorted({s.get("version", "") for s in seeds})
    t_ends = [s["t_end"] for s in seeds]
    text = (
        f"{len(seeds)} seeds ({', '.join(str(s['seed']) for s in seeds)}), each to t = {fmt(min(t_ends))}"
        + (f" to {fmt(max(t_ends))}" if max(t_ends) > min(t_ends) else "")
        + f"; version {', '.join(versions)}, commit {', '.join(commits)}; {'; '.join(cpus)}, kernels for "
        f"{', '.join(targets)}, {'/'.join(str(t) for t in threads)} numba thread(s) a seed"
    )
    if wall:
        lo, hi = fmt(min(wall) / 60, 2), fmt(max(wall) / 60, 2)
        text += f"; wall time a seed {lo if lo == hi else f'{lo}-{hi}'} min"
    if summary.get("missing"):
        text += f". Not yet run: {', '.join(summary['missing'])}"
    return text + "." + _older_text(summary, since)


def _older_text(summary, since) -> str:
    old = older_runs(summary, since)
    if not old:
        return ""
    name = summary["study"]["name"]
    return (
        f" **Runs of version {', '.join(old)}, made before the trajectory change of version {since} (CHANGELOG): "
        f"to be run again (`selfas-graph study run {name} --force`).**"
    )


def definition_changes(study, summary) -> list[str]:
    """The parts of ``study``'s definition (docs/studies.toml now) that differ from those its summary was
    made with (scenario, overrides, seeds, end time, table times): the summary then is of another study."""
    made = summary.get("study", {})
    now = {"scenario": study.scenario, "overrides": list(study.overrides)}
    if summary.get("kind") != "percolation":
        now |= {
            "seeds": list(range(study.first_seed, study.first_seed + study.seeds)),
            "t_end": study.t_end,
            "table_times": list(study.table_times),
        }
    return [key for key, value in now.items() if key in made and made[key] != value]


def _changed_text(study, summary) -> str:
    changed = definition_changes(study, summary)
    if not changed:
        return ""
    return (
        f" **Summarised from another definition of this study than docs/studies.toml gives now (its "
        f"{', '.join(changed)} differ): run and summarise it again (`selfas-graph study run {study.name} --jobs 2 "
        f"--force`, then `study summarise {study.name}`).**"
    )


def page_blocks(studies, folder, figures="figures") -> dict:
    """Every generated block of the results page, keyed by its marker name: ``claims``, and for
    each study ``table NAME``, ``runs NAME`` and ``figures NAME`` (a study without a summary
    yet says how to make it). ``figures``: the figures' folder as the page links it (relative to
    the page)."""
    fig = str(figures).rstrip("/") or "."
    summaries = {name: load_summary(folder, name) for name in studies.studies}
    summaries = {k: v for k, v in summaries.items() if v is not None}
    blocks = {
        "claims": claim_rows(studies, summaries),
        "convergence": convergence_rows(studies, summaries),
        "status": status_text(studies, summaries),
    }
    for name in studies.sweeps:
        blocks[f"sensitivity {name}"] = sweep_rows(studies, summaries, name, fig)
    for name, study in studies.studies.items():
        s = summaries.get(name)
        if s is None:
            where = "" if Path(studies.path).as_posix().endswith("docs/studies.toml") else f" --studies {studies.path}"
            todo = (
                f"Not run at this version yet: `selfas-graph study run {name}{where} --jobs 2`, then "
                f"`study summarise {name}{where}`."
            )
            blocks[f"table {name}"] = blocks[f"runs {name}"] = todo
            blocks[f"figures {name}"] = ""
            continue
        if s.get("kind") == "percolation":
            blocks[f"table {name}"] = percolation_table(s)
            blocks[f"runs {name}"] = (
                f"{len(s['seeds'])} seeds a count to t = {fmt(s['study']['t_max'])}; version {s['version']}, commit "
                f"{(s['commit'] or 'unknown')[:10]}; {s['cpu_model'] or 'unknown CPU'}, kernels for {s['numba_cpu']}, "
                f"{s['workers']} worker(s) of one numba thread; {fmt((s['wall_seconds'] or 0) / 60, 2)} min in all."
                + _older_text(s, studies.since(name))
                + _changed_text(study, s)
            )
            blocks[f"figures {name}"] = ""
            continue
        blocks[f"table {name}"] = study_table(s)
        blocks[f"runs {name}"] = provenance_text(s, studies.since(name)) + _changed_text(study, s)
        blocks[f"figures {name}"] = (
            f"| {study.title}: every measure over time | short-circuit episodes | seed {s['seeds'][0]['seed']} at "
            f"t = {fmt(s['seeds'][0]['t_end'])} |\n|---|---|---|\n"
            f"| ![]({fig}/{name}_series.png) | ![]({fig}/{name}_episodes.png) | ![]({fig}/{name}_snapshot.png) |"
        )
        # the movie made with this summary (summaries before the key: the MP4 of the same name)
        movie = s.get("movie", f"{name}_movie.mp4")
        if study.section in ("paper", "contrast") and movie:
            blocks[f"figures {name}"] += (
                f"\n\nA movie of seed {s['seeds'][0]['seed']}: [`{fig}/{movie}`]({fig}/{movie}) "
                f"(`selfas-graph plot RUN.h5 --movie OUT.mp4`)."
            )
    return blocks


_BLOCK = re.compile(
    r"(<!-- begin generated: (?P<key>[^>]+?) -->\n)(?P<body>.*?)(<!-- end generated: (?P=key) -->)", re.S
)


def replace_blocks(text, blocks) -> tuple[str, list]:
    """``text`` with every generated block replaced by ``blocks[key]``; also the keys found in the
    text that ``blocks`` has no entry for (left as they were)."""
    missing = []

    def sub(m):
        key = m.group("key")
        if key not in blocks:
            missing.append(key)
            return m.group(0)
        return m.group(1) + blocks[key].rstrip("\n") + "\n" + m.group(4)

    return _BLOCK.sub(sub, text), missing


def page_blocks_in(text) -> dict:
    """The generated blocks a page holds now, by key."""
    return {m.group("key"): m.group("body").rstrip("\n") for m in _BLOCK.finditer(text)}
