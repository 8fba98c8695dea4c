"""Smoke test of selfas_graph/bench/tradeoff.py on the quick scene (a few seconds).

The tool's main() runs in this process.
The figures are measurements, not checked here; only that each setting of a knob has its row
with both position errors, that the knob's own reference (float64) differs from itself by
nothing, and that the tree's knobs are left out where the scene sums the tip pairs directly.
"""

import json
from pathlib import Path

from selfas_graph import load_scenario

ROOT = Path(__file__).resolve().parents[2]


def _tool():
    from selfas_graph.bench import tradeoff

    return tradeoff


def test_precision_knob_rows(tmp_path, capsys):
    """forces.yukawa.precision on the quick scene: two rows (float64, the default and the
    reference, with zero error; mixed, with a position error at float32 rounding, far below the
    scene's size), the largest and the median tip's error, and the JSON."""
    tool = _tool()
    js = tmp_path / "t.json"
    scene = str(ROOT / "scenarios" / "quick.toml")
    tool.main([scene, "--from", "0.05", "--t", "0.01", "--knob", "forces.yukawa.precision", "--json", str(js)])
    written = json.loads(js.read_text())
    rows = written["rows"]
    # the CPU and instruction set the costs were taken on, and the code's commit, with the figures
    assert written["machine"]["cpu_model"] and written["machine"]["cpu_name"] and "commit" in written
    assert [(r["knob"], r["value"], r["default"]) for r in rows] == [
        ("forces.yukawa.precision", "float64", True),
        ("forces.yukawa.precision", "mixed", False),
    ]
    assert rows[0]["position_error"] == 0.0 and rows[0]["position_error_median"] == 0.0
    assert 0.0 <= rows[1]["position_error_median"] <= rows[1]["position_error"] < 1e-4
    out = capsys.readouterr().out
    assert "position error (median tip)" in out and "CPU: " in out


def test_tree_knobs_only_where_the_scene_takes_the_tree():
    """opening_angle, group_size and order apply to a scene of tree_above rods or more (Fig. 6) or with
    method = tree, not to the 300 rods of the quick scene, which sums directly."""
    tool = _tool()
    quick = load_scenario(ROOT / "scenarios" / "quick.toml")
    tree = load_scenario(ROOT / "scenarios" / "quick.toml", overrides=["forces.tip_magnetic.method=tree"])
    fig6 = load_scenario(ROOT / "scenarios" / "fig6.toml")
    assert "forces.tip_magnetic.group_size" in tool.TREE_KNOBS
    for knob in tool.TREE_KNOBS:
        assert not tool._applicable(quick, knob)
        assert tool._applicable(tree, knob) and tool._applicable(fig6, knob)
    assert tool._applicable(quick, "forces.tip_magnetic.precision")


def test_the_current_trees_leaves_and_order_are_swept_for_both_terms_where_both_take_the_tree():
    """A value of leaf_size or order for one current term alone costs a second tree where both terms take
    the tree: term 9's row then sets both (term 10's row would repeat it and is left out); the group size,
    the walk's, stays each term's own, and a term alone on the tree keeps its own rows."""
    tool = _tool()
    quick = ROOT / "scenarios" / "quick.toml"
    both = load_scenario(quick, overrides=[f"forces.{t}.method=tree" for t in ("current_field", "current_lorentz")])
    one = load_scenario(quick, overrides=["forces.current_lorentz.method=tree"])
    assert tool._setting(both, "forces.current_field.leaf_size", 128) == [
        "forces.current_field.leaf_size=128",
        "forces.current_lorentz.leaf_size=128",
    ]
    assert tool._setting(both, "forces.current_field.order", 2)[1] == "forces.current_lorentz.order=2"
    assert tool._setting(both, "forces.current_field.group_size", 64) == ["forces.current_field.group_size=64"]
    assert not tool._applicable(both, "forces.current_lorentz.leaf_size")
    assert tool._applicable(both, "forces.current_lorentz.group_size")
    assert tool._applicable(one, "forces.current_lorentz.leaf_size")
    assert tool._setting(one, "forces.current_lorentz.order", 2) == ["forces.current_lorentz.order=2"]
    # the reference of a row that sets both trees takes both terms to the direct sum
    assert tool._reference(both, "forces.current_field.order") == {
        "forces.current_field.method": "direct",
        "forces.current_lorentz.method": "direct",
    }
    assert tool._reference(both, "forces.current_field.group_size") == {"forces.current_field.method": "direct"}


