"""Dynamic percolation: short-circuit times over an ensemble of random runs at several rod densities.

Usage: selfas-graph bench percolation SCENARIO (--densities RHO ... | --fractions PHI ... | --counts N ...)
           --seeds K --t-max T [--fields on|off] [--first-seed S] [--workers W] [--chunk DT]
           [--set key=value ...] [-o results.json] [--plot out.png]
       selfas-graph bench percolation --compare A.json B.json ... --plot out.png

``--fields off`` removes the magnetic and current terms (``forces.tip_magnetic``,
``uniform_field``, ``plasma_filament``, ``current_field``, ``current_lorentz``: the same as
``--set forces.NAME=false`` for each), leaving the brakes, the screened repulsion and the
electrodes: the contrast that tells how much the fields lower the percolation threshold.
``--compare`` draws the results of earlier calls (their ``-o`` files) on one figure: the
fraction short-circuited and the median short-circuit time against the volume fraction.

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
gives the fraction short-circuited by T over the runs that decide it, failed runs left out
(with a 95 % Wilson interval), and the quartiles
of the short-circuit time from the Kaplan-Meier estimate of its distribution (with
censoring only at T these are plain order statistics of all K runs, censored runs
counting as later than T); a quartile not reached by T is printed as ">T" (null in JSON).

Runs go to W worker processes (default W = 1, in this process) through the same runner as
``selfas-graph ensemble`` (:func:`selfas_graph.ensemble.run_tasks` on a
:class:`selfas_graph.parallel.task_pool`; one run is
:func:`selfas_graph.ensemble.run_to_short_circuit`), and the statistics are
:mod:`selfas_graph.analysis.ensemble_stats`. Every run uses one numba thread, so that W
processes share the cores and every number is independent of W. A density whose rods
cannot be placed in the box (checked with the first seed before any run) is skipped with
a message naming it. To keep run files and summarise other measures, run
``selfas-graph ensemble SCENARIO --set rods.count=N`` per density instead.
"""

import argparse
import json
import math
import sys
import time

from .args import positive

#: densest packing of equal spheres: tips at least d apart are spheres of diameter d that do not overlap
_MAX_PACKING = math.pi / (3.0 * math.sqrt(2.0))
#: the terms ``--fields off`` removes: every magnetic field and every force on or from a current
FIELD_TERMS = ("tip_magnetic", "uniform_field", "plasma_filament", "current_field", "current_lorentz")
STATUSES = ("short_circuit", "censored", "failed", "unplaceable", "error", "interrupted")


# ----------------------------------------------------------------------------- statistics


def _none(v):
    return None if v is None or (isinstance(v, float) and math.isnan(v)) else float(v)


def summarise(point, runs):
    """Statistics of one density from its runs (unplaceable and error runs left out, counted)."""
    from selfas_graph.analysis.ensemble_stats import kaplan_meier, km_quantile, wilson_interval

    used = [r for r in runs if r["status"] in ("short_circuit", "censored", "failed")]
    times = [r["time"] if r["status"] == "short_circuit" else r["t_end"] for r in used]
    observed = [r["status"] == "short_circuit" for r in used]
    t, F = kaplan_meier(times, observed)
    n, m = len(used), sum(observed)
    censored = sum(r["status"] == "censored" for r in used)
    # a failed run stopped before t_max without a short circuit: whether it would have short-circuited
    # by t_max is unknown, so the fraction is over the runs that decide it (the Kaplan-Meier curve
    # keeps the failed runs, censored at their failure time)
    decided = m + censored
    lo, hi = wilson_interval(m, decided)
    return {
        **point,
        "runs": n,
        "short_circuited": m,
        "censored": censored,
        "failed": n - decided,
        "decided": decided,
        "excluded": len(runs) - n,
        "fraction": m / decided if decided else None,
        "fraction_ci95": [lo, hi] if decided else None,
        "km_fraction": float(F[-1]) if F.size else 0.0,
        "q25": _none(km_quantile(t, F, 0.25)),
        "median": _none(km_quantile(t, F, 0.5)),
        "q75": _none(km_quantile(t, F, 0.75)),
        "km": [[float(a), float(b)] for a, b in zip(t, F)],
    }


# ----------------------------------------------------------------------------- planning


