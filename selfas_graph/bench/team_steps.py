"""``selfas-graph bench profile --checkpoint RUN.checkpoint.h5 --team [--phases] [--threads 2] [--rounds 8] [--steps 250]``:
what the threads buy in the compiled fast steps (docs/performance.md 'Fast steps on both cores').

In one process on ``--threads`` threads (default 2), turns of ``--steps`` steps with the fast steps on
all threads (``kernels/steps.py::fast_steps_team``) and on the calling thread only (``fast_steps``; the
slow sums and list builds on all threads in both), ``--rounds`` turns each, interleaved, the first of
each discarded; prints the wall and CPU time per step and the median ratio of the wall times. The two
give the same numbers bit for bit (tests/unit/test_compiled_steps.py), so the state goes on from turn
to turn. Meaningful on an otherwise idle machine only.

``--phases``: then as many turns again with the phases of the compiled calls timed
(``FastStepArgs.phase_time``: the cycle counter read by the leading thread around each phase and around
its whole part of each call, x86-64 only) and a table of the microseconds per fast step of each kind of
phase both ways: what the threads buy per part. The counter's rate is measured against
``time.perf_counter`` over the turns (on x86-64 CPUs since about 2008 it runs at a fixed rate); "whole
call" is the compiled part of the calls (not the Python that builds their arguments and books their
results), "between phases" its rest (the control flow, the serial checks between phases); the last row
is the calls on the wall clock, with that Python and the fork and join of the threads: far above "whole
call" on all threads, a thread was late to come or away (another job on its core).
"""

import os
import platform
import time

import numpy as np

from .profile import load_state, start_threads


def add_team_arguments(ap):
    """``--team`` and ``--phases`` on the argument parser of ``bench profile``."""
    ap.add_argument(
        "--team",
        action="store_true",
        help="whole steps with the compiled fast steps on all --threads threads (default 2) against on one, "
        "interleaved, wall time",
    )
    ap.add_argument(
        "--phases",
        action="store_true",
        help="with --team: also time each phase of the compiled fast steps (forces, update, ...) both ways, "
        "by the CPU's cycle counter (x86-64)",
    )


#: the two ways of making the compiled fast steps, timed in turns
MODES = ("all threads", "one thread")


def _turns(rounds):
    """``(round, mode)`` for ``rounds`` rounds of both :data:`MODES`, their order swapped every other round,
    ``model/compiled.py::TEAM_TIPS`` set for each mode and put back at the end."""
    from selfas_graph.model import compiled

    limit = compiled.TEAM_TIPS
    try:
        for r in range(rounds):
            for mode in MODES if r % 2 == 0 else MODES[::-1]:
                compiled.TEAM_TIPS = 0 if mode == MODES[0] else 2**62
                yield r, mode
    finally:
        compiled.TEAM_TIPS = limit


def team(args):
    """``--team``: whole steps with the compiled fast steps on all threads and on one, interleaved."""
    import numba

    if not args.team:
        raise SystemExit("--phases times the phases of --team; give both")

    from .peer import machine_line

    threads = 2 if args.threads == 1 else args.threads
    if threads < 1:
        raise SystemExit(f"--threads must be a positive number of numba threads, not {threads}")
    if threads > numba.config.NUMBA_NUM_THREADS:
        raise SystemExit(f"--team needs {threads} numba threads; this machine gives {numba.config.NUMBA_NUM_THREADS}")
    start_threads(threads)
    sim, origin = load_state(args)
    sim.step(48)
    if sim.compiled is None:
        raise SystemExit(f"{origin}: this scene's steps all run in Python (no compiled fast steps to compare)")
    walls, cpus = {m: [] for m in MODES}, {m: [] for m in MODES}
    for r, mode in _turns(args.rounds + 1):
        t0, c0 = time.perf_counter(), time.process_time()
        sim.step(args.steps)
        if r > 0:
            walls[mode].append((time.perf_counter() - t0) / args.steps)
            cpus[mode].append((time.process_time() - c0) / args.steps)
    print(machine_line())
    print(
        f"{origin}; {sim.state.n_rods} rods; {threads} numba threads; {args.rounds} rounds of {args.steps} steps "
        f"each way, interleaved; load average {os.getloadavg()[0]:.1f}"
    )
    print("| compiled fast steps | wall ms/step | CPU ms/step (process) |")
    print("|---|---|---|")
    for mode in walls:
        w, c = 1e3 * np.array(walls[mode]), 1e3 * np.array(cpus[mode])
        print(f"| on {mode} | {np.median(w):.3f} [{w.min():.3f}-{w.max():.3f}] | {np.median(c):.3f} |")
    ratio = np.array(walls["one thread"]) / np.array(walls["all threads"])
    print(f"speed-up of the whole step (wall): {np.median(ratio):.3f} [{ratio.min():.3f}-{ratio.max():.3f}]")
    if args.phases:
        phases(sim, args)
    return None


