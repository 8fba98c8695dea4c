"""Accuracy and cost of the quadrature of the external dipole's line charge (term 11) on a run's state.

Usage: selfas-graph bench line_charge --checkpoint RUN.checkpoint.h5 [--points 32 24 16 12 8] [--rounds 15]
       selfas-graph bench line_charge --scenario scenarios/fig8.toml --settle 2000 [...]

Each ``--points N`` is ``forces.external_dipole.quadrature_points = N``: the Gauss-Legendre points of
the integral along the line, in the variable u = asinh((z' - z) / rho_e) (docs/model.md 'Term 11';
``selfas_graph/kernels/external.py::line_yukawa_on_centres``). For each N the tool evaluates the force
on every rod centre of the state and compares it with the converged integral (1024 points, itself
checked against 2048); errors are given relative to the rms force of the term over the rods, as
median, 99th percentile and largest. The rods closest to the axis, where the integrand peaks, err
most: the tool prints how many lie within 0.5 L of it. The CPU time of one evaluation (the thread's,
median of ``--rounds``, the settings taking turns) follows, with the ratio to the first setting's
time in the same round.

Prints the CPU model and the instruction set numba compiled for (``NUMBA_CPU_NAME``).
"""

import argparse
import time

import numpy as np

import selfas_graph  # noqa: F401  before any kernel runs: it sets the OpenMP wait policy
from selfas_graph.kernels import external as kx
from selfas_graph.kernels import lorentz as kl

from .peer import machine_line
from .profile import load_state

#: points of the reference integral, and of its check
REFERENCE_POINTS = (1024, 2048)


def line_force(centre, rod_charge, line, points):
    """The line charge's force on each rod centre by ``points`` Gauss-Legendre points."""
    nodes, weights = kl.gauss_legendre_01(points)
    out = np.zeros_like(centre)
    kx.line_yukawa_on_centres(centre, rod_charge, *line, nodes, weights, out)
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--checkpoint", help="a run's checkpoint of a scene with [forces.external_dipole] (read only)")
    ap.add_argument("--scenario", help="or a scenario, run for --settle steps first")
    ap.add_argument("--settle", type=int, default=0)
    ap.add_argument("--points", type=int, nargs="+", default=[32, 24, 16, 12, 8])
    ap.add_argument("--rounds", type=int, default=15)
    ap.add_argument("--set", dest="extra", action="append", default=[], metavar="KEY=VALUE")
    args = ap.parse_args(argv)
    if not args.checkpoint and not args.scenario:
        ap.error("give --checkpoint or --scenario")
    if any(n < 1 for n in args.points) or args.rounds < 1:
        ap.error("--points and --rounds must be positive")
    print(machine_line())
    sim, note = load_state(args)
    print(note)
    term = next((t for t in sim.force_field.terms if t.name == "external_line_charge"), None)
    if term is None:
        raise SystemExit("the scene has no [forces.external_dipole]: no line charge to measure")
    pos = sim.state.position
    centre = 0.5 * (pos[0::2] + pos[1::2])
    q = sim.state.rod_charge
    rho = np.hypot(centre[:, 0], centre[:, 1])
    ref, check = (line_force(centre, q, term.line, n) for n in REFERENCE_POINTS)
    scale = np.sqrt(np.mean(np.sum(ref**2, axis=1)))
    print(
        f"{len(centre)} rods, {int((rho < 0.5).sum())} within 0.5 L of the axis (closest {rho.min():.3g} L, "
        f"line radius {term.line[4]:g}); reference: {REFERENCE_POINTS[0]} points, against "
        f"{REFERENCE_POINTS[1]}: largest difference {np.abs(check - ref).max() / scale:.1e} of the rms"
    )
    rows = []
    for n in args.points:
        err = np.linalg.norm(line_force(centre, q, term.line, n) - ref, axis=1) / scale
        nodes, weights = kl.gauss_legendre_01(n)
        rows.append((n, err, nodes, weights, np.zeros_like(centre), []))
    for _ in range(args.rounds):
        for n, _e, nodes, weights, out, ts in rows:
            t0 = time.thread_time()
            kx.line_yukawa_on_centres(centre, q, *term.line, nodes, weights, out)
            ts.append(time.thread_time() - t0)
    base = np.array(rows[0][5])
    print()
    print("| quadrature_points | CPU ms per evaluation | ratio to the first | median error | p99 | largest |")
    print("|---|---|---|---|---|---|")
    for n, err, _, _, _, ts in rows:
        ts = np.array(ts)
        print(
            f"| {n} | {1e3 * np.median(ts):.3f} [{1e3 * ts.min():.3f}-{1e3 * ts.max():.3f}] | "
            f"{np.median(base / ts):.2f} | {np.median(err):.1e} | {np.quantile(err, 0.99):.1e} | {err.max():.1e} |"
        )


if __name__ == "__main__":
    main()
