"""``selfas-graph bench profile --checkpoint RUN.checkpoint.h5 --team [--threads 2] [--rounds 8] [--steps 250]``:
what the threads buy in the compiled fast steps (docs/performance.md 'Fast steps on both cores').

In one process on ``--threads`` threads (default 2), turns of ``--steps`` steps with the fast steps on
all threads (``kernels/steps.py::fast_steps_team``) and on the calling thread only (``fast_steps``; the
slow sums and list builds on all threads in both), ``--rounds`` turns each, interleaved, the first of
each discarded; prints the wall and CPU time per step and the median ratio of the wall times. The two
give the same numbers bit for bit (tests/unit/test_compiled_steps.py), so the state goes on from turn
to turn. Meaningful on an otherwise idle machine only.
"""

import os
import time

import numpy as np

from .profile import load_state, start_threads


def team(args):
    """``--team``: whole steps with the compiled fast steps on all threads and on one, interleaved."""
    import numba

    from selfas_graph.model import compiled

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
    walls, cpus = {"all threads": [], "one thread": []}, {"all threads": [], "one thread": []}
    limit = compiled.TEAM_TIPS
    try:
        for r in range(args.rounds + 1):
            for mode in ("all threads", "one thread") if r % 2 == 0 else ("one thread", "all threads"):
                compiled.TEAM_TIPS = 0 if mode == "all threads" else 2**62
                t0, c0 = time.perf_counter(), time.process_time()
                sim.step(args.steps)
                if r > 0:
                    walls[mode].append((time.perf_counter() - t0) / args.steps)
                    cpus[mode].append((time.process_time() - c0) / args.steps)
    finally:
        compiled.TEAM_TIPS = limit
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
    return None
