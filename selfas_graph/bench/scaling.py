"""Scaling benchmark: milliseconds per full step of the Fig. 2 scene from 10^3 to 10^5 rods, beside a peer.

Usage: selfas-graph bench scaling [--rods 1200 6000 24000 100000] [--method direct tree]
                                     [--repeat 5] [--no-peer] [--set KEY=VALUE ...] [--json OUT.json]
       selfas-graph bench scaling --plot OUT.png --from-json A.json B.json ...
       mpiexec -n 2 selfas-graph bench scaling ... --no-peer   (force rows split over 2 ranks; rank 0 prints)

For each size the Fig. 2 scene is scaled as in selfas_graph/bench/step.py (the box grows in x and y,
so the density and the electrode gap stay the paper's) and every Fig. 2 term is on, at the
scene's default accuracy. For each way of summing the tip-tip force (``direct``, ``tree``)
it takes warm-up steps (compilation, neighbour lists), then times blocks of steps, ``--repeat``
times, interleaved with blocks of steps of the peer on the same tips (selfas_graph/bench/peer.py:
OpenMM's CPU platform, PME at rc = 6 and tolerance 1e-4, rods as +-q pairs held by a
constraint, as many threads as numba has). Every figure is printed as median [min-max] over the
repeats; the ratio to the peer is the median of the per-repeat ratios ours / peer (each
from a block of ours and the peer's block right after it), so a disturbance of the shared
machine that hits both cancels; the last column is the same ratio of the process's CPU time
per step (both codes on the same threads), which a busy machine disturbs less than the wall
clock (a thread that spins while it waits counts as busy). Beside each tree row: the tree's median and 99th-percentile
relative tip-force error against the direct sum on the same positions (on a random sample of
2000 tips above 2000 rods), and the speed-up over the direct sum measured in the same run.
The header names the CPU and the instruction set numba compiled for (``NUMBA_CPU_NAME=haswell
NUMBA_CPU_FEATURES=`` compiles AVX2 code on any x86 host; the name alone keeps the host's features,
AVX-512 on an AVX-512 host). Without OpenMM the peer is skipped with a note.

``--plot`` draws ms per step against rods on log-log axes from one or more JSON files
written by ``--json`` (e.g. one run on 1 rank and one under ``mpiexec -n 2``), with the
peer's figures of the same runs and an N log N guide.
"""

import argparse
import json
import time
from pathlib import Path

import numpy as np

from selfas_graph import Simulation, load_scenario
from selfas_graph.kernels.tips import tip_tip_direct_rows
from selfas_graph.kernels.tree import tip_tip_tree
from selfas_graph.parallel import world

from .peer import OpenMMPeer, machine, machine_line, summary
from .step import scene

ROOT = Path(__file__).resolve().parents[2]

#: sampled target tips for the tree's error above 2000 rods (the direct rows cost O(sample x N))
SAMPLE = 2000


def tree_error(sim, rng):
    """Median and 99th percentile of |F_tree - F_direct| / |F_direct| over (sampled) tips, with the
    scene's opening angle and near-field precision (``forces.tip_magnetic``)."""
    tm = sim.params.forces.tip_magnetic
    x, y, z = (np.ascontiguousarray(sim.state.position[:, d]) for d in range(3))
    q = sim.force_field.tip_charge
    rstar, kappa = sim.params.rods.rstar, sim.params.rods.tip_stiffness
    n = x.shape[0]
    rows = np.arange(n) if n <= 2 * SAMPLE else np.sort(rng.choice(n, SAMPLE, replace=False))
    direct = np.empty((rows.shape[0], 3))
    tip_tip_direct_rows(x, y, z, q, rstar, kappa, rows.astype(np.int64), direct)
    tree = np.empty((n, 3))
    tip_tip_tree(
        x,
        y,
        z,
        q,
        rstar,
        kappa,
        tm.opening_angle,
        tree,
        leaf_size=tm.leaf_size,
        group_size=tm.group_size,
        order=tm.order,
        precision=tm.precision,
    )
    err = np.linalg.norm(tree[rows] - direct, axis=1) / np.linalg.norm(direct, axis=1)
    return float(np.median(err)), float(np.percentile(err, 99))


