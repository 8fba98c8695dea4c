"""Dynamic percolation: short-circuit times over an ensemble of random runs at several rod densities.

Usage: python tools/percolation.py SCENARIO (--densities RHO ... | --fractions PHI ... | --counts N ...)
           --seeds K --t-max T [--first-seed S] [--workers W] [--chunk DT] [--set key=value ...]
           [-o results.json] [--plot out.png]

The rod density is varied through ``rods.count`` at the scenario's fixed placement box
(volume V). Three ways to give it, one per option:

- ``--densities``: number density n = rods / V (rods per L^3; quick.toml has 300 / 500 = 0.6);
- ``--fractions``: volume fraction phi = rods * pi (D/2)^2 L / V with D = ``rods.diameter``
  (rods of unit length L; quick.toml has phi = 1.7e-3);
- ``--counts``: rod counts.

Each is turned into a count (rounded) and all three numbers are printed. Every run
overrides ``scenario.seed`` (seeds S, S+1, ..., S+K-1; S defaults to the scenario's own
seed), ``rods.count`` and ``run.t_end = T``, writes no file, and stops at the first short
circuit (the step of the SHORT_CIRCUIT event: ``Simulation.run``'s ``stop`` hook) or at T.
A run without a short circuit by T is censored at T; a run that ends in a numerical
failure is censored at the time of the failure and counted apart. Per density the table
gives the fraction short-circuited by T (with a 95 % Wilson interval) and the quartiles
of the short-circuit time from the Kaplan-Meier estimate of its distribution (with
censoring only at T these are plain order statistics of all K runs, censored runs
counting as later than T); a quartile not reached by T is printed as ">T" (null in JSON).

Runs go to W worker processes (``multiprocessing``, spawn; default W = 1, in this process).
Every run uses one numba thread (NUMBA_NUM_THREADS=1 in the workers, ``numba.set_num_threads(1)``
in this process), so that W processes share the cores and every number is independent of W.
A density whose rods cannot be placed in the box (checked with the first seed before any
run) is skipped with a message naming it.
"""
import argparse
import importlib.machinery
import json
import math
import os
import sys
import time
import types
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

# selfas_graph (and with it numba) is imported lazily: a spawned worker must set
# NUMBA_NUM_THREADS before numba is imported.

#: densest packing of equal spheres: tips at least d apart are spheres of diameter d that do not overlap
_MAX_PACKING = math.pi / (3.0 * math.sqrt(2.0))
#: 95 % two-sided normal quantile (Wilson interval of the short-circuited fraction)
_Z95 = 1.959963984540054
STATUSES = ("short_circuit", "censored", "failed", "unplaceable", "error")


# ----------------------------------------------------------------------------- one run

def _worker_init():
    """Pool initializer: one numba thread per worker process (before numba is imported)."""
    os.environ["NUMBA_NUM_THREADS"] = "1"


