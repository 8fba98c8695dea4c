"""Why a network drifts outwards: radial forces on the rods of a run's last frame, by term.

Usage: selfas-graph bench radial_forces RUN.h5 [--frames 20]

Prints the median distance of rod centres from the z axis at a few frames, then, averaged over
the last frames (velocities set to zero, the saved currents on the current-carrying rods), the
mean radial component (positive outwards) of each force term summed over a rod's two tips, over
the current-carrying rods and over all rods, with the Lorentz force of the plasma field and of
B_ext alone on the rod currents (field taken at the rod centre). Rods jiggle in their contacts,
so one frame's contact forces are noisy; the standard error over frames says how much. Used for
the Fig. 2 runs in docs/results.md.
"""

import argparse
import json

import numpy as np

from selfas_graph.io.h5md import RunFile
from selfas_graph.io.scenario import scenario_from_text
from selfas_graph.kernels.fields import plasma_field
from selfas_graph.model.graph import FILAMENT
from selfas_graph.model.placement import random_state
from selfas_graph.model.terms import ForceField


def _axis_frame(x):
    """Rod centres, their distance from the z axis and the radial unit vectors (x, y)."""
    c = 0.5 * (x[0::2] + x[1::2])
    rho = np.hypot(c[:, 0], c[:, 1])
    return c, rho, np.stack([c[:, 0] / rho, c[:, 1] / rho], 1)


def radial_parts(params, x, role, current):
    """{name: radial force per rod (n_rods,)} at positions ``x`` with zero velocities (see the docstring)."""
    state = random_state(params)
    state.position[:] = x
    state.velocity[:] = 0.0
    fil = role == FILAMENT
    ff = ForceField(params, state)
    ff.set_currents(np.where(fil, current, 0.0))
    ff.evaluate(state.position, state.velocity)
    centre, rho, rhat = _axis_frame(x)
    parts = {}
    for name, f in ff.out.items():
        if np.any(f):
            parts[name] = ((f[0::2] + f[1::2])[:, :2] * rhat).sum(1)
    s = x[1::2] - x[0::2]  # from tip a to tip b, the sense of a positive current
    J = np.where(fil, current, 0.0)
    forces = params.forces
    if forces.plasma_filament is not None:
        pf = forces.plasma_filament
        b = np.empty_like(centre)
        plasma_field(np.ascontiguousarray(centre), float(pf.axis[0]), float(pf.axis[1]), pf.radius, pf.current, b)
        parts["Lorentz, plasma field alone"] = ((J[:, None] * np.cross(s, b))[:, :2] * rhat).sum(1)
    if forces.uniform_field is not None:
        bz = np.broadcast_to(np.array(forces.uniform_field.B), s.shape)
        parts["Lorentz, B_ext alone"] = ((J[:, None] * np.cross(s, bz))[:, :2] * rhat).sum(1)
    return parts


def report(path, frames):
    with RunFile(path) as rf:
        times = rf.time
        n = len(times)
        for fr in sorted({0, n // 40, n // 20, n // 10, n // 5, n // 2, n - 1}):
            _, rho, _ = _axis_frame(rf.position(fr))
            print(f"t = {times[fr]:7.1f}: median distance of rod centres from the axis {np.median(rho):6.2f} L")
        # the run's own parameters: its scenario with the overrides it ran with (--set, --t-end)
        params = scenario_from_text(rf.scenario_text, overrides=json.loads(rf.meta.get("overrides", "[]"))).params
        per_frame = []
        for fr in range(max(0, n - frames), n):
            g = rf.graph(frame=fr)
            fil = g["role"] == FILAMENT
            # a frame without filament rods (before the first short circuit) has no filament mean
            per_frame.append(
                {
                    name: (rad[fil].mean() if fil.any() else np.nan, rad.mean())
                    for name, rad in radial_parts(params, rf.position(fr), g["role"], g["current"]).items()
                }
            )
        # a term that is zero in a frame (the current terms without current) is left out of its parts:
        # it counts as 0 for all rods there, and has no filament mean
        names = dict.fromkeys(name for parts in per_frame for name in parts)  # in the order first met
        rows = {name: [parts.get(name, (np.nan, 0.0)) for parts in per_frame] for name in names}
        last = rf.graph(frame=-1)
        x = rf.position(-1)
    fil = last["role"] == FILAMENT
    _, rho, _ = _axis_frame(x)
    where = f", median distance {np.median(rho[fil]):.2f} L" if fil.any() else ""
    print(f"last frame: {fil.sum()} rods in current-carrying filaments{where}")
    m = len(next(iter(rows.values())))
    with_fil = sum(1 for parts in per_frame if any(np.isfinite(f) for f, _ in parts.values()))
    print(
        f"radial force per rod (+ outwards), mean over the last {m} frames ({with_fil} with filament rods) "
        "+- its standard error over the frames"
    )
    print(f"  {'term':34s} {'filament rods':>20s} {'all rods':>20s}")

    def mean_err(col):
        col = col[np.isfinite(col)]
        if not len(col):
            return np.nan, np.nan
        return col.mean(), col.std(ddof=1) / np.sqrt(len(col)) if len(col) > 1 else np.nan

    for name, vals in rows.items():
        v = np.array(vals)
        (f_mean, f_err), (a_mean, a_err) = mean_err(v[:, 0]), mean_err(v[:, 1])
        print(f"  {name:34s} {f_mean:+9.4f} +- {f_err:.4f} {a_mean:+9.4f} +- {a_err:.4f}")
    s = x[1::2] - x[0::2]
    J = np.where(fil, last["current"], 0.0)
    print(
        f"sum of J s_z over the filament rods (last frame): {float((J * s[:, 2])[fil].sum()):+.3f} "
        "(negative: the network current runs along -z)"
    )


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", help="run file (HDF5)")
    ap.add_argument("--frames", type=int, default=20, help="average over this many last frames (default 20)")
    a = ap.parse_args(argv)
    if a.frames < 1:
        ap.error(f"--frames: at least 1 frame to average over, got {a.frames}")
    from selfas_graph.io.h5md import RunFileError

    try:
        report(a.run, a.frames)
    except RunFileError as exc:  # a missing or unreadable run file: its message, no traceback
        raise SystemExit(str(exc)) from None


if __name__ == "__main__":
    main()
