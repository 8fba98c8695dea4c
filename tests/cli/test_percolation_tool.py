"""Smoke test of selfas_graph/bench/percolation.py: an ensemble of short-circuit times on quick.toml.

The tool's main() runs in this process. One small ensemble (2 densities x 2 seeds to t = 2.2, about 30 s on 2 cores) is
shared by the checks of the JSON structure, the statistics, the table and the plot; the
same runs are repeated on 2 worker processes to check that the results do not depend on
the number of workers; a t-max far shorter than the short circuit gives censored runs.
The tool runs on the library's ensemble runner and statistics, whose Kaplan-Meier and
Wilson intervals are tested on hand-made data in tests/unit/test_ensemble_stats.py.
"""

import json
import math
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
QUICK = str(ROOT / "scenarios" / "quick.toml")
T_MAX = 2.2  # quick.toml short-circuits at t = 2.01 with its seed (1) at 300 rods
DENSITIES = ["0.4", "0.6"]  # rods per unit volume: 200 and 300 rods in the 10 x 10 x 5 box
RUN_KEYS = {
    "count",
    "seed",
    "status",
    "time",
    "t_end",
    "steps",
    "events",
    "filament_rods",
    "wall_seconds",
    "message",
    "signum",
}
DENSITY_KEYS = {
    "requested",
    "count",
    "number_density",
    "volume_fraction",
    "runs",
    "short_circuited",
    "censored",
    "failed",
    "decided",
    "excluded",
    "fraction",
    "fraction_ci95",
    "km_fraction",
    "q25",
    "median",
    "q75",
    "km",
}


def _tool():
    from selfas_graph.bench import percolation

    return percolation


@pytest.fixture(scope="module")
def tool():
    return _tool()


@pytest.fixture(scope="module")
def ensemble(tool, tmp_path_factory):
    out = tmp_path_factory.mktemp("percolation")
    js, png = out / "res.json", out / "res.png"
    rc = tool.main(
        [
            QUICK,
            "--densities",
            *DENSITIES,
            "--seeds",
            "2",
            "--t-max",
            str(T_MAX),
            "--workers",
            "1",
            "-o",
            str(js),
            "--plot",
            str(png),
        ]
    )
    assert rc == 0
    return json.loads(js.read_text()), png


def _deterministic(run):
    return {k: v for k, v in run.items() if k != "wall_seconds"}


def test_json_structure(ensemble):
    res, _ = ensemble
    assert res["t_max"] == T_MAX and res["seeds"] == [1, 2] and res["box_volume"] == pytest.approx(500.0)
    assert res["threads_per_run"] == 1 and res["skipped"] == []
    assert [d["count"] for d in res["densities"]] == [200, 300]
    assert len(res["runs"]) == 4
    for run in res["runs"]:
        assert set(run) == RUN_KEYS
        assert run["status"] in ("short_circuit", "censored"), run["message"]
        if run["status"] == "short_circuit":
            assert 0.0 <= run["time"] <= T_MAX and run["time"] == run["t_end"] and run["filament_rods"] > 0
        else:
            assert run["time"] is None and run["t_end"] == pytest.approx(T_MAX) and run["filament_rods"] == 0
    vrod = math.pi * 0.03**2
    for d in res["densities"]:
        assert set(d) == DENSITY_KEYS
        assert d["number_density"] == pytest.approx(d["count"] / 500.0)
        assert d["volume_fraction"] == pytest.approx(d["count"] * vrod / 500.0)
        runs = [r for r in res["runs"] if r["count"] == d["count"]]
        sc = sorted(r["time"] for r in runs if r["status"] == "short_circuit")
        assert d["runs"] == 2 and d["short_circuited"] == len(sc) and d["censored"] == 2 - len(sc)
        assert d["fraction"] == pytest.approx(len(sc) / 2) and d["km_fraction"] == pytest.approx(len(sc) / 2)
        lo, hi = d["fraction_ci95"]
        assert 0.0 <= lo <= d["fraction"] <= hi <= 1.0
        # censoring only at t_max: the Kaplan-Meier curve is the empirical distribution over all runs
        assert d["km"] == [[t, pytest.approx((i + 1) / 2)] for i, t in enumerate(sc)]
        assert d["median"] == (sc[0] if sc else None)
        assert d["q75"] == (sc[1] if len(sc) == 2 else None)
    # the documented short circuit of quick.toml (seed 1, 300 rods, at t = 2.01) is found
    assert res["densities"][1]["short_circuited"] >= 1
    json.dumps(res, allow_nan=False)  # strict JSON


