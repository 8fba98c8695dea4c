"""Speed-accuracy trade of every accuracy knob of a scene, against a tight reference run.

Usage: selfas-graph bench tradeoff SCENARIO [--from T0] [--checkpoint FILE] [--t 0.5] [--knob NAME ...]
       [--set KEY=VALUE ...] [--json OUT] [--plot OUT.png]

The scene is first run at its defaults to ``--from T0`` (e.g. past the short circuit, so
that the current knobs matter), or read from ``--checkpoint`` with the overrides its run was made
with (``simulate --set``; ``--set`` comes after them); every run then branches from that state with a
fresh Adams-Bashforth start. For each knob, the scene is run for a further time ``--t`` at several
settings around its default, one knob changed at a time, and compared with that knob's
reference: the defaults with only this knob at its tightest setting, so that each row
shows the error of its own knob (all measured in this run):

- cost: milliseconds per step and per unit of simulated time (the quantity users pay), timed after the
  branch's start (its RK4 steps with every sum and its first builds: whole periods of the slowest sum,
  at most half the branch), which would otherwise weigh on a coarse dt or a short ``--t``;
- error: the largest position difference from the reference at time t (before the
  dynamics' own divergence amplifies it much, t should be short) and the median over tips
  (one tip on the edge of an event can make the largest alone), the largest bond
  error, the change of the energy balance |E - E0 - W| over the branch relative to the
  energy turned over, and the contact events that differ from the reference (formed or
  missed, by tip pair).

Knobs: integrator.dt, integrator.brake (explicit/split), integrator.restart_on_events
(against a run at dt = 1.25e-4), forces.yukawa.tolerance, forces.yukawa.core_radius (against
the bare law: what the core changes), forces.current_lorentz.quadrature_points,
integrator.bond_force (exact/paper), integrator.position_projection, integrator.slow_every
(multiple time stepping, against evaluating every force every step), integrator.fast_range and
integrator.current_every (with ``--set integrator.slow_every=K``; also against no splitting), the tree's
forces.tip_magnetic.opening_angle, group_size, order and leaf_size (against
the direct sum; only
where the scene takes the tree, e.g. ``--set forces.tip_magnetic.method=tree``) and the
``precision`` of forces.tip_magnetic, forces.yukawa, forces.current_field and
forces.current_lorentz (mixed against float64), the ``method`` of forces.current_field and
forces.current_lorentz (the tree of the rod currents against the direct sum) and their
``opening_angle``, ``leaf_size``, ``group_size`` and ``order`` (against the direct sum; only where the scene
takes the tree). Prints a markdown table and writes JSON and a
plot of error against cost, one curve per knob.
"""

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from selfas_graph import NumericalFailure, Simulation, load_scenario
from selfas_graph.io.checkpoint import CheckpointError, read_checkpoint
from selfas_graph.io.scenario import ScenarioError
from selfas_graph.model import events as ev
from selfas_graph.model.integrator import same_time_step
from selfas_graph.provenance import source_commit

from .peer import machine, machine_line

#: the reference of the multiple-time-stepping knobs: every force every step
NO_SPLITTING = {"integrator.slow_every": 1, "integrator.current_every": 0}

