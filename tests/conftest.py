"""Shared helpers: small hand-built systems with fixed seeds."""

import signal

import numpy as np
import pytest

from selfas_graph.io.scenario import parameters_from_dict
from selfas_graph.model.simulation import Simulation
from selfas_graph.model.state import State


def pytest_configure(config):
    """With ``NUMBA_DISABLE_JIT=1`` (the kernels as Python, .ci/run's second leg) the pair laws of
    ``kernels/laws.py`` raise numpy's RuntimeWarning on coincident tips: like the compiled code they
    evaluate a branch (``1 / sqrt(r2)``, its cube) and discard it by a select, and in Python the
    discarded inf or overflow is reported. The results are the compiled ones; the warning is noise."""
    import numba

    if numba.config.DISABLE_JIT:
        config.addinivalue_line("filterwarnings", "ignore::RuntimeWarning:selfas_graph.kernels.laws")


#: 60 rods between electrodes 2 apart with every term of Fig. 2 but the plasma field: tip
#: contacts from step 91 and a short circuit at step 567 (then 4 terms carry current and the
#: Lorentz term runs), within its 1200 steps; the scene of the restart and MPI contract tests
SMALL_CIRCUIT_SCENE = """
[scenario]
name = "small_circuit"
seed = 3
[rods]
count = 60
[placement]
box = [[-2.0, 2.0], [-2.0, 2.0], [-1.0, 1.0]]
[forces.tip_magnetic]
[forces.tip_brake]
[forces.ambient_brake]
[forces.uniform_field]
[forces.yukawa]
[forces.electrodes]
gap = 2.0
[forces.current_field]
[forces.current_lorentz]
[circuit]
delta_J0 = 2.0
[integrator]
dt = 5e-4
[run]
t_end = 0.6
[output]
interval = 0.05
checkpoint_interval = 0
"""


def params(**sections):
    """Parameters from keyword sections, e.g. ``params(forces={"tip_magnetic": {}})``."""
    raw = {"rods": {"count": 1}}
    for k, v in sections.items():
        raw.setdefault(k, {}).update(v) if isinstance(v, dict) and k in raw else raw.__setitem__(k, v)
    return parameters_from_dict(raw)


def simulation(state, **sections):
    """A Simulation of a given hand-built state under the given sections."""
    sections.setdefault("rods", {})
    sections["rods"] = {**sections["rods"], "count": state.n_rods}
    if state.n_rods and "placement" not in sections:
        # the placement box is only checked for consistency here: use the state's own extent
        lo, hi = state.position.min(axis=0) - 1e-6, state.position.max(axis=0) + 1e-6
        sections["placement"] = {"box": [[float(a), float(b)] for a, b in zip(lo, hi)], "min_tip_distance": 0.0}
    # check_state=False adopts the state as it is: these tests build states the checks refuse (NaN,
    # stretched rods) to test the run's own diagnoses, and follow the object they built as it advances
    return Simulation(params(**sections), state=state, check_state=False)


def random_rods(n, rng, box=4.0, q=(0.5, 2.0)):
    """n rods with random centres in a cube of side ``box``, random axes and charges."""
    centre = rng.uniform(-box / 2, box / 2, (n, 3))
    axis = rng.normal(size=(n, 3))
    return State.from_rods(centre, axis, rng.uniform(*q, n), rng.uniform(*q, n))


@pytest.fixture(autouse=True)
def python_sigint_handler():
    """Python's own SIGINT handler in every test, as in a notebook or a script at a terminal: a process
    started with SIGINT ignored (a shell's background job, some CI runners) starts without it, and the
    tests of a Ctrl-C (``Simulation.run`` defers it only under this handler) would see none arrive.
    The handler found is put back."""
    found = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, found)


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


# --------------------------------------------------------------------------- hostile-input tests
# fixtures of tests/validation/test_hostile.py and tests/validation/test_hostile_bugs.py (their helpers: tests/hostile.py)


class RealRun(dict):
    """A module's real run (a dict with a short repr: failure reports stay readable)."""

    def __repr__(self):
        return f"RealRun({self['run']})"


@pytest.fixture(scope="module")
def real_run(tmp_path_factory):
    """One small real run of ``hostile.BASE`` (4 rods, 2 steps, 3 frames, graph data) and its checkpoint,
    written once per module."""
    from hostile import BASE_TEXT
    from selfas_graph.cli.main import main

    d = tmp_path_factory.mktemp("real_run")
    scen = d / "hostile.toml"
    scen.write_text(BASE_TEXT)
    run = d / "run.h5"
    try:
        code = main(["simulate", str(scen), "-o", str(run), "--progress", "none"])
    except SystemExit as exc:  # pragma: no cover
        code = exc.code
    assert code == 0
    ckpt = d / "run.checkpoint.h5"
    assert run.exists() and ckpt.exists()
    return RealRun(
        dir=d, scenario=scen, run=run, checkpoint=ckpt, run_bytes=run.read_bytes(), checkpoint_bytes=ckpt.read_bytes()
    )


@pytest.fixture
def workdir(tmp_path, monkeypatch):
    """A scratch folder that is also the working directory (so no stray file lands in the repo)."""
    monkeypatch.chdir(tmp_path)
    return tmp_path
