"""Smoke tests of the bench tools that have no test of their own, each at a small size: it runs to the
end and prints its table (a tool that stopped running would otherwise be found only by its next
user). The figures are measurements, not checked."""

import math
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
QUICK = str(ROOT / "scenarios" / "quick.toml")


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory):
    """The quick scene to t = 2.5, past its first short circuit (t = 2.01): a run file with current."""
    from selfas_graph.cli.main import main

    run = tmp_path_factory.mktemp("quick_run") / "quick.h5"
    assert main(["simulate", QUICK, "-o", str(run), "--t-end", "2.5", "--progress", "none"]) == 0
    return run


def _main(name):
    import importlib

    return importlib.import_module(f"selfas_graph.bench.{name}").main


@pytest.mark.parametrize(
    "name, argv, printed",
    [
        ("circuit", ["--sizes", "1000", "--repeat", "1"], "chain"),
        ("rods", ["--steps", "5", "--rounds", "1", "--tips", "600"], "quick.toml (equal rods)"),
        ("checks", ["--scenario", QUICK, "--settle", "10", "--repeat", "1", "--calls", "5"], "skin check"),
        (
            "tree",
            ["--rods", "400", "--theta", "0.5", "--leaf", "64", "--order", "2", "--reps", "1", "--config", "uniform"],
            "crossover (uniform)",
        ),
        ("step", ["--scenario", QUICK, "--rods", "300", "--steps", "10", "--repeat", "1"], "| 300 |"),
        ("current_tree", ["--rods", "300", "--theta", "0.5", "--reps", "1"], "| tree | mixed | 0.5 |"),
        ("walk_parts", ["--rods", "3000", "--config", "uniform", "--reps", "1"], "| uniform | 3000 |"),
        ("walk_parts", ["--separation", "--rods", "1500", "--config", "uniform"], "(b + r_g) / D below"),
        ("fmm", ["--rods", "1500", "--config", "uniform", "--order", "4", "--theta", "0.5", "--reps", "1"], "| FMM,"),
    ],
)
def test_a_tool_runs_to_its_table(name, argv, printed, capsys):
    _main(name)(argv)
    out = capsys.readouterr().out
    assert printed in out
    if name in (
        "step",
        "rods",
        "checks",
        "current_tree",
        "walk_parts",
        "fmm",
    ):  # the timing tools name the CPU they ran on
        assert "CPU" in out
    if name == "walk_parts":  # its parts are the shipped kernel's: with both sums, the same forces bit for bit
        assert "differs from the shipped one" not in out


def test_run_file_tools(quick_run, capsys, monkeypatch):
    """The tools that read a run file: the radial forces of its last frames and its short circuits."""
    _main("radial_forces")([str(quick_run), "--frames", "2"])
    out = capsys.readouterr().out
    assert "current_lorentz" in out and "sum of J s_z over the filament rods" in out
    _main("short_circuits")([str(quick_run)])
    out = capsys.readouterr().out
    assert "| run | episodes | first |" in out and f"| {quick_run.parent.name}/quick.h5 | 1 | 2.01 |" in out
    # a file named without a folder is labelled by its name alone (it read "/quick.h5")
    monkeypatch.chdir(quick_run.parent)
    _main("short_circuits")(["quick.h5"])
    assert "| quick.h5 | 1 | 2.01 |" in capsys.readouterr().out


def test_radial_forces_takes_the_runs_overrides(tmp_path, capsys):
    """A run made with --set (fewer rods, no plasma filament) is read with its own parameters: the
    tool neither fails on the rod count nor reports the force of a filament the run did not have."""
    from selfas_graph.cli.main import main

    run = tmp_path / "noplasma.h5"
    argv = ["simulate", QUICK, "-o", str(run), "--t-end", "0.5", "--progress", "none"]
    assert main([*argv, "--set", "rods.count=30", "--set", "forces.plasma_filament=false"]) == 0
    capsys.readouterr()
    _main("radial_forces")([str(run), "--frames", "2"])
    out = capsys.readouterr().out
    assert "tip_magnetic" in out and "plasma" not in out


def test_current_tree_tool_reads_a_checkpoint_and_refuses_bad_input(quick_run, capsys):
    """The current tree's bench on a run's checkpoint (its rods and currents), and its refusals."""
    tool = _main("current_tree")
    checkpoint = str(quick_run).replace(".h5", ".checkpoint.h5")
    assert tool(["--checkpoint", checkpoint, "--theta", "0", "--precision", "float64", "--reps", "1"]) == 0
    out = capsys.readouterr().out
    assert "rods carrying current" in out and "| tree | float64 | 0 | 64 / 128 / 3 |" in out
    # the tree's shapes: at opening angle 0 every rod is summed by the segment law whatever the leaves
    assert tool(["--checkpoint", checkpoint, "--theta", "0", "--precision", "float64", "--reps", "1",
                 "--leaf", "8", "64", "--group", "16", "--order", "2"]) == 0  # fmt: skip
    out = capsys.readouterr().out
    assert "| tree | float64 | 0 | 8 / 16 / 2 |" in out and "| tree | float64 | 0 | 64 / 16 / 2 |" in out
    for argv, named in (
        (["--theta", "1.0", "--rods", "10"], "--theta"),
        (["--rods", "10", "--leaf", "0"], "--leaf"),
        ([], "--checkpoint"),
        (["--rods", "10", "--carrying", "0"], "--carrying"),
    ):
        with pytest.raises(SystemExit):
            tool(argv)
        assert named in capsys.readouterr().err


