"""Where a step goes: the CPU time of a run's steps, by part, from a checkpoint or a fresh scene.

Usage: selfas-graph bench profile --checkpoint RUN.checkpoint.h5 [--steps 2000] [--threads 1]
       selfas-graph bench profile --kernels [--rounds 8] [--steps 3000]
       selfas-graph bench profile --scenario scenarios/fig2.toml --settle 2000 [--steps 2000]
       selfas-graph bench profile --checkpoint RUN.checkpoint.h5 --before REF [--rounds 8] [--steps 250]
       selfas-graph bench profile --checkpoint RUN.checkpoint.h5 --steps 3000 --sample
       selfas-graph bench profile --checkpoint RUN.checkpoint.h5 --team [--phases] [--threads 2] [--rounds 8] [--steps 250]

Steps the simulation ``--steps`` times after 48 warm-up steps under cProfile on the thread's CPU
clock (on a machine loaded by other jobs the wall clock counts their time too), and sorts the time
spent in each function into the parts of a step: the force kernels (each slow sum, the fast close
pairs, the split brake), neighbour-list builds, contact search, events (graph, circuit), and the
rest (integrator, force-field bookkeeping, numpy glue). Kernel calls are counted, so that the cost
per call and the calls per step are both printed. The profile adds some overhead per Python call
(1-2 us); the first line gives the CPU time per step without it, measured on the same steps'
successors.

``--sample`` also runs ``--steps`` more steps under Linux ``perf`` (sampling the CPU clock of every
thread, when ``perf`` is installed and allowed) and splits their CPU time by the code it runs in:
numba's compiled kernels, the Python interpreter, numpy, numba's dispatch, scipy, the C library, the
operating system. Sampling costs nothing per call, so this is the measure of the glue's share; the
profiled table above charges the profiler's own cost of each Python call (two reads of the thread's
clock, 1-2 us) to the Python parts.

A checkpoint is read as the run left it (read only: a copy of a running job's checkpoint is
fine). One written by an older version without a checksum is read without verification, with a
note: the benchmark needs the state, not its provenance.

``--before REF`` compares whole steps instead: two processes, one running the package of the git
revision REF (exported to a temporary folder), one the working tree, both from the same state,
take turns of ``--steps`` steps (``--rounds`` turns each, the first of each discarded as warm-up)
and report their CPU time per step (the thread's with one thread, the process's with more): the two codes see the same machine load, interleaved.
The ratio is the median of the per-round ratios. The wall clock per step is printed too: it counts the
machine's other jobs, so it means something only on a quiet machine (the load average is printed).

``--team``: the compiled fast steps on all threads against on one (``team_steps.py``).

``--kernels`` times the every-step kernels that do the work of several calls (``ab4_step``,
``constrain_bonds_checked``, ``channel_sum_power``, ``extrapolate_all``) against those calls, on
2400 random tips: ``--rounds 8 --steps 3000`` gives 15 interleaved repeats of 300 calls each.

Prints the CPU model and the instruction set numba compiled for (``NUMBA_CPU_NAME``).
"""

import argparse
import cProfile
import json
import os
import pstats
import shutil
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

from .profile_parts import PARTS, part_of

ROOT = Path(__file__).resolve().parents[2]
#: set (unless set) by the command line, not on import (tests import this): a running job's file
#: is read only here (``selfas-graph bench`` sets them too)
COMMAND_ENV = {"HDF5_USE_FILE_LOCKING": "FALSE"}


def start_threads(threads):
    """``numba.set_num_threads(threads)``, after importing the package: it sets ``OMP_WAIT_POLICY``,
    which the OpenMP runtime reads once, when numba starts its threads (started first, the idle
    workers spin between parallel kernels and double the CPU time per step on 2 threads)."""
    import numba

    import selfas_graph  # noqa: F401

    numba.set_num_threads(threads)


