"""Why a network drifts outwards: radial forces on the rods of a run's last frame, by term.

Usage: python tools/radial_forces.py RUN.h5

Prints the median distance of rod centres from the z axis at a few frames, then, for the last
frame (velocities set to zero, the saved currents on the current-carrying rods), the mean and
median radial component (positive outwards) of each force term summed over a rod's two tips,
over the current-carrying rods and over all rods, and the Lorentz force of the plasma field
and of B_ext alone on the rod currents (field taken at the rod centre). Used for the Fig. 2
runs in docs/results.md.
"""
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from selfas_graph.io.h5md import RunFile  # noqa: E402
from selfas_graph.io.scenario import scenario_from_text  # noqa: E402
from selfas_graph.model.forces import ForceField  # noqa: E402
from selfas_graph.model.graph import FILAMENT  # noqa: E402
from selfas_graph.model.state import random_state  # noqa: E402


def _axis_frame(x):
    """Rod centres, their distance from the z axis, and the radial and azimuthal unit vectors."""
    c = 0.5 * (x[0::2] + x[1::2])
    rho = np.hypot(c[:, 0], c[:, 1])
    rhat = np.stack([c[:, 0] / rho, c[:, 1] / rho], 1)
    phi = np.stack([-c[:, 1] / rho, c[:, 0] / rho, np.zeros_like(rho)], 1)
    return c, rho, rhat, phi


def main(path):
    with RunFile(path) as rf:
        times = rf.time
        n = len(times)
        for fr in sorted({0, n // 40, n // 20, n // 10, n // 5, n // 2, n - 1}):
            _, rho, _, _ = _axis_frame(rf.position(fr))
            print(f"t = {times[fr]:7.1f}: median distance of rod centres from the axis {np.median(rho):6.2f} L")
        g = rf.graph(frame=-1)
        x = rf.position(-1)
        text = rf.scenario_text
    params = scenario_from_text(text).params
    state = random_state(params)
    state.position[:] = x
    state.velocity[:] = 0.0
    fil = g["role"] == FILAMENT
    ff = ForceField(params, state)
    ff.set_currents(np.where(fil, g["current"], 0.0))
    ff.evaluate(state.position, state.velocity)
    _, rho, rhat, phi = _axis_frame(x)
    print(f"last frame: {fil.sum()} rods in current-carrying filaments, median distance {np.median(rho[fil]):.2f} L")
    print("radial force per rod (+ outwards)      filament rods: mean   median | all rods: mean")

    def show(name, per_rod):
        rad = (per_rod[:, :2] * rhat).sum(1)
        print(f"  {name:34s} {rad[fil].mean():+9.4f} {np.median(rad[fil]):+9.4f} | {rad.mean():+9.4f}")

    for name, f in ff.out.items():
        show(name, f[0::2] + f[1::2])
    s = x[1::2] - x[0::2]  # from tip a to tip b, the sense of a positive current
    J = np.where(fil, g["current"], 0.0)
    forces = params.forces
    if forces.plasma_filament is not None:
        pf = forces.plasma_filament
        b = np.where(rho < pf.radius, 2 * pf.current * rho / pf.radius**2, 2 * pf.current / rho)
        show("Lorentz, plasma field alone", J[:, None] * np.cross(s, b[:, None] * phi))
    if forces.uniform_field is not None:
        bz = np.broadcast_to(np.array(forces.uniform_field.B), s.shape)
        show("Lorentz, B_ext alone", J[:, None] * np.cross(s, bz))
    print(f"sum of J s_z over the filament rods: {float((J * s[:, 2])[fil].sum()):+.3f} "
          "(negative: the network current runs along -z)")


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit(__doc__.splitlines()[2])
    main(sys.argv[1])