#: knob -> (settings to sweep, the reference run's overrides); a setting the scene cannot use
#: (e.g. a Yukawa tolerance without Yukawa) is skipped. Most references put the knob itself at
#: its tightest setting; knobs without a "tightest" setting (the AB4 restart at events) are
#: compared with a run at a tight time step, so the row shows which setting is closer to it.
KNOBS = {
    "integrator.dt": ([2e-3, 1e-3, 5e-4, 2.5e-4], {"integrator.dt": 1.25e-4}),
    "integrator.brake": (["explicit", "split"], {"integrator.brake": "explicit"}),
    "integrator.restart_on_events": ([False, True], {"integrator.dt": 1.25e-4}),
    "forces.yukawa.tolerance": ([1e-2, 1e-3, 1e-4, 1e-5], {"forces.yukawa.tolerance": 1e-7}),
    "forces.yukawa.core_radius": ([0.06, 0.03, 0.0], {"forces.yukawa.core_radius": 0.0}),
    "forces.current_lorentz.quadrature_points": ([1, 2, 4, 8], {"forces.current_lorentz.quadrature_points": 16}),
    "integrator.bond_force": (["paper", "exact"], {"integrator.bond_force": "exact"}),
    "integrator.position_projection": ([False, True], {"integrator.position_projection": True}),
    "integrator.slow_every": ([1, 2, 4, 8, 16, 24, 32], NO_SPLITTING),
    # the tip-tip sum: the tree (at its near-field precision, --set forces.tip_magnetic.precision=...)
    # against the exact direct sum
    "forces.tip_magnetic.method": (["direct", "tree"], {"forces.tip_magnetic.method": "direct"}),
    # the tree's knobs, where the scene takes the tree: each against the exact direct sum
    "forces.tip_magnetic.opening_angle": ([0.3, 0.4, 0.475, 0.55, 0.65], {"forces.tip_magnetic.method": "direct"}),
    "forces.tip_magnetic.group_size": ([128, 512, 1024, 4096], {"forces.tip_magnetic.method": "direct"}),
    "forces.tip_magnetic.order": ([2, 3, 4], {"forces.tip_magnetic.method": "direct"}),
    "forces.tip_magnetic.leaf_size": ([16, 32, 64, 128, 256], {"forces.tip_magnetic.method": "direct"}),
    # float32 arithmetic against float64, with everything else as the scene has it
    "forces.tip_magnetic.precision": (["float64", "mixed"], {"forces.tip_magnetic.precision": "float64"}),
    "forces.yukawa.precision": (["float64", "mixed"], {"forces.yukawa.precision": "float64"}),
    "forces.current_field.precision": (["float64", "mixed"], {"forces.current_field.precision": "float64"}),
    "forces.current_lorentz.precision": (["float64", "mixed"], {"forces.current_lorentz.precision": "float64"}),
    # the rod currents' field by the tree against the direct sum; its opening angle where the scene
    # takes the tree (--set forces.current_field.method=tree --set forces.current_lorentz.method=tree)
    "forces.current_field.method": (["direct", "tree"], {"forces.current_field.method": "direct"}),
    "forces.current_lorentz.method": (["direct", "tree"], {"forces.current_lorentz.method": "direct"}),
    "forces.current_field.opening_angle": ([0.3, 0.4, 0.5, 0.6, 0.7], {"forces.current_field.method": "direct"}),
    "forces.current_lorentz.opening_angle": ([0.3, 0.4, 0.5, 0.6, 0.7], {"forces.current_lorentz.method": "direct"}),
    "forces.current_field.leaf_size": ([16, 32, 64, 128, 256], {"forces.current_field.method": "direct"}),
    "forces.current_field.group_size": ([32, 64, 128, 256, 512], {"forces.current_field.method": "direct"}),
    "forces.current_field.order": ([2, 3], {"forces.current_field.method": "direct"}),
    "forces.current_lorentz.leaf_size": ([16, 32, 64, 128, 256], {"forces.current_lorentz.method": "direct"}),
    "forces.current_lorentz.group_size": ([32, 64, 128, 256, 512], {"forces.current_lorentz.method": "direct"}),
    "forces.current_lorentz.order": ([2, 3], {"forces.current_lorentz.method": "direct"}),
    "integrator.slow_extrapolation": ([False, True], NO_SPLITTING),
    # only with slow_every > 1 in the base (--set integrator.slow_every=8): each range against no splitting
    "integrator.fast_range": ([2.0, 3.0, 4.0, 6.0, 8.0, 12.0], NO_SPLITTING),
    # case (ii): the line charge's quadrature against a converged one; held with the slow sums or
    # not, each against no splitting (the row at false is the other slow terms' own error)
    "forces.external_dipole.quadrature_points": (
        [8, 12, 16, 24, 32],
        {"forces.external_dipole.quadrature_points": 128},
    ),
    "forces.external_dipole.line_charge_slow": ([False, True], NO_SPLITTING),
    # the rod-current terms every M steps (0: with the other slow sums), each against no splitting: the
    # row at 0 is the other slow terms' own error
    "integrator.current_every": ([0, 32, 48, 64], NO_SPLITTING),
    # case (ii): how far a filament contact may move along z before the circuit is solved again, against
    # a solve at nearly every move
    "circuit.height_tolerance": ([0.001, 0.003, 0.01, 0.03, 0.1], {"circuit.height_tolerance": 1e-5}),
    # a speed knob alone: the lists hold every pair within the cut-off at any skin, so the rows differ from
    # the default's by the order of the sums only
    "neighbours.skin": ([0.15, 0.3, 0.6, 1.0], {"neighbours.skin": 0.3}),
}


