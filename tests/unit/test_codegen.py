"""What LLVM makes of the mixed-precision pair loops, read from the generated assembly.

The float32 pair loops (the mixed direct tip-tip sum, the rod currents' field in mixed precision)
must load their packed rows with plain vector loads. With signed loop indices numba checks each
index for wraparound, and for CPUs with AVX-512 LLVM then vectorised the loops with gathers, 2.2-2.4
times slower than the AVX2 build on the same Intel Xeon (docs/performance.md 'Unsigned loop
indices on AVX-512'). The kernels are compiled, not run, for an AVX-512 CPU and for an AVX2 CPU in
a fresh process with an empty cache, so the check holds on any x86-64 host.

The mixed Yukawa sum gathers each row's neighbours in a loop of its own (a neighbour list is
indirect: gathers belong there) and runs the float32 law in a second loop, which must stay float32
on 8 lanes with AVX2.
"""

import json
import os
import platform
import subprocess
import sys

import pytest

pytestmark = pytest.mark.skipif(platform.machine().lower() not in ("x86_64", "amd64"), reason="reads x86-64 assembly")

_PROBE = r"""
import json, re, sys, warnings
warnings.simplefilter("ignore")
import numpy as np, numba
from selfas_graph.kernels import currents as kc, tips
n = 64
pos = np.zeros((2 * n, 3)); q = np.ones(2 * n); act = np.arange(n, dtype=np.int64); cur = np.ones(n)
out = np.zeros((2 * n, 3)); x = np.zeros(2 * n)
cases = {
    "current_force_on_tips_mixed": (kc.current_force_on_tips_mixed, (pos, q, act, cur, 0.03, 0, 2 * n, out)),
    "rod_current_field_mixed": (kc.rod_current_field_mixed, (pos, act, pos, act, cur, 0.03, out)),
    "tip_tip_direct_mixed": (tips.tip_tip_direct_mixed, (x, x, x, q, 0.06, 1.0, 0, 2 * n, out)),
}
found = {}
for name, (disp, args) in cases.items():
    sig = tuple(numba.typeof(a) for a in args)
    disp.compile(sig)  # compiled only: the target CPU need not be this one
    lib = disp.overloads[sig].library
    # the parallel loop body is a gufunc in a library linked to the kernel's own
    asm = "".join(l.get_asm_str() for l in [lib] + list(getattr(lib, "_linking_libraries", ())))
    found[name] = {"gathers": len(re.findall(r"\bv(?:p)?gather", asm)), "packed_f32": len(re.findall(r"\bvsubps\b", asm))}
print(json.dumps(found))
"""


@pytest.mark.parametrize("cpu", ["skylake-avx512", "haswell"])
def test_mixed_pair_loops_load_rows_without_gathers(cpu, tmp_path):
    env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_")}
    env.update(NUMBA_CPU_NAME=cpu, NUMBA_CPU_FEATURES="", NUMBA_CACHE_DIR=str(tmp_path))
    got = subprocess.run([sys.executable, "-c", _PROBE], env=env, capture_output=True, text=True, timeout=600)
    assert got.returncode == 0, got.stderr
    found = json.loads(got.stdout.strip().splitlines()[-1])
    for name, counts in found.items():
        assert counts["packed_f32"] > 0, f"{name}: the vectorised float32 loop is not in the inspected code"
        assert counts["gathers"] == 0, f"{name} for {cpu}: {counts['gathers']} gather instructions"


_YUKAWA_PROBE = r"""
import json, re, warnings
warnings.simplefilter("ignore")
import numpy as np, numba
from selfas_graph.kernels import yukawa
n = 8
c = np.zeros((n, 3)); q = np.ones(n); order = np.arange(n); out = np.zeros((n, 3))
start = np.zeros(n + 1, dtype=np.int64); index = np.zeros(0, dtype=np.int64)
args = (c, q, order, start, index, 1.0, 0.06, 3.0, 0, n, out)
sig = tuple(numba.typeof(a) for a in args)
disp = yukawa.yukawa_centres_sorted_mixed
disp.compile(sig)
lib = disp.overloads[sig].library
asm = "".join(l.get_asm_str() for l in [lib] + list(getattr(lib, "_linking_libraries", ())))
patterns = {"sqrt": r"\bvsqrtps\s+%ymm", "div": r"\bvdivps\s[^\n]*%ymm", "widen": r"\bvcvtps2pd\b"}
print(json.dumps({k: len(re.findall(p, asm)) for k, p in patterns.items()}))
"""


def test_mixed_yukawa_law_runs_on_8_float32_lanes_with_avx2(tmp_path):
    """The mixed Yukawa sum's law (``kernels/yukawa.py::yukawa_centres_sorted_mixed``) compiled for
    AVX2: its square root and division are packed float32 on ymm registers, 8 lanes, and nothing
    is widened from float32 to float64 (``vcvtps2pd``: a float64 constant in the float32 law or
    exponential would promote the loop to float64)."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_")}
    env.update(NUMBA_CPU_NAME="haswell", NUMBA_CPU_FEATURES="", NUMBA_CACHE_DIR=str(tmp_path))
    got = subprocess.run([sys.executable, "-c", _YUKAWA_PROBE], env=env, capture_output=True, text=True, timeout=600)
    assert got.returncode == 0, got.stderr
    found = json.loads(got.stdout.strip().splitlines()[-1])
    assert found["sqrt"] > 0 and found["div"] > 0, found
    assert found["widen"] == 0, found


_STEP_PROBE = r"""
import json, re, warnings
warnings.simplefilter("ignore")
import numpy as np, numba
from selfas_graph.kernels import integrate as ki
n = 8
x = np.zeros((n, 3)); h = np.zeros((4, n, 3)); slots = np.arange(4); blk = np.zeros((3, n, 3))
cases = {
    "ab4_step": (ki.ab4_step.serial, (x, x, h, h, slots, 1e-3, np.zeros(0))),
    "channel_sum": (ki.channel_sum.serial, (x, blk)),
}
found = {}
for name, (disp, args) in cases.items():
    sig = tuple(numba.typeof(a) for a in args)
    disp.compile(sig)
    asm = disp.overloads[sig].library.get_asm_str()
    found[name] = {op: len(re.findall(r"\b%s\s[^\n]*%%[yz]mm" % op, asm)) for op in ("vmulpd", "vaddpd")}
print(json.dumps(found))
"""


@pytest.mark.parametrize("cpu", ["skylake-avx512", "haswell"])
def test_step_updates_are_vectorised(cpu, tmp_path):
    """The AB4 update and the channel sum, every step over all tips, run packed double arithmetic: loops
    from 0 over flat arrays. Written as a loop over each rod's two tip rows (``range(2 i, 2 i + 2)``), the
    AB4 update kept numba's negative-index check and had no packed arithmetic at all (2.0 times slower at
    6000 rods, docs/performance.md 'The Fig. 6 run and its fast steps')."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_")}
    env.update(NUMBA_CPU_NAME=cpu, NUMBA_CPU_FEATURES="", NUMBA_CACHE_DIR=str(tmp_path))
    got = subprocess.run([sys.executable, "-c", _STEP_PROBE], env=env, capture_output=True, text=True, timeout=600)
    assert got.returncode == 0, got.stderr
    found = json.loads(got.stdout.strip().splitlines()[-1])
    assert found["ab4_step"]["vmulpd"] > 0, f"ab4_step for {cpu}: no packed multiplication ({found})"
    assert found["channel_sum"]["vaddpd"] > 0, f"channel_sum for {cpu}: no packed addition ({found})"
