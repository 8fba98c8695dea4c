"""Linear combinations used by the time integrators, without temporaries."""

from ._jit import njit_rows, prange


@njit_rows
def ab4_update(y, d0, d1, d2, d3, dt, out):
    """Explicit 4-step Adams-Bashforth: ``out = y + dt/24 (55 d0 - 59 d1 + 37 d2 - 9 d3)``.

    ``d0`` is the derivative at the current step, ``d3`` three steps back.
    All arrays (n, 3) float64; ``out`` may be ``y``.
    """
    c = dt / 24.0
    for k in prange(y.shape[0]):
        for d in range(3):
            out[k, d] = y[k, d] + c * (55.0 * d0[k, d] - 59.0 * d1[k, d] + 37.0 * d2[k, d] - 9.0 * d3[k, d])


@njit_rows
def axpy(y, d, h, out):
    """``out = y + h d`` for (n, 3) arrays; ``out`` may be ``y``."""
    for k in prange(y.shape[0]):
        for c in range(3):
            out[k, c] = y[k, c] + h * d[k, c]
