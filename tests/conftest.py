"""Shared helpers: small hand-built systems with fixed seeds."""
import numpy as np
import pytest

from selfas_graph.io.scenario import parameters_from_dict
from selfas_graph.model.simulation import Simulation
from selfas_graph.model.state import State


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
    return Simulation(params(**sections), state=state)


def random_rods(n, rng, box=4.0, q=(0.5, 2.0)):
    """n rods with random centres in a cube of side ``box``, random axes and charges."""
    centre = rng.uniform(-box / 2, box / 2, (n, 3))
    axis = rng.normal(size=(n, 3))
    return State.from_rods(centre, axis, rng.uniform(*q, n), rng.uniform(*q, n))


@pytest.fixture
def rng():
    return np.random.default_rng(12345)
