"""Smoke test of selfas_graph/bench/same_run.py (``selfas-graph compare``): equal files agree, a one-ulp
change or a missing dataset is found."""

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]


def _write(path, value, extra=False):
    with h5py.File(path, "w") as f:
        f.attrs["created"] = str(path)  # wall-clock-like: ignored
        f.attrs["steps_done"] = ord(Path(path).name[0])  # the last segment's steps: a resumed run counts its own
        g = f.create_group("observables/current")
        g.create_dataset("value", data=value)
        g.attrs["unit"] = "J0"
        f["link"] = h5py.SoftLink("/observables")
        f.attrs["ref"] = g.ref
        if extra:
            f.create_dataset("more", data=[1])


def _run(a, b):
    return subprocess.run(
        [sys.executable, "-m", "selfas_graph.bench.same_run", str(a), str(b)], capture_output=True, text=True
    )


def test_same_run_tool(tmp_path):
    x = np.array([1.0, np.nan, 3.0])
    _write(tmp_path / "a.h5", x)
    _write(tmp_path / "b.h5", x)
    r = _run(tmp_path / "a.h5", tmp_path / "b.h5")
    assert r.returncode == 0 and "the same, bit for bit" in r.stdout, r.stdout + r.stderr
    _write(tmp_path / "c.h5", np.array([1.0, np.nan, np.nextafter(3.0, 4.0)]))
    r = _run(tmp_path / "a.h5", tmp_path / "c.h5")
    assert r.returncode == 1 and "observables/current/value: data differ (1 of 3" in r.stdout, r.stdout
    _write(tmp_path / "d.h5", x, extra=True)
    r = _run(tmp_path / "a.h5", tmp_path / "d.h5")
    assert r.returncode == 1 and "more: only in" in r.stdout, r.stdout


@pytest.mark.slow
def test_same_as_commit_tool_finds_the_working_tree_equal_to_head(tmp_path):
    """selfas_graph/bench/same_as_commit.py runs a short scene with HEAD's code and with the working tree (each
    checked to import the code meant) and compares the run files; a clean tree agrees with HEAD.
    Slow: the exported commit's kernels are compiled afresh."""
    dirty = subprocess.run(["git", "status", "--porcelain", "selfas_graph"], capture_output=True, text=True, cwd=ROOT)
    if dirty.returncode != 0 or dirty.stdout.strip():
        pytest.skip("not a git checkout, or the working tree differs from HEAD in selfas_graph/")
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "selfas_graph.bench.same_as_commit",
            "scenarios/quick.toml+run.t_end=0.02+rods.count=20",
            "--keep",
            str(tmp_path),
        ],
        capture_output=True,
        text=True,
        cwd=ROOT,
    )
    assert r.returncode == 0 and "the same, bit for bit" in r.stdout, r.stdout + r.stderr


def test_same_as_commit_takes_an_override_as_a_word_of_its_own(capsys):
    """``fig8_quick.toml +run.t_end=6`` is ``fig8_quick.toml+run.t_end=6`` (the override was taken for a
    scenario file of its own, and the run failed on a directory); an override before any scenario is a usage
    error that says so."""
    from selfas_graph.bench.same_as_commit import main, scenario_specs

    words = ["a.toml", "+run.t_end=6", "+rods.count=20", "b.toml+run.t_end=1", "c.toml"]
    assert scenario_specs(words) == ["a.toml+run.t_end=6+rods.count=20", "b.toml+run.t_end=1", "c.toml"]
    with pytest.raises(SystemExit) as exc:
        main(["+run.t_end=6", "a.toml"])
    assert exc.value.code == 2
    assert "+run.t_end=6 comes before any scenario file" in capsys.readouterr().err


def test_compare_command_is_the_tool(tmp_path, capsys):
    """``selfas-graph compare A B`` is same_run on the command line (exit 0 equal, 1 different), as is
    ``selfas-graph bench same_run A B``; a missing file is a usage error (exit 2) naming it."""
    from selfas_graph.cli.main import main

    x = np.array([1.0, 2.0, 3.0])
    _write(tmp_path / "a.h5", x)
    _write(tmp_path / "b.h5", x)
    _write(tmp_path / "c.h5", np.array([1.0, 2.0, np.nextafter(3.0, 4.0)]))
    a, b, c = (str(tmp_path / f"{n}.h5") for n in "abc")
    assert main(["compare", a, b]) == 0 and "the same, bit for bit" in capsys.readouterr().out
    assert main(["compare", a, c]) == 1 and "data differ (1 of 3" in capsys.readouterr().out
    assert main(["bench", "same_run", a, c]) == 1 and "data differ (1 of 3" in capsys.readouterr().out
    assert main(["compare", a, str(tmp_path / "nope.h5")]) == 2 and "no such run file" in capsys.readouterr().err