def build_parser():
    ap = argparse.ArgumentParser(
        description=__doc__.splitlines()[0],
        epilog="density = rods / box volume; volume fraction = rods * pi (D/2)^2 L / box volume",
    )
    ap.add_argument("scenario", nargs="?", help="scenario TOML file (not with --compare)")
    grp = ap.add_mutually_exclusive_group()
    grp.add_argument(
        "--densities",
        type=positive(float),
        nargs="+",
        metavar="RHO",
        help="number densities, rods per unit box volume (L^-3)",
    )
    grp.add_argument(
        "--fractions",
        type=positive(float),
        nargs="+",
        metavar="PHI",
        help="rod volume fractions rods * pi (D/2)^2 L / V",
    )
    grp.add_argument("--counts", type=positive(int), nargs="+", metavar="N", help="rod counts")
    ap.add_argument("--seeds", type=positive(int), metavar="K", help="runs per density")
    ap.add_argument(
        "--first-seed",
        type=int,
        default=None,
        metavar="S",
        help="seeds S .. S+K-1 (default: the scenario's scenario.seed)",
    )
    ap.add_argument(
        "--fields",
        choices=("on", "off"),
        default="on",
        help="off: without the magnetic and current terms (" + ", ".join(FIELD_TERMS) + "); default on",
    )
    ap.add_argument(
        "--t-max",
        type=positive(float),
        metavar="T",
        help="simulated time after which a run without short circuit is censored",
    )
    ap.add_argument("--workers", type=positive(int), default=1, metavar="W", help="worker processes (default 1)")
    ap.add_argument(
        "--chunk",
        type=positive(float),
        default=0.25,
        metavar="DT",
        help="simulated time per run() call (progress granularity; results do not depend on it)",
    )
    ap.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="extra scenario override for every run, as selfas-graph simulate --set",
    )
    ap.add_argument("-o", "--output", metavar="JSON", help="write every run's result and the statistics here")
    ap.add_argument("--plot", metavar="PNG", help="plot fraction short-circuited vs density and the distributions")
    ap.add_argument(
        "--compare",
        nargs="+",
        metavar="JSON",
        help="draw earlier results (-o files) on one figure (--plot); runs nothing",
    )
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
        ap.error(
            f"{args.scenario}: no conductor (neither [forces.electrodes] nor [forces.external_filament]), "
            "so no short circuit is possible"
        )
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
        packed = 2 * n * math.pi / 6.0 * dmin**3
        room = math.prod(s + dmin for s in sides)
        if dmin > 0 and packed > _MAX_PACKING * room:
            skip(
                kind,
                value,
                n,
                f"{2 * n} tips at least {dmin:g} apart (placement.min_tip_distance) cannot fit "
                f"in the box {box} even at the densest packing",
            )
            continue
        if n > 2000:
            print(f"checking that {n} rods ({kind} {value:g}) can be placed in the box...", flush=True)
        try:
            sc = scenario_from_text(
                text,
                path=base.path,
                overrides=list(args.overrides) + [f"scenario.seed={first_seed}", f"rods.count={n}"],
            )
            random_state(sc.params)
        except PlacementError as exc:
            skip(kind, value, n, f"the rods cannot be placed in the box with seed {first_seed}: {exc}")
            continue
        except ScenarioError as exc:
            skip(kind, value, n, str(exc))
            continue
        seen[n] = f"{kind} {value:g}"
        points.append(
            {
                "requested": {"by": kind, "value": value},
                "count": n,
                "number_density": n / volume,
                "volume_fraction": n * rod_volume / volume,
            }
        )
    points.sort(key=lambda pt: pt["count"])
    meta = {
        "box": box,
        "box_volume": volume,
        "rod_diameter": p.rods.diameter,
        "rod_volume": rod_volume,
        "min_tip_distance": dmin,
        "first_seed": first_seed,
        "dt": p.integrator.dt,
    }
    return base, points, skipped, meta


# ----------------------------------------------------------------------------- running


def run_all(tasks, workers, report):
    """Run every task on ``workers`` processes (in this process if 1), one numba thread each; results in task order."""
    from selfas_graph.ensemble import run_tasks, run_to_short_circuit
    from selfas_graph.parallel import task_pool

    # largest counts first: better balance of the slow runs over the workers
    order = sorted(range(len(tasks)), key=lambda i: -tasks[i]["count"])
    with task_pool(min(workers, len(tasks)), threads=1) as pool:
        done = run_tasks(run_to_short_circuit, [tasks[i] for i in order], pool, report)
    results = [None] * len(tasks)
    for i, r in zip(order, done):
        results[i] = (
            r
            if r is not None
            else {
                **{k: tasks[i][k] for k in ("count", "seed")},
                "status": "interrupted",  # a signal stopped the pool before this run started
                "time": None,
                "t_end": 0.0,
                "steps": 0,
                "events": 0,
                "filament_rods": 0,
                "wall_seconds": 0.0,
                "message": "not run",
                "signum": None,
            }
        )
    return results


