"""Parameter grids: an ensemble at every point of a product of scenario values.

``selfas-graph ensemble SCENARIO --seeds N --grid KEY=V1,V2,... [--grid KEY2=...]`` runs the
product of the grids times the seeds: grid point ``KEY=V1`` goes to its own folder
``DIR/KEY=V1/`` (two keys: ``DIR/KEY=V1+KEY2=W1/``), which is an ordinary ensemble folder (the same
seed files, resume, skip and lock rules as seeds today). Every point is validated before anything
runs: an unknown key, a value the schema refuses or an empty list is refused naming the key. The
combined summary ``DIR/grid_summary.json`` and ``.csv`` has the grid keys as columns; ``--plot``
draws each measure at the last summarised time against the first grid key, with standard-error
bars, one line per value of the other keys. From Python::

    from selfas_graph.grid import Grid
    grid = Grid("scenarios/quick.toml", {"circuit.delta_J0": ["1", "2"]}, seeds=2, folder="sweep")
    grid.run(jobs=2)
    table = grid.summarise()
"""

from __future__ import annotations

import contextlib
import csv
import io
import itertools
import math
import numbers
from pathlib import Path

import numpy as np

from .ensemble import Ensemble, EnsembleError, run_seed, run_tasks, summarise
from .ensemble.folder import FolderLock, make_folder, own_file
from .ensemble.plan import check_jobs, scenario_source, summary_times
from .ensemble.tables import CSV_EXTRA, summary_rows
from .io.atomic import atomic_write, write_text_atomic
from .io.scenario import ScenarioError, load_scenario
from .parallel import task_pool

__all__ = ["Grid", "parse_grid"]

GRID_JSON, GRID_CSV, GRID_PNG = "grid_summary.json", "grid_summary.csv", "grid_summary.png"


def parse_grid(items) -> dict:
    """``["KEY=V1,V2", ...]`` -> ``{KEY: [V1, V2]}``, in order; EnsembleError naming the item when
    it is not KEY=VALUES, repeats a key or gives an empty list. A value holding a comma (a vector,
    ``[0,0,1]``) is kept whole inside its brackets."""
    out = {}
    for item in items or ():
        key, sep, values = str(item).partition("=")
        key = key.strip()
        if not sep or not key:
            raise EnsembleError(f"--grid {item!r}: expected KEY=V1,V2,... (e.g. --grid circuit.delta_J0=1,2)")
        if key in out:
            raise EnsembleError(f"--grid {key}: given twice; put all its values in one --grid")
        if key == "scenario.seed":
            raise EnsembleError("--grid scenario.seed: the seeds are the ensemble's; use --seeds and --first-seed")
        parts, depth, cur = [], 0, ""
        for ch in values:
            depth += ch in "[(" and 1 or 0
            depth -= ch in "])" and 1 or 0
            if ch == "," and depth == 0:
                parts.append(cur)
                cur = ""
            else:
                cur += ch
        parts.append(cur)
        parts = [p.strip() for p in parts]
        if not any(parts) or any(not p for p in parts):
            raise EnsembleError(f"--grid {key}: an empty value in {values!r}; give V1,V2,... with no empty entry")
        same = _repeated(parts)
        if same:
            raise EnsembleError(f"--grid {key}: {same[0]} and {same[1]} are the same value in {values!r}")
        out[key] = parts
    return out


def _repeated(parts):
    """Two entries of a grid key that give the same value (``1`` and ``1.0``, as the override reads
    them: a TOML value, else the text), or None."""
    import tomllib

    seen = {}
    for p in parts:
        try:
            value = tomllib.loads(f"v = {p}")["v"]
        except tomllib.TOMLDecodeError:
            value = p
        marker = repr(value) if not isinstance(value, (int, float)) or isinstance(value, bool) else float(value)
        if marker in seen:
            return seen[marker], p
        seen[marker] = p
    return None


def _value_text(value) -> str:
    """A grid value as the text of an override: a string as it is (the command line's), a Python
    number, boolean or list as its TOML literal, integral floats as integers."""
    if isinstance(value, str):
        return value.strip()
    if isinstance(value, (bool, np.bool_)):
        return "true" if value else "false"
    if isinstance(value, numbers.Integral):
        return str(int(value))
    if isinstance(value, numbers.Real):
        x = float(value)
        return str(int(x)) if x.is_integer() and abs(x) < 1e15 else repr(x)
    if isinstance(value, (list, tuple, np.ndarray)):
        return "[" + ",".join(_value_text(v) for v in value) + "]"
    raise EnsembleError(f"grid value {value!r}: give a number, a boolean, a list of numbers or the text of a value")


def _folder_name(point) -> str:
    name = "+".join(f"{k}={v}" for k, v in point)
    return name.replace("/", "_").replace(" ", "")


