"""Kernel benchmark: the hot kernels of a step, one at a time, per instruction set.

Usage: selfas-graph bench kernels [--rods 1200 6000 24000] [--repeat 7] [--threads 1]
                                     [--targets host haswell znver3] [--rounds 1] [--before REF]
                                     [--json OUT.json]

On the tips of the Fig. 2 scene scaled to each size (as selfas_graph/bench/step.py), it times, each
``--repeat`` times (median [min-max] ms per call), on ``--threads`` numba threads:

- ``direct``: the tip-tip direct sum (all rows), also as tip pairs per second per thread;
- ``direct mixed``: the same sum in mixed precision (``forces.tip_magnetic.precision = "mixed"``:
  float32 pair law, float64 block sums); with ``--before`` interleaved with ``direct``;
- ``plain``: the same all-pairs loop reduced to a bare Coulomb law (``q_k q_l d / r^3``, no
  soft core, no same-rod select), a reference for what the CPU does with one sqrt and one
  division per pair (up to 6000 rods);
- ``tree build`` and ``tree eval``: the tip tree (kernels/tree.py) at its defaults; ``tree eval
  mixed`` the same evaluation in mixed precision, as the Fig. 2 and Fig. 6 scenes run it;
- ``yukawa``: the screened rod-centre sum over the scene's rod-centre list, as each revision's term
  calls it (over copies in cell order and in the scene's precision where the revision has that kernel);
- ``ab4 step``, ``constraint`` and ``channel sums``: the O(n) kernels of every step (the AB4 update
  with its bond check, the rigid-bond constraint with its checks, the sum of the scene's force
  channels with the powers of its non-conservative ones), each as the run calls it (serial below
  ``kernels/_jit.py::PARALLEL_ROWS`` tips);
- ``tip energy``: the tip-tip energy of a frame (a direct sum over all pairs, up to ``--direct-max``).

- ``current tips`` and ``current field``: the field of the rod currents (docs/model.md 'Term 9',
  'Term 10') on every tip and at the 4 Gauss-Legendre points of every current-carrying rod,
  with ``--active-fraction`` of the rods (default 0.72, the Fig. 2 run at t = 340) carrying
  random currents.

- ``current tips mixed`` and ``current field mixed``: the same two sums with the segment law in
  float32 (``precision = "mixed"`` of ``[forces.current_field]`` and ``[forces.current_lorentz]``);
  with ``--before`` they are interleaved with the float64 kernels of the working tree (their
  "before" column), so that the speed-up is float64 / mixed. The current kernels also print ns
  per target-segment pair.

``--kernels`` times only the named kernels (default: all); ``--active-rods N ...`` sets the
number of current-carrying rods for each ``--rods`` size instead of ``--active-fraction``.

``--mixed-error CHECKPOINT`` instead prints the error of the mixed current kernels against the
float64 ones on the state of a checkpoint (read only): median, p99 and max of the per-row
relative difference of the term-9 force, of the rod currents' field at the quadrature points and
of the term-10 force (with every other field source), and the largest difference over the
largest force.

``--before REF`` also times the kernels of the git revision REF (its ``selfas_graph/kernels``
copied into a temporary package), interleaved with today's in the same process, and prints
both and their ratio (before / after, median of the per-repeat ratios): the fair comparison on
a loaded machine.

``--cpu-time`` times by the process's CPU time instead of the wall clock: on a shared machine
under load it counts only the cycles the kernel got (with one thread).

``--rounds R`` runs the processes of the targets R times in turns (the order reversed every
other round), so that the builds see the same machine load and each build is timed in R processes
(the same machine code can run some percent faster or slower from one process to the next); each
figure is then over all rounds' repeats, and a last table gives, per kernel, every other target's
time over the first's: median [min-max] over the rounds of the ratio of the rounds' medians.

``--targets`` runs the timings once per instruction set, each in a fresh process with
``NUMBA_CPU_NAME`` set to the target and ``NUMBA_CPU_FEATURES`` set empty, so that numba uses
that CPU's own features (selfas_graph/bench/peer.py ``target_env``; ``host`` leaves both unset: numba
compiles for the CPU it runs on). One table then shows what an AVX2 machine gets (``haswell``,
``znver3``) beside the host build, also on an AVX-512 host. Each process prints the CPU and the
target and vector features it compiled for.
"""