def _toml(value):
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return f'"{value}"'
    return repr(value)


def _overrides(values):
    return [f"{key}={_toml(value)}" for key, value in values.items()]


#: knobs of the tip-tip tree: they change nothing where the scene sums the tip pairs directly
TREE_KNOBS = tuple(f"forces.tip_magnetic.{k}" for k in ("opening_angle", "group_size", "order", "leaf_size"))
#: knobs of the rod currents' tree (of either current term): they change nothing where the term sums directly
CURRENT_TREE_KNOBS = ("opening_angle", "leaf_size", "group_size", "order")
#: knobs of the tree itself: where both current terms take the tree, one tree serves both only while these
#: agree, so they are swept for both terms at once (term 9's row; term 10's would repeat it)
SHARED_TREE_KNOBS = ("leaf_size", "order")


def _both_current_trees(scenario) -> bool:
    f = scenario.params.forces
    return all(t is not None and t.method == "tree" for t in (f.current_field, f.current_lorentz))


def _paired(scenario, knob) -> bool:
    """Whether ``knob``'s rows set both current terms: one of term 9's :data:`SHARED_TREE_KNOBS` where both
    terms take the tree (a value for one term alone would cost a second tree,
    :func:`~selfas_graph.model.terms.currents.two_trees_note`)."""
    name = knob.rsplit(".", 1)[1]
    return knob.startswith("forces.current_field.") and name in SHARED_TREE_KNOBS and _both_current_trees(scenario)


def _reference(scenario, knob) -> dict:
    """The reference of ``knob``'s rows: :data:`KNOBS`'s, and term 10 on the direct sum too where the rows
    set both current terms (:func:`_paired`), so that they measure both trees against exact sums."""
    return {**KNOBS[knob][1], **({"forces.current_lorentz.method": "direct"} if _paired(scenario, knob) else {})}


def _setting(scenario, knob, value) -> list[str]:
    """The overrides of one row: ``knob=value``, and the same for term 10 where :func:`_paired`."""
    out = [f"{knob}={_toml(value)}"]
    if _paired(scenario, knob):
        out.append(f"forces.current_lorentz.{knob.rsplit('.', 1)[1]}={_toml(value)}")
    return out


def _applicable(scenario, knob):
    if knob in ("integrator.fast_range", "forces.external_dipole.line_charge_slow", "integrator.current_every") and (
        scenario.params.integrator.slow_every == 1
    ):
        return False  # they split nothing without multiple time stepping
    f = scenario.params.forces
    if knob == "integrator.current_every" and f.current_field is None and f.current_lorentz is None:
        return False
    if knob.startswith("forces.current_") and knob.rsplit(".", 1)[1] in CURRENT_TREE_KNOBS:
        term = getattr(f, knob.split(".")[1])
        if term is None or term.method != "tree":
            return False
        if knob.startswith("forces.current_lorentz.") and knob.rsplit(".", 1)[1] in SHARED_TREE_KNOBS:
            return not _both_current_trees(scenario)  # swept with term 9's, for both terms
    if knob in TREE_KNOBS:
        tm = scenario.params.forces.tip_magnetic
        if tm is None or not (
            tm.method == "tree" or (tm.method == "auto" and scenario.params.rods.count >= tm.tree_above)
        ):
            return False
    node = scenario.params
    for part in knob.split(".")[:-1]:
        node = getattr(node, part, None)
        if node is None:
            return False
    return True


def checkpoint_overrides(meta) -> list[str]:
    """The ``--set KEY=VALUE`` overrides a checkpoint's run was made with (its ``overrides`` record)."""
    return list(json.loads(meta["overrides"]))  # read_checkpoint refuses a file without it


