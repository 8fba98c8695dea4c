"""``selfas-graph analyze`` and :func:`selfas_graph.analysis.claims.frame_claims` on a small run.

One run of ``scenarios/quick.toml`` to t = 2.5 (past its short circuit at t = 2.01; the largest
structure then holds more than 30 rods, so every measure but the fractal dimensions is defined
at the last frame; those are refused while the fit range spans less than a factor 4) is made
once for the module. The measures themselves are tested on hand-built objects in
tests/unit/test_claims.py and tests/unit/test_fractal.py; here: the file-level entry point, the output
forms and the errors.
"""

import csv
import io
import json
import math
from pathlib import Path

import numpy as np
import pytest

from selfas_graph.analysis.claims import CLAIM_KEYS, claims_of_arrays, claims_series, frame_claims
from selfas_graph.analysis.fractal import MIN_RANGE, radius_of_gyration
from selfas_graph.analysis.frame_topology import frame_topology
from selfas_graph.analysis.skeleton import structures
from selfas_graph.cli.main import main
from selfas_graph.io.h5md import RunFile, RunFileError

REPO = Path(__file__).resolve().parents[2]
#: the keys of a frame's measures that the ensemble and study summaries read (ensemble/measures.py,
#: studies/summary.py), and the monopole moment's two others
ENSEMBLE_KEYS = (
    "largest_structure_rods",
    "largest_moment_q",
    "largest_moment_ratio",
    "largest_moment_J_z",
    "moment_J_z",
    "unpaired_charge_largest",
    "fractal_dimension",
    "fractal_dimension_err",
    "rg_dimension",
    "rg_dimension_err",
    "cycle_rank",
    "cycle_rank_largest",
    "structures",
)
DIMENSION_KEYS = ("fractal_dimension", "fractal_dimension_err", "rg_dimension", "rg_dimension_err")


@pytest.fixture(scope="module")
def run_file(tmp_path_factory):
    out = tmp_path_factory.mktemp("analyze") / "quick.h5"
    assert (
        main(
            ["simulate", str(REPO / "scenarios" / "quick.toml"), "-o", str(out), "--t-end", "2.5", "--progress", "none"]
        )
        == 0
    )
    return out


