"""A summary as text and files: the Markdown table (:func:`format_table`), summary.json and
summary.csv (:func:`write_summary`)."""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path

from ..io.atomic import write_text_atomic
from .folder import make_folder, own_file

#: summary files written into the ensemble's folder (rewritten from the run files on every call)
SUMMARY_JSON, SUMMARY_CSV = "summary.json", "summary.csv"


def _pm(mean, sem, n):
    if mean is None:
        return "n/a"
    return f"{mean:.4g} +- {sem:.2g} ({n})" if sem is not None else f"{mean:.4g} ({n})"


def _group_cell(m, i):
    k, n = m["k"][i], m["n_seeds"][i]
    if not k:
        return f"0/{n}"
    f = lambda v: "n/a" if v is None else f"{v:.4g}"  # noqa: E731
    return f"{k}/{n}: {f(m['median'][i])} [{f(m['min'][i])}, {f(m['max'][i])}], {_pm(m['mean'][i], m['sem'][i], k)}"


def format_table(summary) -> str:
    """The summary as a Markdown table: one row per measure, one column per time, ``mean +- sem (seeds)``."""
    lines = []
    sc = summary.get("short_circuit")
    if sc:
        f = lambda v: "not reached" if v is None else f"{v:.4g}"  # noqa: E731
        mean = (
            "n/a"
            if sc["mean_observed"] is None
            else f"{sc['mean_observed']:.4g}"
            + (f" +- {sc['sem_observed']:.2g}" if sc["sem_observed"] is not None else "")
        )
        lines.append(
            f"short circuit: {sc['n_observed']} of {sc['n']} seeds "
            f"({sc['n_censored']} without one, censored at their end time); "
            f"Kaplan-Meier median {f(sc['median'])} (quartiles {f(sc['q25'])}, {f(sc['q75'])}); "
            f"mean over the {sc['n_observed']} that short-circuited {mean}"
        )
    times = summary["times"]
    head = "| measure | unit | " + " | ".join(f"t = {t:g}" for t in times) + " |"
    lines += [
        "",
        "mean +- standard error over seeds (seeds with a frame within half an output interval of that time)",
        "",
        head,
        "|" + "---|" * (len(times) + 2),
    ]
    for name, m in summary["measures"].items():
        if "k" in m:
            cells = [_group_cell(m, i) for i in range(len(times))]
        else:
            cells = [_pm(a, b, n) for a, b, n in zip(m["mean"], m["sem"], m["n"])]
        lines.append(f"| {name} | {m['unit']} | " + " | ".join(cells) + " |")
    if any("k" in m for m in summary["measures"].values()):
        lines += [
            "",
            "current-related measures: k/n seeds carrying a current, the median [min, max] and "
            "mean +- standard error of those k only",
        ]
    if any("fit_err_rms" in m for m in summary["measures"].values()):
        lines += ["fitted dimensions: the standard error adds each seed's fit uncertainty to the spread between seeds"]
    for u in summary.get("unreadable", ()):
        lines += [f"left out: {u['reason']}"]
    if summary.get("note"):
        lines += ["", f"note: {summary['note']}"]
    return "\n".join(lines)


#: columns of summary.csv after measure, unit, time, mean, sem, n (empty where a measure has none):
#: a fitted measure's standard error between seeds and rms fit uncertainty; a grouped measure's
#: seeds in the group (k; its mean, sem and n are the group's), seeds with a value, median, min, max
CSV_EXTRA = ("sem_between", "fit_err_rms", "k", "n_seeds", "median", "min", "max")


def summary_rows(summary) -> list[dict]:
    """The rows of ``summary.csv``: the short circuit's (time None), then one per measure and time,
    each with ``measure, unit, time, mean, sem, n`` and the :data:`CSV_EXTRA` columns (None where a
    measure has none)."""
    rows = []
    blank = dict.fromkeys(CSV_EXTRA)
    sc = summary.get("short_circuit")
    if sc:
        for name, unit, mean, sem, n in (
            ("short_circuit_time_observed", "t0", sc["mean_observed"], sc["sem_observed"], sc["n_observed"]),
            ("short_circuit_time_km_median", "t0", sc["median"], None, sc["n"]),
            ("seeds_without_short_circuit", "seeds", sc["n_censored"], None, sc["n"]),
        ):
            rows.append({"measure": name, "unit": unit, "time": None, "mean": mean, "sem": sem, "n": n, **blank})
    for name, m in summary["measures"].items():
        for i, (t, a, b, n) in enumerate(zip(summary["times"], m["mean"], m["sem"], m["n"])):
            extra = {c: (m[c][i] if c in m else None) for c in CSV_EXTRA}
            rows.append({"measure": name, "unit": m["unit"], "time": t, "mean": a, "sem": b, "n": n, **extra})
    return rows


def write_summary(summary, folder) -> tuple[Path, Path]:
    """Write ``summary.json`` (everything) and ``summary.csv`` (one row per measure and time) into ``folder``,
    each whole or not at all (:func:`~selfas_graph.io.atomic.atomic_write`: a kill or a full disk leaves
    the summary there was)."""
    folder = make_folder(folder)
    js, cs = own_file(folder / SUMMARY_JSON), own_file(folder / SUMMARY_CSV)
    write_text_atomic(js, json.dumps(summary, indent=1, allow_nan=False) + "\n")
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    fields = ["measure", "unit", "time", "mean", "sem", "n", *CSV_EXTRA]
    w.writerow(fields)
    for r in summary_rows(summary):
        w.writerow([_csv(r[f]) for f in fields])
    write_text_atomic(cs, buf.getvalue())
    return js, cs


def _csv(v):
    return "" if v is None else repr(v) if isinstance(v, float) else v