def _fmt_t(v, t_max):
    return f">{t_max:g}" if v is None else f"{v:.4g}"


def print_table(result):
    t_max = result["t_max"]
    print(
        f"\n{result['scenario']}: box volume {result['box_volume']:g}, rod D/L = {result['rod_diameter']:g}, "
        f"t_max = {t_max:g}, seeds {result['seeds'][0]}..{result['seeds'][-1]}, "
        f"{result['threads_per_run']} numba thread per run"
    )
    print(
        "short-circuit time quartiles: Kaplan-Meier, runs without a short circuit censored at t_max "
        f"(failed runs at their failure time); '>{t_max:g}' = not reached by t_max\n"
    )
    head = (
        "| rods | rods/V | vol. fraction | runs | short-circuited by T | fraction (95% CI) | q25 | median "
        "| q75 | censored | failed |"
    )
    print(head)
    print("|" + "---|" * (head.count("|") - 1))
    for d in result["densities"]:
        frac = (
            "n/a"
            if d["fraction"] is None
            else (f"{d['fraction']:.2f} ({d['fraction_ci95'][0]:.2f}-{d['fraction_ci95'][1]:.2f})")
        )
        print(
            f"| {d['count']} | {d['number_density']:.4g} | {d['volume_fraction']:.3g} | {d['runs']} "
            f"| {d['short_circuited']}/{d.get('decided', d['runs'])} | {frac} | {_fmt_t(d['q25'], t_max)} "
            f"| {_fmt_t(d['median'], t_max)} | {_fmt_t(d['q75'], t_max)} | {d['censored']} | {d['failed']} |"
        )
    for s in result["skipped"]:
        print(f"skipped {s['requested']['by']} {s['requested']['value']:g}: {s['reason']}")
    bad = [r for r in result["runs"] if r["status"] in ("unplaceable", "error", "interrupted")]
    for r in bad:
        print(f"left out: {r['count']} rods, seed {r['seed']}: {r['status']}: {r['message']}")


def _fraction_bars(dens):
    """Fraction short-circuited per density (NaN without runs) and its Wilson interval as error-bar lengths."""
    frac = [d["fraction"] if d["fraction"] is not None else float("nan") for d in dens]
    lo = [f - d["fraction_ci95"][0] if d["fraction_ci95"] else 0.0 for f, d in zip(frac, dens)]
    hi = [d["fraction_ci95"][1] - f if d["fraction_ci95"] else 0.0 for f, d in zip(frac, dens)]
    return frac, lo, hi


