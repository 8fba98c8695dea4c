"""The OpenMP wait policy: numba's idle threads sleep between parallel kernels instead of spinning
(selfas_graph/kernels/_jit.py); the package says so when it is imported too late to make it so."""

import os
import subprocess
import sys

import pytest

pytestmark = pytest.mark.skipif(
    os.environ.get("NUMBA_DISABLE_JIT", "0") != "0", reason="no threads to start without the JIT"
)

_PROBE = """
import warnings
warnings.simplefilter("always")
import numba
from numba.np.ufunc import parallel
if {started_first} == "pool":
    from selfas_graph.parallel import set_job_threads
    set_job_threads(1)  # a pool worker's first act, before any kernel module is imported
elif {started_first}:
    numba.set_num_threads(1)  # starts numba's threads, before the package sets the policy
with warnings.catch_warnings(record=True) as caught:
    import selfas_graph.kernels._jit  # noqa: F401
numba.set_num_threads(1)
print(parallel.threading_layer(), sum("OMP_WAIT_POLICY" in str(w.message) for w in caught))
"""


def probe(started_first, **env):
    base = {k: v for k, v in os.environ.items() if k != "OMP_WAIT_POLICY"}
    out = subprocess.run(
        [sys.executable, "-c", _PROBE.format(started_first=started_first)],
        env={**base, **env},
        capture_output=True,
        text=True,
        check=True,
    ).stdout.split()
    return out[0], int(out[1])


def test_threads_started_before_the_import_are_reported():
    layer, warned = probe(True)
    if layer != "omp":
        pytest.skip(f"numba runs the {layer} threading layer here, not OpenMP")
    assert warned == 1


def test_no_report_when_the_policy_takes_effect_or_is_the_users():
    assert probe(False)[1] == 0  # imported first: the package's PASSIVE is read when the threads start
    assert probe(True, OMP_WAIT_POLICY="ACTIVE")[1] == 0  # the user's own setting, read as the threads start


def test_a_pool_worker_that_starts_the_threads_first_sets_the_policy_first():
    """An ``mpi4py.futures`` worker rank sets its threads before it imports a kernel module: the
    launcher in the README warned that the threads would spin. The thread setting now sets the
    policy before it starts them."""
    layer, warned = probe('"pool"')
    if layer != "omp":
        pytest.skip(f"numba runs the {layer} threading layer here, not OpenMP")
    assert warned == 0
