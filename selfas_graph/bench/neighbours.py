"""Neighbour-list and Yukawa benchmark: the list builds and the sum over the rod-centre list, per instruction set.

Usage: selfas-graph bench neighbours [--rods 1200 6000 24000] [--checkpoint STATE.h5] [--repeat 9]
                                        [--targets host haswell] [--before REF] [--json OUT.json]
                                        [--kernels "yukawa mixed" ...]

For each scene (the Fig. 2 scene scaled to each ``--rods`` as selfas_graph/bench/step.py makes it, and
the state of ``--checkpoint`` when given), it times on one numba thread, by the process's CPU
time (``time.process_time``: on a shared machine it counts only the cycles the kernel got):

- ``centre list``: the rod-centre list (kernels/cells.py ``neighbour_rows``), radius Yukawa
  cut-off + ``neighbours.centre_skin`` (``neighbours.skin`` where unset), as model/neighbours.py builds it for the Yukawa term (with the
  rows numbered by cell where the revision has them);
- ``tip list``: the tip list, radius the tip range (r*, or the contact release radius when
  larger) + skin, without the pairs of one rod;
- ``yukawa``: the Yukawa sum as the term calls it over that list (``kernels/yukawa.py::
  yukawa_centres_sorted`` with the copies in cell order it reads, or ``yukawa_centres`` in a
  revision without it), also in ns per listed pair;
- ``yukawa mixed``: the same sum with the pair law in float32 (``forces.yukawa.precision =
  "mixed"``, ``kernels/yukawa.py::yukawa_centres_sorted_mixed``), always interleaved with the
  float64 sum of the working tree (rounds in which the two take turns, the order alternating), and
  printed in a table of its own: both times, the speed-up (median [min-max] of the per-round
  ratios float64 / mixed) and the largest difference of a rod's force over the largest force; with
  ``--before``, also the mixed sum of REF and of the working tree in rounds of their own, and the
  speed-up before / after.

``--kernels`` times only the named ones (default: all four).

``--before REF`` also times the kernels of the git revision REF (selfas_graph/bench/kernels.py
``kernels_at``), interleaved with the working tree's (the order alternates between repeats),
each over the list its own build makes, and prints the speed-up (median [min-max] of the
per-repeat ratios before / after): the fair comparison on a loaded machine. Each target runs in
a fresh process with ``NUMBA_CPU_NAME`` set and ``NUMBA_CPU_FEATURES`` empty (the named CPU's own
features; ``host`` leaves both unset, selfas_graph/bench/peer.py ``target_env``), and prints the CPU and
the target numba compiled for.
"""

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]

KERNELS = ["centre list", "tip list", "yukawa"]
#: timed against the float64 sum of the working tree, interleaved, in a table of its own
MIXED = "yukawa mixed"


def scenes(args):
    """(label, Simulation) for every scene asked for."""
    from selfas_graph import Simulation

    from .step import scene

    out = []
    if args.checkpoint:
        from .profile import load_state

        ns = argparse.Namespace(checkpoint=args.checkpoint, extra=[])
        sim, _ = load_state(ns)
        out.append((f"{sim.state.n_rods} (checkpoint)", sim))
    for n in args.rods:
        out.append((str(n), Simulation.from_scenario(scene(str(ROOT / "scenarios" / "fig2.toml"), n))))
    return out