BENCH = ROOT / "selfas_graph" / "bench"
#: modules of selfas_graph/bench that other tools import and that are no tool themselves
HELPERS = {"__init__", "peer", "oracles", "team_steps", "profile_parts", "args", "mixed_error"}


def test_bench_lists_every_tool(capsys):
    """``selfas-graph bench`` alone lists every tool, one line each; an unknown name exits 2 naming them."""
    from selfas_graph.cli.main import main

    assert main(["bench"]) == 0
    lines = capsys.readouterr().out.split("\n\n")[0].splitlines()
    assert {line.split()[0] for line in lines} == {p.stem for p in BENCH.glob("*.py")} - HELPERS
    assert all(len(line.split(maxsplit=1)) == 2 for line in lines)  # each with its one line
    assert main(["bench", "nope"]) == 2 and "same_run" in capsys.readouterr().err


def test_the_readme_tables_every_tool():
    """Each tool ``selfas-graph bench`` lists has its row in the README's table (``bench walk_parts`` had none)."""
    readme = (ROOT / "README.md").read_text()
    rows = set(re.findall(r"^\| `selfas-graph bench (\w+)", readme, flags=re.M))
    rows |= set(re.findall(r"^\| `selfas-graph bench \w+`, `selfas-graph bench (\w+)", readme, flags=re.M))
    missing = {p.stem for p in BENCH.glob("*.py")} - HELPERS - rows - {"same_run"}  # same_run: `compare`
    assert not missing, f"tools without a row in README.md's table: {sorted(missing)}"


@pytest.mark.parametrize("name", sorted({p.stem for p in BENCH.glob("*.py")} - HELPERS))
def test_every_tool_runs_through_the_command_line(name, capsys):
    """Every tool imports as part of the package and takes its arguments through ``selfas-graph bench``:
    its help names the command."""
    from selfas_graph.cli.main import main

    with pytest.raises(SystemExit) as e:
        main(["bench", name, "--help"])
    assert e.value.code == 0 and f"usage: selfas-graph bench {name}" in capsys.readouterr().out


def test_same_as_commit_passes_over_a_parameter_added_at_its_default(tmp_path):
    """A run file of the working tree whose stored parameters only add a key at its default (a parameter
    added since the commit, e.g. ``neighbours.centre_skin``) is the same run: the key is named; one set
    otherwise, or another value changed, is a difference."""
    import json

    import h5py

    from selfas_graph.bench.same_as_commit import _parameters_added_at_default
    from selfas_graph.model.params import Parameters

    new = Parameters().to_dict()
    old = json.loads(json.dumps(new))
    del old["neighbours"]["centre_skin"]

    def write(name, params):
        with h5py.File(tmp_path / name, "w") as f:
            f.create_group("parameters/selfas_graph").attrs["parameters_json"] = json.dumps(params)
        return tmp_path / name

    commit, tree = write("commit.h5", old), write("tree.h5", new)
    assert _parameters_added_at_default(commit, tree) == ["neighbours.centre_skin"]
    assert _parameters_added_at_default(tree, tree) == []
    set_to = json.loads(json.dumps(new))
    set_to["neighbours"]["centre_skin"] = 1.0
    assert _parameters_added_at_default(commit, write("set.h5", set_to)) == []
    for key, value in (("integrator", ("dt", 2e-3)), ("run", ("t_end", 99.0))):  # run.t_end too: no key exempt
        other = json.loads(json.dumps(new))
        other[key][value[0]] = value[1]
        assert _parameters_added_at_default(commit, write("other.h5", other)) == []


def test_compare_names_the_entries_of_the_parameters_that_differ(tmp_path):
    import json

    for name, seed in (("a.h5", 1), ("b.h5", 2)):
        with h5py.File(tmp_path / name, "w") as f:
            params = {"scenario": {"seed": seed, "name": "quick"}, "rods": {"count": 300}}
            f.attrs["parameters_json"] = json.dumps(params)
            f.attrs["note"] = "plain text"
    r = _run(tmp_path / "a.h5", tmp_path / "b.h5")
    assert r.returncode == 1
    assert "/@parameters_json: scenario.seed: 1 != 2" in r.stdout.splitlines(), r.stdout
    assert "count" not in r.stdout  # the entries that agree are not printed