def test_current_every_applies_with_current_terms_and_a_refused_setting_is_a_failed_run(tmp_path):
    """integrator.current_every applies to a scene with multiple time stepping and current terms only;
    a setting the scene refuses (here 12 with slow_every = 8) comes back from ``run_once`` as a failed
    run naming the key (the sweep prints it as a row and goes on), not as a traceback."""
    tool = _tool()
    quick = load_scenario(ROOT / "scenarios" / "quick.toml")  # slow_every = 8, terms 9 and 10
    no_currents = load_scenario(
        ROOT / "scenarios" / "quick.toml", overrides=["forces.current_field=false", "forces.current_lorentz=false"]
    )
    assert tool._applicable(quick, "integrator.current_every")
    assert not tool._applicable(no_currents, "integrator.current_every")
    from selfas_graph import Simulation

    snap = Simulation.from_scenario(quick).snapshot()
    got = tool.run_once(str(ROOT / "scenarios" / "quick.toml"), ["integrator.current_every=12"], 0.01, snap)
    assert got["failed"].startswith("refused: ") and "integrator.current_every" in got["failed"]


def test_a_checkpoint_branches_with_its_own_run_overrides(tmp_path, capsys):
    """A checkpoint of ``simulate --set circuit.delta_J0=3`` branches at that bias: the tool takes the
    run's own overrides before --set (the scene file alone would give every branch the file's bias, a
    state the run never had), and says so."""
    from selfas_graph.cli.main import main as cli
    from selfas_graph.io.checkpoint import read_checkpoint

    tool = _tool()
    run = tmp_path / "run.h5"
    scene = str(ROOT / "scenarios" / "quick.toml")
    assert cli(
        ["simulate", scene, "-o", str(run), "--set", "circuit.delta_J0=3.0", "--t-end", "0.02", "--progress", "none"]
    ) in (0, None)
    ckpt = tmp_path / "run.checkpoint.h5"
    assert tool.checkpoint_overrides(read_checkpoint(ckpt)[1]) == ["circuit.delta_J0=3.0"]
    capsys.readouterr()
    js = tmp_path / "t.json"
    tool.main(
        [scene, "--checkpoint", str(ckpt), "--t", "0.005", "--knob", "forces.yukawa.precision", "--json", str(js)]
    )
    assert "made with --set circuit.delta_J0=3.0: every run takes them" in capsys.readouterr().out
    assert len(json.loads(js.read_text())["rows"]) == 2


def test_a_checkpoint_branches_at_a_base_time_step_of_its_own(tmp_path, capsys):
    """A base ``--set integrator.dt=...`` with ``--checkpoint`` ended in from_snapshot's ValueError: the base
    simulation now continues the checkpoint at that time step, its history forgotten."""
    from selfas_graph.cli.main import main as cli

    tool = _tool()
    run = tmp_path / "run.h5"
    scene = str(ROOT / "scenarios" / "quick.toml")
    argv = ["simulate", scene, "-o", str(run), "--set", "rods.count=20", "--t-end", "0.02", "--progress", "none"]
    assert cli(argv) in (0, None)
    js = tmp_path / "t.json"
    ckpt = str(tmp_path / "run.checkpoint.h5")
    tool.main(
        [
            scene,
            "--checkpoint",
            ckpt,
            "--set",
            "integrator.dt=5e-4",
            "--t",
            "0.002",
            "--knob",
            "forces.yukawa.precision",
        ]
        + ["--json", str(js)]
    )
    assert len(json.loads(js.read_text())["rows"]) == 2