class Grid:
    """An :class:`~selfas_graph.ensemble.Ensemble` at every point of ``grid`` (key -> values).

    Every point's scenario is built (and so validated) here: :class:`EnsembleError` names the
    grid key whose value the schema refuses before anything runs.
    """

    def __init__(self, scenario, grid: dict, seeds, folder, overrides=(), t_end=None, first_seed=None, force=False):
        if not grid:
            raise EnsembleError("a grid needs at least one key and its values ({KEY: [V1, V2]}, --grid KEY=V1,V2,...)")
        scenario, overrides, t_end = scenario_source(scenario, overrides, t_end)
        self.keys = list(grid)
        for key in self.keys:
            values = grid[key]
            if isinstance(values, str) or not len(values):
                raise EnsembleError(f"grid key {key}: give a non-empty list of values, e.g. ['1', '2'], got {values!r}")
        self.folder = Path(folder)
        base = [o.split("=", 1)[0].strip() for o in overrides]
        for key in self.keys:
            if key in base:
                raise EnsembleError(f"grid key (--grid) {key}: also given in overrides (--set); give it in one place")
            if key == "run.t_end":  # every point was summarised at the first point's end
                raise EnsembleError(
                    "--grid run.t_end: the end time is the grid's (t_end, --t-end); run to the latest end and read "
                    "the earlier ones with --times"
                )
        # Python values as the text of an override (False -> false, 2.0 -> 2, [0, 0, 1.5] -> [0,0,1.5]), so
        # that a point has one folder however its value was written
        texts = {k: [_value_text(v) for v in grid[k]] for k in self.keys}
        for key in self.keys:
            same = _repeated(texts[key])
            if same:
                what = f"{same[0]!r} and {same[1]!r} are the same value" if same[0] != same[1] else f"{same[0]} twice"
                raise EnsembleError(f"grid key {key}: {what} in {list(grid[key])!r}")
        self.points = [tuple(zip(self.keys, values)) for values in itertools.product(*(texts[k] for k in self.keys))]
        seen = {}
        for point in self.points:  # a folder name drops spaces and turns "/" into "_": two values could share one
            other = seen.setdefault(_folder_name(point).casefold(), point)
            if other is not point:
                raise EnsembleError(
                    f"grid points {', '.join(f'{k}={v}' for k, v in other)} and {', '.join(f'{k}={v}' for k, v in point)} "
                    f"would share the folder {_folder_name(point)!r}: give values that differ in more than spaces, "
                    f"'/' and '_' (or case)"
                )
        self.ensembles = []
        for point in self.points:
            extra = [f"{k}={v}" for k, v in point]
            try:  # the key and value checked as a scenario file's, naming the key
                load_scenario(scenario, overrides=[*overrides, *extra], t_end=t_end)
            except ScenarioError as exc:
                raise EnsembleError(f"--grid {', '.join(extra)}: {exc}") from None
            self.ensembles.append(
                Ensemble(
                    scenario,
                    seeds,
                    self.folder / _folder_name(point),
                    overrides=[*overrides, *extra],
                    t_end=t_end,
                    first_seed=first_seed,
                    force=force,
                )
            )
        self.t_end = self.ensembles[0].t_end

    def plans(self, summary_only=False):
        """Every point's :meth:`Ensemble.plan` (EnsembleError lists the unusable seed files)."""
        return [e.plan(summary_only=summary_only) for e in self.ensembles]

    def tasks(self, plans):
        return [t for e, p in zip(self.ensembles, plans) for t in e.tasks(p)]

    def lock(self, stack: contextlib.ExitStack) -> None:
        """Create and lock the grid's folder and every point's folder (:class:`FolderLock`, held until
        ``stack`` closes): EnsembleError naming the folder if another ensemble or grid runs in one."""
        for folder in [self.folder, *(e.folder for e in self.ensembles)]:
            make_folder(folder)
            stack.enter_context(FolderLock(folder))

    def run(self, jobs=1, report=None, pool=None) -> list:
        """Run what is missing at every point, all points' seeds in one pool, with the grid's folder and
        every point's locked (:meth:`lock`; EnsembleError if another ensemble runs in one of them)."""
        if pool is None:
            check_jobs(jobs)
        with contextlib.ExitStack() as stack:
            self.lock(stack)
            tasks = self.tasks(self.plans())
            if pool is None:
                with task_pool(jobs) as own:
                    return run_tasks(run_seed, tasks, own, report)
            return run_tasks(run_seed, tasks, pool, report)

    def summarise(self, times=None, flux_radius=None) -> dict:
        """Each point's :func:`~selfas_graph.ensemble.summarise`, and the rows of the combined table:
        one per point, measure and time, with the grid keys as columns. Each point's times fall on its own
        frames (a grid over ``output.interval`` or ``integrator.dt`` has frames of its own at each point);
        ``times`` of the table are the first point's."""
        points, rows, point_times = [], [], []
        for point, ens in zip(self.points, self.ensembles):
            params = ens.base.params
            at = summary_times(times, ens.t_end, params.output.interval, params.integrator.dt)
            point_times.append(at)
            paths = [p for p in (ens.folder / f"seed_{s:04d}.h5" for s in ens.seeds) if p.exists()]
            s = summarise(paths, at, t_end=ens.t_end, flux_radius=flux_radius)
            points.append({"point": dict(point), "folder": ens.folder.name, "summary": s})
            # each point's summary.csv rows: the short circuit's, and the current measures' seeds
            # carrying current (k) of the seeds with a value (n_seeds), whose mean, sem and n are the k's
            rows += [{**dict(point), **r} for r in summary_rows(s)]
        return {"keys": self.keys, "times": point_times[0], "t_end": self.t_end, "points": points, "rows": rows}