def run_one(task):
    """Run one (count, seed) to its first short circuit or to t_max; returns a JSON-ready dict.

    ``task`` is a dict with keys text, path, overrides, count, seed, t_max, chunk.
    """
    from selfas_graph import NumericalFailure, PlacementError, Simulation, scenario_from_text
    from selfas_graph.model.simulation import RunInterrupted

    count, seed, t_max = task["count"], task["seed"], task["t_max"]
    out = {"count": count, "seed": seed, "status": None, "time": None, "t_end": 0.0, "steps": 0,
           "events": 0, "filament_rods": 0, "wall_seconds": 0.0, "message": None}
    t0 = time.perf_counter()
    sim = None
    try:
        over = list(task["overrides"]) + [f"scenario.seed={seed}", f"rods.count={count}", f"run.t_end={t_max!r}"]
        scenario = scenario_from_text(task["text"], path=Path(task["path"]), overrides=over)
        sim = Simulation.from_scenario(scenario)
        total = sim.steps_for(t_max)
        stop = lambda: sim.short_circuit_time is not None  # noqa: E731
        while sim.short_circuit_time is None and sim.state.step < total:
            # run() takes whole steps only: the chunk and the end rounded to steps
            n = min(sim.steps_for(task["chunk"]), total - sim.state.step)
            target = sim.state.time + n * sim.dt
            try:
                summary = sim.run(t_end=target, stop=stop)
            except RunInterrupted:
                break
            if summary.steps == 0:  # the chunk rounds to no step: the end is reached
                break
        if sim.short_circuit_time is not None:
            out["status"], out["time"] = "short_circuit", float(sim.short_circuit_time)
        else:
            out["status"] = "censored"
    except PlacementError as exc:
        out["status"], out["message"] = "unplaceable", str(exc)
    except NumericalFailure as exc:
        out["status"], out["message"] = "failed", str(exc)
    except Exception as exc:  # noqa: BLE001 - a bug in one run must not lose the ensemble; reported
        out["status"], out["message"] = "error", f"{type(exc).__name__}: {exc}"
    if sim is not None:
        out["t_end"] = float(sim.state.time)
        out["steps"] = int(sim.state.step)
        out["events"] = len(sim.events)
        if sim.graph is not None:
            out["filament_rods"] = int(sim.graph.topology().n_filament)
    out["wall_seconds"] = time.perf_counter() - t0
    return out


# ----------------------------------------------------------------------------- statistics

def kaplan_meier(times, censored_at):
    """Kaplan-Meier estimate of the distribution F(t) = P(short circuit <= t).

    Parameters
    ----------
    times : list of float
        Short-circuit times.
    censored_at : list of float
        Times at which runs without a short circuit stopped (T, or a failure's time).

    Returns
    -------
    list of (t, F(t)) at every distinct short-circuit time, increasing. A run censored
    at the time of a short circuit counts as still at risk then.
    """
    n_at_risk = len(times) + len(censored_at)
    if not times:
        return []
    order = sorted(times)
    cens = sorted(censored_at)
    out, surv, i, j = [], 1.0, 0, 0
    while i < len(order):
        t = order[i]
        while j < len(cens) and cens[j] < t:  # censored strictly before t: no longer at risk
            j += 1
            n_at_risk -= 1
        d = 0
        while i < len(order) and order[i] == t:
            d += 1
            i += 1
        surv *= 1.0 - d / n_at_risk
        n_at_risk -= d
        out.append((t, 1.0 - surv))
    return out


def km_quantile(curve, q):
    """Smallest t with F(t) >= q on a Kaplan-Meier curve, or None if not reached."""
    for t, f in curve:
        if f >= q - 1e-12:
            return t
    return None


def wilson(m, n, z=_Z95):
    """Wilson score interval of a binomial proportion m / n."""
    if n == 0:
        return (0.0, 1.0)
    p = m / n
    den = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / den
    half = z * math.sqrt(p * (1.0 - p) / n + z * z / (4 * n * n)) / den
    return (max(0.0, centre - half), min(1.0, centre + half))


def summarise(point, runs):
    """Statistics of one density from its runs (unplaceable and error runs left out, counted)."""
    used = [r for r in runs if r["status"] in ("short_circuit", "censored", "failed")]
    sc = [r["time"] for r in used if r["status"] == "short_circuit"]
    cens = [r["t_end"] for r in used if r["status"] != "short_circuit"]
    curve = kaplan_meier(sc, cens)
    n, m = len(used), len(sc)
    lo, hi = wilson(m, n)
    return {
        **point,
        "runs": n,
        "short_circuited": m,
        "censored": sum(r["status"] == "censored" for r in used),
        "failed": sum(r["status"] == "failed" for r in used),
        "excluded": len(runs) - n,
        "fraction": m / n if n else None,
        "fraction_ci95": [lo, hi] if n else None,
        "km_fraction": curve[-1][1] if curve else 0.0,
        "q25": km_quantile(curve, 0.25),
        "median": km_quantile(curve, 0.5),
        "q75": km_quantile(curve, 0.75),
        "km": [[t, f] for t, f in curve],
    }