def load_state(args):
    """(Simulation, origin text) from ``--checkpoint`` or ``--scenario`` + ``--settle``."""
    from selfas_graph import Simulation, load_scenario
    from selfas_graph.io.checkpoint import CheckpointError, read_checkpoint
    from selfas_graph.io.scenario import scenario_from_text

    if args.checkpoint:
        note = ""
        try:
            snap, meta = read_checkpoint(args.checkpoint)
        except CheckpointError as exc:
            if "checksum" not in str(exc):
                raise SystemExit(str(exc)) from None  # a missing or unreadable file: its message, no traceback
            import h5py

            with h5py.File(args.checkpoint, "r") as f:
                g = f["snapshot"]
                snap = {k: v for k, v in g.attrs.items()}
                for k in g:
                    snap[k] = g[k][()]
                meta = dict(f["meta"].attrs)
            note = " (no checksum: written by an older version, read without verification)"
        sc = scenario_from_text(meta["scenario_text"], overrides=json.loads(meta["overrides"]) + list(args.extra))
        from selfas_graph.model.integrator import same_time_step

        # --set integrator.dt=...: the snapshot continued at that time step, its history forgotten (RK4 again)
        new_dt = not same_time_step(snap, sc.params.integrator.dt)
        sim = Simulation.from_snapshot(sc.params, snap, new_dt=new_dt)
        if new_dt:
            note += f" (at integrator.dt = {sc.params.integrator.dt:g}, started again with RK4)"
        return sim, f"checkpoint {args.checkpoint} at t = {float(snap['time']):.3f}{note}"
    from selfas_graph.io.scenario import ScenarioError

    try:
        sc = load_scenario(args.scenario, overrides=args.extra)
    except ScenarioError as exc:
        raise SystemExit(str(exc)) from None
    sim = Simulation.from_scenario(sc)
    sim.step(args.settle)
    return sim, f"{args.scenario} after {args.settle} steps"


#: (part, test on the path of a shared object as ``perf report -v --sort dso`` names it) in order; the
#: first match wins. Numba's compiled code has no file: perf names it ``[JIT] tid N`` (``perf-N.map``
#: with ``-v``, from the map numba's LLVM leaves).
SAMPLED_PARTS = [
    (
        "compiled kernels (numba)",
        lambda d: d.startswith("[JIT]") or (Path(d).name.startswith("perf-") and d.endswith(".map")),
    ),
    ("Python interpreter", lambda d: "libpython" in d or "lib-dynload" in d or Path(d).name.startswith("python")),
    ("numpy", lambda d: "/numpy/" in d or "numpy.libs" in d),
    (
        "numba's dispatch, runtime and threads",
        lambda d: "/numba/" in d or any(k in d for k in ("libgomp", "libiomp", "libtbb")),
    ),
    ("scipy (the circuit's sparse solve)", lambda d: "/scipy/" in d or "scipy.libs" in d),
    ("HDF5", lambda d: "h5py" in d or "hdf5" in d),
    (
        "C library (allocation, memory copies, maths)",
        lambda d: any(k in Path(d).name for k in ("libc.", "libm.", "ld-linux", "libstdc++", "libgcc")),
    ),
    ("operating system", lambda d: d.startswith("[kernel") or d in ("[vdso]", "[vsyscall]")),
    ("other", lambda d: True),
]
#: the parts that count as Python and numpy, the glue around the kernels; the C library's share
#: (the allocations and copies of numpy and of numba's runtime alike) is an upper bound beside them
GLUE_PARTS = ("Python interpreter", "numpy", "numba's dispatch, runtime and threads")


def sampled_part_of(dso: str) -> str:
    """The part of :data:`SAMPLED_PARTS` a shared object (its path) belongs to."""
    for part, test in SAMPLED_PARTS:
        if test(dso):
            return part
    return SAMPLED_PARTS[-1][0]


def parse_dso_samples(report: str) -> dict:
    """{shared object: samples} from ``perf report --stdio -v --sort dso -F sample,dso`` text."""
    counts = {}
    for line in report.splitlines():
        fields = line.split(None, 1)
        if len(fields) == 2 and fields[0].isdigit() and not line.lstrip().startswith("#"):
            counts[fields[1].strip()] = counts.get(fields[1].strip(), 0) + int(fields[0])
    return counts