def grid_csv(table) -> str:
    buf = io.StringIO()
    fields = [*table["keys"], "measure", "unit", "time", "mean", "sem", "n", *CSV_EXTRA]
    w = csv.DictWriter(buf, fieldnames=fields, lineterminator="\n")
    w.writeheader()
    for r in table["rows"]:
        w.writerow({k: ("" if v is None else v) for k, v in r.items()})
    return buf.getvalue()


def plot_grid(table, out, title) -> Path:
    """Each measure at the last time against the first grid key (SE bars; a line per value of the others)."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    key, others = table["keys"][0], table["keys"][1:]
    t = table["times"][-1]
    rows = [r for r in table["rows"] if r["time"] is not None and abs(r["time"] - t) < 1e-9]
    names = list(dict.fromkeys(r["measure"] for r in rows))
    ncols = 2
    nrows = math.ceil(len(names) / ncols)
    fig = Figure(figsize=(7.2, 2.0 * nrows + 0.8), layout="constrained")
    axes = fig.subplots(nrows, ncols, squeeze=False).ravel()

    def num(v):
        try:
            return float(v)
        except ValueError:
            return v

    for ax, name in zip(axes, names):
        mine = [r for r in rows if r["measure"] == name]
        groups = {}
        for r in mine:
            groups.setdefault(tuple(r[o] for o in others), []).append(r)
        grouped = any(r.get("k") is not None for r in mine)
        for label, rs in groups.items():
            xs = [num(r[key]) for r in rs]
            ys = [math.nan if r["mean"] is None else r["mean"] for r in rs]
            es = [math.nan if r["sem"] is None else r["sem"] for r in rs]
            lab = ", ".join(f"{o} = {v}" for o, v in zip(others, label)) or None
            line = ax.errorbar(xs, ys, yerr=es, marker="o", ms=3, capsize=3, lw=1, label=lab)
            # a mean of one seed has no standard error: an open marker, not a bar of zero
            lone = [(x, y) for x, y, e in zip(xs, ys, es) if math.isnan(e) and not math.isnan(y)]
            if lone:
                colour = line[0].get_color()
                ax.plot(*zip(*lone), ls="none", marker="o", ms=6, mfc="white", mec=colour, zorder=3)
            if grouped:  # the seeds carrying current of the seeds with a value, at each point
                for x, r in zip(xs, rs):
                    y = r["mean"] if r["mean"] is not None else 0.0
                    ax.annotate(f"{r['k'] or 0}/{r['n_seeds'] or 0}", (x, y), fontsize="xx-small",
                                textcoords="offset points", xytext=(3, 3))  # fmt: skip
        unit = mine[0]["unit"] if mine else ""
        head = name.replace("_", " ") + (f" ({unit})" if unit not in ("", "1") else "")
        ax.set_title(head + (": seeds carrying current, k/n" if grouped else ""), fontsize="small")
        ax.set_xlabel(key, fontsize="small")
        ax.tick_params(labelsize="small")
        if others:
            ax.legend(fontsize="x-small", frameon=False)
    for ax in axes[len(names) :]:
        ax.set_visible(False)
    fig.suptitle(
        f"{title}: mean and one standard error over seeds at t = {t:g} (open marker: one seed, no error)",
        fontsize="medium",
    )
    return atomic_write(out, lambda tmp: fig.savefig(tmp, dpi=150, format="png"))


def write_grid_summary(table, folder) -> tuple[Path, Path]:
    """``grid_summary.json`` and ``grid_summary.csv`` in ``folder``, each written aside and renamed."""
    import json

    folder = Path(folder)
    js, cs = own_file(folder / GRID_JSON), own_file(folder / GRID_CSV)
    write_text_atomic(js, json.dumps(table, indent=1, allow_nan=False) + "\n")
    write_text_atomic(cs, grid_csv(table))
    return js, cs