#: the kinds of phase of kernels/step_tasks.py, by their number
PHASE_NAMES = {
    1: "tip-list test before the step",
    2: "forces",
    3: "AB4 update and powers",
    4: "step undone",
    5: "split brake's pair search",
    6: "split brakes (one task)",
    7: "constraint",
    8: "contact test",
}


def phases(sim, args):
    """``--phases``: the compiled calls' phases timed, the fast steps on all threads and on one in turns."""
    from selfas_graph.model import compiled

    if platform.machine().lower() not in ("x86_64", "amd64"):
        print(f"--phases: the cycle counter is read on x86-64 only, not on {platform.machine()}")
        return
    from selfas_graph.kernels.team import read_ticks

    cs = sim.compiled
    make = compiled.CompiledSteps.advance
    totals = {m: np.zeros(len(PHASE_NAMES) + 1) for m in MODES}
    steps = dict.fromkeys(MODES, 0)
    walls = dict.fromkeys(MODES, 0.0)
    mode = MODES[0]

    def counted(self, n_max):
        w0 = time.perf_counter()
        done, reason = make(self, n_max)
        walls[mode] += time.perf_counter() - w0
        steps[mode] += done
        return done, reason

    kept = cs.phase_time
    compiled.CompiledSteps.advance = counted
    read_ticks()  # compiled before the clock starts: else its compilation counts in the rate as time without ticks
    t0, k0 = time.perf_counter(), read_ticks()
    try:
        for _, mode in _turns(args.rounds):
            cs.phase_time = totals[mode]
            sim.step(args.steps)
    finally:
        compiled.CompiledSteps.advance = make
        cs.phase_time = kept
    rate = (read_ticks() - k0) / (time.perf_counter() - t0)  # ticks per second
    print(
        f"\nphases of the compiled calls, us per fast step (the leading thread's view; cycle counter at {rate / 1e9:.2f} GHz):"
    )
    print("| phase | on all threads | on one thread | speed-up |")
    print("|---|---|---|---|")
    per = {}
    for m, t in totals.items():
        if steps[m] == 0 or t[0] <= 0:
            print(f"no compiled fast steps on {m}")
            return
        per[m] = t / rate / steps[m] * 1e6
    rows = [(PHASE_NAMES[k], k) for k in PHASE_NAMES] + [("between phases", None), ("whole call", 0)]
    for name, k in rows:
        a, o = ((per[m][0] - per[m][1:].sum() if k is None else per[m][k]) for m in MODES)
        if k is not None and k > 0 and a == 0.0 and o == 0.0:
            continue  # a kind of phase these steps never opened
        print(f"| {name} | {a:.1f} | {o:.1f} | {o / a if a > 0 else float('nan'):.2f} |")
    # the caller's view: the whole call on the wall clock, with the Python that builds its arguments, the fork
    # of the threads and their join; far above "whole call" on all threads, a thread came late or was away
    a, o = (walls[m] / steps[m] * 1e6 for m in MODES)
    print(f"| the call, wall clock (fork and join of the threads, Python) | {a:.1f} | {o:.1f} | {o / a:.2f} |")
    print(f"(fast steps timed: {steps['all threads']} on all threads, {steps['one thread']} on one)")
