"""Linear combinations used by the time integrators, without temporaries, and the sums of a step
that must come out as numpy computed them before (:func:`dot_as_numpy`)."""

from ._jit import inline, njit_rows, prange
from .rigid import worst_bond_error


@inline
def dot_as_numpy(a, b, n):
    """``sum_i a[i] b[i]`` over the first ``n`` elements of the flat arrays ``a`` and ``b``, as
    ``np.einsum("ij,ij->", A, B)`` sums two C-contiguous arrays (here flattened) on x86-64, bit for bit.

    numpy's kernel for it (``sum_of_products_contig_contig_outstride0_two``, compiled for the x86-64
    baseline: two SSE2 lanes of doubles, multiply and add unfused): lane L takes the elements
    L, L + 2, ...; per block of eight elements it adds its four products last-first,
    ``a0 b0 + (a2 b2 + (a4 b4 + (a6 b6 + lane)))`` (:func:`dot_block`); past the blocks one product
    per lane and pair (a missing second element counts as the product 0 * 0); then ``lane0 + lane1``,
    added to the output's 0 (:func:`dot_finish`). The kernels sum the powers and kinetic energies of a
    step so, as the numpy code they replace did (tests/unit/test_step_kernels.py holds them to ``np.einsum``
    bit for bit); where numpy sums otherwise (e.g. with fused multiply-adds on ARM) they differ from it
    by round-off only.
    """
    lane0 = 0.0
    lane1 = 0.0
    i = 0
    while n - i >= 8:
        lane0, lane1 = dot_block(a, b, i, lane0, lane1)
        i += 8
    return dot_finish(a, b, i, n, lane0, lane1)


@inline
def dot_block(a, b, i, lane0, lane1):
    """The block of eight elements from ``i`` on of :func:`dot_as_numpy`, added into its two lanes."""
    lane0 = a[i] * b[i] + (a[i + 2] * b[i + 2] + (a[i + 4] * b[i + 4] + (a[i + 6] * b[i + 6] + lane0)))
    lane1 = a[i + 1] * b[i + 1] + (a[i + 3] * b[i + 3] + (a[i + 5] * b[i + 5] + (a[i + 7] * b[i + 7] + lane1)))
    return lane0, lane1


@inline
def dot_finish(a, b, i, n, lane0, lane1):
    """The elements from ``i`` to ``n`` past the blocks of :func:`dot_as_numpy`, and the lanes added."""
    while i < n:
        lane0 = a[i] * b[i] + lane0
        if i + 1 < n:
            lane1 = a[i + 1] * b[i + 1] + lane1
        else:
            lane1 = 0.0 * 0.0 + lane1
        i += 2
    return 0.0 + (lane0 + lane1)


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
def ab4_step(x, v, hist_v, hist_a, slots, dt, length):
    """The Adams-Bashforth 4 update of positions and velocities (:func:`ab4_update` of each) in one
    pass, in place; returns the largest bond-length error ``| |x_a - x_b| - l_i |`` after it
    (``rigid.bond_length_error``), all bit for bit as the three calls.

    Parameters
    ----------
    x, v : (n_tips, 3) float64, modified in place
    hist_v, hist_a : (4, n_tips, 3) float64
        Ring buffers of the derivatives of x and v; ``slots[j]`` holds the one ``j`` steps back.
    slots : (4,) int64
    dt : float
    length : (n_rods,) float64, or empty for rods of length 1
    """
    c = dt / 24.0
    n_rods = x.shape[0] // 2
    # flat views: one loop over all elements, from 0 (vectorised; a loop over the rows of a rod,
    # ``range(2 i, 2 i + 2)``, is not: `bench kernels --kernels "ab4 step"`, 6000 rods, one thread, Zen 5,
    # 61 against 31 us, AVX2 build 64 against 31)
    xf, vf = x.reshape(-1), v.reshape(-1)
    v0, v1 = hist_v[slots[0]].reshape(-1), hist_v[slots[1]].reshape(-1)
    v2, v3 = hist_v[slots[2]].reshape(-1), hist_v[slots[3]].reshape(-1)
    a0, a1 = hist_a[slots[0]].reshape(-1), hist_a[slots[1]].reshape(-1)
    a2, a3 = hist_a[slots[2]].reshape(-1), hist_a[slots[3]].reshape(-1)
    for k in prange(6 * n_rods):
        xf[k] = xf[k] + c * (55.0 * v0[k] - 59.0 * v1[k] + 37.0 * v2[k] - 9.0 * v3[k])
        vf[k] = vf[k] + c * (55.0 * a0[k] - 59.0 * a1[k] + 37.0 * a2[k] - 9.0 * a3[k])
    return worst_bond_error(x[: 2 * n_rods].reshape(n_rods, 6), length)