def plot(result, path):
    """Fraction short-circuited vs density, and the distribution of short-circuit times per density."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    dens = result["densities"]
    t_max = result["t_max"]
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(13, 4.6), gridspec_kw={"width_ratios": [1, 1.15]})
    rho = [d["number_density"] for d in dens]
    frac, lo, hi = _fraction_bars(dens)
    ax1.errorbar(rho, frac, yerr=[lo, hi], marker="o", ms=4, lw=1.2, capsize=3)
    ax1.set_xscale("log")
    ax1.set_xlabel("rods per unit volume (L$^{-3}$)")
    ax1.set_ylabel(f"fraction short-circuited by t = {t_max:g}")
    ax1.set_ylim(-0.03, 1.03)
    ax1.set_title("Short circuit against density (95 % Wilson intervals)", fontsize=10)
    vrod = result["rod_volume"]
    top = ax1.secondary_xaxis("top", functions=(lambda x: x * vrod, lambda x: x / vrod))
    top.set_xlabel(r"rod volume fraction $\phi$")
    ax1.grid(alpha=0.3)
    for d in dens:
        curve = d["km"]
        ts = [0.0] + [t for t, _ in curve] + [t_max]
        fs = [0.0] + [f for _, f in curve] + [curve[-1][1] if curve else 0.0]
        n_cens = d["censored"]  # at t_max; a failed run is censored at its failure, inside the curve
        label = f"{d['count']} rods\nrods/V = {d['number_density']:.3g}, phi = {d['volume_fraction']:.2g}\n"
        label += f"{d['short_circuited']} of {d.get('decided', d['runs'])} runs short-circuited"
        label += f", {d['failed']} failed" if d.get("failed") else ""
        (line,) = ax2.step(ts, fs, where="post", label=label)
        if n_cens:
            ax2.plot([t_max], [fs[-1]], marker=">", color=line.get_color(), clip_on=False)
    ax2.set_xlim(0.0, t_max)
    ax2.set_ylim(-0.03, 1.03)
    ax2.set_xlabel("short-circuit time (t$_0$)")
    ax2.set_ylabel("fraction of runs short-circuited (Kaplan-Meier)")
    ax2.set_title(
        "Distribution of short-circuit times\n(runs without one by t$_{max}$ are censored: arrow)", fontsize=10
    )
    ax2.grid(alpha=0.3)
    ax2.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0, labelspacing=0.9)
    fields = "" if fields_of(result) == "on" else ", without the magnetic and current terms"
    fig.suptitle(f"Scene '{result['scenario_name']}'{fields}: {len(result['seeds'])} seeds per density", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def fields_of(result) -> str:
    """'on' or 'off' for a result file (files without the key: 'off' if their overrides removed tip_magnetic)."""
    if "fields" in result:
        return result["fields"]
    return "off" if "forces.tip_magnetic=false" in result.get("overrides", []) else "on"


def plot_compare(results, path):
    """Fraction short-circuited by t_max and the median short-circuit time against the volume fraction,
    one curve per result (e.g. the fields on and off)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.2))
    for res in results:
        dens = res["densities"]
        phi = [d["volume_fraction"] for d in dens]
        frac, lo, hi = _fraction_bars(dens)
        label = (
            f"fields {fields_of(res)} ({res['scenario_name']}, {len(res['seeds'])} seeds per point, "
            f"t$_{{max}}$ = {res['t_max']:g} t$_0$)"
        )
        (line,) = ax1.plot(phi, frac, lw=1.2, marker="o", ms=3.5, label=label)
        ax1.errorbar(phi, frac, yerr=[lo, hi], fmt="none", ecolor=line.get_color(), capsize=3, lw=0.8)
        med = [(d["volume_fraction"], d["median"], d["q25"], d["q75"]) for d in dens if d["median"] is not None]
        if med:
            x, m, q1, q3 = (list(v) for v in zip(*med))
            q3 = [res["t_max"] if v is None else v for v in q3]
            ax2.plot(x, m, lw=1.2, marker="o", ms=3.5, color=line.get_color(), label=label)
            ax2.fill_between(x, q1, q3, color=line.get_color(), alpha=0.2, lw=0)
    for ax in (ax1, ax2):
        ax.set_xscale("log")
        ax.set_xlabel(r"rod volume fraction $\phi = N \pi (D/2)^2 L / V$")
        ax.grid(alpha=0.3)
    ax1.set_ylim(-0.03, 1.03)
    ax1.set_ylabel("fraction of runs short-circuited by t$_{max}$")
    ax1.set_title("Short circuit against volume fraction (95 % Wilson intervals)", fontsize=10)
    ax2.set_ylabel("short-circuit time (t$_0$)")
    ax2.set_title("Median short-circuit time, band from the first to the third quartile", fontsize=10)
    ax1.legend(fontsize=8, loc="center right")  # between the curves (1 and 0 at the dense end)
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)


def compare_main(ap, args):
    if not args.plot:
        ap.error("--compare needs --plot PNG")
    if args.scenario or args.densities or args.fractions or args.counts or args.seeds or args.t_max:
        ap.error("--compare draws earlier results only: give no scenario, densities, --seeds or --t-max")
    from selfas_graph.cli.paths import same_file

    for name in args.compare:
        if same_file(args.plot, name):
            ap.error(f"--plot {args.plot} is the input {name}; give another name (it would be destroyed)")
    results = []
    for name in args.compare:
        try:
            with open(name) as fh:
                res = json.load(fh)
            res["densities"], res["seeds"], res["t_max"]  # noqa: B018 - the keys a result file must have
        except (OSError, ValueError, KeyError, TypeError) as exc:
            ap.error(f"{name}: not a result file of this tool ({exc.__class__.__name__}: {exc})")
        results.append(res)
    plot_compare(results, args.plot)
    print(f"wrote {args.plot}")
    return 0


