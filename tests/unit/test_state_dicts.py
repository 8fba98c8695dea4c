"""Each component saves and restores its own state; the checkpoint is their union, and a
checkpoint written before the components had their own methods still resumes."""

import json
from pathlib import Path

import numpy as np

from selfas_graph.io.checkpoint import read_checkpoint
from selfas_graph.io.h5md import NullWriter
from selfas_graph.io.scenario import scenario_from_text
from selfas_graph.model.simulation import Simulation

DATA = Path(__file__).resolve().parent.parent / "data"


def _same(a, b) -> bool:
    """Equal bit for bit (NaN equal to NaN at the same place)."""
    a, b = np.asarray(a), np.asarray(b)
    if a.dtype.fields is not None or b.dtype.fields is not None:
        return a.shape == b.shape and a.tobytes() == b.astype(a.dtype).tobytes()
    return a.shape == b.shape and np.array_equal(a, b, equal_nan=a.dtype.kind == "f")


def test_checkpoint_of_version_0_2_resumes_with_the_same_state():
    """A checkpoint written by selfas-graph 0.2 (case (ii), currents flowing; tests/data/README.md)
    rebuilds a simulation whose snapshot holds every saved entry unchanged, bit for bit: the
    network takes its contacts, flags, filament heights and contact potentials from it and solves
    the circuit again to the saved currents."""
    snap, meta = read_checkpoint(DATA / "checkpoint_0.2_case2.h5")
    scenario = scenario_from_text(meta["scenario_text"], overrides=json.loads(meta["overrides"]))
    assert "circuit_log" not in snap
    sim = Simulation.from_snapshot(scenario.params, snap)
    assert sim.circuit_log == []  # older than the circuit log: it starts empty
    again = sim.snapshot()
    differ = [k for k in snap if k not in again or not _same(snap[k], again[k])]
    assert not differ, differ
    assert sim.network.solution is not None and np.count_nonzero(sim.force_field.current) > 0
    np.testing.assert_array_equal(sim.network.current, snap["current"])
    sim.step(20)  # and it runs on
    assert sim.state.step == int(snap["step"]) + 20


def test_network_state_round_trip():
    """Network.state_dict -> load_state_dict into a fresh network gives the same arrays, topology
    and solution."""
    snap, meta = read_checkpoint(DATA / "checkpoint_0.2_case2.h5")
    scenario = scenario_from_text(meta["scenario_text"], overrides=json.loads(meta["overrides"]))
    a = Simulation.from_snapshot(scenario.params, snap).network
    b = Simulation.from_snapshot(scenario.params, snap).network
    b.load_state_dict(a.state_dict())
    for k, v in a.arrays().items():
        np.testing.assert_array_equal(b.arrays()[k], v, err_msg=k)
    np.testing.assert_array_equal(b.topology().role, a.topology().role)
    np.testing.assert_array_equal(b.solution.current, a.solution.current)


def test_writer_state_round_trip():
    """A writer's buffered per-step rows and event count move through its own state methods."""
    w = NullWriter(3)
    w.reserve_per_step(4)
    w.buffer_per_step(7, 1e-16)
    w.buffer_per_step(8, 2e-16)
    w.flush_pending([(1, 0.1, 1, 0, 2)], [(1, 0.1, 5, 2.0, 3, 3)])
    assert (w.events_written, w.circuit_rows_written) == (1, 1)
    w.buffer_per_step(9, 3e-16)
    d = w.state_dict()
    v = NullWriter()
    v.load_state_dict(d)
    assert (v.n_frames, v.events_written, v.circuit_rows_written) == (3, 1, 1)
    d.pop("circuit_rows_written")  # a state from before the circuit log
    v.load_state_dict(d)
    assert v.circuit_rows_written == 0
    np.testing.assert_array_equal(v.state_dict()["pending_step"], [9])
    np.testing.assert_array_equal(v.state_dict()["pending_value"], [3e-16])


def test_the_components_give_disjoint_entries_of_the_snapshot():
    """The snapshot is one flat namespace: a key two components both gave would silently lose one state
    (Simulation.snapshot merges them with dict.update). Checked on a scene with every component that
    saves state: the network of case (ii) with currents flowing, multiple time stepping (held slow
    forces) and both current terms on the tree."""
    snap, meta = read_checkpoint(DATA / "checkpoint_0.2_case2.h5")
    overrides = json.loads(meta["overrides"]) + ["integrator.slow_every=4"]
    overrides += [f"forces.{t}.method=tree" for t in ("current_field", "current_lorentz")]
    scenario = scenario_from_text(meta["scenario_text"], overrides=overrides)
    sim = Simulation.from_snapshot(scenario.params, snap)
    sim.step(5)
    parts = [sim.state.state_dict(), sim.integrator.state_dict(), sim.network.state_dict()]
    parts.append(sim.force_field.state_dict())
    own = {"max_bond_error", "energy0", "events", "circuit_log", "short_circuit_time"}
    keys = [set(p) for p in parts] + [own]
    assert all(len(a & b) == 0 for i, a in enumerate(keys) for b in keys[i + 1 :]), keys
    assert set().union(*keys) == set(sim.snapshot())