@inline
def ab4_rods(x, v, hist_v, hist_a, slots, dt, length, lo, hi):
    """:func:`ab4_step` of the rods ``lo`` to ``hi`` (their tips ``2 lo`` to ``2 hi``), serial: the same
    numbers for them as :func:`ab4_step` of all rods; returns the largest bond-length error among them
    (``length`` empty: rods of length 1)."""
    c = dt / 24.0
    a, b = 6 * lo, 6 * hi
    xf, vf = x.reshape(-1)[a:b], v.reshape(-1)[a:b]
    v0, v1 = hist_v[slots[0]].reshape(-1)[a:b], hist_v[slots[1]].reshape(-1)[a:b]
    v2, v3 = hist_v[slots[2]].reshape(-1)[a:b], hist_v[slots[3]].reshape(-1)[a:b]
    a0, a1 = hist_a[slots[0]].reshape(-1)[a:b], hist_a[slots[1]].reshape(-1)[a:b]
    a2, a3 = hist_a[slots[2]].reshape(-1)[a:b], hist_a[slots[3]].reshape(-1)[a:b]
    for k in range(b - a):
        xf[k] = xf[k] + c * (55.0 * v0[k] - 59.0 * v1[k] + 37.0 * v2[k] - 9.0 * v3[k])
        vf[k] = vf[k] + c * (55.0 * a0[k] - 59.0 * a1[k] + 37.0 * a2[k] - 9.0 * a3[k])
    rods = x[2 * lo : 2 * hi].reshape(hi - lo, 6)
    return worst_bond_error(rods, length if length.shape[0] == 0 else length[lo:hi])


@njit_rows
def axpy(y, d, h, out):
    """``out = y + h d`` for (n, 3) arrays; ``out`` may be ``y``."""
    for k in prange(y.shape[0]):
        for c in range(3):
            out[k, c] = y[k, c] + h * d[k, c]


@inline
def _sum_rows(flat, rows):
    """``flat = ((0 + rows[0]) + rows[1]) + ...``, four rows a pass over ``flat``: each element gets the
    same additions in the same order as one row a pass, and the element loop, free of any reduction,
    vectorises (with the powers three at a time, `bench kernels --kernels "channel sums"`: 96 against 80 us at
    6000 rods of the Fig. 2 scene, one thread, Zen 5; AVX2 build 115 against 83)."""
    for i in prange(flat.shape[0]):
        flat[i] = 0.0
    n_rows = rows.shape[0]
    j = 0
    while n_rows - j >= 4:
        r0, r1, r2, r3 = rows[j], rows[j + 1], rows[j + 2], rows[j + 3]
        for i in prange(flat.shape[0]):
            flat[i] = (((flat[i] + r0[i]) + r1[i]) + r2[i]) + r3[i]
        j += 4
    while j < n_rows:
        r0 = rows[j]
        for i in prange(flat.shape[0]):
            flat[i] += r0[i]
        j += 1


@inline
def sum_rows_range(flat, rows, a, b):
    """:func:`_sum_rows` of the elements ``a`` to ``b`` only (each the same additions in the same order)."""
    f = flat[a:b]
    for i in range(b - a):
        f[i] = 0.0
    n_rows = rows.shape[0]
    j = 0
    while n_rows - j >= 4:
        r0, r1, r2, r3 = rows[j][a:b], rows[j + 1][a:b], rows[j + 2][a:b], rows[j + 3][a:b]
        for i in range(b - a):
            f[i] = (((f[i] + r0[i]) + r1[i]) + r2[i]) + r3[i]
        j += 4
    while j < n_rows:
        r0 = rows[j][a:b]
        for i in range(b - a):
            f[i] += r0[i]
        j += 1


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
    _sum_rows(flat, rows)