def test_compare_names_descriptions_an_earlier_version_lacks_but_does_not_count_them(tmp_path, capsys):
    """A run file of an earlier version lacks the charges' H5MD ``type`` and ``quantity`` (added in 0.4.3)
    and may word the ``*_sum`` entries of ``derived_json`` otherwise: ``compare`` names those, exits 0;
    any other attribute in one file only, or any other entry that differs, still counts."""
    import json

    from selfas_graph.cli.main import main

    def write(name, new=True, words="direct", theta=0.5):
        with h5py.File(tmp_path / name, "w") as f:
            for g in ("tips", "rods"):
                ds = f.create_dataset(f"particles/{g}/charge", data=[1.0, -1.0])
                if new:
                    ds.attrs["type"], ds.attrs["quantity"] = "effective", "charge"
            derived = {"tip_magnetic_sum": words, "tip_magnetic_theta": theta}
            f.create_group("parameters").attrs["derived_json"] = json.dumps(derived)

    write("old.h5", new=False, words="tree of leaves")
    write("new.h5")
    write("other.h5", theta=0.6)
    old, new, other = (str(tmp_path / n) for n in ("old.h5", "new.h5", "other.h5"))
    assert main(["compare", old, new]) == 0
    out = capsys.readouterr().out
    assert "the same, bit for bit (descriptions only, not counted: parameters@derived_json (tip_magnetic_sum), " in out
    assert all(f"particles/{g}/charge@{a}" in out for g in ("tips", "rods") for a in ("type", "quantity")), out
    assert main(["compare", new, other]) == 1
    assert "parameters@derived_json: tip_magnetic_theta: 0.5 != 0.6" in capsys.readouterr().out
    with h5py.File(tmp_path / "other.h5", "a") as f:
        f["particles/tips/charge"].attrs["unit"] = "q0"
    assert main(["compare", new, other]) == 1
    assert "particles/tips/charge@unit: only in one file" in capsys.readouterr().out


def test_compare_passes_over_how_a_run_was_launched(tmp_path, capsys):
    """An MPI run and its serial twin hold the same data bit for bit (docs/performance.md 'Several MPI ranks'),
    but compare counted ``mpi_ranks`` (and the threads, and the folder the scene was read from, and the
    end times a resume moved) as a difference; these record the launch, not the run."""
    from selfas_graph.cli.main import main

    for name, ranks in (("a.h5", 2), ("b.h5", 1)):
        _write(tmp_path / name, np.array([1.0, 2.0]))
        with h5py.File(tmp_path / name, "a") as f:
            g = f.require_group("parameters/selfas_graph")
            g.attrs["mpi_ranks"], g.attrs["numba_threads"] = ranks, 3 - ranks
            g.attrs["scenario_path"] = str(tmp_path / name / "scene.toml")
            if ranks == 2:  # a resume to a later end time keeps the earlier one: history, not data
                g.attrs["t_end_before"] = "[1.5]"
    assert main(["compare", str(tmp_path / "a.h5"), str(tmp_path / "b.h5")]) == 0
    assert "the same, bit for bit" in capsys.readouterr().out


def test_compare_takes_the_overrides_in_any_order(tmp_path, capsys):
    """An ensemble seed lists its ``--set`` overrides in another order than its ``simulate --set ...``
    twin: the same overrides in another order agree; another override or value does not."""
    from selfas_graph.cli.main import main

    def write(name, overrides):
        _write(tmp_path / name, np.array([1.0, 2.0]))
        with h5py.File(tmp_path / name, "a") as f:
            f.require_group("parameters/selfas_graph").attrs["overrides"] = json.dumps(overrides)

    write("a.h5", ["scenario.seed=2", "run.t_end=1"])
    write("b.h5", ["run.t_end=1", "scenario.seed=2"])
    write("c.h5", ["run.t_end=1", "scenario.seed=3"])
    write("d.h5", ["run.t_end=1"])
    assert main(["compare", str(tmp_path / "a.h5"), str(tmp_path / "b.h5")]) == 0
    assert "the same, bit for bit" in capsys.readouterr().out
    for other in ("c.h5", "d.h5"):
        assert main(["compare", str(tmp_path / "a.h5"), str(tmp_path / other)]) == 1
        assert "parameters/selfas_graph@overrides" in capsys.readouterr().out


def test_compare_into_a_closed_pipe_is_no_read_error(tmp_path, monkeypatch):
    """``compare A B | head -1``: the reader leaving (BrokenPipeError, an OSError) was reported as 'cannot read
    the run files' (exit 2); it reaches the command line's handler, which ends quietly."""
    from selfas_graph.bench import same_run
    from selfas_graph.cli import compare

    _write(tmp_path / "a.h5", np.arange(3.0))
    _write(tmp_path / "b.h5", np.arange(3.0) + 1)

    def closed(args):
        raise BrokenPipeError(32, "Broken pipe")

    monkeypatch.setattr(same_run, "run", closed)
    args = type("Args", (), {"a": tmp_path / "a.h5", "b": tmp_path / "b.h5"})()
    with pytest.raises(BrokenPipeError):
        compare.run(args)


