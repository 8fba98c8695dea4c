"""Accuracy and cost of the quadrature of term 10 (the Lorentz force on rod currents) on a run's state.

Usage: selfas-graph bench lorentz_rule --checkpoint RUN.checkpoint.h5 [--rule 4:0 2:1.5 ...] [--rounds 7]

Each ``--rule N:R`` is ``forces.current_lorentz.quadrature_points = N`` with ``near_range = R``
(R = 0: the plain rule on every pair; docs/model.md 'Term 10'), the rest of the run's scenario as it
is (its ``precision`` too). For each rule the tool computes the term once on the checkpoint's state
and compares the tip forces with a converged reference: the field of the other rods' currents
integrated along each rod by 64 Gauss-Legendre points, and for the pairs with centres closer than
3 rod lengths (where the field is peaked) by 2048 panels of 4 points (converged to about 1e-13 of
the force here: twice as many panels change it by less). Errors are given relative to the rms
tip force of the term, as median, 99th percentile and largest over the tips of current-carrying
rods. The CPU time of one evaluation of the term (the thread's, median of ``--rounds``, the rules
taking turns) follows, with the ratio to the first rule's time in the same round.

Prints the CPU model and the instruction set numba compiled for (``NUMBA_CPU_NAME``).
"""

import argparse
import time

import numpy as np

import selfas_graph  # noqa: F401  before any kernel runs: it sets the OpenMP wait policy
from selfas_graph.kernels import currents as kc
from selfas_graph.kernels import lorentz as kl

from .peer import machine_line
from .profile import load_state


def lorentz_force(ff, active, rule, sources=None, rods=None, with_fields=True):
    """Term 10 on ``rods`` (default: every active rod) by the rule ``(t, wt)`` from the currents of
    ``sources`` (default: every active rod) and, with ``with_fields``, every field source."""
    t, wt = rule
    rods = active if rods is None else rods
    pts = np.empty((len(rods) * len(t), 3))
    kl.quadrature_points(ff.position, rods, t, pts)
    field = np.empty_like(pts)
    src = active if sources is None else sources
    kc.rod_current_field(pts, np.repeat(rods, len(t)), ff.position, src, ff.current, ff.wire_radius, field)
    if with_fields:
        extra = np.empty_like(pts)
        for source in ff.field_sources:
            source.field_at(pts, extra)
            field += extra
    out = np.zeros_like(ff.position)
    kl.lorentz_force_on_rods(ff.position, rods, ff.current, field, t, wt, out)
    return out


def composite(panels, points=4):
    t4, w4 = kl.gauss_legendre_01(points)
    edges = np.linspace(0.0, 1.0, panels + 1)
    t = np.concatenate([a + (b - a) * t4 for a, b in zip(edges[:-1], edges[1:])])
    wt = np.concatenate([(b - a) * w4 for a, b in zip(edges[:-1], edges[1:])])
    return t, wt


def reference(ff, active, near=3.0, panels=2048):
    """The converged term: 64 points for far pairs, ``panels`` panels of 4 points for near ones."""
    far = kl.gauss_legendre_01(64)
    fine = composite(panels)
    out = lorentz_force(ff, active, far)
    centre = 0.5 * (ff.position[2 * active] + ff.position[2 * active + 1])
    for r, i in enumerate(active):
        d = np.linalg.norm(centre - centre[r], axis=1)
        nb = active[(d < near) & (active != i)]
        if len(nb):
            one = np.array([i])
            out += lorentz_force(ff, active, fine, nb, one, False) - lorentz_force(ff, active, far, nb, one, False)
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--checkpoint", required=True, help="a run's checkpoint with currents flowing (read only)")
    ap.add_argument("--rule", nargs="+", default=["4:0", "2:1.5", "2:2", "3:1.5"], help="N:R pairs")
    ap.add_argument("--rounds", type=int, default=7)
    ap.add_argument("--set", dest="extra", action="append", default=[], metavar="KEY=VALUE")
    args = ap.parse_args(argv)
    print(machine_line())
    rules = []
    for spec in args.rule:
        n, r = spec.split(":")
        rules.append((int(n), float(r)))
    sims = []
    for n, r in rules:
        extra = args.extra + [f"forces.current_lorentz.quadrature_points={n}", f"forces.current_lorentz.near_range={r}"]
        ns = argparse.Namespace(checkpoint=args.checkpoint, extra=extra, scenario=None, settle=0)
        sim, note = load_state(ns)
        sims.append(sim)
    print(note)
    ff0 = sims[0].force_field
    active = ff0.active_rod.copy()
    if not len(active):
        raise SystemExit(f"{args.checkpoint}: no rod carries current in this state; term 10 is zero")
    print(f"{len(active)} of {ff0.n_rods} rods carry current; reference: 64 points, 2048 x 4 within 3 L")
    ref = reference(ff0, active)
    check = reference(ff0, active, panels=4096)
    tips = np.concatenate([2 * active, 2 * active + 1])
    scale = np.sqrt(np.mean(np.sum(ref[tips] ** 2, axis=1)))
    print(f"reference against twice the panels: largest difference {np.abs(check - ref).max() / scale:.1e} of the rms")
    results = []
    for (n, r), sim in zip(rules, sims):
        ff = sim.force_field
        term = next(t for t in ff.terms if t.name == "current_lorentz")
        out = {"current_lorentz": np.zeros_like(ff.position)}
        term.compute(ff.context, out)
        e = np.linalg.norm(out["current_lorentz"][tips] - ref[tips], axis=1) / scale
        results.append([n, r, term, ff.context, out, e, []])
    for _ in range(args.rounds):
        for res in results:
            t0 = time.thread_time()
            res[2].compute(res[3], res[4])
            res[6].append(time.thread_time() - t0)
    base = np.array(results[0][6])
    print()
    print(
        "| quadrature_points | near_range | CPU ms per evaluation | ratio to the first | median error | p99 | largest |"
    )
    print("|---|---|---|---|---|---|---|")
    for n, r, _, _, _, e, ts in results:
        ts = np.array(ts)
        ratio = np.median(base / ts)
        print(
            f"| {n} | {r:g} | {1e3 * np.median(ts):.2f} [{1e3 * ts.min():.2f}-{1e3 * ts.max():.2f}] | "
            f"{ratio:.2f} | {np.median(e):.1e} | {np.quantile(e, 0.99):.1e} | {e.max():.1e} |"
        )


if __name__ == "__main__":
    main()
