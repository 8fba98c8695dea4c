"""A scene of 10^5-10^6 rods on one node: peak memory, the tip tree's stages and whole steps.

Usage: selfas-graph bench million [--rods 250000 500000 1000000] [--steps 4] [--ranks 16 64 256]
                                  [--latency 2e-6] [--bandwidth 1e10] [--energy-check RODS]
                                  [--carrying 0.5] [--set KEY=VALUE ...]
       selfas-graph bench million --checkpoint RUN.checkpoint.h5 [...]

The Fig. 2 scene scaled as in selfas_graph/bench/step.py (``scene``: the box grows in x and y, the
density stays the paper's), every term every step (``integrator.slow_every=1``) and the tip-tip
tree. For each size, in one process (sizes in increasing order, so that the peak resident memory
``ru_maxrss`` after a size is that size's): the seconds to place the rods and build the simulation,
the tree's stages once on the starting positions (``plan_tip_tree``: keys, sort and cells, which
every MPI rank repeats; ``fill_cells``: the moments, which the ranks share; one evaluation, shared),
the tip-tip energy of a frame by the direct sum (estimated from 2000 rows, or whole below
``--energy-check`` rods) and by the tree (the energy of every frame from
``forces.tip_magnetic.energy_tree_above`` rods on), then ``--steps`` steps timed one by one (the first three are the RK4 start, four evaluations each;
AB4 steps from the fourth) with the seconds of each force term (``Simulation(timing=True)``) and the
rest of the step: integration, constraint, contacts and events, neighbour lists, which every rank
repeats (docs/performance.md 'Beyond one node'). Wall clock; run it niced on a quiet machine with
``NUMBA_NUM_THREADS=1`` for the one-thread figures.

``--carrying F`` gives a fraction F of the rods, drawn at random, currents uniform in (-3, 3) J0 (the
gas of ``selfas-graph bench current_tree``), set again before every timed step: the scene has no
path between its electrodes, so its circuit would zero them at its next event. The current terms
then take their share of each step; ``--set forces.current_field.method=tree --set
forces.current_lorentz.method=tree`` times them by the tree of the rod currents.

``--checkpoint`` compares instead, at the states runs left, the tip-tip energy by the tree with the
direct sum, against the run's own energy balance.
"""

import argparse
import math
import resource
import time
from pathlib import Path

import numpy as np

from selfas_graph import Simulation
from selfas_graph.kernels import tree as ktree
from selfas_graph.kernels.tips import tip_tip_energy
from selfas_graph.parallel import world

from .peer import machine_line
from .step import scene

ROOT = Path(__file__).resolve().parents[2]
#: the terms whose rows the MPI ranks split (parallel.py RowBlocks); every other term runs whole on every rank
SPLIT_TERMS = ("tip_magnetic", "yukawa", "current_field", "current_lorentz")


def peak_mb():
    """The process's peak resident memory so far, MB (Linux reports ru_maxrss in kB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def tree_stages(sim):
    """Seconds of the tip tree's stages on the current positions: plan, fill (moments), finish, one evaluation."""
    tm = sim.params.forces.tip_magnetic
    x, y, z = (np.ascontiguousarray(sim.state.position[:, d]) for d in range(3))
    q = sim.force_field.tip_charge
    t = [time.perf_counter()]
    tree = ktree.plan_tip_tree(x, y, z, q, group_size=tm.group_size, order=tm.order)
    t.append(time.perf_counter())
    ktree.fill_cells(tree, 0, tree.start.shape[0])
    t.append(time.perf_counter())
    tree = ktree.finish_tip_tree(tree)
    t.append(time.perf_counter())
    out = np.empty((x.shape[0], 3))
    ktree.evaluate_tip_tree(
        tree, sim.params.rods.rstar, sim.params.rods.tip_stiffness, tm.opening_angle, out, precision=tm.precision
    )
    t.append(time.perf_counter())
    s = np.diff(t)
    return {"plan": s[0], "fill": s[1], "finish": s[2], "evaluate": s[3], "cells": int(tree.start.shape[0])}