def test_plot_written(ensemble):
    _, png = ensemble
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 10_000


def test_deterministic_with_two_workers(tool, ensemble, tmp_path):
    """The runs of one density again, on 2 worker processes: the same numbers."""
    res, _ = ensemble
    js = tmp_path / "w2.json"
    assert (
        tool.main(
            [QUICK, "--densities", DENSITIES[1], "--seeds", "2", "--t-max", str(T_MAX), "--workers", "2", "-o", str(js)]
        )
        == 0
    )
    again = json.loads(js.read_text())
    first = [_deterministic(r) for r in res["runs"] if r["count"] == 300]
    assert [_deterministic(r) for r in again["runs"]] == first
    assert again["densities"][0] == res["densities"][1]


def test_censored_and_skipped(tool, tmp_path, capsys):
    """No run can short-circuit by a tiny t-max; a density that cannot be placed is skipped by name."""
    js = tmp_path / "c.json"
    assert tool.main([QUICK, "--densities", "0.6", "1000", "--seeds", "1", "--t-max", "0.01", "-o", str(js)]) == 0
    res = json.loads(js.read_text())
    out = capsys.readouterr().out
    assert "skipping density 1000 (500000 rods)" in out
    assert res["skipped"][0]["requested"] == {"by": "density", "value": 1000.0}
    (run,) = res["runs"]
    assert run["status"] == "censored" and run["time"] is None and run["t_end"] == pytest.approx(0.01)
    (d,) = res["densities"]
    assert d["short_circuited"] == 0 and d["censored"] == 1 and d["fraction"] == 0.0
    assert d["median"] is None and d["km"] == []
    assert "| 300 | 0.6 |" in out and ">0.01" in out


def test_a_signal_stops_the_runs_and_the_tool_exits_as_simulate_does(tool, tmp_path, monkeypatch, capsys):
    """SIGTERM in a run: it stops after its step, "interrupted" with the signal's number, no further run
    starts, the statistics are still written, and the tool exits 143 (128 + the signal's number, as
    simulate and ensemble do; it exited 130 whatever the signal)."""
    import os
    import signal

    from selfas_graph.model.simulation import Simulation

    run = Simulation.run

    def run_then_signal(sim, *a, **kw):
        if sim.state.step >= 5:
            os.kill(os.getpid(), signal.SIGTERM)  # caught by the run's handler: the run stops after its step
        return run(sim, *a, **kw)

    monkeypatch.setattr(Simulation, "run", run_then_signal)
    js = tmp_path / "s.json"
    argv = [QUICK, "--counts", "40", "--seeds", "2", "--t-max", "5", "--chunk", "0.01", "-o", str(js)]
    assert tool.main(argv) == 128 + signal.SIGTERM
    first, second = json.loads(js.read_text())["runs"]
    assert first["status"] == "interrupted" and first["signum"] == signal.SIGTERM
    assert "signal 15 at step" in first["message"] and first["t_end"] < 5
    assert second["status"] == "interrupted" and second["message"] == "not run" and second["signum"] is None


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--counts", "300", "--seeds", "0", "--t-max", "1"], "--seeds: 0 must be positive"),
        (["--counts", "300", "--seeds", "-2", "--t-max", "1"], "--seeds: -2 must be positive"),
        (["--densities", "--seeds", "1", "--t-max", "1"], "--densities: expected at least one argument"),
        (["--seeds", "1", "--t-max", "1"], "required: --densities, --fractions or --counts"),
        (["--counts", "300", "--t-max", "1"], "required: --seeds"),
        (["--counts", "300", "--seeds", "1", "--t-max", "1", "--fields", "none"], "--fields: invalid choice"),
        (["--densities", "0", "--seeds", "1", "--t-max", "1"], "--densities: 0 must be positive"),
        (["--counts", "300", "--seeds", "1", "--t-max", "0"], "--t-max: 0 must be positive"),
        (["--counts", "300", "--seeds", "1", "--t-max", "1", "--workers", "0"], "--workers: 0 must be positive"),
        (["--fractions", "0.3", "0.5", "--seeds", "1", "--t-max", "1"], "no density left to run"),
        (["--counts", "300", "--seeds", "1", "--t-max", "1", "--set", "integrator.dt=-1"], "integrator.dt"),
        (["--counts", "300", "--seeds", "1", "--t-max", "1", "--set", "contacts.enabled=false"], "contacts.enabled"),
    ],
)
def test_bad_inputs(tool, capsys, argv, message):
    with pytest.raises(SystemExit) as exc:
        tool.main([QUICK, *argv])
    assert exc.value.code == 2
    assert message in capsys.readouterr().err