# ----------------------------------------------------------------------------- planning

def _positive(kind):
    def parse(text):
        try:
            v = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not {'an integer' if kind is int else 'a number'}") from None
        if not (v > 0 and math.isfinite(v)):
            raise argparse.ArgumentTypeError(f"{text} must be positive")
        return v
    return parse


def build_parser():
    ap = argparse.ArgumentParser(
        prog="percolation.py", description=__doc__.splitlines()[0],
        epilog="density = rods / box volume; volume fraction = rods * pi (D/2)^2 L / box volume")
    ap.add_argument("scenario", help="scenario TOML file")
    grp = ap.add_mutually_exclusive_group(required=True)
    grp.add_argument("--densities", type=_positive(float), nargs="+", metavar="RHO",
                     help="number densities, rods per unit box volume (L^-3)")
    grp.add_argument("--fractions", type=_positive(float), nargs="+", metavar="PHI",
                     help="rod volume fractions rods * pi (D/2)^2 L / V")
    grp.add_argument("--counts", type=_positive(int), nargs="+", metavar="N", help="rod counts")
    ap.add_argument("--seeds", type=_positive(int), required=True, metavar="K", help="runs per density")
    ap.add_argument("--first-seed", type=int, default=None, metavar="S",
                    help="seeds S .. S+K-1 (default: the scenario's scenario.seed)")
    ap.add_argument("--t-max", type=_positive(float), required=True, metavar="T",
                    help="simulated time after which a run without short circuit is censored")
    ap.add_argument("--workers", type=_positive(int), default=1, metavar="W", help="worker processes (default 1)")
    ap.add_argument("--chunk", type=_positive(float), default=0.25, metavar="DT",
                    help="simulated time per run() call (progress granularity; results do not depend on it)")
    ap.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                    help="extra scenario override for every run, as selfas-graph simulate --set")
    ap.add_argument("-o", "--output", metavar="JSON", help="write every run's result and the statistics here")
    ap.add_argument("--plot", metavar="PNG", help="plot fraction short-circuited vs density and the distributions")
    return ap


