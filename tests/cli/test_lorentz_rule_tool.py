"""Smoke test of selfas_graph/bench/lorentz_rule.py on a small hand-made state with currents: a table row per
rule, the errors against the converged integral ordered as the rules' accuracy (the times are
measurements, not checked)."""

from pathlib import Path

import numpy as np
import pytest

from conftest import SMALL_CIRCUIT_SCENE
from selfas_graph.io.checkpoint import write_checkpoint
from selfas_graph.io.scenario import scenario_from_text
from selfas_graph.model.simulation import Simulation

ROOT = Path(__file__).resolve().parents[2]


def _tool():
    from selfas_graph.bench import lorentz_rule

    return lorentz_rule


def test_rules_table_on_a_state_with_currents(tmp_path, capsys):
    sim = Simulation.from_scenario(scenario_from_text(SMALL_CIRCUIT_SCENE))
    sim.force_field.set_currents(np.random.default_rng(4).uniform(-2.0, 2.0, sim.state.n_rods))
    path = tmp_path / "state.checkpoint.h5"
    meta = {"scenario_text": SMALL_CIRCUIT_SCENE, "overrides": "[]", "run_file": "x", "version": "t"}
    write_checkpoint(path, sim.snapshot(), meta)
    _tool().main(["--checkpoint", str(path), "--rule", "1:0", "4:0", "2:1.5", "--rounds", "1"])
    out = capsys.readouterr().out
    assert "compiles for" in out and "60 of 60 rods carry current" in out
    rows = [line.split("|") for line in out.splitlines() if line.startswith("| ") and "quadrature" not in line]
    p99 = {(r[1].strip(), r[2].strip()): float(r[6]) for r in rows}
    assert set(p99) == {("1", "0"), ("4", "0"), ("2", "1.5")}
    assert p99[("2", "1.5")] < p99[("4", "0")] < p99[("1", "0")]


def test_a_state_without_currents_is_refused(tmp_path):
    sim = Simulation.from_scenario(scenario_from_text(SMALL_CIRCUIT_SCENE))
    path = tmp_path / "state.checkpoint.h5"
    meta = {"scenario_text": SMALL_CIRCUIT_SCENE, "overrides": "[]", "run_file": "x", "version": "t"}
    write_checkpoint(path, sim.snapshot(), meta)
    with pytest.raises(SystemExit, match="no rod carries current"):
        _tool().main(["--checkpoint", str(path), "--rounds", "1"])