@pytest.mark.parametrize(
    "a, b, words",
    [
        ({"x": 0.0}, {"x": -0.0}, "x: 0.0 != -0.0"),
        ({"x": 1}, {"x": 1.0}, "x: 1 != 1.0"),
        ({"x": True}, {"x": 1}, "x: True != 1"),
        ({"x": [0.0, 1]}, {"x": [-0.0, 1]}, "x: [0.0, 1] != [-0.0, 1]"),
        ({"x": 1, "y": 2}, {"y": 2, "x": 1}, "the same entries, written differently"),
    ],
)
def test_json_attributes_that_differ_in_their_bytes_are_a_difference(tmp_path, a, b, words):
    """A JSON attribute whose text differs was compared by its parsed values with Python's ==, which
    takes 0.0 for -0.0, 1 for 1.0 and true for 1: files that differ were called the same, bit for bit.
    NaN entries are the same as each other."""
    from selfas_graph.bench.same_run import compare

    for path, params in ((tmp_path / "a.h5", a), (tmp_path / "b.h5", b)):
        with h5py.File(path, "w") as f:
            f.create_group("parameters/selfas_graph").attrs["parameters_json"] = json.dumps(params)
    out = compare(tmp_path / "a.h5", tmp_path / "b.h5")
    assert len(out) == 1 and words in out[0], out
    for path, params in (
        (tmp_path / "a.h5", {"x": float("nan"), "y": 1}),
        (tmp_path / "b.h5", {"x": float("nan"), "y": 2}),
    ):
        with h5py.File(path, "w") as f:
            f.create_group("parameters/selfas_graph").attrs["parameters_json"] = json.dumps(params)
    assert [line.split("@")[1] for line in compare(tmp_path / "a.h5", tmp_path / "b.h5")] == [
        "parameters_json: y: 1 != 2"
    ]


def test_compare_names_the_file_it_cannot_read(tmp_path, capsys):
    """A folder, a missing file, a file that is not HDF5 and a file another process is writing: each a
    one-line error naming it (exit 2), not "no such run file" for a folder or the raw errno of a lock."""
    from selfas_graph.cli.main import main

    _write(tmp_path / "a.h5", np.arange(3.0))
    (tmp_path / "text.json").write_text("{}")
    (tmp_path / "dir").mkdir()
    for other, words in [
        ("dir", "is a folder, not a run file"),
        ("gone.h5", "no such run file"),
        ("text.json", "text.json is not an HDF5 file"),
    ]:
        assert main(["compare", str(tmp_path / "a.h5"), str(tmp_path / other)]) == 2
        assert words in capsys.readouterr().err
    _write(tmp_path / "b.h5", np.arange(3.0))
    env = {k: v for k, v in os.environ.items() if k != "HDF5_USE_FILE_LOCKING"}  # HDF5's locks, as a user has them
    hold = "import h5py, sys, time; f = h5py.File(sys.argv[1], 'r+'); print('open', flush=True); time.sleep(60)"
    proc = subprocess.Popen(
        [sys.executable, "-c", hold, str(tmp_path / "b.h5")], stdout=subprocess.PIPE, text=True, env=env
    )
    cmd = [sys.executable, "-m", "selfas_graph", "compare", str(tmp_path / "a.h5"), str(tmp_path / "b.h5")]
    try:
        assert proc.stdout.readline().strip() == "open"
        res = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=120)
    finally:
        proc.kill()
        proc.communicate(timeout=30)
    if res.returncode == 0:
        pytest.skip("HDF5 file locking is off here (a file system without locks)")
    assert res.returncode == 2, res.stdout + res.stderr
    assert "b.h5: locked by another process" in res.stderr and "a.h5:" not in res.stderr


def test_compare_refuses_a_run_file_against_a_checkpoint(tmp_path, capsys):
    """Every dataset of the two differs: the list was of no use. Two checkpoints compare as two run files do."""
    import shutil

    from selfas_graph.cli.main import main

    data = Path(__file__).parent.parent / "data"
    run, ckpt = data / "legacy_run_58b30f8.h5", data / "checkpoint_0.2_case2.h5"
    assert main(["compare", str(run), str(ckpt)]) == 2
    err = capsys.readouterr().err
    assert f"{run} is a run file and {ckpt} a checkpoint: compare two run files, or two checkpoints" in err
    shutil.copyfile(ckpt, tmp_path / "c.h5")
    assert main(["compare", str(ckpt), str(tmp_path / "c.h5")]) == 0