def run(args):
    import numba

    from selfas_graph import kernels

    from .kernels import kernels_at, timed, timed_pair
    from .peer import machine, machine_line

    numba.set_num_threads(1)
    clock = time.process_time
    now = kernels
    import selfas_graph.kernels.cells  # noqa: F401  (loaded as attributes of the package)
    import selfas_graph.kernels.yukawa  # noqa: F401

    chosen = getattr(args, "kernels", None) or [*KERNELS, MIXED]
    before = None
    if args.before:
        before = kernels_at(args.before)
    rows = []
    for label, sim in scenes(args):
        ff = sim.force_field
        st = sim.state
        ff.bind(st.position, st.velocity)
        yk = next(t for t in ff.terms if t.name == "yukawa")
        c = np.ascontiguousarray(ff.context.centre())
        tips = np.ascontiguousarray(st.position)
        skin = sim.params.neighbours.skin
        tip_radius = ff.lists.tip_range + skin
        centre_skin = sim.params.neighbours.centre_skin
        centre_radius = yk.cutoff + (skin if centre_skin is None else centre_skin)
        n = c.shape[0]
        fy = np.empty((n, 3))
        lists = {}

        def sorted_sum(K):
            """True where the revision sums over copies in cell order (yukawa.yukawa_centres_sorted)."""
            return hasattr(K.yukawa, "yukawa_centres_sorted")

        def centre_list(K):
            if id(K) not in lists:
                if sorted_sum(K):
                    lists[id(K)] = K.cells.neighbour_rows(c, centre_radius, cell_order=True)
                else:
                    lists[id(K)] = K.cells.neighbour_rows(c, centre_radius)
            return lists[id(K)]

        def job(name, K):
            if name == "centre list":
                if sorted_sum(K):  # as the Yukawa term asks for it: also the rows numbered by cell
                    return lambda: K.cells.neighbour_rows(c, centre_radius, cell_order=True)
                return lambda: K.cells.neighbour_rows(c, centre_radius)
            if name == "tip list":
                return lambda: K.cells.neighbour_rows(tips, tip_radius, True)
            if sorted_sum(K):  # as the Yukawa term calls it: copies in cell order made per call
                _, _, (order, s, i) = centre_list(K)
                kernel = K.yukawa.yukawa_centres_sorted_mixed if name == MIXED else K.yukawa.yukawa_centres_sorted
                return lambda: kernel(
                    c[order], st.rod_charge[order], order, s, i, yk.screening, yk.core, yk.cutoff, 0, n, fy
                )
            s, i = centre_list(K)
            return lambda: K.yukawa.yukawa_centres(c, st.rod_charge, s, i, yk.screening, yk.core, yk.cutoff, 0, n, fy)

        res = {"scene": label, "rods": n, "centre_radius": centre_radius, "tip_radius": tip_radius}
        for name in KERNELS:
            if name not in chosen:
                continue
            if before is None:
                res[name] = timed(job(name, now), args.repeat, clock)
            else:
                res[name + " before"], res[name] = timed_pair(job(name, before), job(name, now), args.repeat, clock)
        if MIXED in chosen:
            res["float64"], res[MIXED] = timed_pair(job("yukawa", now), job(MIXED, now), args.repeat, clock)
            f64 = np.empty((n, 3))
            job("yukawa", now)()
            f64[:] = fy
            job(MIXED, now)()
            norm = np.linalg.norm(f64, axis=1)
            res["mixed_error"] = float(np.linalg.norm(fy - f64, axis=1).max() / norm.max())
            if before is not None and hasattr(before.yukawa, "yukawa_centres_sorted_mixed"):
                res[MIXED + " before"], res[MIXED + " after"] = timed_pair(
                    job(MIXED, before), job(MIXED, now), args.repeat, clock
                )
        res["yukawa_pairs"] = int(centre_list(now)[0][-1])  # start[n] of either form
        res["tip_pairs"] = int(kernels.cells.neighbour_rows(tips, tip_radius, True)[0][-1])
        rows.append(res)
    return {"machine": machine(), "line": machine_line(), "rows": rows, "before": args.before}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rods", type=int, nargs="*", default=[1200, 6000, 24000])
    ap.add_argument(
        "--checkpoint", help="also time the state of this checkpoint (selfas-graph bench profile --checkpoint)"
    )
    ap.add_argument("--repeat", type=int, default=9)
    ap.add_argument("--targets", nargs="+", default=["host"], help="host, or NUMBA_CPU_NAME values (haswell, znver3)")
    ap.add_argument("--before", help="also time the kernels of this git revision, interleaved (e.g. main)")
    ap.add_argument("--kernels", nargs="+", default=[*KERNELS, MIXED], choices=[*KERNELS, MIXED])
    ap.add_argument("--json", help="write all results to this file")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.repeat < 1:
        ap.error("--repeat must be at least 1")
    if args.child:
        print(json.dumps(run(args)))
        return
    results = {}
    from .peer import target_env, tool_command, tool_env

    for target in args.targets:
        env = tool_env(target_env(target))
        cmd = [*tool_command("neighbours"), "--child", "--repeat", str(args.repeat)]
        cmd += ["--rods", *map(str, args.rods), "--kernels", *args.kernels]
        cmd += ["--checkpoint", args.checkpoint] if args.checkpoint else []
        cmd += ["--before", args.before] if args.before else []
        got = subprocess.run(cmd, env=env, capture_output=True, text=True)
        if got.returncode:
            print(f"{target}: failed, left out of the table:\n{got.stderr}", file=sys.stderr, flush=True)
            continue
        results[target] = json.loads(got.stdout.strip().splitlines()[-1])
        print(f"{target}: {results[target]['line']}", flush=True)
        if args.json:
            Path(args.json).write_text(json.dumps(results, indent=1))
    targets = [t for t in args.targets if t in results]
    if not targets:
        sys.exit(1)

    def cell(row, key, k):
        v = np.array(row[key])
        text = f"{np.median(v):.3g} [{v.min():.3g}-{v.max():.3g}]"
        if k == "yukawa" and not key.endswith("before"):
            text += f" ({np.median(v) * 1e6 / row['yukawa_pairs']:.1f} ns/pair)"
        return text

    kernels = [k for k in KERNELS if k in args.kernels]
    if kernels:
        print(f"\nCPU ms per call on 1 thread, median [min-max] of {args.repeat}")
        cols = [(t, k) for t in targets for k in (("before", "after", "speed-up") if args.before else ("",))]
        if args.before:
            print(f"before = {args.before}, after = the working tree; speed-up = median of before/after per repeat")
        print("| rods | kernel | " + " | ".join(f"{t} {k}".strip() for t, k in cols) + " |")
        print("|---|---|" + "---|" * len(cols))

        for i, row0 in enumerate(results[targets[0]]["rows"]):
            for k in kernels:
                cells = []
                for target, what in cols:
                    row = results[target]["rows"][i]
                    if what == "before":
                        cells.append(cell(row, k + " before", k))
                    elif what == "speed-up":
                        r = np.array(row[k + " before"]) / np.array(row[k])
                        cells.append(f"{np.median(r):.2f} [{r.min():.2f}-{r.max():.2f}]")
                    else:
                        cells.append(cell(row, k, k))
                print(f"| {row0['scene']} | {k} | " + " | ".join(cells) + " |")
    if MIXED in args.kernels:
        print(
            f"\n{MIXED}: CPU ms per call on 1 thread, float64 and mixed taking turns, median [min-max] of "
            f"{args.repeat} rounds; speed-up = median [min-max] of the per-round float64 / mixed; error = the "
            "largest difference of a rod's force / the largest force"
        )
        against = any(MIXED + " before" in row for t in targets for row in results[t]["rows"])
        if against:
            print(
                f"and the mixed sum of {args.before} and of the working tree taking turns (their own rounds): "
                "before, after, speed-up = median [min-max] of the per-round before / after"
            )
        extra = " mixed before | mixed after | speed-up over before |" if against else ""
        print("| rods | target | float64 | mixed | speed-up | error |" + extra)
        print("|---|---|---|---|---|---|" + "---|" * (3 if against else 0))
        for i, row0 in enumerate(results[targets[0]]["rows"]):
            for target in targets:
                row = results[target]["rows"][i]
                r = np.array(row["float64"]) / np.array(row[MIXED])
                line = (
                    f"| {row0['scene']} | {target} | {cell(row, 'float64', 'yukawa')} | {cell(row, MIXED, 'yukawa')} | "
                    f"{np.median(r):.2f} [{r.min():.2f}-{r.max():.2f}] | {row['mixed_error']:.1e} |"
                )
                if against and MIXED + " before" in row:
                    b = np.array(row[MIXED + " before"]) / np.array(row[MIXED + " after"])
                    line += (
                        f" {cell(row, MIXED + ' before', 'before')} | {cell(row, MIXED + ' after', 'yukawa')} | "
                        f"{np.median(b):.2f} [{b.min():.2f}-{b.max():.2f}] |"
                    )
                elif against:
                    line += " | | |"
                print(line)
    for row in results[targets[0]]["rows"]:
        print(
            f"{row['scene']}: centre list radius {row['centre_radius']:.3f}, {row['yukawa_pairs']} directed pairs; "
            f"tip list radius {row['tip_radius']:.3f}, {row['tip_pairs']} directed pairs"
        )


if __name__ == "__main__":
    main()
