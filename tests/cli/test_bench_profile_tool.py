"""Smoke test of selfas_graph/bench/profile.py on the quick scene (a few steps): every part of the table
sums to the profiled total and the kernels are counted; the times are measurements, not checked."""

from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def _tool():
    from selfas_graph.bench import profile

    return profile


def test_profile_table_of_a_few_steps(capsys):
    tool = _tool()
    tool.main(["--scenario", str(ROOT / "scenarios" / "quick.toml"), "--settle", "4", "--steps", "12"])
    out = capsys.readouterr().out
    assert "compiles for" in out and "| total (profiled) |" in out
    rows = [line for line in out.splitlines() if line.startswith("| ") and "ms/step" not in line]
    shares = [float(line.split("|")[3].strip().rstrip(" %")) for line in rows[:-1]]
    assert abs(sum(shares) - 100.0) < 1.0  # each share is rounded to 0.1 %
    assert "kernel calls per 1000 steps:" in out and "ab4_step" in out


def test_fused_kernels_table(capsys):
    tool = _tool()
    tool.main(["--kernels", "--rounds", "1", "--steps", "10"])
    out = capsys.readouterr().out
    assert "| channel sum of 10 channels and 6 powers |" in out and "| extrapolation of 4 held arrays |" in out


def test_every_function_falls_in_one_part():
    tool = _tool()
    assert tool.part_of(("/x/selfas_graph/kernels/tips.py", 1, "tip_tip_direct")).startswith("tip-tip far")
    assert tool.part_of(("/x/selfas_graph/kernels/currents.py", 1, "rod_current_field")).startswith("current field at")
    assert tool.part_of(("/x/selfas_graph/kernels/cells.py", 1, "_row_fill")) == "neighbour-list builds"
    assert tool.part_of(("~", 0, "<built-in method numpy.einsum>")) == "numpy and other"


def test_checks_tool_times_both_checks(capsys):
    from selfas_graph.bench import checks as tool

    got = tool.main(
        ["--scenario", str(ROOT / "scenarios" / "quick.toml"), "--settle", "4", "--repeat", "2", "--calls", "2"]
    )
    assert len(got) == 2 and all(v[0] > 0 and v[1] > 0 for v in got.values())
    assert "compiles for" in capsys.readouterr().out
