"""Time a scene end to end with the working tree against a git commit, in turns, in one session.

Usage::

    selfas-graph bench against_commit SCENARIO --commit REV [--threads N] [--rounds R]
        [--seeds S [S ...]] [--t-end T] [--set KEY=VALUE ...] [--scene own|tree] [--json FILE] [--keep DIR]

Exports ``REV``'s package (and, with ``--scene own``, the default, its copy of SCENARIO: each
version runs the scene file it shipped, as a user of that version would) with ``git archive``
into a temporary folder, and runs ``selfas-graph simulate`` with that code and with the working
tree, in turns: in round 1 the commit first, in round 2 the working tree first, and so on, each run
checked to import the code meant (as ``same_as_commit``). With ``--seeds`` a round runs each seed
(``scenario.seed``) with both codes, and its ratio is that of the summed times: a change that moves
trajectories (another path, other work) is judged on several paths, not one. Before the timed runs each code runs
the scene for ``--warm-up`` t0 untimed, so that the kernels it reaches are compiled into its cache;
kernels first used later (the circuit and the current terms, after the first short circuit, t = 7-23
in Fig. 2) are compiled in the first timed run that reaches them, and so is every kernel of a source
file edited since the warm-up: each run times numba's compilations (its ``numba:compile`` events,
which fire only on a cache miss) and the tool prints the ratio of the wall times less them too. Each
run is a fresh process with ``NUMBA_NUM_THREADS`` = ``OMP_NUM_THREADS`` = ``--threads``.

It prints the CPU model and the instruction set numba compiles for, each run's wall and CPU
time (the child's user + system time), its seconds compiling kernels and its end state (rods in
current-carrying filaments and the current through the gap: runs that take other paths do other
work), and the ratios of the commit's times to the working tree's (above 1: the working tree is
faster; wall, CPU, and each less compiling), the median over the rounds. Use it on an otherwise idle machine; the ratio of two builds,
``NUMBA_CPU_NAME=haswell NUMBA_CPU_FEATURES= selfas-graph bench against_commit ...``, is the
AVX2 build's. Example, the goal of docs/performance.md 'Where the speed goals stand'::

    selfas-graph bench against_commit scenarios/fig2.toml --commit c2989a3 --threads 2
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from ..provenance import machine, source_commit
from .same_as_commit import ROOT, RUNNER, export

#: :data:`~.same_as_commit.RUNNER` with numba's compilations timed (its ``numba:compile`` events, which
#: fire only for kernels not found in the cache; nested compilations counted once), the seconds written
#: at exit to the file named by ``SELFAS_COMPILE_SECONDS``
TIMED_RUNNER = (
    """import atexit, os
