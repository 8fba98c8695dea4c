"""Smoke test of selfas_graph/bench/million.py's measurement of one size (a few seconds at 400 rods).

The figures are measurements, not checked here; only that a row has its parts, and that the tree
energy it times is the direct sum's within the tree's error.
"""

import math
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_one_size_measures_memory_tree_energy_and_steps():
    """One size, one step: the build, the tree's stages, both energies (the direct one summed whole
    below ``full_below`` rods, its difference from the tree's printed in units of the sum of |row|:
    measured 1.5e-5 in the Fig. 2 slab of 400 rods, 1e-4 leaves room for another random state) and
    the step's parts."""
    from selfas_graph.bench import million

    row = million.measure(str(ROOT / "scenarios" / "fig2.toml"), 400, 1, [], full_below=1000)
    assert row["rods"] == 400 and row["peak_mb"] >= row["mb_after_build"] > 0
    assert row["tree"]["cells"] > 0 and row["tree"]["evaluate"] > 0
    en = row["energy"]
    assert en["direct_s"] > 0 and en["tree_s"] > 0 and math.isfinite(en["energy"])
    assert abs(en["difference"]) < 1e-4
    (step,) = row["steps"]
    assert step["wall"] > 0 and set(million.SPLIT_TERMS) & set(step["terms"])


def test_steps_with_currents_held_time_the_current_terms():
    """``carrying``: a fraction of the rods carries current through every timed step (set again before
    each; the scene's circuit, with no path between the electrodes, would zero them), so that the two
    current terms are timed in each step, here by the tree of the currents."""
    from selfas_graph.bench import million

    tree = ["forces.current_field.method=tree", "forces.current_lorentz.method=tree"]
    row = million.measure(str(ROOT / "scenarios" / "fig2.toml"), 400, 2, tree, carrying=0.5)
    assert 150 < row["carrying"] < 250
    for step in row["steps"]:
        assert step["terms"]["current_field"] > 0 and step["terms"]["current_lorentz"] > 0
    assert row["current_tree_terms"] == ["current_field", "current_lorentz"]
    assert all(row["current_tree"][k] > 0 for k in ("plan", "fill", "sort_tips", "sort_points"))


def test_energy_at_a_checkpoint(tmp_path, capsys):
    """``--checkpoint``: the tip-tip energy of a run's state by the tree and by the direct sum, their
    difference printed against the run's energy balance (a step taken first, so that its scale is
    not zero). The quick scene, 300 rods after 20 steps, a gas whose tip-tip energy is a near
    cancellation: the two differ by the tree's error, measured 8.2e-4 of the tip-tip energy, a
    twelfth of the run's own balance (the late Fig. 6 state of docs/performance.md: 7e-8)."""
    from selfas_graph import Simulation, load_scenario
    from selfas_graph.bench import million
    from selfas_graph.io.checkpoint import write_checkpoint

    path = ROOT / "scenarios" / "quick.toml"
    sim = Simulation.from_scenario(load_scenario(path))
    sim.step(20)
    ck = tmp_path / "state.checkpoint.h5"
    meta = {"scenario_text": path.read_text(), "overrides": "[]", "run_file": "x", "version": "t"}
    write_checkpoint(ck, sim.snapshot(), meta)
    (row,) = million.main(["--checkpoint", str(ck)])
    assert row["rods"] == 300 and row["scale"] > 0
    d, t = row["direct"]["energy"], row["tree"]["energy"]
    assert d != t and abs(t - d) < 2e-3 * abs(d)
    assert "of the tip-tip energy" in capsys.readouterr().out
