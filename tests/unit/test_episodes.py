"""Short-circuit episodes from hand-built event records (selfas_graph.analysis.episodes), and the
tool that prints them for run files (selfas_graph/bench/short_circuits.py) on a file with known events."""

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from selfas_graph.analysis.episodes import (
    OPENED_BY_BOTH,
    OPENED_BY_UNKNOWN,
    STILL_CLOSED,
    circuit_episodes,
)
from selfas_graph.model.circuitlog import circuit_log_array
from selfas_graph.model.events import (
    CONDUCTOR_CONTACT,
    CONDUCTOR_RELEASE,
    OPEN_CIRCUIT,
    SHORT_CIRCUIT,
    TIP_CONTACT,
    TIP_RELEASE,
    event_array,
)

ROOT = Path(__file__).resolve().parents[2]


def rows(*r):
    return event_array([(s, s * 1e-3, k, a, b) for s, k, a, b in r])


@pytest.mark.jit_off_ok
def test_two_episodes_one_opened_by_a_tip_release_one_by_an_electrode_release_then_closed_again():
    ev = rows(
        (10, TIP_CONTACT, 3, 8),
        (10, SHORT_CIRCUIT, 40, -1),
        (60, TIP_RELEASE, 3, 8),
        (60, OPEN_CIRCUIT, -1, -1),
        (100, CONDUCTOR_CONTACT, 5, 1),
        (100, SHORT_CIRCUIT, 41, -1),
        (250, TIP_CONTACT, 7, 9),  # an event of another step does not count as the opening
        (300, CONDUCTOR_RELEASE, 5, 1),
        (300, OPEN_CIRCUIT, -1, -1),
        (400, SHORT_CIRCUIT, 12, -1),
    )
    ep = circuit_episodes(ev)
    assert len(ep) == 3
    np.testing.assert_array_equal(ep.start, [0.010, 0.100, 0.400])
    np.testing.assert_array_equal(ep.end[:2], [0.060, 0.300])
    assert np.isnan(ep.end[2]) and np.isnan(ep.duration[2])
    np.testing.assert_allclose(ep.duration[:2], [0.050, 0.200], rtol=1e-12)  # differences of exact inputs
    np.testing.assert_array_equal(ep.filament_rods, [40, 41, 12])
    np.testing.assert_array_equal(ep.opened_by, [TIP_RELEASE, CONDUCTOR_RELEASE, STILL_CLOSED])


@pytest.mark.jit_off_ok
def test_circuit_log_gives_each_episode_its_current_and_rods_in_series():
    """Each episode takes the total current and rods in series of the circuit log's SHORT_CIRCUIT
    row of its closing step; an episode the log misses (closed before a resume from a checkpoint
    older than the log) gets NaN and -1; without a log both are None."""
    ev = rows(
        (10, SHORT_CIRCUIT, 40, -1),
        (60, TIP_RELEASE, 3, 8),
        (60, OPEN_CIRCUIT, -1, -1),
        (100, SHORT_CIRCUIT, 41, -1),
        (300, CONDUCTOR_RELEASE, 5, 1),
        (300, OPEN_CIRCUIT, -1, -1),
        (400, SHORT_CIRCUIT, 12, -1),
    )
    log = circuit_log_array(
        [
            (100, 0.1, SHORT_CIRCUIT, 2.5, 7, 41),
            (300, 0.3, OPEN_CIRCUIT, 0.0, 0, 0),
            (400, 0.4, SHORT_CIRCUIT, 0.75, 12, 12),
        ]
    )
    ep = circuit_episodes(ev, log)
    np.testing.assert_array_equal(ep.total_current[1:], [2.5, 0.75])
    assert np.isnan(ep.total_current[0])
    np.testing.assert_array_equal(ep.rods_in_series, [-1, 7, 12])
    plain = circuit_episodes(ev)
    assert plain.total_current is None and plain.rods_in_series is None
    with pytest.raises(ValueError, match="missing"):
        circuit_episodes(ev, np.zeros(2, dtype=[("step", "i8")]))


@pytest.mark.jit_off_ok
def test_opening_step_with_both_kinds_or_none():
    ev = rows(
        (1, SHORT_CIRCUIT, 5, -1),
        (2, TIP_RELEASE, 0, 3),
        (2, CONDUCTOR_RELEASE, 4, 0),
        (2, OPEN_CIRCUIT, -1, -1),
        (5, SHORT_CIRCUIT, 5, -1),
        (9, OPEN_CIRCUIT, -1, -1),
    )
    np.testing.assert_array_equal(circuit_episodes(ev).opened_by, [OPENED_BY_BOTH, OPENED_BY_UNKNOWN])


@pytest.mark.jit_off_ok
def test_no_events_and_no_short_circuit_give_no_episode():
    for ev in (rows(), rows((3, TIP_CONTACT, 0, 2), (4, TIP_RELEASE, 0, 2))):
        ep = circuit_episodes(ev)
        assert len(ep) == 0 and ep.start.dtype == np.float64 and ep.opened_by.dtype == np.int64


