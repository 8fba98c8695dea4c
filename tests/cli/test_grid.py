"""Parameter grids: parsing, validation before anything runs (naming the key), one folder per point,
the combined summary with the grid keys as columns, and a rerun that runs nothing new."""

import csv
import json
from pathlib import Path

import pytest

from selfas_graph.ensemble import EnsembleError
from selfas_graph.grid import Grid, parse_grid

ROOT = Path(__file__).resolve().parents[2]
QUICK = ROOT / "scenarios" / "quick.toml"


def test_parse_grid_keeps_vectors_whole_and_refuses_bad_items():
    g = parse_grid(["circuit.delta_J0=1,2.5", "forces.uniform_field.B=[0,0,0.5],[0,0,1]"])
    assert g == {"circuit.delta_J0": ["1", "2.5"], "forces.uniform_field.B": ["[0,0,0.5]", "[0,0,1]"]}
    for bad, words in [
        (["circuit.delta_J0"], "expected KEY=V1,V2"),
        (["circuit.delta_J0="], "empty value"),
        (["circuit.delta_J0=1,,2"], "empty value"),
        (["circuit.delta_J0=1,1"], "1 and 1 are the same value"),
        (["circuit.delta_J0=1, 1.0"], "1 and 1.0 are the same value"),  # one point, run twice otherwise
        (["a=1", "a=2"], "given twice"),
        (["scenario.seed=1,2"], "--seeds"),
    ]:
        with pytest.raises(EnsembleError, match=words):
            parse_grid(bad)


@pytest.mark.parametrize(
    "grid, words",
    [
        ({"circuit.delta_j0": ["1", "2"]}, "circuit.delta_j0"),  # unknown key
        ({"circuit.delta_J0": ["1", "-2"]}, "circuit.delta_J0"),  # a value the schema refuses
        ({"rods.count": ["10", "many"]}, "rods.count"),
        ({"circuit.delta_J0": []}, "circuit.delta_J0"),  # an empty list (it was an IndexError)
        ({"circuit.delta_J0": "12"}, "circuit.delta_J0"),  # a string, not a list of values
        # every point was summarised at the first point's end time
        ({"run.t_end": ["0.1", "0.2"]}, "run.t_end: the end time is the grid's"),
        # two points in one folder: the second ensemble found the folder locked by its own process
        ({"scenario.name": ["a/b", "a_b"]}, "would share the folder 'scenario.name=a_b'"),
        ({"scenario.name": ['"a b"', '"ab"']}, "would share the folder"),
    ],
)
def test_a_bad_grid_is_refused_naming_the_key_before_anything_is_written(tmp_path, grid, words):
    with pytest.raises(EnsembleError, match=words.replace(".", r"\.").replace("'", ".")):
        Grid(QUICK, grid, seeds=2, folder=tmp_path / "g")
    assert not (tmp_path / "g").exists()


def test_python_values_name_one_point_however_written(tmp_path):
    """From Python a grid takes numbers, booleans and lists as well as the command line's text: False
    switches a term off (it was refused, 'expected a table, got False'), and 2.0 and "2" are one point
    with one folder (a cell run again with floats ran everything again); 1 and 1.0 are one value."""
    g = Grid(QUICK, {"forces.yukawa": [False], "circuit.delta_J0": [2.0]}, seeds=1, folder=tmp_path / "a")
    assert [e.folder.name for e in g.ensembles] == ["forces.yukawa=false+circuit.delta_J0=2"]
    assert g.ensembles[0].base.params.forces.yukawa is None
    h = Grid(QUICK, {"forces.yukawa": ["false"], "circuit.delta_J0": ["2"]}, seeds=1, folder=tmp_path / "a")
    assert h.ensembles[0].folder == g.ensembles[0].folder
    with pytest.raises(EnsembleError, match="1 twice"):
        Grid(QUICK, {"circuit.delta_J0": [1, 1.0]}, seeds=1, folder=tmp_path / "b")
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()