def sampled_shares(counts: dict) -> dict:
    """{part: share of the samples} of :func:`parse_dso_samples`' counts, in :data:`SAMPLED_PARTS` order."""
    total = sum(counts.values())
    shares = dict.fromkeys((p for p, _ in SAMPLED_PARTS), 0.0)
    for dso, n in counts.items():
        shares[sampled_part_of(dso)] += n / total if total else 0.0
    return shares


def sample(sim, steps, frequency=4000, timeout=120.0):
    """``({shared object: samples}, None)`` of ``steps`` steps of ``sim`` sampled by Linux perf on the
    CPU clock (every thread of this process), or ``(None, why not)``.

    The split of the CPU time by the code it runs in, without cProfile's cost per Python call (which
    lands in the Python parts of the profiled table): perf attaches to this process, the steps run,
    perf stops. The process sleeps while perf starts and stops, and a sleeping thread draws no sample.
    perf is stopped whatever happens to the steps, each perf command is given ``timeout`` seconds,
    nothing is written outside a temporary folder (``--no-buildid-cache``), which is removed.
    """
    perf = shutil.which("perf")
    if perf is None:
        return None, "perf not found (Debian and Ubuntu: the linux-perf or linux-tools package)"
    import signal

    def reason(text, default):
        lines = [line.strip() for line in text.splitlines() if line.strip() and line.strip() != "Error:"]
        return lines[0] if lines else default

    with tempfile.TemporaryDirectory() as tmp:
        data = Path(tmp) / "perf.data"
        rec = [perf, "record", "-q", "--no-buildid-cache", "-e", "cpu-clock", "-F", str(frequency)]
        rec += ["-p", str(os.getpid()), "-o", str(data)]
        proc = subprocess.Popen(rec, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        try:
            for _ in range(50):  # perf writes its file's header once it is attached
                if proc.poll() is not None or (data.exists() and data.stat().st_size > 0):
                    break
                time.sleep(0.1)
            time.sleep(0.2)
            if proc.poll() is not None:
                return None, "perf record failed: " + reason(proc.stderr.read(), f"exit {proc.returncode}")
            sim.step(steps)
        finally:
            if proc.poll() is None:
                proc.send_signal(signal.SIGINT)
                try:
                    proc.communicate(timeout=timeout)
                except subprocess.TimeoutExpired:
                    proc.kill()
                    proc.communicate()
        try:
            report = subprocess.run(
                [perf, "report", "-i", str(data), "--stdio", "-v", "--sort", "dso", "-F", "sample,dso"],
                capture_output=True,
                text=True,
                timeout=timeout,
            )
        except subprocess.TimeoutExpired:
            return None, f"perf report took more than {timeout:g} s"
    if report.returncode != 0:
        return None, "perf report failed: " + reason(report.stderr, f"exit {report.returncode}")
    counts = parse_dso_samples(report.stdout)
    if not counts:
        return None, "perf recorded no samples (too few steps?)"
    return counts, None


def profile(sim, steps):
    """{part: CPU seconds} and {kernel function: calls} over ``steps`` steps."""
    pr = cProfile.Profile(time.thread_time)
    pr.enable()
    sim.step(steps)
    pr.disable()
    st = pstats.Stats(pr)
    parts = defaultdict(float)
    calls = {}
    for key, (_cc, nc, tt, _ct, _callers) in st.stats.items():
        parts[part_of(key)] += tt
        if "selfas_graph/kernels/" in key[0].replace(os.sep, "/") and key[2] != "__call__" and tt > 0:
            calls[key[2]] = calls.get(key[2], 0) + nc
    return parts, calls


def export(ref):
    """The tree of git revision ``ref`` in a temporary folder (kept, keyed by its commit): its path.

    Today's ``selfas_graph/bench/profile.py`` and the module it imports, ``profile_parts.py``, are put
    beside that revision's package (as ``selfas_graph/bench``), so that the child of ``--before`` serves
    steps the same way with the old code (a revision without ``profile_parts.py``, or with another, failed)."""
    sha = subprocess.run(["git", "rev-parse", ref], cwd=ROOT, capture_output=True, text=True, check=True).stdout.strip()
    dest = Path(tempfile.gettempdir()) / "selfas_bench_profile" / sha[:12]
    if not (dest / "selfas_graph").exists():
        dest.mkdir(parents=True, exist_ok=True)
        archive = subprocess.run(["git", "archive", sha], cwd=ROOT, capture_output=True, check=True).stdout
        subprocess.run(["tar", "-x", "-C", str(dest)], input=archive, check=True)
    bench = dest / "selfas_graph" / "bench"
    bench.mkdir(exist_ok=True)
    for f in ("__init__.py", "profile.py", "profile_parts.py"):
        shutil.copyfile(Path(__file__).with_name(f), bench / f)
    return dest


def serve(args):
    """Child of ``--before``: load the state, then run ``--steps`` steps per line read, print the CPU time."""
    start_threads(args.threads)
    sim, origin = load_state(args)
    sim.step(48)
    import selfas_graph

    print(json.dumps({"origin": origin, "rods": sim.state.n_rods, "package": selfas_graph.__file__}), flush=True)
    # one thread: the thread's CPU clock; more: the process's, which counts the workers too
    clock = time.thread_time if args.threads == 1 else time.process_time
    for line in sys.stdin:
        if not line.strip():
            break
        t0, w0 = clock(), time.perf_counter()
        sim.step(args.steps)
        cpu, wall = (clock() - t0) / args.steps, (time.perf_counter() - w0) / args.steps
        print(json.dumps({"cpu": cpu, "wall": wall, "active": int(len(sim.force_field.active_rod))}), flush=True)


def compare(args):
    from .peer import machine_line, tool_command, tool_env

    base = [
        *tool_command("profile"),
        "--serve",
        "--steps",
        str(args.steps),
        "--threads",
        str(args.threads),
        "--settle",
        str(args.settle),
        "--scenario",
        args.scenario,
    ]
    base += ["--checkpoint", args.checkpoint] if args.checkpoint else []
    for e in args.extra:
        base += ["--set", e]
    old_root = export(args.before)
    procs = {}
    for name, root in (("before", old_root), ("after", ROOT)):
        env = dict(os.environ)
        env.pop("PYTHONPATH", None)
        env = tool_env(env, root)
        procs[name] = subprocess.Popen(base, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env)
    head = {k: json.loads(p.stdout.readline()) for k, p in procs.items()}
    times = {k: [] for k in procs}
    walls = {k: [] for k in procs}
    for r in range(args.rounds + 1):
        for name in ("before", "after") if r % 2 == 0 else ("after", "before"):
            p = procs[name]
            p.stdin.write("go\n")
            p.stdin.flush()
            got = json.loads(p.stdout.readline())
            if r > 0:
                times[name].append(got["cpu"])
                walls[name].append(got["wall"])
    for p in procs.values():
        p.stdin.write("\n")
        p.stdin.close()
        p.wait()
    b, a = np.array(times["before"]), np.array(times["after"])
    print(machine_line())
    print(f"before: {head['before']['package']}; after: {head['after']['package']}")
    print(
        f"{head['after']['origin']}; {args.threads} numba thread(s); {args.rounds} rounds of {args.steps} steps each, "
        f"interleaved; load average {os.getloadavg()[0]:.1f}"
    )
    what = "CPU of the thread" if args.threads == 1 else "CPU of the process, all threads"
    print(f"before ({args.before}): {1e3 * np.median(b):.3f} ms/step {what} [{1e3 * b.min():.3f}-{1e3 * b.max():.3f}]")
    print(f"after (working tree): {1e3 * np.median(a):.3f} ms/step {what} [{1e3 * a.min():.3f}-{1e3 * a.max():.3f}]")
    r = b / a
    print(f"speed-up before/after: {np.median(r):.3f} [{r.min():.3f}-{r.max():.3f}]")
    wb, wa = np.array(walls["before"]), np.array(walls["after"])
    print(
        f"wall clock per step (counts the machine's other jobs): before {1e3 * np.median(wb):.3f} ms, "
        f"after {1e3 * np.median(wa):.3f} ms, ratio {np.median(wb / wa):.3f}"
    )


def fused_kernels(tips=2400, calls=300, repeats=15):
    """The every-step kernels that do the work of several calls, each against the calls it replaced
    (the same numbers bit for bit, tests/unit/test_step_kernels.py), on random tips, one thread, CPU time,
    interleaved: {name: (before us, after us, median per-repeat speed-up)}."""
    from selfas_graph.kernels import integrate as ki
    from selfas_graph.kernels import rigid as kr

    rng = np.random.default_rng(0)
    n = tips
    x0, v0, ell = rng.normal(size=(n, 3)), rng.normal(size=(n, 3)), np.zeros(0)
    hv, ha, slots = rng.normal(size=(4, n, 3)), rng.normal(size=(4, n, 3)), np.array([3, 2, 1, 0])
    x, v = x0.copy(), v0.copy()
    c, total = rng.normal(size=(10, n, 3)), np.zeros((n, 3))
    powered, power = np.array([1, 2, 4, 7, 8, 9]), np.zeros(6)
    held = tuple(rng.normal(size=(n, 3)) for _ in range(4))
    rate, base, steps = rng.normal(size=(4, n, 3)), rng.normal(size=(4, n, 3)), np.full(4, 5.0)

    def step_before():
        x[:], v[:] = x0, v0
        ki.ab4_update(x, hv[3], hv[2], hv[1], hv[0], 1e-3, x)
        ki.ab4_update(v, ha[3], ha[2], ha[1], ha[0], 1e-3, v)
        kr.bond_length_error(x, ell)
        kr.constrain_bonds(x, v, True, True, ell)
        kr.bond_length_error(x, ell)
        float(np.abs(v).max(initial=0.0))

    def step_after():
        x[:], v[:] = x0, v0
        ki.ab4_step(x, v, hv, ha, slots, 1e-3, ell)
        kr.constrain_bonds_checked(x, v, True, True, ell)

    def sum_before():
        ki.channel_sum(total, c)
        for j, k in enumerate(powered):
            power[j] = np.einsum("ij,ij->", c[k], v)

    def sum_after():
        ki.channel_sum_power(total, c, v, powered, power)

    def extrapolate_before():
        for j in range(4):
            ki.extrapolate(held[j], rate[j], base[j], 5.0)

    def extrapolate_after():
        ki.extrapolate_all(held, rate, base, steps)

    cases = {
        f"channel sum of 10 channels and {len(powered)} powers": (sum_before, sum_after),
        "AB4 update, bond check, constraint, bond check, max abs v": (step_before, step_after),
        "extrapolation of 4 held arrays": (extrapolate_before, extrapolate_after),
    }
    times = {k: ([], []) for k in cases}
    for pair in cases.values():
        for f in pair:
            f()  # compiled
    for r in range(repeats):
        for name, pair in cases.items():
            for i in (0, 1) if r % 2 == 0 else (1, 0):
                t0 = time.thread_time()
                for _ in range(calls):
                    pair[i]()
                times[name][i].append(1e6 * (time.thread_time() - t0) / calls)
    return {
        k: (float(np.median(b)), float(np.median(a)), float(np.median(np.array(b) / np.array(a))))
        for k, (b, a) in times.items()
    }


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--checkpoint", help="start from this checkpoint (read only)")
    ap.add_argument("--scenario", default=str(ROOT / "scenarios" / "fig2.toml"))
    ap.add_argument("--settle", type=int, default=2000, help="steps before the profile, from a fresh scene")
    ap.add_argument("--steps", type=int, default=2000)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--set", dest="extra", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--json", help="write the figures to this file")
    ap.add_argument("--before", help="compare whole steps with the package of this git revision, interleaved")
    ap.add_argument("--rounds", type=int, default=8)
    ap.add_argument(
        "--kernels", action="store_true", help="time the fused every-step kernels against the calls they replaced"
    )
    ap.add_argument(
        "--sample",
        action="store_true",
        help="also sample --steps more steps with Linux perf: the CPU time by the code it runs in "
        "(compiled kernels, Python, numpy, ...), without the profiler's cost per Python call",
    )
    from .team_steps import add_team_arguments, team  # team_steps imports this module

    add_team_arguments(ap)
    ap.add_argument("--serve", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.serve:
        return serve(args)
    if args.kernels:
        from .peer import machine_line

        start_threads(1)
        figures = fused_kernels(calls=max(1, args.steps // 10), repeats=args.rounds * 2 - 1)
        print(machine_line())
        print(f"2400 random tips, 1 numba thread, CPU time, interleaved; load average {os.getloadavg()[0]:.1f}\n")
        print("| calls | before (us) | after (us) | speed-up |")
        print("|---|---|---|---|")
        for name, (b, a, r) in figures.items():
            print(f"| {name} | {b:.1f} | {a:.1f} | {r:.2f} |")
        return None
    if args.before:
        return compare(args)
    if args.team or args.phases:
        return team(args)
    from .peer import machine, machine_line

    start_threads(args.threads)
    sim, origin = load_state(args)
    sim.step(48)  # compiled kernels, warm caches
    t0 = time.thread_time()
    sim.step(args.steps)
    plain = (time.thread_time() - t0) / args.steps
    active = len(sim.force_field.active_rod)
    parts, calls = profile(sim, args.steps)
    total = sum(parts.values())
    print(machine_line())
    print(
        f"{origin}; {sim.state.n_rods} rods, {active} carrying current at the end; {args.threads} numba "
        f"thread(s); load average {os.getloadavg()[0]:.1f}"
    )
    print(
        f"CPU time per step of the main thread (time.thread_time; the workers' time is not in it): "
        f"{1e3 * plain:.3f} ms without the profiler, {1e3 * total / args.steps:.3f} ms with it "
        f"({args.steps} steps each)\n"
    )
    print("| part | ms/step | share |")
    print("|---|---|---|")
    for part, _ in PARTS:
        if parts.get(part, 0.0) > 0.0:
            print(f"| {part} | {1e3 * parts[part] / args.steps:.3f} | {100 * parts[part] / total:.1f} % |")
    print(f"| total (profiled) | {1e3 * total / args.steps:.3f} | 100 % |\n")
    top = sorted(calls.items(), key=lambda kv: -kv[1])
    print("kernel calls per 1000 steps: " + ", ".join(f"{k} {1000 * v / args.steps:.0f}" for k, v in top[:14]))
    shares = None
    if args.sample:
        counts, why = sample(sim, args.steps)
        if counts is None:
            print(f"\nno sampled profile: {why}")
        else:
            shares = sampled_shares(counts)
            print(
                f"\nCPU time by the code it runs in, {args.steps} more steps sampled by perf ({sum(counts.values())} "
                "samples, no cost per Python call):\n"
            )
            print("| code | share |")
            print("|---|---|")
            for part, share in shares.items():
                if share > 0.0:
                    print(f"| {part} | {100 * share:.1f} % |")
            glue = sum(shares[p] for p in GLUE_PARTS)
            libc = shares["C library (allocation, memory copies, maths)"]
            print(
                f"\nPython and numpy ({', '.join(GLUE_PARTS)}): {100 * glue:.1f} %; with the C library's "
                f"allocations and copies, at most {100 * (glue + libc):.1f} %"
            )
    if args.json:
        Path(args.json).write_text(
            json.dumps(
                {
                    "machine": machine(),
                    "origin": origin,
                    "steps": args.steps,
                    "ms_per_step": 1e3 * plain,
                    "active_rods": active,
                    "parts_ms_per_step": {k: 1e3 * v / args.steps for k, v in parts.items()},
                    "kernel_calls": calls,
                    "sampled_shares": shares,
                },
                indent=1,
            )
        )


if __name__ == "__main__":
    for key, value in COMMAND_ENV.items():
        os.environ.setdefault(key, value)
    main()
