"""What a user sees while a run goes: the progress line and the end summary name the contacts,
the electrode contacts, the short-circuit time and the current."""

import io
import re

import numpy as np

import selfas_graph as sg
from selfas_graph.cli.progress import Lines
from selfas_graph.cli.simulate import _print_summary


def _column(short):
    """Three vertical rods between electrodes, tips 0.02 apart: joined from step 0 when ``short``."""
    gap = 3.06 if short else 4.0
    p = sg.Parameters.from_dict(
        {
            "rods": {"count": 3},
            "placement": {"box": [[-1.0, 1.0], [-1.0, 1.0], [-1.53, 1.53]]},
            "forces": {"tip_magnetic": {}, "tip_brake": {}, "electrodes": {"gap": gap}},
            "circuit": {"delta_J0": 2.0},
        }
    )
    state = sg.State.from_rods(
        [[0, 0, -1.02], [0, 0, 0], [0, 0, 1.02]], np.tile([0, 0, 1.0], (3, 1)), np.ones(3), np.ones(3)
    )
    return sg.Simulation(p, state=state)


def test_progress_line_and_summary_after_a_short_circuit(tmp_path, capsys):
    sim = _column(short=True)
    summary = sim.run(0.01)
    stream = io.StringIO()
    Lines(stream)(sim, 10, 10)
    line = stream.getvalue()
    assert re.search(r"contacts 2, on electrodes 2, short circuit at t = 0, I = 2\.04 J0", line), line
    _print_summary(summary, tmp_path / "x.h5", sim)
    out = capsys.readouterr().out
    assert (
        "short circuit: the conductors were first joined at t = 0; at the end 3 rods carry current, total 2.04 J0"
        in out
    )
    assert sim.status()["current_rods"] == 3


def test_progress_line_before_a_short_circuit(tmp_path, capsys):
    sim = _column(short=False)
    summary = sim.run(0.01)
    stream = io.StringIO()
    Lines(stream)(sim, 10, 10)
    assert "no short circuit, I = 0 J0" in stream.getvalue()
    _print_summary(summary, tmp_path / "x.h5", sim)
    assert "short circuit: never; at the end 0 rods carry current" in capsys.readouterr().out


def test_topology_labels_its_event_columns(capsys):
    from pathlib import Path

    from selfas_graph.cli.main import main

    assert (
        main(["topology", str(Path(__file__).parent.parent / "data" / "legacy_run_58b30f8.h5"), "--events", "40"]) == 0
    )
    out = capsys.readouterr().out
    assert re.search(r"step +t +kind +a +b +\(what a and b are\)", out)
    assert "a, b = tips (rods" in out and "b = conductor (anode)" in out
    assert "a = rods in current-carrying filaments (3)" in out