def plan(ap, args):
    """Load the scenario and turn the requested densities into rod counts; returns (base, points, skipped)."""
    from selfas_graph import PlacementError, ScenarioError, load_scenario, random_state, scenario_from_text

    if args.first_seed is not None and args.first_seed < 0:
        ap.error(f"--first-seed must be >= 0, got {args.first_seed}")
    try:
        base = load_scenario(args.scenario, overrides=args.overrides)
    except ScenarioError as exc:
        ap.error(str(exc))
    p = base.params
    if not p.contacts.enabled:
        ap.error(f"{args.scenario}: contacts.enabled is false, so no short circuit can ever be detected")
    if p.forces.electrodes is None and p.forces.external_filament is None:
        ap.error(f"{args.scenario}: no conductor (neither [forces.electrodes] nor [forces.external_filament]), "
                 "so no short circuit is possible")
    box = [[float(a), float(b)] for a, b in p.placement.box]
    sides = [b - a for a, b in box]
    volume = math.prod(sides)
    rod_volume = math.pi * (0.5 * p.rods.diameter) ** 2 * 1.0
    dmin = p.min_tip_distance
    if args.densities:
        requested = [("density", v, round(v * volume)) for v in args.densities]
    elif args.fractions:
        requested = [("fraction", v, round(v * volume / rod_volume)) for v in args.fractions]
    else:
        requested = [("count", v, v) for v in args.counts]
    first_seed = p.scenario.seed if args.first_seed is None else args.first_seed
    points, skipped, seen = [], [], {}
    text = base.text

    def skip(kind, value, n, reason):
        name = f"{kind} {value:g}" + (f" ({n} rods)" if kind != "count" else "")
        print(f"skipping {name}: {reason}", flush=True)
        skipped.append({"requested": {"by": kind, "value": value}, "count": n, "reason": reason})

    for kind, value, n in requested:
        n = int(n)
        if n < 1:
            skip(kind, value, n, f"it gives {n} rods in the box of volume {volume:g}")
            continue
        if n in seen:
            print(f"note: {kind} {value:g} gives {n} rods, as {seen[n]} does; run once", flush=True)
            continue
        # tips of different rods start at least dmin apart: 2n non-overlapping spheres of
        # diameter dmin with centres in the box, i.e. inside the box grown by dmin / 2
        packed = 2 * n * math.pi / 6.0 * dmin ** 3
        room = math.prod(s + dmin for s in sides)
        if dmin > 0 and packed > _MAX_PACKING * room:
            skip(kind, value, n, f"{2 * n} tips at least {dmin:g} apart (placement.min_tip_distance) cannot fit "
                                 f"in the box {box} even at the densest packing")
            continue
        if n > 2000:
            print(f"checking that {n} rods ({kind} {value:g}) can be placed in the box...", flush=True)
        try:
            sc = scenario_from_text(text, path=base.path, overrides=list(args.overrides) + [
                f"scenario.seed={first_seed}", f"rods.count={n}"])
            random_state(sc.params)
        except PlacementError as exc:
            skip(kind, value, n, f"the rods cannot be placed in the box with seed {first_seed}: {exc}")
            continue
        except ScenarioError as exc:
            skip(kind, value, n, str(exc))
            continue
        seen[n] = f"{kind} {value:g}"
        points.append({"requested": {"by": kind, "value": value}, "count": n,
                       "number_density": n / volume, "volume_fraction": n * rod_volume / volume})
    points.sort(key=lambda pt: pt["count"])
    meta = {"box": box, "box_volume": volume, "rod_diameter": p.rods.diameter, "rod_volume": rod_volume,
            "min_tip_distance": dmin, "first_seed": first_seed, "dt": p.integrator.dt}
    return base, points, skipped, meta


# ----------------------------------------------------------------------------- running

def _spawn_importable():
    """Make the worker functions importable in spawned processes.

    Run as a script, spawn re-imports this file as ``__mp_main__``. Loaded from its path
    under another name (as the tests do), the workers could not import that name: the
    worker functions are then exposed as module ``percolation`` (an alias module in
    sys.modules here, for pickle) with tools/ on sys.path (for the spawned processes).
    """
    name = __name__
    if name == "__main__":
        return
    me = Path(__file__).resolve()
    if "." not in name:
        spec = importlib.machinery.PathFinder.find_spec(name, sys.path)
        if spec is not None and spec.origin and Path(spec.origin).resolve() == me:
            return
    existing = sys.modules.get("percolation")
    if existing is not None and Path(getattr(existing, "__file__", None) or "").resolve() != me:
        raise RuntimeError(f"another module named 'percolation' is loaded ({existing!r}); run the tool as a script "
                           "or with --workers 1")
    alias = types.ModuleType("percolation")
    alias.__file__ = str(me)
    for fn in (_worker_init, run_one, _indexed_run):
        fn.__module__ = "percolation"
        setattr(alias, fn.__name__, fn)
    sys.modules["percolation"] = alias  # what pickle looks the workers up in, here
    if str(me.parent) not in sys.path:
        sys.path.append(str(me.parent))  # spawned processes get sys.path and import tools/percolation.py