def test_fields_off_removes_the_magnetic_and_current_terms(tool, tmp_path, capsys):
    """--fields off is --set forces.NAME=false for each magnetic and current term, recorded in the result."""
    js = tmp_path / "off.json"
    assert (
        tool.main([QUICK, "--counts", "300", "--seeds", "1", "--t-max", "0.05", "--fields", "off", "-o", str(js)]) == 0
    )
    res = json.loads(js.read_text())
    assert res["fields"] == "off" and tool.fields_of(res) == "off"
    assert res["overrides"][: len(tool.FIELD_TERMS)] == [f"forces.{n}=false" for n in tool.FIELD_TERMS]
    from selfas_graph import load_scenario

    params = load_scenario(QUICK, overrides=res["overrides"]).params
    assert all(getattr(params.forces, n) is None for n in tool.FIELD_TERMS)
    assert params.forces.yukawa is not None and params.forces.electrodes is not None


def test_compare_draws_results_and_refuses_other_files(tool, ensemble, tmp_path, capsys):
    res, _ = ensemble
    on = tmp_path / "on.json"
    on.write_text(json.dumps(res))
    old_off = dict(res, overrides=["forces.tip_magnetic=false"])  # a file written before the "fields" key
    old_off.pop("fields", None)
    off = tmp_path / "off.json"
    off.write_text(json.dumps(old_off))
    assert tool.fields_of(old_off) == "off" and tool.fields_of(res) == "on"
    png = tmp_path / "cmp.png"
    assert tool.main(["--compare", str(on), str(off), "--plot", str(png)]) == 0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    bad = tmp_path / "bad.json"
    bad.write_text("{}")
    for argv, message in (
        (["--compare", str(bad), "--plot", str(png)], "bad.json: not a result file"),
        (["--compare", str(on)], "--compare needs --plot"),
        ([QUICK, "--compare", str(on), "--plot", str(png)], "draws earlier results only"),
        (["--compare", str(on), str(off), "--plot", str(off)], "is the input"),
    ):
        with pytest.raises(SystemExit) as exc:
            tool.main(argv)
        assert exc.value.code == 2 and message in capsys.readouterr().err
    assert tool.fields_of(json.loads(off.read_text())) == "off"  # the input refused as a target is intact


def test_a_failed_run_is_censored_in_the_curve_and_left_out_of_the_fraction():
    """A run that failed at t = 1 without a short circuit might have short-circuited by t_max: it is
    censored there in the Kaplan-Meier curve and left out of the fraction, whose Wilson interval is
    over the 3 runs that decide it (2 short circuits, 1 censored at t_max), not over 4."""
    from selfas_graph.analysis.ensemble_stats import wilson_interval

    runs = [
        {"status": "short_circuit", "time": 0.5, "t_end": 0.5},
        {"status": "short_circuit", "time": 1.5, "t_end": 1.5},
        {"status": "censored", "time": None, "t_end": 2.0},
        {"status": "failed", "time": None, "t_end": 1.0},
        {"status": "error", "time": None, "t_end": 0.0},
    ]
    d = _tool().summarise({"count": 10}, runs)
    assert (d["runs"], d["short_circuited"], d["censored"], d["failed"], d["decided"]) == (4, 2, 1, 1, 3)
    assert d["excluded"] == 1 and d["fraction"] == pytest.approx(2 / 3)
    assert d["fraction_ci95"] == pytest.approx(list(wilson_interval(2, 3)))
    # the curve: 1/4 at t = 0.5 (4 at risk); the failure at t = 1 leaves 2 at risk at t = 1.5, where the
    # survival falls by half: 1 - 3/4 * 1/2 = 5/8, not the 1 - 3/4 * 2/3 of the run counted as still at risk
    assert [x for row in d["km"] for x in row] == pytest.approx([0.5, 0.25, 1.5, 0.625])
