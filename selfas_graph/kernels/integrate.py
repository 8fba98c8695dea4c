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


@njit_rows
def channel_sum(out, channels):
    """``out = ((0 + channels[0]) + channels[1]) + ...``: the force channels summed in their order.

    The sum a numpy loop ``out.fill(0); out += c`` over the channels gives, bit for bit (the same
    additions in the same order, no reassociation), in one pass instead of one per channel.

    Parameters
    ----------
    out : (n, 3) float64, C-contiguous
        Overwritten.
    channels : (n_channels, n, 3) float64, C-contiguous
    """
    flat = out.reshape(-1)  # both C-contiguous: one loop over all elements (measured 19 us at 2400
    rows = channels.reshape(channels.shape[0], flat.shape[0])  # tips and 11 channels, numpy 31 us)
    for i in prange(flat.shape[0]):
        flat[i] = 0.0
    # channel after channel: each element gets the same additions in the same order, and the
    # element loop, free of any reduction, vectorises
    for j in range(rows.shape[0]):
        row = rows[j]
        for i in prange(flat.shape[0]):
            flat[i] += row[i]


@njit_rows
def extrapolate(out, rate, base, steps):
    """``out = rate * steps + base`` (linear extrapolation of a held force), as numpy's
    ``np.multiply(rate, steps, out=out); out += base`` computes it: two roundings, no fused multiply-add.

    All arrays (n, 3) float64; ``steps`` a float (a whole number of steps).
    """
    for k in prange(out.shape[0]):
        for c in range(3):
            out[k, c] = rate[k, c] * steps + base[k, c]
