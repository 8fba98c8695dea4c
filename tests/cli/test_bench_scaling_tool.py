"""Smoke test of selfas_graph/bench/scaling.py on a tiny scaled Fig. 2 scene (a few seconds).

The tool's main() runs in this process; the numbers themselves are measurements, not checked here, only that every row is
there with its ratios and the tree's error, and that the plot is written.
"""

import json
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def _tool():
    from selfas_graph.bench import scaling

    return scaling


def test_rows_errors_ratios_and_plot(tmp_path, capsys):
    """Two sizes x both methods, two repeats: ms per step as median [min-max], the tree's error
    (small: below 1e-2 median at the default opening angle), speed-up over direct, the CPU and
    the instruction set in the header, the peer's figure and ratio from the same run when
    OpenMM is installed (a note when not), and a non-empty PNG."""
    tool = _tool()
    js, png = tmp_path / "s.json", tmp_path / "s.png"
    tool.main(["--rods", "60", "1200", "--step-seconds", "0.05", "--repeat", "2", "--json", str(js)])
    data = json.loads(js.read_text())
    rows = data["rows"]
    assert [(r["rods"], r["method"]) for r in rows] == [(60, "direct"), (60, "tree"), (1200, "direct"), (1200, "tree")]
    assert all(r["ms_per_step"] > 0 and r["vs_direct"] > 0 and len(r["ms_all"]) == 2 for r in rows)
    assert all(r["median_error"] < 1e-2 for r in rows if r["method"] == "tree")
    assert data["machine"]["cpu_name"] and data["machine"]["widest"]
    out = capsys.readouterr().out
    assert "| 1200 | tree | 1 x" in out and "numba" in out and "compiles for" in out
    if tool.OpenMMPeer.available():
        assert all(r["peer_ms"] > 0 and r["vs_peer"] > 0 and len(r["peer_ms_all"]) == 2 for r in rows)
        assert "OpenMM" in out
    else:
        assert all("vs_peer" not in r for r in rows) and "peer skipped" in out
    tool.main(["--plot", str(png), "--from-json", str(js)])
    assert png.stat().st_size > 1000


def test_no_peer_flag(tmp_path, capsys):
    """``--no-peer`` times our step alone: no peer figure, no ratio."""
    tool = _tool()
    js = tmp_path / "s.json"
    tool.main(
        ["--rods", "60", "--method", "tree", "--step-seconds", "0.02", "--repeat", "1", "--no-peer", "--json", str(js)]
    )
    rows = json.loads(js.read_text())["rows"]
    assert len(rows) == 1 and "peer_ms" not in rows[0] and "vs_peer" not in rows[0]
