"""Smoke test of tools/bench_scaling.py on a tiny scaled Fig. 2 scene (a few seconds).

The tool's main() runs in this process (tools/ is not a package: it is imported from its
path); the numbers themselves are measurements, not checked here, only that every row is
there with its ratios and the tree's error, and that the plot is written.
"""
import importlib.util
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def _tool():
    sys.path.insert(0, str(ROOT / "tools"))  # the tool imports bench_step beside it
    spec = importlib.util.spec_from_file_location("_selfas_tools_bench_scaling", ROOT / "tools" / "bench_scaling.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_rows_errors_ratios_and_plot(tmp_path, capsys):
    """Two sizes x both methods: ms per step, the tree's error (small: below 1e-2 median at
    the default opening angle), speed-up over direct, the peer ratio where the peer was
    measured (1200 rods), and a non-empty PNG."""
    tool = _tool()
    js, png = tmp_path / "s.json", tmp_path / "s.png"
    tool.main(["--rods", "60", "1200", "--step-seconds", "0.05", "--json", str(js)])
    rows = json.loads(js.read_text())["rows"]
    assert [(r["rods"], r["method"]) for r in rows] == [(60, "direct"), (60, "tree"), (1200, "direct"), (1200, "tree")]
    assert all(r["ms_per_step"] > 0 and r["vs_direct"] > 0 for r in rows)
    assert all(r["median_error"] < 1e-2 for r in rows if r["method"] == "tree")
    assert "vs_peer" in rows[2] and "vs_peer" not in rows[0]
    assert "| 1200 | tree | 1 x" in capsys.readouterr().out
    tool.main(["--plot", str(png), "--from-json", str(js)])
    assert png.stat().st_size > 1000