def current_tree_stages(sim):
    """Seconds of the stages of an evaluation by the tree of the rod currents on the current positions
    and currents: what every MPI rank repeats, the tree's plan (its rods sorted, its cells cut) and the
    sorts of the points of term 9 (the tips) and term 10 (its quadrature points, with their placing),
    and the moments of its cells (``fill``), which the ranks share as they share the walks."""
    from selfas_graph.kernels import currenttree as kt
    from selfas_graph.kernels import lorentz as kl

    position = sim.state.position
    current = sim.force_field.currents.current
    active = np.flatnonzero(current != 0.0).astype(np.int64)
    t = [time.perf_counter()]
    tree = kt.plan_current_tree(position, active, current)
    t.append(time.perf_counter())
    kt.fill_current_cells(tree, 0, tree.start.shape[0])
    t.append(time.perf_counter())
    kt.sort_targets(position, np.arange(position.shape[0], dtype=np.int64) // 2)
    t.append(time.perf_counter())
    nodes, _ = kl.gauss_legendre_01(sim.params.forces.current_lorentz.quadrature_points)
    points = np.empty((len(active) * len(nodes), 3))
    kl.quadrature_points(position, active, nodes, points)
    kt.sort_targets(points, np.repeat(active, len(nodes)))
    t.append(time.perf_counter())
    s = np.diff(t)
    return {"plan": s[0], "fill": s[1], "sort_tips": s[2], "sort_points": s[3]}


def tip_energy(sim, rows=2000, full_below=0):
    """The tip-tip energy of the starting positions, as the energy reference and every frame pay it:
    ``direct_s``, seconds of the direct sum (``kernels/tips.py::tip_tip_energy``) estimated from ``rows``
    of its rows, or timed whole below ``full_below`` rods; ``tree_s``, seconds of the tree's
    (``kernels/tree.py::tip_tree_energy``, build included); ``difference``, tree less direct in units
    of the sum of |row| of the direct sum (where it ran whole, else NaN)."""
    x, y, z = (np.ascontiguousarray(sim.state.position[:, d]) for d in range(3))
    n = x.shape[0]
    q, rstar, kappa = sim.force_field.tip_charge, sim.params.rods.rstar, sim.params.rods.tip_stiffness
    tm = sim.params.forces.tip_magnetic
    e = np.empty(n)
    full = sim.state.n_rods < full_below
    rows = n if full else min(rows, n)
    t0 = time.perf_counter()
    tip_tip_energy(x, y, z, q, rstar, kappa, 0, rows, e)
    direct_s = (time.perf_counter() - t0) * (1.0 if full else 0.5 * n / rows)  # row k sums the n - k later tips
    t0 = time.perf_counter()
    tree = ktree.build_tip_tree(x, y, z, q, group_size=tm.group_size, order=tm.order)
    f = ktree.tip_tree_energy(tree, rstar, kappa, tm.opening_angle, np.empty(n))
    tree_s = time.perf_counter() - t0
    difference = (f.sum() - e.sum()) / np.abs(e).sum() if full else math.nan
    return {"direct_s": direct_s, "tree_s": tree_s, "difference": float(difference), "energy": float(f.sum())}


def energy_at_checkpoint(path):
    """The tip-tip energy of a run's checkpoint by the direct sum and by the tree (the term's own
    ``energy``, the threshold ``energy_tree_above`` set either way): both values and seconds (best of
    3), and the run's energy balance and its scale there (``Simulation.energy_scale``; the balance
    with the direct energy, as the run, below 20 000 rods, had it), against which the difference counts."""
    from .profile import load_state

    out = {}
    for how, above in (("direct", 2**62), ("tree", 1)):
        args = argparse.Namespace(checkpoint=path, extra=[f"forces.tip_magnetic.energy_tree_above={above}"])
        sim, origin = load_state(args)
        term = next(t for t in sim.force_field.terms if t.name == "tip_magnetic")
        seconds = []
        for _ in range(4):  # the first call compiles
            t0 = time.perf_counter()
            e = term.energy(sim.force_field.context)["tip_magnetic"]
            seconds.append(time.perf_counter() - t0)
        out[how] = {"energy": e, "seconds": min(seconds[1:])}
        if how == "direct":
            obs = sim.observables()
            out.update(balance=obs["energy_balance"], scale=sim.energy_scale(obs))
    out.update(origin=origin, rods=sim.state.n_rods)
    return out


def rod_currents(n, carrying, seed=1):
    """Currents uniform in (-3, 3) J0 on a fraction ``carrying`` of ``n`` rods drawn at random (the
    synthetic gas of ``selfas-graph bench current_tree``), zero on the others."""
    rng = np.random.default_rng(seed)
    return np.where(rng.random(n) < carrying, rng.uniform(-3, 3, n), 0.0)


def measure(path, n, steps, extra, full_below=0, carrying=0.0):
    over = [*extra, "integrator.slow_every=1", "forces.tip_magnetic.method=tree"]
    t0 = time.perf_counter()
    sim = Simulation.from_scenario(scene(path, n, over), timing=True, comm=world)
    current = rod_currents(n, carrying) if carrying > 0.0 else None
    row = {"rods": n, "build_s": time.perf_counter() - t0, "mb_after_build": peak_mb()}
    row["tree"] = tree_stages(sim)
    row["energy"] = tip_energy(sim, full_below=full_below)
    # the energy reference of the balance (timed above) taken as 0 here, so that the first step is a step
    sim.observe.energy0 = 0.0
    ff = sim.force_field
    row["steps"] = []
    for _ in range(steps):
        if current is not None:
            # before every step: the scene's circuit, with no path between the electrodes, zeroes them
            # at its next event (from the next evaluation on)
            ff.set_currents(current)
        ff.seconds.clear()
        t0, c0 = time.perf_counter(), time.process_time()
        sim.step(1)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        terms = {k: float(v) for k, v in ff.seconds.items()}
        split = sum(v for k, v in terms.items() if k in SPLIT_TERMS)
        row["steps"].append({"wall": wall, "cpu": cpu, "split_terms": split, "repeated": wall - split, "terms": terms})
    row["peak_mb"] = peak_mb()
    row["carrying"] = 0 if current is None else int(np.count_nonzero(current))
    fp = sim.params.forces
    on_tree = [
        n
        for n in ("current_field", "current_lorentz")
        if getattr(fp, n) is not None and getattr(fp, n).method == "tree"
    ]
    if current is not None and on_tree:
        ff.set_currents(current)
        row["current_tree"] = current_tree_stages(sim)
        row["current_tree_terms"] = on_tree
    return row


def bytes_per_rod(cells_per_rod, channels=1):
    """Bytes gathered per rod and evaluation (all ranks' rows): the tree's cell moments (box 6, centre 3,
    radius 1, moments 25 doubles per cell), its tip forces (2 tips x 3 doubles) and ``channels`` more tip
    channels (the Yukawa term; 3 with the two current terms, and the fraction of rods carrying current
    more for term 10's field at 2 points of each by the tree of the currents)."""
    return 280.0 * cells_per_rod + 48.0 + 48.0 * channels


def model(t_par, t_rep, n, per_rod, ranks, alpha=2e-6, beta=1e10, collectives=6):
    """Modelled seconds per step on ``ranks`` ranks: ``t_par / P + t_rep + T_comm`` with
    T_comm = collectives ceil(log2 P) alpha + (P - 1) / P n per_rod / beta (Allgatherv), and the efficiency."""
    comm = (
        0.0
        if ranks == 1
        else collectives * math.ceil(math.log2(ranks)) * alpha + (ranks - 1) / ranks * n * per_rod / beta
    )
    t = t_par / ranks + t_rep + comm
    return t, comm, (t_par + t_rep) / (ranks * t)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default=str(ROOT / "scenarios" / "fig2.toml"))
    ap.add_argument("--rods", type=int, nargs="+", default=[250000, 500000, 1000000])
    ap.add_argument("--steps", type=int, default=4, help="steps timed one by one (3 RK4 steps, then AB4)")
    ap.add_argument("--set", dest="extra", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument(
        "--carrying",
        type=float,
        default=0.0,
        help="fraction of the rods carrying current (uniform in (-3, 3) J0, drawn at random; 0: none)",
    )
    ap.add_argument("--ranks", type=int, nargs="+", default=[16, 64, 256], help="ranks of the modelled step")
    ap.add_argument("--latency", type=float, default=2e-6, help="seconds per message of the modelled network")
    ap.add_argument("--bandwidth", type=float, default=1e10, help="bytes per second of the modelled network")
    ap.add_argument(
        "--energy-check",
        type=int,
        default=0,
        metavar="RODS",
        help="below this many rods also sum the direct energy whole and print the tree energy's difference from it",
    )
    ap.add_argument(
        "--checkpoint",
        nargs="+",
        default=[],
        help="only compare the tip-tip energy by the tree with the direct sum at these runs' checkpoints",
    )
    args = ap.parse_args(argv)
    if not 0.0 <= args.carrying <= 1.0:
        ap.error("--carrying: a fraction in [0, 1]")
    say = print if world.rank == 0 else (lambda *a, **k: None)
    if args.checkpoint:
        say(machine_line())
        rows = [energy_at_checkpoint(path) for path in args.checkpoint]
        for r in rows:
            d, t = r["direct"], r["tree"]
            diff = t["energy"] - d["energy"]
            say(
                f"{r['origin']}: {r['rods']} rods; tip-tip energy direct {d['energy']:.6f} ({1e3 * d['seconds']:.1f} ms), "
                f"tree {t['energy']:.6f} ({1e3 * t['seconds']:.1f} ms); tree less direct {diff:.3e}: "
                f"{abs(diff) / abs(d['energy']):.1e} of the tip-tip energy, {abs(diff) / r['scale']:.1e} of the energy "
                f"scale {r['scale']:.4e}, where the run's balance is {abs(r['balance']) / r['scale']:.1e} of it"
            )
        return rows
    import numba

    say(machine_line())
    say(f"{world.size} MPI rank(s) x {numba.get_num_threads()} numba threads; {args.scenario}, slow_every=1, tree")
    if args.carrying:
        say(f"a fraction {args.carrying:g} of the rods carrying current, held through the timed steps")
    # compile every kernel (the threaded row kernels from 50 000 rows on)
    measure(args.scenario, 26000, 4, args.extra, carrying=args.carrying)
    rows = []
    for n in sorted(args.rods):
        r = measure(args.scenario, n, args.steps, args.extra, args.energy_check, args.carrying)
        rows.append(r)
        tr, en = r["tree"], r["energy"]
        how = "whole" if math.isfinite(en["difference"]) else "from 2000 rows"
        check = f", tree less direct {en['difference']:.1e} of the sum of |row|" if how == "whole" else ""
        say(
            f"{n} rods: build {r['build_s']:.1f} s, peak {r['mb_after_build']:.0f} MB after build, "
            f"{r['peak_mb']:.0f} MB after the steps; tree ({tr['cells']} cells): plan {tr['plan']:.3f} s, "
            f"moments {tr['fill']:.3f} s, finish {tr['finish']:.3f} s, one evaluation {tr['evaluate']:.3f} s; "
            f"tip-tip energy: direct sum ({how}) {en['direct_s']:.1f} s, tree (build included) "
            f"{en['tree_s']:.2f} s{check}" + (f"; {r['carrying']} rods carrying current" if r["carrying"] else ""),
            flush=True,
        )
        for k, s in enumerate(r["steps"]):
            kind = "RK4" if k < 3 else "AB4"
            terms = ", ".join(f"{a} {b:.3f}" for a, b in sorted(s["terms"].items()) if b > 5e-4)
            say(
                f"  step {k + 1} ({kind}): {s['wall']:.3f} s (CPU {s['cpu']:.3f}), split terms {s['split_terms']:.3f} s, "
                f"the rest (every rank repeats it) {s['repeated']:.3f} s [{terms}]",
                flush=True,
            )
        last = r["steps"][-1]
        repeated = last["repeated"] + tr["plan"] + tr["finish"]  # every rank also plans the tree itself
        ct = r.get("current_tree")
        if ct is not None:
            # and plans the tree of the currents and sorts the points of each term that takes it
            on_tree = r["current_tree_terms"]
            repeated += ct["plan"] + ct["sort_tips"] * ("current_field" in on_tree)
            repeated += ct["sort_points"] * ("current_lorentz" in on_tree)
            say(
                f"  tree of the rod currents: every rank repeats its plan {ct['plan']:.3f} s, the sort of the "
                f"tips {ct['sort_tips']:.3f} s, of term 10's points {ct['sort_points']:.3f} s; the ranks share "
                f"its moments {ct['fill']:.3f} s"
                f" (terms on the tree: {', '.join(on_tree)})",
                flush=True,
            )
        per_rod = bytes_per_rod(tr["cells"] / n, channels=3 + r["carrying"] / n if r["carrying"] else 1)
        cells = []
        for p in args.ranks:
            t, comm, eff = model(last["wall"] - repeated, repeated, n, per_rod, p, args.latency, args.bandwidth)
            cells.append(f"{p} ranks {1e3 * t:.0f} ms (communication {1e3 * comm:.1f}), efficiency {eff:.2f}")
        say(f"  model from the last step ({per_rod:.0f} B gathered per rod): " + "; ".join(cells), flush=True)
    return rows


if __name__ == "__main__":
    main()
