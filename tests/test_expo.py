"""The vectorisable exponential used by the Yukawa law agrees with libm's to round-off."""

import math

import numpy as np
import pytest

from selfas_graph.kernels._jit import njit
from selfas_graph.kernels.expo import exp_nonpositive

#: small inputs: also run with NUMBA_DISABLE_JIT=1, the kernels as Python (.ci/run)
pytestmark = pytest.mark.jit_off_ok


@njit
def _apply(x, out):
    for i in range(x.shape[0]):
        out[i] = exp_nonpositive(x[i])


def evaluate(x):
    x = np.ascontiguousarray(x, dtype=np.float64)
    out = np.empty_like(x)
    _apply(x, out)
    return out


def test_within_two_ulp_of_libm(rng):
    """Over the whole range of normal results (x down to -708), the error is at most 2 ulp (module docstring)."""
    x = np.concatenate(
        [
            -rng.uniform(0, 1, 200_000),
            -rng.uniform(0, 40, 200_000),
            -rng.uniform(0, 708, 200_000),
            -np.logspace(-300, 2.85, 2000),
            -np.arange(0, 709) * math.log(2.0),
        ]
    )
    ref = np.exp(x)
    err = np.abs(evaluate(x) - ref) / np.spacing(ref)
    assert err.max() <= 2.0


def test_special_values():
    """exp(0) = 1, the subnormal range ends in 0 like libm's (to the smallest subnormal), -inf gives 0, NaN stays NaN."""
    x = np.array([0.0, -0.0, -5e-324, -709.0, -740.0, -745.0, -745.2, -746.0, -1e300, -np.inf, np.nan])
    out = evaluate(x)
    ref = np.exp(x)
    np.testing.assert_array_equal(out[:3], [1.0, 1.0, 1.0])
    np.testing.assert_allclose(out[3:-1], ref[3:-1], rtol=4.5e-16, atol=5e-324)
    assert np.isnan(out[-1])