def build(path, n_rods, method, extra=()):
    """The simulation of one size and method, warmed up (compilation, neighbour lists, the RK4 start)."""
    sc = load_scenario(
        path, overrides=list(scene(path, n_rods, extra).overrides) + [f"forces.tip_magnetic.method={method}"]
    )
    sim = Simulation.from_scenario(sc, timing=True, comm=world)
    sim.step(3)
    return sim


def time_block(sim, steps):
    """ms per full step over ``steps`` steps and ms of the tip-tip term per step (rank 0's).

    With multiple time stepping (``integrator.slow_every = K``) the step count is rounded up to a
    multiple of K, so that the time is the average over whole cycles of K steps."""
    k = sim.params.integrator.slow_every
    steps = -(-steps // k) * k
    ff = sim.force_field
    ff.seconds.clear()
    world.Barrier()
    c0 = time.process_time()
    t0 = time.perf_counter()
    sim.step(steps)
    world.Barrier()
    ms = 1e3 * (time.perf_counter() - t0) / steps
    cpu = 1e3 * (time.process_time() - c0) / steps
    return ms, 1e3 * ff.seconds["tip_magnetic"] / steps, steps, cpu


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default=str(ROOT / "scenarios" / "fig2.toml"))
    ap.add_argument("--rods", type=int, nargs="+", default=[1200, 6000, 24000, 100000])
    ap.add_argument("--method", nargs="+", choices=["direct", "tree"], default=["direct", "tree"])
    ap.add_argument(
        "--step-seconds",
        type=float,
        default=4.0,
        help="time about this long per block of steps (at least 2 steps, at most 200)",
    )
    ap.add_argument("--repeat", type=int, default=5, help="blocks of steps per figure, ours and the peer's in turn")
    ap.add_argument("--no-peer", action="store_true", help="do not time the peer (OpenMM)")
    ap.add_argument(
        "--set",
        dest="extra",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="change the scene for every size, e.g. --set integrator.slow_every=1 (repeatable)",
    )
    ap.add_argument("--json", help="write the rows to this JSON file (rank 0)")
    ap.add_argument("--plot", help="draw ms/step against rods from --from-json files into this PNG")
    ap.add_argument("--from-json", nargs="+", default=[], help="JSON files of earlier runs for --plot")
    args = ap.parse_args(argv)
    if args.plot:
        return plot(args.from_json or ([args.json] if args.json else []), args.plot)
    say = print if world.rank == 0 else (lambda *a, **k: None)
    import numba

    threads = numba.get_num_threads()
    use_peer = not args.no_peer and world.rank == 0 and OpenMMPeer.available()
    if world.size > 1 and not args.no_peer:
        say("peer skipped under MPI (it would share the cores with the other ranks); run with 1 rank for the ratio")
        use_peer = False
    elif not args.no_peer and not OpenMMPeer.available():
        say(OpenMMPeer.missing())
    say(machine_line())
    tm = load_scenario(args.scenario, overrides=list(args.extra)).params.forces.tip_magnetic
    tree = f"tree opening angle {tm.opening_angle:g}, groups of up to {tm.group_size} tips; " if tm else ""
    say(
        f"{world.size} MPI rank(s) x {threads} numba threads; scenario {args.scenario}; {tree}{args.repeat} repeats, "
        "median [min-max]" + (f"; {' '.join(args.extra)}" if args.extra else "")
    )
    rng = np.random.default_rng(0)
    rows = []
    for n in args.rods:
        direct_ms = None
        peer = None
        for method in args.method:
            sim = build(args.scenario, n, method, args.extra)
            if use_peer and peer is None:
                peer = OpenMMPeer(sim.state.position, sim.state.tip_charge, threads)
                say(f"peer: {peer.label}")
            # a first short block decides how many steps fill --step-seconds
            ms, _, _, _ = time_block(sim, 2)
            steps = int(min(200, max(2, args.step_seconds * 1e3 / max(ms, 1e-3))))
            peer_steps = None
            ours, tips, theirs, ours_cpu, theirs_cpu = [], [], [], [], []
            for _ in range(max(1, args.repeat)):
                ms, tip_ms, steps, cpu = time_block(sim, steps)
                ours.append(ms)
                ours_cpu.append(cpu)
                tips.append(tip_ms / ms)
                if peer is not None:
                    if peer_steps is None:
                        peer_steps = int(min(200, max(2, args.step_seconds * 1e3 / max(peer.ms_per_step(2)[0], 1e-3))))
                    wall, cpu = peer.ms_per_step(peer_steps)
                    theirs.append(wall)
                    theirs_cpu.append(cpu)
            med, text = summary(ours)
            row = {
                "rods": n,
                "method": method,
                "ranks": world.size,
                "threads": threads,
                "slow_every": sim.params.integrator.slow_every,
                "steps": steps,
                "ms_per_step": med,
                "ms_all": ours,
                "ms_text": text,
                "tip_share": float(np.median(tips)),
                "cpu_ms_all": ours_cpu,
            }
            if method == "direct":
                direct_ms = med
            if method == "tree" and world.rank == 0:
                row["median_error"], row["p99_error"] = tree_error(sim, rng)
            if direct_ms is not None:
                row["vs_direct"] = direct_ms / med
            if theirs:
                row["peer_ms"], row["peer_text"] = summary(theirs)
                row["peer_ms_all"] = theirs
                row["peer_steps"] = peer_steps
                ratios = [a / b for a, b in zip(ours, theirs)]
                row["vs_peer"], row["vs_peer_text"] = summary(ratios)
                row["peer_cpu_ms_all"] = theirs_cpu
                row["vs_peer_cpu"] = float(np.median([a / b for a, b in zip(ours_cpu, theirs_cpu)]))
                row["peer"] = peer.label
            rows.append(row)
            say(_fmt(row), flush=True)
            if args.json and world.rank == 0:  # after every row, so that an interrupted run keeps its figures
                _write(args, rows)
    say(
        "\n| rods | tip-tip sum | ranks x threads | ms per step | tip-tip share | tree median / p99 error "
        "| speed-up over direct | peer ms per step | ratio to the peer (ours / peer) | ratio of CPU time |"
    )
    say("|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        say(_fmt(r, markdown=True))
    return rows


def _write(args, rows):
    Path(args.json).write_text(
        json.dumps({"scenario": args.scenario, "machine": machine(), "extra": args.extra, "rows": rows}, indent=1)
    )


def _fmt(r, markdown=False):
    err = f"{r['median_error']:.1e} / {r['p99_error']:.1e}" if "median_error" in r else ""
    cells = [
        str(r["rods"]),
        r["method"],
        f"{r['ranks']} x {r['threads']}",
        r["ms_text"],
        f"{r['tip_share']:.0%}",
        err,
        f"{r['vs_direct']:.2f}" if "vs_direct" in r else "",
        r.get("peer_text", "(no peer)"),
        r.get("vs_peer_text", ""),
        f"{r['vs_peer_cpu']:.2f}" if "vs_peer_cpu" in r else "",
    ]
    return ("| " + " | ".join(cells) + " |") if markdown else "  ".join(cells)


def plot(files, out):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 5))
    for f in files:
        rows = json.loads(Path(f).read_text())["rows"]
        for method in ("direct", "tree"):
            pts = sorted((r["rods"], r["ms_per_step"]) for r in rows if r["method"] == method)
            if pts:
                r0 = next(r for r in rows if r["method"] == method)
                x, y = zip(*pts)
                ax.loglog(
                    x,
                    y,
                    "o-" if method == "tree" else "s--",
                    label=f"{method}, {r0['ranks']} rank(s) x {r0['threads']} thread(s)"
                    + (
                        f", slow sums every {r0['slow_every']} steps"
                        if r0.get("slow_every", 1) > 1
                        else ", every term every step"
                    ),
                )
    peer = {}
    for f in files:
        for r in json.loads(Path(f).read_text())["rows"]:
            if "peer_ms" in r:
                peer.setdefault(r["rods"], []).append(r["peer_ms"])
    if peer:
        px = sorted(peer)
        py = [min(peer[n]) for n in px]
        ax.loglog(px, py, "k^:", label="peer (OpenMM CPU, PME), measured in the same runs")
        n = np.array([1e3, 1e5])
        ax.loglog(n, py[0] * (n * np.log(n)) / (px[0] * np.log(px[0])), color="grey", lw=0.8, label="N log N")
    ax.set_xlabel("rods")
    ax.set_ylabel("ms per step (all Fig. 2 terms)")
    ax.set_title("cost of a step against system size")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out, dpi=120)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
