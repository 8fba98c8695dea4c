"""Smoke test of selfas_graph/bench/kernels.py on a tiny scaled Fig. 2 scene (a few seconds).

The timings in this process (no child per instruction set); the numbers are measurements, not
checked here, only that every kernel was timed the asked number of times and that the machine
and the numba target are reported.
"""

import argparse
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _tool():
    from selfas_graph.bench import kernels

    return kernels


def test_every_kernel_timed_with_machine_and_target():
    tool = _tool()
    args = argparse.Namespace(rods=[60], repeat=2, threads=1, direct_max=100, cpu_time=True)
    got = tool.run(args)
    row = got["rows"][0]
    kernels = ("direct", "plain", "tree build", "tree eval", "yukawa", "current tips", "current field")
    kernels += ("ab4 step", "constraint", "channel sums", "tip energy")
    for kernel in kernels + ("direct mixed", "tree eval mixed", "current tips mixed", "current field mixed"):
        assert len(row[kernel]) == 2 and all(t >= 0 for t in row[kernel])
    assert row["yukawa_pairs"] > 0 and row["active_rods"] > 0
    assert got["machine"]["cpu_name"] and "compiles for" in got["line"]


def test_rounds_merge_and_give_one_ratio_per_round():
    """``--rounds``: each target's repeats are pooled over its rounds, and the ratio of two targets
    is taken round by round from the rounds' medians (hand-made timings, no process started)."""
    tool = _tool()

    def result(ms, r):
        return {"line": "x", "rows": [{"rods": 60, "tree eval": ms, "yukawa_pairs": 5}], "round": r}

    rounds = {
        "host": [result([1.0, 3.0], 0), result([2.0, 2.0], 1)],
        "haswell": [result([4.0, 4.0], 0), result([3.0, 5.0], 1)],
    }
    merged = tool.merge_rounds({**rounds, "znver3": []})
    assert set(merged) == {"host", "haswell"}
    assert merged["host"]["rows"][0]["tree eval"] == [1.0, 3.0, 2.0, 2.0] and merged["host"]["rounds"] == 2
    assert merged["haswell"]["rows"][0]["yukawa_pairs"] == 5
    assert list(tool.target_ratios(rounds, "host", "haswell", 0, "tree eval")) == [2.0, 2.0]
    assert len(tool.target_ratios(rounds, "host", "haswell", 0, "yukawa")) == 0
    # a target whose process failed in round 0: its round 1 is set against round 1, not round 0
    assert list(
        tool.target_ratios({**rounds, "haswell": [result([6.0, 6.0], 1)]}, "host", "haswell", 0, "tree eval")
    ) == [3.0]


def test_a_named_target_compiles_with_its_own_features_only():
    """``--targets haswell`` must time an AVX2 build on any x86 host. numba takes the vector features
    from the host unless NUMBA_CPU_FEATURES is set, whatever NUMBA_CPU_NAME says (on an AVX-512 host
    the name alone still gives AVX-512 code), so the target's environment sets it empty, and the
    report reads the features the way numba does."""
    import json
    import os
    import subprocess

    from selfas_graph.bench.peer import target_env

    env = target_env("haswell", {"NUMBA_CPU_FEATURES": "+avx512f", "PATH": os.environ.get("PATH", "")})
    assert env["NUMBA_CPU_NAME"] == "haswell" and env["NUMBA_CPU_FEATURES"] == ""
    host = target_env("host", {"NUMBA_CPU_NAME": "haswell", "NUMBA_CPU_FEATURES": ""})
    assert "NUMBA_CPU_NAME" not in host and "NUMBA_CPU_FEATURES" not in host

    probe = (
        "import json; from selfas_graph.bench.peer import numba_target; "
        "import llvmlite.binding as ll; t = numba_target(); "
        "t['host_avx512'] = bool(ll.get_host_cpu_features().get('avx512f', False)); print(json.dumps(t))"
    )

    def report(extra):
        env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_CPU")}
        env.update(extra)
        out = subprocess.run([sys.executable, "-c", probe], env=env, capture_output=True, text=True)
        assert out.returncode == 0, out.stderr
        return json.loads(out.stdout)

    own = report({"NUMBA_CPU_NAME": "haswell", "NUMBA_CPU_FEATURES": ""})
    assert own["widest"] == "AVX2" and own["cpu_name"] == "haswell"
    name_only = report({"NUMBA_CPU_NAME": "haswell"})
    if name_only["host_avx512"]:  # the name alone keeps the host's AVX-512, and the report says so
        assert name_only["widest"] == "AVX-512"
    else:
        assert name_only["widest"] in ("AVX2", "AVX", "SSE")


def test_unknown_kernel_is_refused_with_the_valid_names(capsys):
    tool = _tool()
    with pytest.raises(SystemExit) as exc:
        tool.main(["--rods", "60", "--kernels", "bogus", "tree eval"])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "--kernels: unknown 'bogus'" in err and "'ab4 step'" in err and "'tip energy'" in err


def test_every_named_kernel_is_timed():
    """The table's names (``KERNELS``, what ``--kernels`` takes) are those of the timed rows."""
    tool = _tool()
    row = tool.run(argparse.Namespace(rods=[60], repeat=1, threads=1, direct_max=100, cpu_time=True))["rows"][0]
    assert {k for k in row if isinstance(row[k], list)} == set(tool.KERNELS)