import argparse
import importlib
import importlib.util
import inspect
import json
import subprocess
import sys
import tempfile
import time
import types
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]


def _plain():
    import numba

    from selfas_graph.kernels._jit import _SUM_FLAGS, prange

    # the package's flags, but not cached: a cache entry of a function defined in a tool loaded
    # under another module name cannot be loaded back
    @numba.njit(parallel=True, fastmath=_SUM_FLAGS, cache=False)
    def plain_coulomb(x, y, z, q, out):
        n = x.shape[0]
        for k in prange(n):
            fx = 0.0
            fy = 0.0
            fz = 0.0
            for l in range(n):
                dx = x[k] - x[l]
                dy = y[k] - y[l]
                dz = z[k] - z[l]
                r2 = dx * dx + dy * dy + dz * dz + 1e-300
                ir = 1.0 / np.sqrt(r2)
                g = q[k] * q[l] * ir * ir * ir
                fx += g * dx
                fy += g * dy
                fz += g * dz
            out[k, 0] = fx
            out[k, 1] = fy
            out[k, 2] = fz

    return plain_coulomb


#: the kernels the tool times, in the order of its table (``--kernels`` takes these names)
KERNELS = (
    "direct",
    "direct mixed",
    "plain",
    "tree build",
    "tree eval",
    "tree eval mixed",
    "yukawa",
    "ab4 step",
    "constraint",
    "channel sums",
    "tip energy",
    "current tips",
    "current field",
    "current tips mixed",
    "current field mixed",
)


def timed(fn, repeat, clock=time.perf_counter):
    fn()  # compile / warm
    t = []
    for _ in range(repeat):
        t0 = clock()
        fn()
        t.append(1e3 * (clock() - t0))
    return t


def timed_pair(fn_before, fn_after, repeat, clock=time.perf_counter):
    """Both callables, interleaved (the order alternates between repeats): two lists of ms."""
    fn_before()
    fn_after()
    t = ([], [])
    for i in range(repeat):
        for j in (0, 1) if i % 2 == 0 else (1, 0):
            fn = fn_before if j == 0 else fn_after
            t0 = clock()
            fn()
            t[j].append(1e3 * (clock() - t0))
    return t


def kernels_at(ref):
    """The kernel modules of git revision ``ref``, as a namespace with ``tips``, ``tree``, ``yukawa``,
    ``currents``, ``cells`` (``selfas_graph/kernels`` of that revision copied into a package of its own;
    ``integrate``, ``rigid``; ``yukawa`` is ``pairs`` in revisions that held the Yukawa sums there)."""
    sha = subprocess.run(["git", "rev-parse", ref], cwd=ROOT, capture_output=True, text=True, check=True).stdout.strip()
    name = f"selfas_kernels_{sha[:12]}"
    home = Path(tempfile.gettempdir()) / "selfas_bench_kernels"
    pkg = home / name
    if not (pkg / "__init__.py").exists():
        pkg.mkdir(parents=True, exist_ok=True)
        files = subprocess.run(
            ["git", "ls-tree", "--name-only", sha, "selfas_graph/kernels/"],
            cwd=ROOT,
            capture_output=True,
            text=True,
            check=True,
        ).stdout.split()
        for f in files:
            if f.endswith(".py"):
                text = subprocess.run(["git", "show", f"{sha}:{f}"], cwd=ROOT, capture_output=True, check=True).stdout
                (pkg / Path(f).name).write_bytes(text)
    if name not in sys.modules:  # the copy as a package of its own name, imported from its folder
        spec = importlib.util.spec_from_file_location(name, pkg / "__init__.py", submodule_search_locations=[str(pkg)])
        package = importlib.util.module_from_spec(spec)
        sys.modules[name] = package
        spec.loader.exec_module(package)
    modules = {
        m: importlib.import_module(f"{name}.{m}") for m in ("tips", "tree", "currents", "cells", "integrate", "rigid")
    }
    yukawa = "yukawa" if (pkg / "yukawa.py").exists() else "pairs"
    return types.SimpleNamespace(yukawa=importlib.import_module(f"{name}.{yukawa}"), **modules)