def run_all(tasks, workers, report):
    """Run every task (in this process if workers == 1); returns results in task order."""
    results = [None] * len(tasks)
    if workers == 1:
        import numba
        before = numba.get_num_threads()
        numba.set_num_threads(1)
        try:
            for i, task in enumerate(tasks):
                results[i] = run_one(task)
                report(results[i])
        finally:
            numba.set_num_threads(before)
        return results
    import multiprocessing as mp
    _spawn_importable()
    ctx = mp.get_context("spawn")
    # largest counts first: better balance of the slow runs over the workers
    order = sorted(range(len(tasks)), key=lambda i: -tasks[i]["count"])
    with ctx.Pool(processes=min(workers, len(tasks)), initializer=_worker_init) as pool:
        it = pool.imap_unordered(_indexed_run, [(i, tasks[i]) for i in order])
        for i, res in it:
            results[i] = res
            report(res)
    return results


def _indexed_run(item):
    i, task = item
    return i, run_one(task)


def _fmt_t(v, t_max):
    return f">{t_max:g}" if v is None else f"{v:.4g}"


def print_table(result):
    t_max = result["t_max"]
    print(f"\n{result['scenario']}: box volume {result['box_volume']:g}, rod D/L = {result['rod_diameter']:g}, "
          f"t_max = {t_max:g}, seeds {result['seeds'][0]}..{result['seeds'][-1]}, "
          f"{result['threads_per_run']} numba thread per run")
    print("short-circuit time quartiles: Kaplan-Meier, runs without a short circuit censored at t_max "
          f"(failed runs at their failure time); '>{t_max:g}' = not reached by t_max\n")
    head = ("| rods | rods/V | vol. fraction | runs | short-circuited by T | fraction (95% CI) | q25 | median "
            "| q75 | censored | failed |")
    print(head)
    print("|" + "---|" * (head.count("|") - 1))
    for d in result["densities"]:
        frac = "n/a" if d["fraction"] is None else (
            f"{d['fraction']:.2f} ({d['fraction_ci95'][0]:.2f}-{d['fraction_ci95'][1]:.2f})")
        print(f"| {d['count']} | {d['number_density']:.4g} | {d['volume_fraction']:.3g} | {d['runs']} "
              f"| {d['short_circuited']}/{d['runs']} | {frac} | {_fmt_t(d['q25'], t_max)} "
              f"| {_fmt_t(d['median'], t_max)} | {_fmt_t(d['q75'], t_max)} | {d['censored']} | {d['failed']} |")
    for s in result["skipped"]:
        print(f"skipped {s['requested']['by']} {s['requested']['value']:g}: {s['reason']}")
    bad = [r for r in result["runs"] if r["status"] in ("unplaceable", "error")]
    for r in bad:
        print(f"left out: {r['count']} rods, seed {r['seed']}: {r['status']}: {r['message']}")


