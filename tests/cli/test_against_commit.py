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


def test_a_json_file_in_a_missing_folder_is_refused_before_anything_runs(tmp_path, capsys):
    with pytest.raises(SystemExit) as info:
        main(
            [
                "bench",
                "against_commit",
                "scenarios/quick.toml",
                "--commit",
                "HEAD",
                "--json",
                str(tmp_path / "no" / "r.json"),
            ]
        )
    assert info.value.code == 2 and "no folder" in capsys.readouterr().err


def test_an_unknown_commit_is_named(capsys):
    dirty = subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True, cwd=ROOT)
    if dirty.returncode != 0:
        pytest.skip("not a git checkout")
    with pytest.raises(SystemExit) as info:
        main(["bench", "against_commit", str(ROOT / "scenarios" / "quick.toml"), "--commit", "no-such-rev"])
    assert "git archive no-such-rev: no such commit" in str(info.value.code)


@pytest.mark.slow
def test_each_code_runs_each_seed_in_turns_and_the_ratios_are_printed(tmp_path):
    """Two rounds of two seeds of a 20-rod quick scene against HEAD: the codes in turns (the commit first
    in round 1, the working tree first in round 2), each run's file kept, each run's line, the ratios of
    the rounds' summed times, and the same in the JSON file. Slow: the exported commit's kernels are
    compiled afresh."""
    if subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, cwd=ROOT).returncode != 0:
        pytest.skip("not a git checkout")
    r = subprocess.run(
        [sys.executable, "-m", "selfas_graph.bench.against_commit", "scenarios/quick.toml", "--commit", "HEAD"]
        + ["--set", "rods.count=20", "--t-end", "0.02", "--warm-up", "0", "--rounds", "2", "--seeds", "3", "4"]
        + ["--keep", str(tmp_path), "--json", str(tmp_path / "r.json")],
        capture_output=True,
        text=True,
        cwd=ROOT,
    )
    assert r.returncode == 0, r.stdout + r.stderr
    lines = [line.split(":")[0] for line in r.stdout.splitlines()[1:9]]
    assert lines == [
        "round 1, seed 3, HEAD",
        "round 1, seed 3, working tree",
        "round 1, seed 4, HEAD",
        "round 1, seed 4, working tree",
        "round 2, seed 3, working tree",
        "round 2, seed 3, HEAD",
        "round 2, seed 4, working tree",
        "round 2, seed 4, HEAD",
    ]
    assert "wall time, HEAD over the working tree: " in r.stdout and "at t = 0.02: 0 rods carry 0 J0" in r.stdout
    assert "wall less compiling time, HEAD over the working tree: " in r.stdout and "compiling kernels " in r.stdout
    got = json.loads((tmp_path / "r.json").read_text())
    assert [(x["round"], x["seed"]) for x in got["runs"]["tree"]] == [(1, 3), (1, 4), (2, 3), (2, 4)]
    assert len(got["runs"]["commit"]) == 4 and len(got["commit_hash"]) == 40 and got["seeds"] == [3, 4]
    # the exported commit compiles its kernels afresh in its first run (no warm-up here): numba's
    # compilations are timed, and the wall time less them is what the third ratio compares
    first = got["runs"]["commit"][0]
    assert first["compile_seconds"] > 0 and first["wall_less_compile_seconds"] < first["wall_seconds"]
    assert len(got["ratios"]["wall_less_compile_seconds"]) == 2
    assert len(got["ratios"]["wall_seconds"]) == len(got["ratios"]["cpu_seconds"]) == 2
    kept = sorted(p.name for p in tmp_path.glob("round*.h5") if "checkpoint" not in p.name)
    assert kept == sorted(f"round{r}_seed{s}_{c}.h5" for r in (1, 2) for s in (3, 4) for c in ("commit", "tree"))
