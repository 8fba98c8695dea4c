"""The vectorisable exponentials used by the Yukawa law (float64, and float32 for the mixed sum)
agree with libm's to round-off."""

import math

import numba
import numpy as np
import pytest

from selfas_graph.kernels._jit import njit
from selfas_graph.kernels.expo import EXP_F32_MIN, exp_nonpositive, exp_nonpositive_f32

#: small inputs: also run with NUMBA_DISABLE_JIT=1, the kernels as Python (.ci/run)
jit_off_ok = pytest.mark.jit_off_ok


@njit
def _apply(x, out):
    for i in range(x.shape[0]):
        out[i] = exp_nonpositive(x[i])


@njit
def _apply_f32(x, out):
    for i in range(x.shape[0]):
        out[i] = exp_nonpositive_f32(x[i])


def evaluate(x):
    x = np.ascontiguousarray(x, dtype=np.float64)
    out = np.empty_like(x)
    _apply(x, out)
    return out


def evaluate_f32(x):
    x = np.ascontiguousarray(x, dtype=np.float32)
    out = np.empty_like(x)
    _apply_f32(x, out)
    return out


def f32_ulps(x):
    """Error of :func:`exp_nonpositive_f32` at the float32 ``x`` in float32 ulps of libm's float64 exp."""
    ref = np.exp(x.astype(np.float64))
    return np.abs(evaluate_f32(x).astype(np.float64) - ref) / np.spacing(ref.astype(np.float32)).astype(np.float64)


@jit_off_ok
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


@jit_off_ok
def test_special_values():
    """exp(0) = 1, the subnormal range ends in 0 like libm's (to the smallest subnormal), -inf gives 0, NaN stays NaN."""
    x = np.array([0.0, -0.0, -5e-324, -709.0, -740.0, -745.0, -745.2, -746.0, -1e300, -np.inf, np.nan])
    out = evaluate(x)
    ref = np.exp(x)
    np.testing.assert_array_equal(out[:3], [1.0, 1.0, 1.0])
    # rtol just above 2^-51 = 4.44e-16, the 2 ulp of the normal range (test above); from x = -709 on the
    # results are subnormal, whose ulp is the atol 5e-324. Measured: equal to libm's bit for bit at all these x
    np.testing.assert_allclose(out[3:-1], ref[3:-1], rtol=4.5e-16, atol=5e-324)
    assert np.isnan(out[-1])


def test_f32_within_two_ulp_of_libm(rng):
    """float32: over the range of normal results, x from -87.3 to 0, the error is at most 2 float32
    ulp (expo.py: 1.28 measured over 6e7 random x), also either side of every multiple and odd half
    multiple of ln 2, where the range reduction changes n."""
    k = np.arange(0, 127)
    edges = np.concatenate([k * math.log(2.0), (k + 0.5) * math.log(2.0)]).astype(np.float32)
    x = np.concatenate(
        [
            -rng.uniform(0, 1, 100_000),
            -rng.uniform(0, 87.3, 300_000),
            -np.logspace(-45, 1.94, 2000),
            np.linspace(EXP_F32_MIN, -87.0, 1000),
        ]
    ).astype(np.float32)
    x = np.concatenate([x, -edges, np.nextafter(-edges, np.float32(0)), np.nextafter(-edges, np.float32(-100))])
    x = x[x >= EXP_F32_MIN]
    assert f32_ulps(x).max() <= 2.0


@jit_off_ok
def test_f32_special_values():
    """float32: exp(0) = exp(-0) = 1, tiny x gives 1, -87 and the last x with a normal result within 2
    ulp; below it 0 (no subnormal results), -inf gives 0, NaN stays NaN; the result is a float32."""
    x = np.array([0.0, -0.0, -1e-45, -1e-30, -87.0, EXP_F32_MIN], np.float32)
    out = evaluate_f32(x)
    y = exp_nonpositive_f32(np.float32(-1.0))
    if hasattr(exp_nonpositive_f32, "overloads"):  # compiled: typed float32 -> float32
        assert str(exp_nonpositive_f32.overloads[(numba.float32,)].signature.return_type) == "float32"
    else:  # as Python (NUMBA_DISABLE_JIT=1): a numpy float32
        assert type(y) is np.float32
    np.testing.assert_array_equal(out[:4], [1.0, 1.0, 1.0, 1.0])
    assert f32_ulps(x).max() <= 2.0
    assert out[-1] >= np.finfo(np.float32).tiny
    below = np.array([np.nextafter(EXP_F32_MIN, np.float32(-100)), -88.0, -1e30, -np.inf], np.float32)
    np.testing.assert_array_equal(evaluate_f32(below), np.zeros(4, np.float32))
    assert np.isnan(evaluate_f32(np.array([np.nan], np.float32))).all()