def run(args):
    import numba

    from selfas_graph import Simulation
    from selfas_graph.kernels import cells, currents, integrate, lorentz, rigid, tips, tree, yukawa

    from .peer import machine, machine_line
    from .step import scene

    numba.set_num_threads(args.threads)
    plain = _plain()
    clock = time.process_time if args.cpu_time else time.perf_counter
    now = types.SimpleNamespace(
        tips=tips, tree=tree, yukawa=yukawa, currents=currents, integrate=integrate, rigid=rigid, cells=cells
    )
    before_ref = getattr(args, "before", None)
    before = kernels_at(before_ref) if before_ref else None
    fraction = getattr(args, "active_fraction", 0.72)
    out_rows = []
    for n in args.rods:
        sc = scene(str(ROOT / "scenarios" / "fig2.toml"), n)
        sim = Simulation.from_scenario(sc)
        st = sim.state
        x, y, z = (np.ascontiguousarray(st.position[:, d]) for d in range(3))
        q = st.tip_charge
        p = sim.params
        rstar, kappa = p.rods.rstar, p.rods.tip_stiffness
        f = np.empty((x.shape[0], 3))
        res = {"rods": n}
        ntips = x.shape[0]
        ff = sim.force_field
        ff.bind(st.position, st.velocity)
        yk = next(t for t in ff.terms if t.name == "yukawa")
        nl = ff.centre_neighbours()
        c = ff.context.centre()
        own_lists = {}

        def centre_list(K):
            """The rod-centre list as revision K builds it (its own integer types), made once."""
            if id(K) not in own_lists:
                own_lists[id(K)] = K.cells.neighbour_rows(c, nl.cutoff + nl.skin)
            return own_lists[id(K)]

        def yukawa_job(K):
            """The Yukawa sum as revision K's term calls it: over copies in cell order, in the scene's
            precision, where the revision has that kernel (a list over the rows as built, before)."""
            if not hasattr(K.yukawa, "yukawa_centres_sorted"):
                return lambda: K.yukawa.yukawa_centres(
                    c, st.rod_charge, *centre_list(K), yk.screening, yk.core, yk.cutoff, 0, n, fy
                )
            key = ("sorted", id(K))
            if key not in own_lists:
                own_lists[key] = K.cells.neighbour_rows(c, nl.cutoff + nl.skin, cell_order=True)[2]
            order, start, index = own_lists[key]
            mixed = yk.precision == "mixed" and hasattr(K.yukawa, "yukawa_centres_sorted_mixed")
            kernel = K.yukawa.yukawa_centres_sorted_mixed if mixed else K.yukawa.yukawa_centres_sorted
            return lambda: kernel(
                c[order], st.rod_charge[order], order, start, index, yk.screening, yk.core, yk.cutoff, 0, n, fy
            )

        fy = np.empty((n, 3))
        rng = np.random.default_rng(7)
        n_active = getattr(args, "active_rods", None)
        if n_active:
            current = np.zeros(n)
            pick = rng.choice(n, size=min(n, n_active[args.rods.index(n)]), replace=False)
            current[pick] = rng.uniform(-3.0, 3.0, len(pick))
        else:
            current = np.where(rng.random(n) < fraction, rng.uniform(-3.0, 3.0, n), 0.0)
        active = np.flatnonzero(current != 0.0).astype(np.int64)
        gl_t, _ = lorentz.gauss_legendre_01(4)
        pts = np.empty((len(active) * len(gl_t), 3))
        lorentz.quadrature_points(st.position, active, gl_t, pts)
        excl = np.repeat(active, len(gl_t))
        fb = np.empty_like(pts)
        w = 0.5 * p.rods.diameter
        trees = {}
        # the scene's tree settings for both revisions, whatever their defaults were
        tm = p.forces.tip_magnetic
        groups, theta = (tm.group_size, tm.opening_angle) if tm is not None else (1024, 0.55)
        # the leaves and order too, where the revision's build takes them (older ones fixed them)
        shape = {"leaf_size": tm.leaf_size, "order": tm.order} if tm is not None else {}

        def tree_of(K):
            if id(K) not in trees:
                known = inspect.signature(K.tree.build_tip_tree).parameters
                extra = {k: v for k, v in shape.items() if k in known}
                trees[id(K)] = K.tree.build_tip_tree(x, y, z, q, group_size=groups, **extra)
            return trees[id(K)]

        direct = n <= args.direct_max
        # the every-step kernels on copies of the state (each call moves them a little: its cost does not
        # depend on the values), the scene's own channels and powered rows
        xs, vs = st.position.copy(), st.velocity.copy()
        hist = np.random.default_rng(3).normal(size=(4, ntips, 3))
        slots = np.arange(4, dtype=np.int64)
        ell = st.bond_length()
        ff.evaluate(st.position, st.velocity, np.zeros(len(ff.powered)))
        block, powered, power = ff.channel_block, ff.powered, np.zeros(len(ff.powered))
        e = np.empty(ntips)
        rep_big = args.repeat if n <= 6000 else max(2, args.repeat // 3)
        jobs = [
            ("direct", direct, rep_big, lambda K: lambda: K.tips.tip_tip_direct(x, y, z, q, rstar, kappa, 0, ntips, f)),
            (
                "direct mixed",
                direct,
                rep_big,
                lambda K: lambda: K.tips.tip_tip_direct_mixed(x, y, z, q, rstar, kappa, 0, ntips, f),
            ),
            ("tree build", True, args.repeat, lambda K: lambda: K.tree.build_tip_tree(x, y, z, q, group_size=groups)),
            (
                "tree eval",
                True,
                args.repeat,
                lambda K: lambda: K.tree.evaluate_tip_tree(tree_of(K), rstar, kappa, theta, f),
            ),
            (
                "tree eval mixed",
                True,
                args.repeat,
                lambda K: lambda: K.tree.evaluate_tip_tree(tree_of(K), rstar, kappa, theta, f, precision="mixed"),
            ),
            ("yukawa", True, args.repeat, yukawa_job),
            (
                "ab4 step",
                True,
                args.repeat,
                lambda K: lambda: K.integrate.ab4_step(xs, vs, hist, hist, slots, 1e-9, ell),
            ),
            (
                "constraint",
                True,
                args.repeat,
                lambda K: lambda: K.rigid.constrain_bonds_checked(xs, vs, True, True, ell),
            ),
            (
                "channel sums",
                True,
                args.repeat,
                lambda K: lambda: K.integrate.channel_sum_power(f, block, vs, powered, power),
            ),
            (
                "tip energy",
                direct,
                rep_big,
                lambda K: lambda: K.tips.tip_tip_energy(x, y, z, q, rstar, kappa, 0, ntips, e),
            ),
            (
                "current tips",
                direct,
                rep_big,
                lambda K: lambda: K.currents.current_force_on_tips(st.position, q, active, current, w, 0, ntips, f),
            ),
            (
                "current field",
                direct,
                rep_big,
                lambda K: lambda: K.currents.rod_current_field(pts, excl, st.position, active, current, w, fb),
            ),
            (
                "current tips mixed",
                direct,
                rep_big,
                lambda K: (
                    lambda: K.currents.current_force_on_tips_mixed(st.position, q, active, current, w, 0, ntips, f)
                ),
            ),
            (
                "current field mixed",
                direct,
                rep_big,
                lambda K: lambda: K.currents.rod_current_field_mixed(pts, excl, st.position, active, current, w, fb),
            ),
        ]
        chosen = getattr(args, "kernels", None)
        for name, on, rep, make in jobs:
            if not on or (chosen and name not in chosen):
                continue
            if name.endswith(" mixed"):
                # the peer of a mixed kernel is the float64 kernel of the working tree
                peer = jobs[[j[0] for j in jobs].index(name[: -len(" mixed")])][3](now)
                if before is None:
                    res[name] = timed(make(now), rep, clock)
                else:
                    res[name + " before"], res[name] = timed_pair(peer, make(now), rep, clock)
            elif before is None:
                res[name] = timed(make(now), rep, clock)
            else:
                res[name + " before"], res[name] = timed_pair(make(before), make(now), rep, clock)
        if direct and (not chosen or "plain" in chosen):
            res["plain"] = timed(lambda: plain(x, y, z, q, f), rep_big, clock)
        res["yukawa_pairs"] = int(nl.start[-1])
        res["active_rods"] = int(len(active))
        out_rows.append(res)
    return {
        "machine": machine(),
        "line": machine_line(),
        "threads": args.threads,
        "rows": out_rows,
        "before": before_ref,
    }


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rods", type=int, nargs="+", default=[1200, 6000, 24000])
    ap.add_argument("--repeat", type=int, default=7)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument(
        "--cpu-time",
        action="store_true",
        help="time by the process's CPU time, not the wall clock: on a busy shared machine "
        "this counts only the cycles the kernel got (use with --threads 1)",
    )
    ap.add_argument("--direct-max", type=int, default=6000, help="time the direct sums up to this many rods")
    ap.add_argument("--targets", nargs="+", default=["host"], help="host, or NUMBA_CPU_NAME values (haswell, znver3)")
    ap.add_argument("--before", help="also time the kernels of this git revision, interleaved (e.g. HEAD~3)")
    ap.add_argument(
        "--active-fraction",
        type=float,
        default=0.72,
        help="fraction of the rods carrying current in the current kernels",
    )
    ap.add_argument("--kernels", nargs="+", help="time only these kernels (names as in the table)")
    ap.add_argument("--active-rods", type=int, nargs="+", help="current-carrying rods for each --rods size")
    ap.add_argument("--mixed-error", metavar="CHECKPOINT", help="error of the mixed current kernels on this state")
    ap.add_argument(
        "--rounds",
        type=int,
        default=1,
        help="run the targets' processes this many times in turns; ratios per round (module docstring)",
    )
    ap.add_argument("--json", help="write all results to this file")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    unknown = [k for k in args.kernels or () if k not in KERNELS]
    if unknown:
        ap.error(f"--kernels: unknown {', '.join(map(repr, unknown))}; the kernels are {', '.join(map(repr, KERNELS))}")
    if args.mixed_error:
        from .mixed_error import mixed_error
        from .peer import machine_line

        origin, n_active, n_rods, rows = mixed_error(args.mixed_error)
        print(machine_line())
        print(f"{origin}; {n_active} of {n_rods} rods carrying current; mixed against float64, per row relative")
        print("| quantity | median | p99 | max | max difference / largest force |")
        print("|---|---|---|---|---|")
        for name, *v in rows:
            print(f"| {name} | " + " | ".join(f"{x:.1e}" for x in v) + " |")
        return
    if args.child:
        print(json.dumps(run(args)))
        return
    rounds = {t: [] for t in args.targets}
    from .peer import target_env, tool_command, tool_env

    turns = [(r, t) for r in range(args.rounds) for t in (args.targets if r % 2 == 0 else args.targets[::-1])]
    for r, target in turns:
        env = tool_env(target_env(target))
        cmd = [
            *tool_command("kernels"),
            "--child",
            "--rods",
            *map(str, args.rods),
            "--repeat",
            str(args.repeat),
            "--threads",
            str(args.threads),
            "--direct-max",
            str(args.direct_max),
        ]
        cmd += ["--cpu-time"] if args.cpu_time else []
        cmd += ["--before", args.before] if args.before else []
        cmd += ["--active-fraction", str(args.active_fraction)]
        cmd += ["--kernels", *args.kernels] if args.kernels else []
        cmd += ["--active-rods", *map(str, args.active_rods)] if args.active_rods else []
        got = subprocess.run(cmd, env=env, capture_output=True, text=True)
        if got.returncode:
            print(f"{target}: failed, left out of the table:\n{got.stderr}", file=sys.stderr, flush=True)
            continue
        rounds[target].append({**json.loads(got.stdout.strip().splitlines()[-1]), "round": r})
        print(f"{target}: {rounds[target][-1]['line']}", flush=True)
        results = merge_rounds(rounds)
        if args.json:  # after every target, so that a failure later keeps the figures
            Path(args.json).write_text(json.dumps(results, indent=1))
    results = merge_rounds(rounds)
    args.targets = [t for t in args.targets if t in results]
    print(
        f"\n{'CPU' if args.cpu_time else 'wall'} ms per call on {args.threads} thread(s), median [min-max] of {args.repeat} x {args.rounds} round(s); "
        "direct and plain also in 1e9 tip pairs/s/thread (median)"
    )
    kernels = KERNELS
    cols = [(t, k) for t in args.targets for k in (("before", "after", "speed-up") if args.before else ("",))]
    if args.before:
        print(
            f"before = {args.before}, after = the working tree; speed-up = median of before/after per repeat; "
            "for the mixed kernels, before = the float64 kernel of the working tree"
        )
    print("| rods | kernel | " + " | ".join(f"{t} {k}".strip() for t, k in cols) + " |")
    print("|---|---|" + "---|" * len(cols))

    def cell(row, key, n, k):
        v = np.array(row[key])
        text = f"{np.median(v):.3g} [{v.min():.3g}-{v.max():.3g}]"
        if k in ("direct", "direct mixed", "plain"):
            # per thread of wall time; CPU time already sums the threads
            per = 1 if args.cpu_time else args.threads
            text += f" ({(2 * n) ** 2 / (np.median(v) * 1e-3) / per / 1e9:.2f}e9)"
        if k == "yukawa":
            text += f" ({np.median(v) * 1e6 / row['yukawa_pairs']:.1f} ns/pair)"
        if k.startswith("current"):
            targets = 2 * n if k.startswith("current tips") else 4 * row["active_rods"]
            text += f" ({np.median(v) * 1e6 / (targets * row['active_rods']):.2f} ns/pair)"
        return text

    for i, n in enumerate(args.rods):
        for k in kernels:
            cells = []
            for target, what in cols:
                row = results[target]["rows"][i]
                if k not in row:
                    cells.append("")
                elif what == "before":
                    cells.append(cell(row, k + " before", n, k) if k + " before" in row else "")
                elif what == "speed-up":
                    if k + " before" in row:
                        r = np.array(row[k + " before"]) / np.array(row[k])
                        cells.append(f"{np.median(r):.2f} [{r.min():.2f}-{r.max():.2f}]")
                    else:
                        cells.append("")
                else:
                    cells.append(cell(row, k, n, k))
            if any(cells):
                print(f"| {n} | {k} | " + " | ".join(cells) + " |")
    if len(args.targets) > 1 and not args.before:
        first = args.targets[0]
        print(f"\nms of each target over {first}'s, median [min-max] over {args.rounds} round(s)")
        print("| rods | kernel | " + " | ".join(f"{t} / {first}" for t in args.targets[1:]) + " |")
        print("|---|---|" + "---|" * (len(args.targets) - 1))
        for i, n in enumerate(args.rods):
            for k in kernels:
                ratios = [target_ratios(rounds, first, t, i, k) for t in args.targets[1:]]
                if all(len(r) for r in ratios):
                    cells = [f"{np.median(r):.2f} [{r.min():.2f}-{r.max():.2f}]" for r in ratios]
                    print(f"| {n} | {k} | " + " | ".join(cells) + " |")


def merge_rounds(rounds):
    """One result per target from its rounds (``{target: [result, ...]}``, each a :func:`run`
    result): the lists of times of every kernel concatenated over the rounds, the rest of the
    first round's result; targets without a round are left out."""
    merged = {}
    for target, results in rounds.items():
        if not results:
            continue
        first = results[0]
        rows = []
        for i, row in enumerate(first["rows"]):
            out = dict(row)
            for key, value in row.items():
                if isinstance(value, list):
                    out[key] = [t for r in results for t in r["rows"][i][key]]
            rows.append(out)
        merged[target] = {**first, "rows": rows, "rounds": len(results)}
    return merged


def target_ratios(rounds, first, other, i, kernel):
    """Per round, the median time of ``kernel`` in row ``i`` of target ``other`` over that of
    ``first`` (rounds where both timed it); an array, empty if none."""
    out = []
    # paired by the round they were timed in: a failed process leaves a round out of one target's list
    by_round = {r["round"]: r for r in rounds.get(other, [])}
    for a in rounds.get(first, []):
        b = by_round.get(a["round"])
        if b is None:
            continue
        ta, tb = a["rows"][i].get(kernel), b["rows"][i].get(kernel)
        if ta and tb:
            out.append(np.median(tb) / np.median(ta))
    return np.array(out)


if __name__ == "__main__":
    main()
