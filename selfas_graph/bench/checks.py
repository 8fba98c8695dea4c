"""The per-step checks that became kernels, against the numpy code they replace, in one process.

Usage: selfas-graph bench checks --checkpoint RUN.checkpoint.h5 [--repeat 15] [--calls 200]
       selfas-graph bench checks --scenario scenarios/fig2.toml --settle 2000

On a state from a checkpoint (read as selfas_graph/bench/profile.py reads it) or a settled scene, times,
on one numba thread and the thread's CPU clock, interleaved (the order alternates between repeats):

- ``contact check``: ``ContactTracker.search`` on a step without events, with its one-pass
  kernel (``kernels/contacts.py::contacts_unchanged``) and with the kernel answering "no" (so the
  full numpy check runs, as before the kernel existed);
- ``skin check``: a Verlet list's largest displacement since its build over all tips, by
  ``kernels/cells.py::max_displacement2`` and by the three numpy passes it replaced.

Prints microseconds per call (median of the repeats), the ratio, the CPU model and the
instruction set numba compiled for (``NUMBA_CPU_NAME``).
"""

import argparse
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]


def interleaved(a, b, repeat, calls):
    """Median microseconds per call of ``a`` and ``b``, and the median of the per-repeat ratios."""
    ta, tb = [], []
    for r in range(repeat + 1):
        for fn, t in ((a, ta), (b, tb)) if r % 2 == 0 else ((b, tb), (a, ta)):
            t0 = time.thread_time()
            for _ in range(calls):
                fn()
            t.append(1e6 * (time.thread_time() - t0) / calls)
    ta, tb = np.array(ta[1:]), np.array(tb[1:])  # the first repeat warms up
    return float(np.median(ta)), float(np.median(tb)), float(np.median(ta / tb))


def run(args):
    import numba

    import selfas_graph.model.contacts as contacts_module
    from selfas_graph.kernels.cells import max_displacement2

    from .peer import machine_line
    from .profile import load_state

    numba.set_num_threads(1)
    sim, origin = load_state(args)
    sim.step(8)
    position = sim.state.position
    nl = sim.force_field.tip_neighbours(position)
    sim.network.update(position, nl, 0, 0.0)  # any events of this step applied: the next search is quiet
    tracker, contacts = sim.network.tracker, sim.network.contacts
    kernel = contacts_module.contacts_unchanged

    def full_check():
        contacts_module.contacts_unchanged = lambda *a: False
        try:
            tracker.search(contacts, position, nl, 0, 0.0)
        finally:
            contacts_module.contacts_unchanged = kernel

    reference = position + 1e-4

    def skin_numpy():
        d = position - reference
        return np.einsum("ij,ij->i", d, d).max(initial=0.0)

    rows = [
        ("contact check, step without events", full_check, lambda: tracker.search(contacts, position, nl, 0, 0.0)),
        (f"skin check, {len(position)} tips", skin_numpy, lambda: max_displacement2(position, reference)),
    ]
    print(machine_line())
    print(f"{origin}; {sim.contacts.n_contacts} contacts; one thread, CPU time, median of {args.repeat}")
    print("| check | numpy (us) | kernel (us) | ratio |")
    print("|---|---|---|---|")
    out = {}
    for name, a, b in rows:
        ma, mb, r = interleaved(a, b, args.repeat, args.calls)
        out[name] = (ma, mb, r)
        print(f"| {name} | {ma:.1f} | {mb:.1f} | {r:.1f} |")
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--checkpoint", help="start from this checkpoint (read only)")
    ap.add_argument("--scenario", default=str(ROOT / "scenarios" / "fig2.toml"))
    ap.add_argument("--settle", type=int, default=2000)
    ap.add_argument("--repeat", type=int, default=15)
    ap.add_argument("--calls", type=int, default=200)
    ap.add_argument("--set", dest="extra", action="append", default=[], metavar="KEY=VALUE")
    return run(ap.parse_args(argv))


if __name__ == "__main__":
    main()
