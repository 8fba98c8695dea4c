"""Smoke test of selfas_graph/bench/neighbours.py on a tiny scaled Fig. 2 scene (a few seconds).

The timings in this process (no child per instruction set); the numbers are measurements, not
checked here, only that every kernel was timed the asked number of times, that the lists are
not empty and that the machine and the numba target are reported.
"""

import argparse
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def _tool():
    from selfas_graph.bench import neighbours

    return neighbours


def test_every_kernel_timed_with_machine_and_target():
    tool = _tool()
    got = tool.run(argparse.Namespace(rods=[60], repeat=2, checkpoint=None, before=None))
    row = got["rows"][0]
    for kernel in [*tool.KERNELS, tool.MIXED, "float64"]:
        assert len(row[kernel]) == 2 and all(t >= 0 for t in row[kernel])
    assert 0.0 < row["mixed_error"] < 1e-5  # float32 ran, within its rounding of the float64 sum
    assert row["yukawa_pairs"] > 0 and row["tip_radius"] > 0
    assert got["machine"]["cpu_name"] and "compiles for" in got["line"]


def test_before_times_the_mixed_sum_of_both_revisions(capsys):
    """With ``--before`` the mixed Yukawa sum of the revision is timed against the working tree's
    too (here the revision is HEAD, exported by git archive as the tool does for any)."""
    tool = _tool()
    got = tool.run(argparse.Namespace(rods=[60], repeat=1, checkpoint=None, before="HEAD", kernels=[tool.MIXED]))
    row = got["rows"][0]
    assert len(row[tool.MIXED + " before"]) == len(row[tool.MIXED + " after"]) == 1
