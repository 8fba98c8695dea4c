"""``selfas-graph bench against_commit``: the working tree timed against a commit, in turns. Only what
it runs and prints is checked (no timed assertion)."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

from selfas_graph.cli.main import main

ROOT = Path(__file__).resolve().parents[2]


def test_a_scene_outside_the_repository_needs_the_trees_copy(tmp_path, capsys):
    scene = tmp_path / "s.toml"
    scene.write_text((ROOT / "scenarios" / "quick.toml").read_text())
    with pytest.raises(SystemExit) as info:
        main(["bench", "against_commit", str(scene), "--commit", "HEAD"])
    assert info.value.code == 2 and "is not in the repository" in capsys.readouterr().err


def test_an_unknown_commit_is_named(capsys):
    dirty = subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True, cwd=ROOT)
    if dirty.returncode != 0:
        pytest.skip("not a git checkout")
    with pytest.raises(SystemExit) as info:
        main(["bench", "against_commit", str(ROOT / "scenarios" / "quick.toml"), "--commit", "no-such-rev"])
    assert "git archive no-such-rev" in str(info.value.code)


@pytest.mark.slow
def test_each_code_runs_in_turns_and_the_ratios_are_printed(tmp_path):
    """Two rounds of a 20-rod quick scene against HEAD: each code's runs in the kept folder, each
    round's line, the ratios, and the same in the JSON file. Slow: the exported commit's kernels are
    compiled afresh."""
    if subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, cwd=ROOT).returncode != 0:
        pytest.skip("not a git checkout")
    r = subprocess.run(
        [sys.executable, "-m", "selfas_graph.bench.against_commit", "scenarios/quick.toml", "--commit", "HEAD"]
        + ["--set", "rods.count=20", "--t-end", "0.02", "--warm-up", "0", "--rounds", "2"]
        + ["--keep", str(tmp_path), "--json", str(tmp_path / "r.json")],
        capture_output=True,
        text=True,
        cwd=ROOT,
    )
    assert r.returncode == 0, r.stdout + r.stderr
    lines = r.stdout.splitlines()
    assert [line.split(":")[0] for line in lines[1:5]] == [
        "round 1, HEAD",
        "round 1, working tree",
        "round 2, working tree",
        "round 2, HEAD",
    ]
    assert "wall time, HEAD over the working tree: " in r.stdout and "at t = 0.02: 0 rods carry 0 J0" in r.stdout
    got = json.loads((tmp_path / "r.json").read_text())
    assert len(got["runs"]["HEAD"]) == len(got["runs"]["tree"]) == 2 and len(got["ratios"]["wall_seconds"]) == 2
    assert sorted(p.name for p in tmp_path.glob("round*.h5") if "checkpoint" not in p.name) == [
        "round1_HEAD.h5",
        "round1_tree.h5",
        "round2_HEAD.h5",
        "round2_tree.h5",
    ]