def plot(result, path):
    """Fraction short-circuited vs density, and the distribution of short-circuit times per density."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    dens = result["densities"]
    t_max = result["t_max"]
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(13, 4.6), gridspec_kw={"width_ratios": [1, 1.15]})
    rho = [d["number_density"] for d in dens]
    frac = [d["fraction"] if d["fraction"] is not None else float("nan") for d in dens]
    lo = [f - d["fraction_ci95"][0] if d["fraction_ci95"] else 0.0 for f, d in zip(frac, dens)]
    hi = [d["fraction_ci95"][1] - f if d["fraction_ci95"] else 0.0 for f, d in zip(frac, dens)]
    ax1.errorbar(rho, frac, yerr=[lo, hi], marker="o", capsize=3)
    ax1.set_xlabel("rods per unit volume (L$^{-3}$)")
    ax1.set_ylabel(f"fraction short-circuited by t = {t_max:g}")
    ax1.set_ylim(-0.03, 1.03)
    ax1.set_title("short circuit vs density (95% Wilson CI)")
    vrod = result["rod_volume"]
    top = ax1.secondary_xaxis("top", functions=(lambda x: x * vrod, lambda x: x / vrod))
    top.set_xlabel("volume fraction")
    ax1.grid(alpha=0.3)
    for d in dens:
        curve = d["km"]
        ts = [0.0] + [t for t, _ in curve] + [t_max]
        fs = [0.0] + [f for _, f in curve] + [curve[-1][1] if curve else 0.0]
        n_cens = d["runs"] - d["short_circuited"]
        label = f"{d['count']} rods\nrods/V = {d['number_density']:.3g}, phi = {d['volume_fraction']:.2g}\n"
        label += f"{d['short_circuited']} of {d['runs']} runs short-circuited"
        (line,) = ax2.step(ts, fs, where="post", label=label)
        if n_cens:
            ax2.plot([t_max], [fs[-1]], marker=">", color=line.get_color(), clip_on=False)
    ax2.set_xlim(0.0, t_max)
    ax2.set_ylim(-0.03, 1.03)
    ax2.set_xlabel("short-circuit time")
    ax2.set_ylabel("fraction of runs short-circuited (Kaplan-Meier)")
    ax2.set_title("distribution of short-circuit times\n(runs without one are censored: > t_max, arrow)")
    ax2.grid(alpha=0.3)
    ax2.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0, labelspacing=0.9)
    fig.suptitle(f"{Path(result['scenario']).name}: {len(result['seeds'])} seeds per density", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv=None):
    ap = build_parser()
    args = ap.parse_args(argv)
    base, points, skipped, meta = plan(ap, args)
    if not points:
        ap.error("no density left to run (every one was skipped, see above)")
    from selfas_graph import __version__

    seeds = [meta["first_seed"] + k for k in range(args.seeds)]
    tasks = [{"text": base.text, "path": str(base.path), "overrides": list(args.overrides), "count": pt["count"],
              "seed": s, "t_max": args.t_max, "chunk": args.chunk} for pt in points for s in seeds]
    print(f"{len(points)} densities x {len(seeds)} seeds = {len(tasks)} runs to t = {args.t_max:g} "
          f"on {args.workers} worker(s)", flush=True)
    done = [0]

    def report(r):
        done[0] += 1
        if r["status"] == "short_circuit":
            what = f"short circuit at t = {r['time']:.4g}"
        elif r["status"] == "censored":
            what = f"no short circuit by t = {r['t_end']:.4g}"
        else:
            what = f"{r['status']} at t = {r['t_end']:.4g}: {r['message']}"
        print(f"[{done[0]}/{len(tasks)}] {r['count']} rods, seed {r['seed']}: {what} ({r['wall_seconds']:.1f} s)",
              flush=True)

    t0 = time.perf_counter()
    runs = run_all(tasks, args.workers, report)
    runs.sort(key=lambda r: (r["count"], r["seed"]))
    result = {
        "scenario": str(args.scenario), "scenario_name": base.params.scenario.name, "version": __version__,
        "overrides": list(args.overrides), "t_max": args.t_max, "chunk": args.chunk, "seeds": seeds,
        "workers": args.workers, "threads_per_run": 1, **meta,
        "censoring": "status 'censored': no short circuit by t_max (censored at t_end = t_max); 'failed': a numerical "
                     "failure at t_end (censored there); 'unplaceable' and 'error' runs are left out of the "
                     "statistics. q25/median/q75 are Kaplan-Meier quantiles, null when not reached by t_max; "
                     "km lists (t, F(t)) at every short-circuit time",
        "densities": [summarise(pt, [r for r in runs if r["count"] == pt["count"]]) for pt in points],
        "skipped": skipped,
        "runs": runs,
        "wall_seconds": time.perf_counter() - t0,
    }
    print_table(result)
    if args.output:
        with open(args.output, "w") as fh:
            json.dump(result, fh, indent=1, allow_nan=False)
        print(f"wrote {args.output}")
    if args.plot:
        plot(result, args.plot)
        print(f"wrote {args.plot}")
    return 1 if any(r["status"] == "error" for r in runs) else 0


if __name__ == "__main__":
    sys.exit(main())