@njit_rows
def channel_sum_power(out, channels, velocity, powered, power):
    """:func:`channel_sum`, and the power ``sum_k F_k . v_k`` of the channels ``powered`` (indices
    into ``channels``) into ``power``, as ``np.einsum("ij,ij->", channels[j], velocity)`` gives it
    bit for bit (:func:`dot_as_numpy`).

    Parameters
    ----------
    out : (n, 3) float64, C-contiguous
        Overwritten with the sum.
    channels : (n_channels, n, 3) float64, C-contiguous
    velocity : (n, 3) float64, C-contiguous
    powered : (m,) int64
    power : (m,) float64
        Overwritten.
    """
    flat = out.reshape(-1)
    rows = channels.reshape(channels.shape[0], flat.shape[0])
    vel = velocity.reshape(-1)
    _sum_rows(flat, rows)
    # the powers, each the sum dot_as_numpy forms, three channels at a time
    for j in range(0, powered.shape[0], 3):
        power_group(rows, vel, powered, power, j)


@inline
def power_group(rows, vel, powered, power, j):
    """The powers of :func:`channel_sum_power` of ``powered[j]`` to ``powered[j + 2]`` (as many as there
    are), into ``power[j:j + 3]``: ``rows`` the channels and ``vel`` the velocities, both flat."""
    # the three sums in one pass over the blocks of eight elements: their chains of dependent
    # additions overlap (one channel after another, each waits on the latency of its own: measured 1.7
    # times slower at 6 channels of 2400 tips; three at a time 7 % faster than two at 12 000 tips, Zen 5)
    m = powered.shape[0]
    n = vel.shape[0]
    # the last one again when fewer are left, its sum discarded
    a = rows[powered[j]]
    b = rows[powered[min(j + 1, m - 1)]]
    e = rows[powered[min(j + 2, m - 1)]]
    a0 = a1 = b0 = b1 = e0 = e1 = 0.0
    i = 0
    while n - i >= 8:
        a0, a1 = dot_block(a, vel, i, a0, a1)
        b0, b1 = dot_block(b, vel, i, b0, b1)
        e0, e1 = dot_block(e, vel, i, e0, e1)
        i += 8
    power[j] = dot_finish(a, vel, i, n, a0, a1)
    if j + 1 < m:
        power[j + 1] = dot_finish(b, vel, i, n, b0, b1)
    if j + 2 < m:
        power[j + 2] = dot_finish(e, vel, i, n, e0, e1)


@njit_rows
def extrapolate_all(out, rate, base, steps):
    """:func:`extrapolate` of several held forces in one call: ``out[j] = rate[j] * steps[j] + base[j]``
    for every ``j`` whose ``steps[j]`` is not NaN (the others are left as they are).

    Parameters
    ----------
    out : tuple of (n, 3) float64 arrays
    rate, base : (len(out), n, 3) float64
    steps : (len(out),) float64
        Whole numbers of steps, or NaN.
    """
    for j in range(len(out)):
        s = steps[j]
        if s != s:
            continue
        o, r, b = out[j], rate[j], base[j]
        for k in prange(o.shape[0]):
            for c in range(3):
                o[k, c] = r[k, c] * s + b[k, c]


@njit_rows
def extrapolate(out, rate, base, steps):
    """``out = rate * steps + base`` (linear extrapolation of a held force), as numpy's
    ``np.multiply(rate, steps, out=out); out += base`` computes it: two roundings, no fused multiply-add.

    All arrays (n, 3) float64; ``steps`` a float (a whole number of steps).
    """
    for k in prange(out.shape[0]):
        for c in range(3):
            out[k, c] = rate[k, c] * steps + base[k, c]