def test_radial_forces_refuses_bad_input(tmp_path, capsys):
    """No frames to average over, or no run file: a message naming the flag or the file, no traceback."""
    tool = _main("radial_forces")
    with pytest.raises(SystemExit) as info:
        tool([str(tmp_path / "none.h5"), "--frames", "0"])
    assert info.value.code == 2 and "--frames: at least 1 frame" in capsys.readouterr().err
    with pytest.raises(SystemExit) as info:
        tool([str(tmp_path / "none.h5")])
    assert "none.h5" in str(info.value.code) and "no such file" in str(info.value.code)


def test_far_separation_takes_the_walks_cells():
    """``walk_parts --separation``: the cells it finds for each group are those the shipped walk accepts
    (as many per group as the walk records, padded to its chunks), each with the ratio (b + r_g) / D
    computed here in plain Python. To 1e-14: the same float64 numbers, the squares perhaps summed in
    another order."""
    from selfas_graph.bench.tree import RSTAR, uniform
    from selfas_graph.bench.walk_parts import NEAR, far_separation, run_parts
    from selfas_graph.kernels.tree import build_tip_tree
    from selfas_graph.kernels.treewalk import FAR_CHUNK

    t = build_tip_tree(*uniform(1500, np.random.default_rng(3)), 32, 128, 4)
    ratio, work = far_separation(t.start, t.end, t.next, t.box, t.centre, t.radius, t.group, 0.55, RSTAR)
    counts = np.zeros((t.group.shape[0], 2), np.int64)
    run_parts(t, 0.55, NEAR, np.empty((t.x.shape[0], 3)), counts)
    expect, expect_work = [], 0
    for gi, g in enumerate(t.group):
        lo, hi = t.box[g, :3], t.box[g, 3:]
        mid, rg = 0.5 * (lo + hi), 0.5 * math.sqrt(((hi - lo) ** 2).sum())
        c, taken = 0, 0
        while c < len(t.start):
            d2 = (np.maximum(np.maximum(lo - t.centre[c], 0.0), t.centre[c] - hi) ** 2).sum()
            b = t.radius[c]
            if d2 * 0.55**2 > b * b and d2 > (b + RSTAR) ** 2:
                expect.append((b + rg) / math.sqrt(((t.centre[c] - mid) ** 2).sum()))
                c, taken = t.next[c], taken + 1
            else:
                c += 1
        n_tips = t.end[g] - t.start[g]
        assert counts[gi, 1] == n_tips * -(-taken // FAR_CHUNK) * FAR_CHUNK
        expect_work += n_tips * taken
    assert work.sum() == expect_work > 0
    np.testing.assert_allclose(ratio, expect, rtol=1e-14)


@pytest.mark.parametrize(
    "argv, words",
    [
        (["--order", "0"], "--order: 0 must be positive"),
        (["--theta", "1.2"], "--theta: 1.2 must be in [0, 1)"),
        (["--leaf", "0"], "--leaf: 0 must be positive"),
        (["--rods", "-5"], "--rods: -5 must be positive"),
        (["--reps", "x"], "--reps: 'x' is not an integer"),
    ],
)
def test_bench_fmm_refuses_values_out_of_range_naming_the_option(argv, words, capsys):
    with pytest.raises(SystemExit) as exc:
        _main("fmm")(argv)
    assert exc.value.code == 2
    assert words in capsys.readouterr().err


def test_a_tools_environment_is_its_own(monkeypatch, capsys):
    """`bench profile` reads a running seed's file with HDF5's file locks off (its COMMAND_ENV); called
    in-process it set that for the caller for good, after which HDF5 no longer locked the caller's files
    (a notebook's, or every later test's). It is set for the tool's run alone."""
    import os

    from selfas_graph.bench import profile
    from selfas_graph.cli.main import main

    assert profile.COMMAND_ENV == {"HDF5_USE_FILE_LOCKING": "FALSE"}
    monkeypatch.delenv("HDF5_USE_FILE_LOCKING", raising=False)
    seen = {}
    monkeypatch.setattr(profile, "main", lambda argv: seen.update(env=os.environ.get("HDF5_USE_FILE_LOCKING")) or 0)
    assert main(["bench", "profile"]) == 0
    assert seen["env"] == "FALSE" and "HDF5_USE_FILE_LOCKING" not in os.environ
    monkeypatch.setenv("HDF5_USE_FILE_LOCKING", "TRUE")  # the caller's own setting is kept, before and after
    assert main(["bench", "profile"]) == 0
    assert seen["env"] == "TRUE" and os.environ["HDF5_USE_FILE_LOCKING"] == "TRUE"