from numba.core import event
_compiling = event.TimingListener()
event.register("numba:compile", _compiling)
_to = os.environ["SELFAS_COMPILE_SECONDS"]
atexit.register(lambda: open(_to, "w").write(repr(_compiling.duration if _compiling.done else 0.0)))
"""
    + RUNNER
)


def timed_simulate(code: Path, scenario: Path, sets: list[str], out: Path, threads: int, cwd: Path) -> dict:
    """One ``simulate`` run of ``scenario`` with the package in ``code``: wall and CPU seconds, and the
    seconds numba spent compiling kernels its cache did not hold (``compile_seconds``)."""
    seconds_file = out.with_suffix(".compile_seconds")
    env = dict(
        os.environ,
        PYTHONPATH=str(code),
        NUMBA_NUM_THREADS=str(threads),
        OMP_NUM_THREADS=str(threads),
        SELFAS_COMPILE_SECONDS=str(seconds_file),
    )
    cmd = [sys.executable, "-c", TIMED_RUNNER, str(code), "simulate", str(scenario), "-o", str(out)]
    cmd += ["--progress", "none", "--force"] + [a for s in sets for a in ("--set", s)]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    started = time.perf_counter()
    r = subprocess.run(cmd, env=env, cwd=cwd, capture_output=True, text=True)
    wall = time.perf_counter() - started
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if r.returncode != 0:
        raise SystemExit(f"{code}: simulate {scenario} failed (exit {r.returncode}):\n{r.stdout}{r.stderr}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    compiling = float(seconds_file.read_text())
    seconds_file.unlink()
    return {
        "wall_seconds": wall,
        "cpu_seconds": cpu,
        "compile_seconds": compiling,
        "wall_less_compile_seconds": wall - compiling,
        # numba compiles on one thread, its CPU time about its wall time
        "cpu_less_compile_seconds": cpu - compiling,
        **end_state(out),
    }


def end_state(path: Path) -> dict:
    """The last frame's time, rods in current-carrying filaments and current through the gap of a run
    file (None for what the file lacks)."""
    import h5py

    out = {"t": None, "filament_rods": None, "total_current": None}
    with h5py.File(path, "r") as h:
        for key, name in (
            ("t", "observables/total_current/time"),
            ("filament_rods", "observables/rods/filament/value"),
        ):
            if name in h and len(h[name]):
                out[key] = float(h[name][-1])
        if "observables/total_current/value" in h and len(h["observables/total_current/value"]):
            out["total_current"] = float(h["observables/total_current/value"][-1])
    return out


def _run_text(run: dict) -> str:
    state = (
        f"at t = {run['t']:g}: {run['filament_rods']:.0f} rods carry {run['total_current']:.3g} J0"
        if run["t"] is not None and run["filament_rods"] is not None and run["total_current"] is not None
        else "no current observables"
    )
    return (
        f"wall {run['wall_seconds']:.1f} s, CPU {run['cpu_seconds']:.1f} s, compiling kernels "
        f"{run['compile_seconds']:.1f} s; {state}"
    )


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenario", help="the scene (a path in the repository for --scene own)")
    ap.add_argument("--commit", required=True, help="the commit to time against (e.g. c2989a3, version 0.3.0)")
    ap.add_argument("--threads", type=int, default=1, help="numba threads of every run (default 1)")
    ap.add_argument("--rounds", type=int, default=1, help="timed runs of each code, in turns (default 1)")
    ap.add_argument(
        "--seeds", type=int, nargs="+", help="run each of these seeds in every round (default: the scene's)"
    )
    ap.add_argument("--t-end", type=float, help="end time of every run (default: the scene's)")
    ap.add_argument("--warm-up", type=float, default=0.05, help="untimed first run of each code to this t (0: none)")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override for both codes")
    ap.add_argument(
        "--scene",
        choices=("own", "tree"),
        default="own",
        help="each code's own copy of the scene (default) or the tree's",
    )
    ap.add_argument("--json", type=Path, help="write the runs and ratios to this file")
    ap.add_argument("--keep", type=Path, help="keep the run files in this folder")
    args = ap.parse_args(argv)
    if args.threads < 1 or args.rounds < 1 or (args.t_end is not None and not args.t_end > 0) or args.warm_up < 0:
        ap.error("--threads and --rounds must be >= 1, --t-end > 0 and --warm-up >= 0")
    if args.seeds and (min(args.seeds) < 0 or len(set(args.seeds)) != len(args.seeds)):
        ap.error(f"--seeds: distinct integers >= 0, got {args.seeds}")
    if args.json is not None and not args.json.resolve().parent.is_dir():
        ap.error(f"--json {args.json}: no folder {args.json.resolve().parent}")
    scene_tree = Path(os.path.abspath(args.scenario))
    if not scene_tree.is_file() and (ROOT / args.scenario).is_file():
        scene_tree = ROOT / args.scenario  # a path relative to the repository
    if not scene_tree.is_file():
        ap.error(f"no scenario file {args.scenario}")
    got = subprocess.run(
        ["git", "rev-parse", "--verify", "--quiet", f"{args.commit}^{{commit}}"],
        cwd=ROOT,
        capture_output=True,
        text=True,
    )
    if got.returncode != 0:
        raise SystemExit(f"git archive {args.commit}: no such commit in {ROOT}")
    commit = got.stdout.strip()
    with tempfile.TemporaryDirectory(prefix="against_commit_") as tmp:
        tmp = Path(tmp)
        base = tmp / "code"
        base.mkdir()
        paths = ["selfas_graph"]
        scene_commit = scene_tree
        if args.scene == "own":
            try:
                rel = scene_tree.relative_to(ROOT)
            except ValueError:
                ap.error(f"--scene own: {args.scenario} is not in the repository {ROOT}; pass --scene tree")
            paths.append(rel.as_posix())
            scene_commit = base / rel
            listed = subprocess.run(
                ["git", "cat-file", "-e", f"{commit}:{rel.as_posix()}"], cwd=ROOT, capture_output=True
            )
            if listed.returncode != 0:
                ap.error(f"--scene own: commit {args.commit} has no {rel.as_posix()}; pass --scene tree")
        export(commit, base, paths)
        out_dir = (args.keep or tmp).resolve()
        out_dir.mkdir(parents=True, exist_ok=True)
        # fixed keys and file names, whatever the commit is called (origin/main, tree, ...)
        codes = {"commit": (base, scene_commit), "tree": (ROOT, scene_tree)}
        names = {"commit": args.commit, "tree": "working tree"}
        sets = args.set + ([f"run.t_end={args.t_end!r}"] if args.t_end is not None else [])
        m = machine()
        print(
            f"{m['cpu_model']}, {m['cores']} cores; numba target {m['cpu_name']} ({m['widest']}); "
            f"{args.threads} thread(s) a run; {args.rounds} round(s); {args.commit} = {commit[:10]}"
        )
        if args.warm_up > 0:
            for code, scene in codes.values():
                warm = args.set + [f"run.t_end={args.warm_up!r}"]
                timed_simulate(code, scene, warm, out_dir / "warm.h5", args.threads, tmp)
        record = {
            "machine": m,
            "commit": args.commit,
            "commit_hash": commit,
            "tree_commit": source_commit(),
            "scenario": str(args.scenario),
            "scene": args.scene,
            "threads": args.threads,
            "seeds": args.seeds,
            "t_end": args.t_end,
            "set": args.set,
            "warm_up": args.warm_up,
            "runs": {name: [] for name in codes},
        }
        runs = record["runs"]
        seeds = args.seeds or [None]
        for r in range(args.rounds):
            order = list(codes) if r % 2 == 0 else list(codes)[::-1]
            for seed in seeds:
                own = [] if seed is None else [f"scenario.seed={seed}"]
                tag = "" if seed is None else f"_seed{seed}"
                for name in order:
                    code, scene = codes[name]
                    out = out_dir / f"round{r + 1}{tag}_{name}.h5"
                    run = {
                        "round": r + 1,
                        "seed": seed,
                        **timed_simulate(code, scene, sets + own, out, args.threads, tmp),
                    }
                    runs[name].append(run)
                    print(
                        f"round {r + 1}{'' if seed is None else f', seed {seed}'}, {names[name]}: {_run_text(run)}",
                        flush=True,
                    )
                    if args.json:  # after every run: a later failure loses nothing measured
                        args.json.write_text(json.dumps(record, indent=1))

    def per_round(name, key):
        return [sum(x[key] for x in runs[name] if x["round"] == r + 1) for r in range(args.rounds)]

    record["ratios"] = ratios = {
        key: [a / b for a, b in zip(per_round("commit", key), per_round("tree", key))]
        for key in ("wall_seconds", "cpu_seconds", "wall_less_compile_seconds", "cpu_less_compile_seconds")
    }
    for key, label in (
        ("wall_seconds", "wall"),
        ("cpu_seconds", "CPU"),
        ("wall_less_compile_seconds", "wall less compiling"),
        ("cpu_less_compile_seconds", "CPU less compiling"),
    ):
        rs = ratios[key]
        spread = f" [{min(rs):.3f}-{max(rs):.3f}]" if len(rs) > 1 else ""
        print(f"{label} time, {args.commit} over the working tree: {statistics.median(rs):.3f}{spread}")
    if args.json:
        args.json.write_text(json.dumps(record, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
