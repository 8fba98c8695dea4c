"""``selfas-graph topology``: filaments, currents and events of a saved frame, and its errors.

The run file is written in-process the way ``selfas-graph simulate`` writes it
(:class:`RunWriter` and ``Simulation.run(writer=...)``), from a hand-built chain
of three rods that short-circuits the electrodes at a known step: a random scene
would not say when (or whether) that happens.
"""

import json
import math

import h5py
import numpy as np
import pytest

from conftest import simulation
from selfas_graph._version import __version__
from selfas_graph.cli.main import main
from selfas_graph.io.h5md import RunFile, RunFileError, RunWriter
from selfas_graph.model import events as ev
from selfas_graph.model.state import State

GAP = 3.16
DELTA_J0 = 2.0
DT = 1e-3
INTERVAL = 0.01
T_END = 0.1
N_FRAMES = 11  # t = 0, 0.01, ..., 0.1


def chain_state():
    """Three rods along +z between the electrodes at z = -+GAP/2: tips 1-2 in contact,
    tips 3-4 0.08 apart (closed by the attraction at step 14, measured), tips 0 and 5
    touching the cathode and the anode (h = 0.025 < r*)."""
    z0 = -GAP / 2 + 0.025 + 0.5
    return State.from_rods([[0, 0, z0], [0, 0, z0 + 1.03], [0, 0, z0 + 2.11]], [[0, 0, 1.0]] * 3, [1.0] * 3, [0.0] * 3)


def write_run(path, contacts=True, circuit=True):
    """Run the chain to T_END and write it as ``simulate`` does; returns the Simulation."""
    state = chain_state()
    extra = {"circuit": {"delta_J0": DELTA_J0}} if contacts and circuit else {}  # a circuit needs contacts
    sim = simulation(
        state,
        forces={"tip_magnetic": {}, "tip_brake": {}, "ambient_brake": {}, "electrodes": {"gap": GAP}},
        integrator={"dt": DT},
        contacts={"enabled": contacts},
        output={"interval": INTERVAL},
        **extra,
    )
    provenance = {
        "scenario_text": "# hand-built chain of three rods (tests/cli/test_topology_cli.py)",
        "parameters_json": json.dumps(sim.params.to_dict()),
        "version": __version__,
        "command_line": "pytest tests/cli/test_topology_cli.py",
        "seed": 0,
        "mpi_ranks": 1,
        "numba_threads": 1,
    }
    writer = RunWriter(path, state.n_tips, state.tip_charge, state.rod_charge, provenance)
    try:
        sim.run(t_end=T_END, writer=writer)
    finally:
        writer.close()
    return sim


@pytest.fixture(scope="module")
def chain_run(tmp_path_factory):
    path = tmp_path_factory.mktemp("topology") / "chain.h5"
    sim = write_run(path)
    return path, sim


def _short_circuit(sim):
    rows = [e for e in sim.events if e[2] == ev.SHORT_CIRCUIT]
    assert len(rows) == 1
    return rows[0]


def test_chain_run_file_is_complete(chain_run):
    """The run file has one graph row per frame and the same events as the Simulation."""
    path, sim = chain_run
    with RunFile(path) as run:
        assert run.n_frames == N_FRAMES and run.has_graph
        assert run.f["graph/step"].shape == (N_FRAMES,)
        e = run.events()
        assert [tuple(r) for r in e.tolist()] == [tuple(r) for r in sim.events]


def test_topology_text_names_an_open_circuit(chain_run, capsys):
    """Before the chain spans the gap the circuit is open: no finite resistance, which the text
    said as "n/a (no circuit)", as for a run without a circuit."""
    path, _ = chain_run
    assert main(["topology", str(path), "--frame", "0"]) == 0
    out = capsys.readouterr().out
    assert "effective resistance between the electrodes: infinite (open: no current-carrying path)" in out