def main(argv=None):
    ap = build_parser()
    args = ap.parse_args(argv)
    if args.plot:  # before any run, not after an hour of them
        try:
            import matplotlib  # noqa: F401
        except ImportError:
            ap.error('--plot needs matplotlib: pip install "selfas-graph[plot]"')
    if args.compare:
        return compare_main(ap, args)
    missing = [
        name
        for name, v in (
            ("SCENARIO", args.scenario),
            ("--seeds", args.seeds),
            ("--t-max", args.t_max),
            ("--densities, --fractions or --counts", args.densities or args.fractions or args.counts),
        )
        if not v
    ]
    if missing:
        ap.error("required: " + ", ".join(missing) + " (or --compare JSON ... --plot PNG)")
    if args.fields == "off":
        args.overrides = [f"forces.{name}=false" for name in FIELD_TERMS] + list(args.overrides)
    base, points, skipped, meta = plan(ap, args)
    if not points:
        ap.error("no density left to run (every one was skipped, see above)")
    from selfas_graph import __version__
    from selfas_graph.cli.main import interrupted_code
    from selfas_graph.provenance import cpu_model, numba_target, source_commit

    seeds = [meta["first_seed"] + k for k in range(args.seeds)]
    tasks = [
        {
            "text": base.text,
            "path": str(base.path),
            "count": pt["count"],
            "seed": s,
            "echo": ("count",),
            "overrides": [*args.overrides, f"scenario.seed={s}", f"rods.count={pt['count']}"],
            "t_max": args.t_max,
            "chunk": args.chunk,
        }
        for pt in points
        for s in seeds
    ]
    print(
        f"{len(points)} densities x {len(seeds)} seeds = {len(tasks)} runs to t = {args.t_max:g} "
        f"on {args.workers} worker(s)",
        flush=True,
    )
    done = [0]

    def report(r):
        done[0] += 1
        if r["status"] == "short_circuit":
            what = f"short circuit at t = {r['time']:.4g}"
        elif r["status"] == "censored":
            what = f"no short circuit by t = {r['t_end']:.4g}"
        else:
            what = f"{r['status']} at t = {r['t_end']:.4g}: {r['message']}"
        print(
            f"[{done[0]}/{len(tasks)}] {r['count']} rods, seed {r['seed']}: {what} ({r['wall_seconds']:.1f} s)",
            flush=True,
        )

    t0 = time.perf_counter()
    runs = run_all(tasks, args.workers, report)
    runs.sort(key=lambda r: (r["count"], r["seed"]))
    result = {
        "scenario": str(args.scenario),
        "scenario_name": base.params.scenario.name,
        "version": __version__,
        "overrides": list(args.overrides),
        "fields": args.fields,
        "t_max": args.t_max,
        "chunk": args.chunk,
        "seeds": seeds,
        "workers": args.workers,
        "threads_per_run": 1,
        **meta,
        "censoring": "status 'censored': no short circuit by t_max (censored at t_end = t_max); 'failed': a numerical "
        "failure at t_end (censored there, and left out of fraction and fraction_ci95, which are over the "
        "'decided' runs); 'unplaceable' and 'error' runs are left out of the statistics. q25/median/q75 are Kaplan-Meier quantiles, null when not reached by t_max; "
        "km lists (t, F(t)) at every short-circuit time",
        "densities": [summarise(pt, [r for r in runs if r["count"] == pt["count"]]) for pt in points],
        "skipped": skipped,
        "runs": runs,
        "wall_seconds": time.perf_counter() - t0,
        "commit": source_commit(),
        "cpu_model": cpu_model(),
        "numba_cpu": "{cpu_name} ({widest})".format(**numba_target()),
    }
    print_table(result)
    if args.output:
        with open(args.output, "w") as fh:
            json.dump(result, fh, indent=1, allow_nan=False)
        print(f"wrote {args.output}")
    if args.plot:
        plot(result, args.plot)
        print(f"wrote {args.plot}")
    if any(r["status"] == "interrupted" for r in runs):
        return interrupted_code(runs)  # 128 + the signal's number, as simulate and ensemble exit
    return 1 if any(r["status"] == "error" for r in runs) else 0


if __name__ == "__main__":
    sys.exit(main())