@pytest.mark.jit_off_ok
@pytest.mark.parametrize(
    "ev, match",
    [
        (rows((1, OPEN_CIRCUIT, -1, -1)), "OPEN_CIRCUIT without a SHORT_CIRCUIT"),
        (rows((1, SHORT_CIRCUIT, 3, -1), (2, SHORT_CIRCUIT, 3, -1)), "two SHORT_CIRCUIT"),
        (np.zeros(3, dtype=[("time", "f8"), ("kind", "i4")]), "missing"),
        (np.zeros(3), "structured array"),
    ],
)
def test_malformed_events_are_refused_with_the_reason(ev, match):
    with pytest.raises(ValueError, match=match):
        circuit_episodes(ev)


def _tool():
    from selfas_graph.bench import short_circuits

    return short_circuits


@pytest.fixture(scope="module")
def small_run(tmp_path_factory):
    """A 20-rod quick-scene run of 10 steps (two frames), written by the command line."""
    from selfas_graph.cli.main import main

    d = tmp_path_factory.mktemp("episodes")
    run = d / "run.h5"
    args = ["simulate", str(ROOT / "scenarios" / "quick.toml"), "-o", str(run), "--progress", "none"]
    assert main(args + ["--set", "rods.count=20", "--t-end", "0.01"]) == 0
    return run


def test_tool_summary_table_and_json_of_a_run_file(small_run, tmp_path, capsys):
    import json
    import shutil

    import h5py

    run = tmp_path / "run.h5"
    shutil.copy(small_run, run)
    ev = rows(
        (10, SHORT_CIRCUIT, 40, -1), (60, TIP_RELEASE, 3, 8), (60, OPEN_CIRCUIT, -1, -1), (100, SHORT_CIRCUIT, 41, -1)
    )
    with h5py.File(run, "r+") as f:  # known events in place of the run's own
        dtype = f["events"].dtype
        del f["events"]
        f.create_dataset("events", data=np.array(ev.tolist(), dtype=dtype))
    tool = _tool()
    out = tmp_path / "s.json"
    assert tool.main([str(run), "--json", str(out)]) == 0
    assert "| 2 | 0.01 | 0.05 | 0.05 | 1 / 0 / 0 | since t = 0.1 " in capsys.readouterr().out
    (row,) = json.loads(out.read_text())
    assert row["episodes"] == 2 and row["closed_at_end"] and row["opened_by_tip_release"] == 1
    # the run's own circuit log (empty: it never closed) has no row of these hand-made closings
    assert row["closing_current"] == row["closing_rods_in_series"] == [None, None]


def test_tool_replay_restarts_from_a_frame(small_run, capsys):
    tool = _tool()

    def replay(frame):
        scenario = str(ROOT / "scenarios" / "quick.toml")
        args = ["--replay", str(small_run), "--scenario", scenario, "--set", "rods.count=20", "--frame", frame]
        return tool.main(args + ["--for", "0.01"])

    assert replay("-1") == 0
    text = capsys.readouterr().out
    assert "restart of" in text and "20 rods" in text
    with pytest.raises(SystemExit, match="outside the 2 frames"):
        replay("5")


def test_tool_refuses_missing_files_and_incomplete_replay(tmp_path, capsys):
    tool = _tool()
    with pytest.raises(SystemExit) as e:
        tool.main([str(tmp_path / "nope.h5")])
    assert e.value.code == 2 and "no such run file" in capsys.readouterr().err
    with pytest.raises(SystemExit) as e:
        tool.main(["--replay", str(tmp_path / "nope.h5"), "--frame", "0"])
    assert e.value.code == 2 and "--scenario" in capsys.readouterr().err


def test_importing_the_tools_leaves_the_environment_alone():
    """The tools turn HDF5 file locking off for their own command line only: imported (as these
    tests do) they must not change it for the rest of the process, whose locking tests need it."""
    import os

    before = dict(os.environ)
    for name in ("short_circuits", "profile", "events"):
        spec = importlib.util.find_spec(f"selfas_graph.bench.{name}")
        spec.loader.exec_module(importlib.util.module_from_spec(spec))  # a fresh copy: its import runs again
    assert dict(os.environ) == before


def test_tool_refuses_bad_files_settings_and_writing_over_its_input(small_run, tmp_path, capsys):
    tool = _tool()
    junk = tmp_path / "junk.h5"
    junk.write_text("not HDF5")
    with pytest.raises(SystemExit) as e:
        tool.main([str(junk)])
    assert e.value.code == 2 and "not a readable HDF5 file" in capsys.readouterr().err
    before = small_run.read_bytes()
    with pytest.raises(SystemExit) as e:
        tool.main([str(small_run), "--json", str(small_run)])
    assert e.value.code == 2 and "one of the run files read" in capsys.readouterr().err
    assert small_run.read_bytes() == before
    args = ["--replay", str(small_run), "--scenario", str(ROOT / "scenarios" / "quick.toml"), "--frame", "0"]
    with pytest.raises(SystemExit) as e:
        tool.main(args + ["--for", "0.01", "--set", "rods.nonsense=1"])
    assert e.value.code == 2 and "rods.nonsense" in capsys.readouterr().err