def test_grid_runs_every_point_once_and_writes_the_combined_summary(tmp_path, capsys):
    from selfas_graph.cli.main import main

    argv = ["ensemble", str(QUICK), "--seeds", "2", "--grid", "circuit.delta_J0=1,2", "--jobs", "1"]
    argv += ["--set", "rods.count=40", "--set", "output.interval=0.1", "--t-end", "0.2", "-o", str(tmp_path / "g")]
    argv += ["--times", "0.1,0.2", "--plot"]
    assert main(argv) == 0
    out = capsys.readouterr().out
    folders = sorted(p.name for p in (tmp_path / "g").iterdir() if p.is_dir())
    assert folders == ["circuit.delta_J0=1", "circuit.delta_J0=2"]
    for f in folders:
        assert sorted(p.name for p in (tmp_path / "g" / f).glob("seed_*[0-9].h5")) == ["seed_0001.h5", "seed_0002.h5"]
    rows = list(csv.DictReader((tmp_path / "g" / "grid_summary.csv").open()))
    assert rows[0].keys() >= {"circuit.delta_J0", "measure", "time", "mean", "sem", "n", "k", "n_seeds"}
    # as each point's summary.csv: the short circuit's rows, and the seeds carrying current (k) of the
    # seeds with a value (n_seeds) beside the current measures, whose mean is that of the k
    point = [{k: v for k, v in r.items() if k != "circuit.delta_J0"} for r in rows if r["circuit.delta_J0"] == "1"]
    own = list(csv.DictReader((tmp_path / "g" / "circuit.delta_J0=1" / "summary.csv").open()))
    assert point == own and any(r["k"] != "" for r in own)
    assert (tmp_path / "g" / "grid_summary.png").exists()
    assert {r["circuit.delta_J0"] for r in rows} == {"1", "2"} and {r["n"] for r in rows} <= {"0", "2"}
    table = json.loads((tmp_path / "g" / "grid_summary.json").read_text())
    assert table["keys"] == ["circuit.delta_J0"] and len(table["points"]) == 2
    assert "grid of 2 points x 2 seeds: 4 to run" in out
    # run again: nothing new runs
    assert main(argv) == 0
    assert "grid of 2 points x 2 seeds: 0 to run" in capsys.readouterr().out
    # summarising a grid that has no seed files yet: said so, nothing written, as for one ensemble
    empty = [a if a != str(tmp_path / "g") else str(tmp_path / "none") for a in argv] + ["--no-run"]
    assert main(empty) == 0
    assert "no seed file to summarise" in capsys.readouterr().out and not (tmp_path / "none").exists()


def test_grid_from_python_locks_its_folders_and_summarises_at_frame_times(tmp_path):
    """``Grid.run`` ran seeds in a point's folder that another ensemble held locked (the command
    line locked, the Python call did not); and ``Grid.summarise()``'s default times were the
    quarters of the end time wherever they fell, labelling one frame's values with two times."""
    from selfas_graph.ensemble import FolderLock

    grid = Grid(QUICK, {"circuit.delta_J0": ["1"]}, seeds=1, folder=tmp_path / "g", overrides=["rods.count=20"])
    point = tmp_path / "g" / "circuit.delta_J0=1"
    point.mkdir(parents=True)
    with FolderLock(point):
        with pytest.raises(EnsembleError, match="in use by another ensemble"):
            grid.run(jobs=1)
    assert not list(point.glob("seed_*.h5"))
    grid = Grid(
        QUICK,
        {"circuit.delta_J0": ["1"]},
        seeds=1,
        folder=tmp_path / "g",
        overrides=["rods.count=20", "output.interval=0.04"],
        t_end=0.1,
    )
    grid.run(jobs=1)
    assert grid.summarise()["times"] == [0.04, 0.08, 0.1]  # frames at 0, 0.04, 0.08 and the end
    assert not list(tmp_path.rglob(".ensemble.lock"))  # every lock released


def test_each_point_is_summarised_at_its_own_frames(tmp_path):
    """A grid over the output interval summarises each point at its own frames (each took the first
    point's, which the other point's frames need not hold)."""
    grid = Grid(
        QUICK,
        {"output.interval": ["0.04", "0.05"]},
        seeds=1,
        folder=tmp_path / "g",
        overrides=["rods.count=20"],
        t_end=0.1,
    )
    grid.run(jobs=1)
    table = grid.summarise()
    assert [p["summary"]["times"] for p in table["points"]] == [[0.04, 0.08, 0.1], [0.05, 0.1]]
    assert table["times"] == [0.04, 0.08, 0.1]


def test_a_grid_refuses_a_bad_flux_radius_before_anything_runs(tmp_path, capsys):
    """``--grid`` took ``--flux-radius -1`` and ran every seed, to end with a traceback at the first
    frame carrying current; it is refused first, as for one ensemble (exit 2, nothing written)."""
    from selfas_graph.cli.main import main

    argv = ["ensemble", str(QUICK), "--seeds", "1", "--grid", "circuit.delta_J0=1,2", "--t-end", "0.1"]
    for bad, words in [
        (["--flux-radius", "-1"], "--flux-radius must be a positive length"),
        (["--times", "5"], "--times 5 is after the end time 0.1; give times up to it"),
    ]:
        assert main(argv + bad + ["-o", str(tmp_path / "g")]) == 2
        assert words in capsys.readouterr().err
        assert not (tmp_path / "g").exists()


def test_a_grid_with_a_kept_failed_seed_exits_3_as_one_ensemble_does(tmp_path, capsys):
    """A grid whose folder keeps a failed seed from an earlier run exited 0 (it read only the seeds it ran
    now), where one ensemble exits 3 for the same folder."""
    import h5py

    from selfas_graph.cli.main import main
    from selfas_graph.ensemble import seed_path

    argv = ["ensemble", str(QUICK), "--seeds", "1", "--grid", "circuit.delta_J0=1,2", "--jobs", "1"]
    argv += ["--set", "rods.count=20", "--t-end", "0.02", "-o", str(tmp_path / "g")]
    assert main(argv) == 0
    with h5py.File(seed_path(tmp_path / "g" / "circuit.delta_J0=2", 1), "r+") as f:
        f["parameters/selfas_graph"].attrs["status"] = "failed: a test"
    capsys.readouterr()
    assert main(argv) == 3
    assert "0 done, 1 failed" in capsys.readouterr().out