def run_once(path, overrides, duration, snap):
    """One branch from snapshot ``snap`` for ``duration``; positions, new events and cost, or the failure
    (also a setting the scene refuses, e.g. a current_every that its slow_every does not divide)."""
    try:
        sc = load_scenario(path, overrides=overrides)
    except ScenarioError as exc:
        return {"failed": "refused: " + str(exc).splitlines()[-1].strip()}
    # the history was taken with the base dt; a branch at another one starts afresh with RK4
    sim = Simulation.from_snapshot(sc.params, snap, new_dt=True)
    n_old = len(sim.events)
    t_start, step_start = sim.state.time, sim.state.step
    balance0 = sim.observables()["energy_balance"]
    n_steps = sim.steps_for(duration)
    # the branch's start (the RK4 steps with every sum, the first list and tree builds) untimed: whole
    # periods of the slowest sum that cover it, at most half the branch; then the same steps as one run
    ip = sc.params.integrator
    period = max(ip.slow_every, ip.current_every or ip.slow_every)
    warm = min(period * -(-4 // period), n_steps // 2)
    try:
        sim.run(t_end=t_start + warm * sim.dt)
        t0 = time.perf_counter()
        sim.run(t_end=t_start + n_steps * sim.dt)  # run() takes whole steps only
    except NumericalFailure as exc:
        return {"failed": str(exc).split(";")[0]}
    wall = time.perf_counter() - t0
    obs = sim.observables()
    timed = max(sim.state.step - step_start - warm, 1)
    contacts = {(int(r[3]), int(r[4])) for r in sim.events[n_old:] if r[2] == ev.TIP_CONTACT}
    return {
        "position": sim.state.position.copy(),
        "contacts": contacts,
        "ms_per_step": 1e3 * wall / timed,
        "s_per_time": wall / (timed * sim.dt),
        "bond_error": sim.max_bond_error,
        "energy_balance": abs(obs["energy_balance"] - balance0) / max(sim.energy_scale(obs), 1e-300),
    }


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenario")
    ap.add_argument("--from", dest="t0", type=float, default=0.0, help="branch all runs from this time (default 0)")
    ap.add_argument(
        "--checkpoint",
        help="branch from this checkpoint file (e.g. a long run past the short circuit) "
        "instead of a fresh start; --from then runs on from its time",
    )
    ap.add_argument("--t", type=float, default=0.5, help="simulated time of each run (default 0.5)")
    ap.add_argument(
        "--knob",
        nargs="+",
        choices=sorted(KNOBS),
        metavar="KNOB",
        help=f"only these knobs (default: all that apply), of: {', '.join(sorted(KNOBS))}",
    )
    ap.add_argument(
        "--set",
        dest="base_set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="change the scene's defaults for every run, e.g. --set integrator.brake=split (repeatable)",
    )
    ap.add_argument("--json", help="write all results to this JSON file")
    ap.add_argument("--plot", help="write the error-cost plot to this PNG file")
    args = ap.parse_args(argv)
    if not args.t > 0:
        ap.error("--t must be positive")
    snap0 = None
    if args.checkpoint:
        try:
            snap0, meta = read_checkpoint(args.checkpoint)
        except CheckpointError as exc:
            ap.error(f"--checkpoint: {exc}")
        # the run's own overrides first (a checkpoint of `simulate --set circuit.delta_J0=2.23` branches
        # at that bias, not at the scene file's), then --set
        own = checkpoint_overrides(meta)
        if own:
            print(f"the checkpoint's run was made with --set {' '.join(own)}: every run takes them", flush=True)
        args.base_set = own + args.base_set
    try:
        base = load_scenario(args.scenario, overrides=args.base_set)
    except ScenarioError as exc:
        ap.error(str(exc))
    knobs = [k for k in (args.knob or KNOBS) if _applicable(base, k)]
    if snap0 is not None:
        # a base --set integrator.dt: the checkpoint continued at that time step, its history forgotten
        sim0 = Simulation.from_snapshot(base.params, snap0, new_dt=not same_time_step(snap0, base.params.integrator.dt))
    else:
        sim0 = Simulation.from_scenario(base)
    if args.t0 > sim0.state.time:
        sim0.run(t_end=sim0.state.time + sim0.steps_for(args.t0 - sim0.state.time) * sim0.dt)
    snap = sim0.snapshot()
    # warm-up: compile the scene's kernels before timing
    run_once(args.scenario, args.base_set, min(args.t, 0.01), snap)
    print(machine_line(), flush=True)
    print(
        f"branch point t = {sim0.state.time:g} ({len(sim0.force_field.active_rod)} rods carry current); "
        f"each run {args.t} t0; each knob against the defaults with that knob at its tightest",
        flush=True,
    )
    rows = []
    refs = {}
    for knob in knobs:
        reference = args.base_set + _overrides(_reference(base, knob))
        run_once(args.scenario, reference, min(args.t, 0.01), snap)
        ref = refs[knob] = run_once(args.scenario, reference, args.t, snap)
        if "failed" in ref:
            if ref["failed"].startswith("refused: "):  # a reference the scene refuses with the base --set
                print(f"{knob}: not measured, its reference run is {ref['failed']}", flush=True)
                del refs[knob]
                continue
            sys.exit(f"the reference run of {knob} failed: {ref['failed']}")
        default = eval(f"base.params.{knob}")  # noqa: S307 - a dotted attribute path of our own
        for value in KNOBS[knob][0]:
            setting = args.base_set + _setting(base, knob, value)
            run_once(args.scenario, setting, min(args.t, 0.01), snap)  # compile a setting's own kernels untimed
            res = run_once(args.scenario, setting, args.t, snap)
            row = {
                "knob": knob + (" (both current terms)" if _paired(base, knob) else ""),
                "value": value,
                "default": value == default,
            }
            if "failed" in res:
                row["failed"] = res["failed"]
            else:
                diff = np.abs(res["position"] - ref["position"]).max(axis=1)
                row.update(
                    ms_per_step=res["ms_per_step"],
                    s_per_time=res["s_per_time"],
                    position_error=float(diff.max()),
                    position_error_median=float(np.median(diff)),
                    bond_error=res["bond_error"],
                    energy_balance=res["energy_balance"],
                    events_missed=len(ref["contacts"] - res["contacts"]),
                    events_extra=len(res["contacts"] - ref["contacts"]),
                )
            rows.append(row)
            print(_fmt_row(row), flush=True)
    print(
        "\n| knob | setting | ms/step | s per t0 | position error (largest) | position error (median tip) "
        "| bond error | energy balance | contacts missed/extra |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(_fmt_row(r, markdown=True))
    print(
        "\nreferences (the defaults with one knob at its tightest): "
        + "; ".join(
            f"{k}: {_overrides(_reference(base, k))} at {r['ms_per_step']:.2f} ms/step" for k, r in refs.items()
        )
    )
    if args.json:
        Path(args.json).write_text(
            json.dumps(
                {
                    "scenario": args.scenario,
                    "machine": machine(),
                    "commit": source_commit(),
                    "from": args.t0,
                    "t": args.t,
                    "references": {k: _reference(base, k) for k in refs},
                    "rows": rows,
                },
                indent=1,
            )
        )
    if args.plot:
        _plot(rows, args.plot)


def _fmt_row(r, markdown=False):
    setting = f"{r['value']}" + (" (default)" if r["default"] else "")
    if "failed" in r:
        cells = [r["knob"], setting, "failed: " + r["failed"], "", "", "", "", "", ""]
    else:
        cells = [
            r["knob"],
            setting,
            f"{r['ms_per_step']:.2f}",
            f"{r['s_per_time']:.1f}",
            f"{r['position_error']:.2e}",
            f"{r['position_error_median']:.1e}",
            f"{r['bond_error']:.1e}",
            f"{r['energy_balance']:.1e}",
            f"{r['events_missed']}/{r['events_extra']}",
        ]
    return ("| " + " | ".join(cells) + " |") if markdown else "  ".join(cells)


def _plot(rows, out):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 5))
    for knob in dict.fromkeys(r["knob"] for r in rows):
        pts = [
            (r["s_per_time"], max(r["position_error"], 1e-16), r["value"])
            for r in rows
            if r["knob"] == knob and "failed" not in r
        ]
        if pts:
            x, y, labels = zip(*pts)
            ax.loglog(x, y, "o-", label=knob)
            for xi, yi, lab in pts:
                ax.annotate(str(lab), (xi, yi), fontsize=7, xytext=(3, 3), textcoords="offset points")
    ax.set_xlabel("cost: wall seconds per unit of simulated time")
    ax.set_ylabel("largest position difference from the reference")
    ax.set_title("speed-accuracy trade, one curve per knob")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out, dpi=120)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