def test_without_a_circuit_the_filaments_are_not_called_current_carrying(tmp_path, capsys):
    """The filament role is topological (a path between two conductors); in a run without a circuit no
    current flows in it, and the text says so instead of calling the rods current-carrying."""
    path = tmp_path / "nocircuit.h5"
    write_run(path, circuit=False)
    assert main(["topology", str(path)]) == 0
    out = capsys.readouterr().out
    assert "3 in filaments joining conductors (no circuit)" in out and "current-carrying" not in out
    assert "total current: n/a (no circuit)" in out
    assert main(["topology", str(path), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["circuit"] is False


def test_topology_text_shows_filament_currents_and_events(chain_run, capsys):
    """The last frame: 3 filament rods with their currents, total current, R_eff = 3 R0, short-circuit time, events.

    The currents are -delta_J0 dZ / 3 (current flows from the anode down the chain,
    from tip b to tip a); printed with 4 significant digits.
    """
    path, sim = chain_run
    step, t, _, n_fil, _ = _short_circuit(sim)
    assert main(["topology", str(path)]) == 0
    out = capsys.readouterr().out
    J = DELTA_J0 * GAP / 3.0
    assert f"frame {N_FRAMES - 1} of 0..{N_FRAMES - 1}, step 100, t = 0.1" in out
    assert "rods: 3 = 3 in current-carrying filaments + 0 dead ends + 0 in floating clusters + 0 free" in out
    assert f"short circuit: yes (first at step {step}, t = {t:.6g})" in out
    assert f"total current: {J:.6g} J0" in out
    assert "effective resistance between the electrodes: 3 R0" in out
    assert "current-carrying filament rods" in out
    table = out.split("current-carrying filament rods")[1].splitlines()[1]
    assert table.split() == ["0", f"{-J:+.4g}", "1", f"{-J:+.4g}", "2", f"{-J:+.4g}"]
    assert "events up to this frame: conductor_contact 2, short_circuit 1, tip_contact 2" in out
    event_lines = [line.split() for line in out.splitlines() if line.startswith("  step")]
    assert [(int(w[1]), w[5], int(w[6]), int(w[7])) for w in event_lines] == [
        (0, "tip_contact", 1, 2),
        (0, "conductor_contact", 0, 0),
        (0, "conductor_contact", 5, 1),
        (step, "tip_contact", 3, 4),
        (step, "short_circuit", n_fil, -1),
    ]
    # the closing's current from the circuit log, made at the SHORT_CIRCUIT step: all 3 rods in series
    assert f"a = rods in current-carrying filaments (3); total current {J:.6g} J0, 3 rods in series" in out


def test_topology_json_matches_the_simulation(chain_run, capsys):
    """``--json`` parses; its counts, currents, total current and resistance are the Simulation's numbers.

    The currents pass through HDF5 (float64) and JSON (shortest round-trip repr), so
    they compare exactly.
    """
    path, sim = chain_run
    assert main(["topology", str(path), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    sol = sim.solution
    assert data["frame"] == N_FRAMES - 1 and data["frames"] == N_FRAMES
    assert data["step"] == sim.state.step and data["time"] == pytest.approx(T_END, abs=1e-12)
    assert data["rods"] == {"free": 0, "cluster": 0, "dead_end": 0, "filament": 3, "total": 3}
    assert [d["rod"] for d in data["filament_rods"]] == [0, 1, 2]
    assert len(data["filament_rods"]) == data["rods"]["filament"] == sim.graph.topology().n_filament
    assert [d["current"] for d in data["filament_rods"]] == sol.current.tolist()
    assert data["total_current"] == sol.total_current
    # the file stores the conductance 1/R (finite for an open circuit too): 1/(1/R) is R to rounding
    assert data["effective_resistance"] == pytest.approx(sol.effective_resistance, rel=4e-16)
    assert data["effective_resistance"] == pytest.approx(3.0, abs=1e-12)  # three unit resistors
    step, t, _, _, _ = _short_circuit(sim)
    assert data["first_short_circuit"] == {"step": step, "time": t}
    assert data["short_circuit"] is True
    assert data["conductors"] == {"cathode": -DELTA_J0 * GAP / 2, "anode": DELTA_J0 * GAP / 2}
    assert data["structures"] == [
        {"id": 0, "rods": 3, "filament": 3, "dead_end": 0, "conductors": ["anode", "cathode"]}
    ]
    assert len(data["events"]) == len(sim.events)
    (closing,) = [e for e in data["events"] if e["kind"] == "short_circuit"]
    assert (closing["total_current"], closing["rods_in_series"]) == (sim.circuit_log[0][3], 3)
    assert all("total_current" not in e for e in data["events"] if e["kind"] != "short_circuit")
    assert data["event_counts"] == {"tip_contact": 2, "conductor_contact": 2, "short_circuit": 1}


def test_frame_and_time_select_frames(chain_run, capsys):
    """``--frame`` (negative from the end) and ``--time`` (nearest frame) pick the frame.

    Frame 1 (t = 0.01) predates the short circuit (step 14): two structures, one per
    electrode, all dead ends, no current, no short-circuit event yet. Frame 5 (t = 0.05)
    is after it; ``--time 0.047`` and ``--frame -6`` are the same frame.
    """
    path, sim = chain_run
    step = _short_circuit(sim)[0]
    assert 10 < step < 20  # frame 1 before, frame 2 after the short circuit

    def query(*args):
        assert main(["topology", str(path), "--json", *args]) == 0
        return json.loads(capsys.readouterr().out)

    early = query("--frame", "1")
    assert early["frame"] == 1 and early["step"] == 10
    assert early["time"] == pytest.approx(0.01, abs=1e-12)
    assert early["rods"]["filament"] == 0 and early["rods"]["dead_end"] == 3
    assert early["short_circuit"] is False and early["first_short_circuit"] is None
    assert early["total_current"] == 0.0
    assert sorted(s["rods"] for s in early["structures"]) == [1, 2]
    assert early["event_counts"] == {"tip_contact": 1, "conductor_contact": 2}
    assert all(e["step"] <= 10 for e in early["events"])

    late = query("--time", "0.047")
    assert late["frame"] == 5 and late["step"] == 50 and late["rods"]["filament"] == 3
    assert late == query("--frame", "-6")
    assert query("--frame", "0")["step"] == 0
    last = query("--frame", "-1")["time"]
    assert query("--time", repr(last + 0.005))["frame"] == N_FRAMES - 1  # within a frame spacing: the nearest
    # far beyond the frames it names no frame of this run (not silently the last one)
    assert main(["topology", str(path), "--time", "1e9"]) == 2
    assert "time 1e+09 lies outside the run's frames" in capsys.readouterr().err
    assert main(["topology", str(path), "--frame", "2"]) == 0
    assert "short circuit: yes" in capsys.readouterr().out


@pytest.fixture(scope="module")
def bad_files(tmp_path_factory, chain_run):
    d = tmp_path_factory.mktemp("bad")
    write_run(d / "no_graph.h5", contacts=False)
    (d / "notes.h5").write_text("these are not HDF5 bytes\n")
    (d / "empty.h5").write_bytes(b"")
    with h5py.File(d / "foreign.h5", "w") as f:
        f["data"] = np.arange(10)
    return d


@pytest.mark.parametrize(
    "name, args, message",
    [
        ("chain", ["--frame", "11"], "frame 11 out of range; the file has frames 0..10"),
        ("chain", ["--frame", "-12"], "frame -12 out of range; the file has frames 0..10"),
        ("no_graph.h5", [], "the file has no graph data (the run had contacts.enabled = false"),
        ("missing.h5", [], "missing.h5: no such file"),
        ("notes.h5", [], "not a readable HDF5 file"),
        ("empty.h5", [], "not a readable HDF5 file"),
        ("foreign.h5", [], "an HDF5 file, but not a selfas-graph run"),
    ],
)
def test_bad_input_exits_2_with_one_line(chain_run, bad_files, capsys, name, args, message):
    """Each bad input gives exit code 2 and one line on stderr naming the problem, no traceback, no stdout."""
    path = chain_run[0] if name == "chain" else bad_files / name
    for extra in ([], ["--json"]):
        assert main(["topology", str(path), *args, *extra]) == 2
        captured = capsys.readouterr()
        assert captured.out == ""
        lines = captured.err.strip("\n").splitlines()
        assert len(lines) == 1, captured.err
        assert lines[0].startswith("selfas-graph topology: error: ")
        assert message in lines[0]
        assert "Traceback" not in captured.err


def test_run_without_contacts_still_reads_as_a_run(bad_files):
    """The contacts.enabled = false file is a valid run (frames, positions), only the graph is absent."""
    with RunFile(bad_files / "no_graph.h5") as run:
        assert run.n_frames == N_FRAMES and not run.has_graph
        assert len(run.events()) == 0
        assert np.isfinite(run.position(-1)).all()


def test_json_is_strict_json_before_the_short_circuit(chain_run, capsys):
    """``--json`` is for scripts: it must parse with a strict JSON parser (no NaN / Infinity tokens).

    Before the short circuit the effective resistance is inf; json.dumps would write it
    as the non-standard token ``Infinity``, which jq and other strict parsers reject, so
    the command reports null instead.
    """
    path, _ = chain_run
    assert main(["topology", str(path), "--json", "--frame", "1"]) == 0
    text = capsys.readouterr().out

    def reject(token):
        raise ValueError(f"non-standard JSON token {token}")

    data = json.loads(text, parse_constant=reject)
    assert data["effective_resistance"] is None or math.isfinite(data["effective_resistance"])


def test_directory_instead_of_file_gives_one_line(tmp_path, capsys):
    """A directory given as the run file is an error of one line, like every other bad path."""
    d = tmp_path / "run.h5"
    d.mkdir()
    assert main(["topology", str(d)]) == 2
    err = capsys.readouterr().err
    assert len(err.strip("\n").splitlines()) == 1, err


def test_time_nan_is_rejected(chain_run, capsys):
    """``--time nan`` names no frame; it should be a usage error (exit 2), not frame 0."""
    path, _ = chain_run
    assert main(["topology", str(path), "--time", "nan"]) == 2


def test_topology_and_analyze_say_a_run_did_not_finish(tmp_path, capsys):
    """A file of an interrupted, killed or failed run is read as any other, and its first line says so
    (with what continues it); the JSON carries the status too. A finished run's line is as before."""
    path = tmp_path / "cut.h5"
    write_run(path)
    for status, said in (
        ("interrupted at step 50", "the run was interrupted at step 50; simulate --resume continues it"),
        ("running", "the run has not finished: it is still running, or was killed"),
        ("failed: numerical failure at step 9", "the run failed: numerical failure at step 9"),
        ("finished", None),
    ):
        with h5py.File(path, "r+") as f:
            f["parameters/selfas_graph"].attrs["status"] = status
        for command in ("topology", "analyze"):
            assert main([command, str(path)]) == 0
            first = capsys.readouterr().out.splitlines()[0]
            assert (said in first) if said else first.endswith("t = 0.1"), (command, first)
        assert main(["topology", str(path), "--json"]) == 0
        assert json.loads(capsys.readouterr().out)["run_status"] == status


def test_snapshot_legend_counts_every_dead_end_topology_counts(chain_run):
    """Frame 1 holds three dead ends on single electrodes and no filament: the snapshot's red is the
    dead ends of filament networks (none), and its grey rods name the three that ``topology`` counts."""
    from matplotlib.figure import Figure

    from selfas_graph.cli.plots.frame import _snapshot

    path, _ = chain_run
    with RunFile(path) as run:
        frame = run.frame(1)
        fig = Figure(layout="constrained")
        _snapshot(fig, run, frame, None)
        labels = [t.get_text() for t in fig.legends[0].get_texts()]
    assert "dead ends of filament networks (0)" in labels
    assert any(
        t.startswith("other rods (") and t.endswith("3 of them dead ends off the filament networks)") for t in labels
    )


def test_a_frame_named_twice_or_by_a_boolean_is_refused(chain_run):
    """``run.frame(1, t=0.05)`` took the time and dropped the number without a word; ``frame(True)`` was
    frame 1: both are refused, naming what was given."""
    path, _ = chain_run
    with RunFile(path) as run:
        with pytest.raises(RunFileError, match="frame 1 and time 0.05 both given"):
            run.frame(1, t=0.05)
        with pytest.raises(RunFileError, match="frame True"):
            run.frame(True)
        with pytest.raises(RunFileError, match="time True names no frame"):
            run.graph(t=True)
        assert run.frame(t=0.05).index == run.frame(5).index