def test_frame_claims_keys_and_values(run_file):
    with RunFile(run_file) as run:
        c = frame_claims(run, -1)
        assert set(ENSEMBLE_KEYS) <= set(c) and set(c) == set(CLAIM_KEYS)
        assert all(isinstance(v, float) for v in c.values())
        assert all(math.isfinite(c[k]) for k in ENSEMBLE_KEYS if k not in DIMENSION_KEYS), c  # >= 30 rods
        # a dimension is defined, or refused because its range is under the minimum
        label, _ = structures(run.tip_charge.shape[0] // 2, run.graph(frame=-1)["tip_contacts"])
        big = np.flatnonzero(label == np.bincount(label[label >= 0]).argmax())
        rg_big = radius_of_gyration(run.position(-1)[np.column_stack([2 * big, 2 * big + 1]).ravel()])[0][0]
        assert math.isfinite(c["fractal_dimension"]) == (rg_big >= MIN_RANGE), (rg_big, c["fractal_dimension"])
        for k in DIMENSION_KEYS:
            assert math.isfinite(c[k]) == math.isfinite(c[k.replace("_err", "")]), k
        assert frame_claims(run, run.n_frames - 1) == c  # negative frames count from the end
        assert frame_claims(run, t=float(run.time[-1]) - 1e-9) == c  # by time, as analyze --time
        assert frame_claims(run) == c  # default: the last frame
        with pytest.raises(RunFileError, match="frame 0 and time 1.0 both given"):
            frame_claims(run, 0, t=1.0)  # t was taken and the frame dropped without a word
        # the same largest structure as the topology command, the same numbers as the array API
        assert c["largest_structure_rods"] == frame_topology(run)["largest_structure"]
        g = run.graph(frame=-1)
        direct = claims_of_arrays(run.position(-1), run.tip_charge, g["tip_contacts"], g["current"])
        assert {k: v for k, v in c.items() if k not in ("time", "step")} == pytest.approx(direct, nan_ok=True)
        assert c["largest_moment_ratio"] == pytest.approx(
            c["largest_moment_q"] / np.abs(run.tip_charge[0::2]).mean(), rel=1e-12
        )  # round-off
        # the first frame: no contact yet, measures of structures undefined
        c0 = frame_claims(run, 0)
        assert c0["largest_structure_rods"] == 0 and math.isnan(c0["largest_moment_q"]) and c0["cycle_rank"] == 0
        s = claims_series(run, loops=False)
        assert s["time"].shape == (run.n_frames,) and s["largest_structure_rods"][-1] == c["largest_structure_rods"]


def test_analyze_table_json_csv_and_series(run_file, capsys):
    assert main(["analyze", str(run_file)]) == 0
    out = capsys.readouterr().out
    assert "largest_moment_ratio" in out and "fractal_dimension" in out
    assert ("+-" in out and "fit over" in out) or "not testable at this size" in out
    assert main(["analyze", str(run_file), "--json", "--frame", "-1"]) == 0
    data = json.loads(capsys.readouterr().out)
    with RunFile(run_file) as run:
        expected = frame_claims(run, -1)
        n_frames = run.n_frames
    assert data["largest_moment_q"] == pytest.approx(expected["largest_moment_q"]) and data["frame"] == n_frames - 1
    for key in ("structures", "largest_structure_rods", "cycle_rank", "junctions"):  # counts are integers
        assert type(data[key]) is int and data[key] == expected[key]
    assert main(["analyze", str(run_file), "--json", "--frame", "0"]) == 0
    assert json.loads(capsys.readouterr().out)["largest_moment_q"] is None  # NaN -> null: strict JSON
    assert main(["analyze", str(run_file), "--csv"]) == 0
    rows = list(csv.DictReader(io.StringIO(capsys.readouterr().out)))
    assert len(rows) == n_frames and [int(r["frame"]) for r in rows] == list(range(n_frames))
    assert rows[0]["largest_moment_q"] == ""  # undefined -> empty cell
    assert main(["analyze", str(run_file), "--csv", "--time", "1.0"]) == 0
    rows = list(csv.DictReader(io.StringIO(capsys.readouterr().out)))
    assert len(rows) == 1 and float(rows[0]["time"]) == 1.0
    assert main(["analyze", str(run_file), "--series", "--every", "2", "--no-loops"]) == 0
    lines = capsys.readouterr().out.splitlines()
    picked = sorted(set(range(0, n_frames, 2)) | {n_frames - 1})  # and the last, as plot --every takes it
    assert len(lines) == 2 + len(picked) and "D_mass" in lines[1]
    assert int(lines[-1].split()[0]) == n_frames - 1


def test_analyze_errors_are_one_line(run_file, tmp_path, capsys):
    assert main(["analyze", str(tmp_path / "missing.h5")]) == 2
    assert "no such file" in capsys.readouterr().err
    assert main(["analyze", str(run_file), "--frame", "99"]) == 2
    assert "out of range" in capsys.readouterr().err
    assert main(["analyze", str(run_file), "--series", "--every", "0"]) == 2
    assert "--every" in capsys.readouterr().err


def test_every_with_one_frame_says_what_picks_the_frame(real_run, capsys):
    """``--csv --every 0 --frame 0`` was told to give --every with --csv, which it had."""
    from selfas_graph.cli.main import main

    assert main(["analyze", str(real_run["run"]), "--csv", "--every", "2", "--frame", "0"]) == 2
    err = capsys.readouterr().err
    assert "--frame and --time pick one frame" in err and "with --csv and no --frame or --time" in err
