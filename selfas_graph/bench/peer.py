"""What the benchmarks in selfas_graph/bench/ print beside their figures: the machine, the instruction set numba
compiled for, and a peer code timed on the same rods in the same run.

``machine()`` names the CPU model (``/proc/cpuinfo``), the CPU numba compiles for (``NUMBA_CPU_NAME``
when set, else LLVM's name of the host CPU) and the vector features it compiles with. numba takes
the features from ``NUMBA_CPU_FEATURES`` and, when that is unset, from the host CPU, whatever
``NUMBA_CPU_NAME`` says: on an AVX-512 host, ``NUMBA_CPU_NAME=haswell`` alone still emits AVX-512
(tuned for Haswell). ``target_env(target)`` gives the environment of a build for a named CPU with
that CPU's own features (``NUMBA_CPU_FEATURES`` set empty): ``haswell`` or ``znver3`` then use
AVX2 at most, on any x86 host.

``OpenMMPeer`` is the peer of the step benchmarks: OpenMM's CPU platform (the optional ``bench``
extra, ``pip install -e ".[bench]"``) on the same tips as the simulation, each rod two particles of
charge +q and -q held at the rod length by a constraint, their own pair excluded, Coulomb by PME
with a real-space cut-off ``cutoff`` (6 rod lengths, taken as nm) at Ewald error tolerance 1e-4, in
a periodic box around the rods (at least twice the cut-off on every side), Verlet steps. It times
the same number of tip pairs' electrostatics as the tip-tip term of a step plus a constraint
solve; it does not know the screened rod charges, the brakes or the circuit, which the
simulation's step carries on top. Without OpenMM, ``OpenMMPeer.available()`` is False and
``missing()`` says how to install it.
"""

import os
import sys
import time
from pathlib import Path

import numpy as np

#: real-space cut-off of the peer's PME, in rod lengths
PEER_CUTOFF = 6.0
#: the peer's Ewald error tolerance
PEER_TOLERANCE = 1e-4


def target_env(target: str, environ=None) -> dict:
    """The environment of a process whose kernels numba compiles for ``target``.

    ``"host"``: the CPU it runs on (``NUMBA_CPU_NAME`` and ``NUMBA_CPU_FEATURES`` removed). Any other
    name (``haswell``, ``znver3``, ...): that CPU with its own features only, ``NUMBA_CPU_FEATURES``
    set empty; without it numba would add the host's features to the name (AVX-512 on an AVX-512
    host, whatever the name).
    """
    env = dict(os.environ if environ is None else environ)
    env.pop("NUMBA_CPU_NAME", None)
    env.pop("NUMBA_CPU_FEATURES", None)
    if target != "host":
        env["NUMBA_CPU_NAME"] = target
        env["NUMBA_CPU_FEATURES"] = ""
    return env


from selfas_graph.provenance import cpu_model, numba_target  # noqa: F401  (re-exported)

#: the folder that holds this package: a tool's child process imports the same code from it
PACKAGE_ROOT = Path(__file__).resolve().parents[2]


def tool_command(name: str) -> list:
    """The command line of a process running the tool ``name`` (``python -P -m selfas_graph.bench.NAME``).

    ``-P`` keeps the current folder off the module path, so the package is the one ``tool_env``
    names, whatever folder the child runs in.
    """
    return [sys.executable, "-P", "-m", f"selfas_graph.bench.{name}"]


def tool_env(environ=None, root=PACKAGE_ROOT) -> dict:
    """``environ`` (default: this process's environment) with ``root`` first on ``PYTHONPATH``: a
    child started with ``tool_command`` imports the package in ``root`` (by default this one)."""
    env = dict(os.environ if environ is None else environ)
    env["PYTHONPATH"] = os.pathsep.join([str(root)] + ([env["PYTHONPATH"]] if env.get("PYTHONPATH") else []))
    return env


def machine() -> dict:
    """CPU model, core count and the numba target, for the header of a benchmark's output."""
    return {"cpu_model": cpu_model(), "cores": os.cpu_count(), **numba_target()}


def machine_line() -> str:
    m = machine()
    return (
        f"CPU: {m['cpu_model']} ({m['cores']} cores); numba {m['numba']} compiles for {m['cpu_name']} "
        f"({m['set_by']}; widest vectors {m['widest']}: {' '.join(m['vector_features'])})"
    )


class OpenMMPeer:
    """OpenMM CPU platform on the given tips (module docstring); ``ms_per_step(steps)`` times steps."""

    @staticmethod
    def available() -> bool:
        try:
            import openmm  # noqa: F401
        except ImportError:
            return False
        return True

    @staticmethod
    def missing() -> str:
        return (
            'peer skipped: OpenMM is not installed (pip install -e ".[bench]" or pip install openmm); '
            "no ratio to it is printed"
        )

    def __init__(self, position, tip_charge, threads, cutoff=PEER_CUTOFF, tolerance=PEER_TOLERANCE, dt=1e-4):
        import openmm
        from openmm import unit

        self.version = openmm.Platform.getOpenMMVersion()
        pos = np.asarray(position, dtype=np.float64)
        lo, hi = pos.min(axis=0), pos.max(axis=0)
        side = np.maximum(hi - lo + 1.0, 2.0 * cutoff + 1e-6)  # PME needs the cut-off below half a side
        shifted = pos - lo + 0.5 * (side - (hi - lo))
        n = pos.shape[0]
        system = openmm.System()
        system.setDefaultPeriodicBoxVectors(
            openmm.Vec3(side[0], 0, 0), openmm.Vec3(0, side[1], 0), openmm.Vec3(0, 0, side[2])
        )
        nb = openmm.NonbondedForce()
        nb.setNonbondedMethod(openmm.NonbondedForce.PME)
        nb.setCutoffDistance(cutoff)
        nb.setEwaldErrorTolerance(tolerance)
        nb.setUseDispersionCorrection(False)
        for k in range(n):
            system.addParticle(10.0)
            nb.addParticle(float(tip_charge[k]), 1.0, 0.0)
        for i in range(n // 2):
            length = float(np.linalg.norm(pos[2 * i + 1] - pos[2 * i]))
            system.addConstraint(2 * i, 2 * i + 1, length)
            nb.addException(2 * i, 2 * i + 1, 0.0, 1.0, 0.0)
        system.addForce(nb)
        self.integrator = openmm.VerletIntegrator(dt)
        platform_ = openmm.Platform.getPlatformByName("CPU")
        self.context = openmm.Context(system, self.integrator, platform_, {"Threads": str(int(threads))})
        self.context.setPositions(shifted * unit.nanometer)
        self.label = f"OpenMM {self.version} CPU, {threads} thread(s), PME rc = {cutoff:g}, tolerance {tolerance:g}"
        self.integrator.step(3)  # setup: neighbour grid, PME plans

    def ms_per_step(self, steps):
        """Wall-clock and process CPU ms per step over ``steps`` steps."""
        c0 = time.process_time()
        t0 = time.perf_counter()
        self.integrator.step(int(steps))
        self.context.getState(getEnergy=False)  # waits for the platform to finish
        return 1e3 * (time.perf_counter() - t0) / steps, 1e3 * (time.process_time() - c0) / steps


def summary(values):
    """``median [min-max]`` of a list of figures, and the median."""
    v = np.asarray(values, dtype=float)
    return float(np.median(v)), f"{np.median(v):.3g} [{v.min():.3g}-{v.max():.3g}]"
