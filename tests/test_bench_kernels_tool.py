"""Smoke test of tools/bench_kernels.py on a tiny scaled Fig. 2 scene (a few seconds).

The timings in this process (no child per instruction set); the numbers are measurements, not
checked here, only that every kernel was timed the asked number of times and that the machine
and the numba target are reported.
"""

import argparse
import importlib.util
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def _tool():
    sys.path.insert(0, str(ROOT / "tools"))  # the tool imports bench_step and bench_peer beside it
    spec = importlib.util.spec_from_file_location("_selfas_tools_bench_kernels", ROOT / "tools" / "bench_kernels.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_every_kernel_timed_with_machine_and_target():
    tool = _tool()
    args = argparse.Namespace(rods=[60], repeat=2, threads=1, direct_max=100, cpu_time=True)
    got = tool.run(args)
    row = got["rows"][0]
    kernels = ("direct", "plain", "tree build", "tree eval", "yukawa", "current tips", "current field")
    for kernel in kernels + ("current tips mixed", "current field mixed"):
        assert len(row[kernel]) == 2 and all(t >= 0 for t in row[kernel])
    assert row["yukawa_pairs"] > 0 and row["active_rods"] > 0
    assert got["machine"]["cpu_name"] and "compiles for" in got["line"]
