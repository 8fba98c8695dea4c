"""Screened electric repulsion between rod centres over the centre neighbour list (docs/model.md 'Term 6').

The force in float64 (:func:`yukawa_centres`, and :func:`yukawa_centres_sorted` on copies in cell
order), the same sum with the law in float32 (:func:`yukawa_centres_sorted_mixed`) and the energy by
rows (:func:`yukawa_energy`). Neighbour lists are in compressed-row form and hold both directions of
every pair: the neighbours of rod ``i`` are ``index[start[i]:start[i + 1]]``. Each parallel
iteration writes only its own row (gather). The list may hold pairs beyond the cut-off (a Verlet
skin); the kernels test the distance.
"""

import math

import numpy as np

from ._jit import inline_sum, njit, njit_parallel, njit_parallel_sum, prange
from .laws import yukawa_force_over_r, yukawa_force_over_r_f32, yukawa_potential


@inline_sum
def _yukawa_row(centre, rod_charge, i, start, index, screening, core, rc2):
    """The Yukawa force on row ``i`` of ``centre`` from its listed neighbours (:func:`yukawa_centres`),
    as (fx, fy, fz); inlined, so that the loop vectorises in the kernel that calls it."""
    inv_s = 1.0 / screening
    core2 = core * core
    fx = 0.0
    fy = 0.0
    fz = 0.0
    for j in range(start[i], start[i + 1]):
        l = index[j]
        dx = centre[i, 0] - centre[l, 0]
        dy = centre[i, 1] - centre[l, 1]
        dz = centre[i, 2] - centre[l, 2]
        r2 = dx * dx + dy * dy + dz * dz
        g = yukawa_force_over_r(r2, rod_charge[i] * rod_charge[l], inv_s, core2)
        g = g if r2 < rc2 else 0.0  # a select, not a branch: the loop vectorises
        fx += g * dx
        fy += g * dy
        fz += g * dz
    return fx, fy, fz


@njit_parallel_sum
def yukawa_centres(centre, rod_charge, start, index, screening, core, cutoff, lo, hi, out):
    """Screened electric repulsion between rod centres (docs/model.md 'Term 6').

    ``F_i = sum_j Z_i Z_j exp(-r/R_D) (1/r^2 + 1/(R_D r)) r_hat_ij`` over neighbours
    with ``r < cutoff``, softened inside the core radius (see ``laws.yukawa_force_over_r``).

    Parameters
    ----------
    centre : (n_rods, 3) float64
        Rod centres.
    rod_charge : (n_rods,) float64
        Electric charge Z_i of each rod.
    start, index : int64 offsets and int32 or int64 entries (``cells.list_dtype``)
        Rod neighbour list (compressed rows, both directions).
    screening, core, cutoff : float
        Screening length R_D, core radius a (0: none) and the cut-off radius.
    lo, hi : int
        Target rods, ``0 <= lo <= hi <= n_rods``; a row does not depend on the range.
    out : (n_rods, 3) float64
        Rows ``lo:hi`` overwritten with the force on those rod centres; other rows untouched.

    The pair loop is a select and a vectorisable sum (``njit_parallel_sum``): measured on one
    core of the 2-core machine, 1.4 times faster at 1200 rods and 1.1-1.3 times at 24 000
    than a branch under strict IEEE sums, results within 1e-15 relative of it.
    """
    rc2 = cutoff * cutoff
    for i in prange(lo, hi):
        fx, fy, fz = _yukawa_row(centre, rod_charge, i, start, index, screening, core, rc2)
        out[i, 0] = fx
        out[i, 1] = fy
        out[i, 2] = fz


@njit_parallel_sum
def yukawa_centres_sorted(centre, rod_charge, order, start, index, screening, core, cutoff, lo, hi, out):
    """:func:`yukawa_centres` on copies of the inputs in cell order: the same rows, summed in the same order.

    ``centre`` and ``rod_charge`` are ``centre[order]`` and ``rod_charge[order]``, and ``start``,
    ``index`` the rows renumbered by ``order`` (``NeighbourList.sorted_rows``). Row t is the force
    on rod ``order[t]``, written to ``out[order[t]]`` for the rods ``lo <= order[t] < hi`` (other
    rows untouched). Each row's terms are those of :func:`yukawa_centres` in the same sequence, so
    the two give the same forces bit for bit; only the memory they are read from differs: the
    neighbours of a rod lie in a few cells, a few contiguous stretches of the sorted copy, where
    rods numbered at random are spread over the whole array (measured at 24 000 rods on one core,
    docs/performance.md 'The Yukawa sum and the neighbour lists').
    """
    rc2 = cutoff * cutoff
    for t in prange(order.shape[0]):
        i = order[t]
        if i < lo or i >= hi:
            continue
        fx, fy, fz = _yukawa_row(centre, rod_charge, t, start, index, screening, core, rc2)
        out[i, 0] = fx
        out[i, 1] = fy
        out[i, 2] = fz


#: the mixed Yukawa sum (:func:`yukawa_centres_sorted_mixed`) runs in float32 only when every
#: charge |Z_i| is 0 or in [MIXED_CHARGE_MIN, MIXED_CHARGE_MAX], the screening length, the cut-off
#: and a nonzero core radius lie in [MIXED_LENGTH_MIN, MIXED_LENGTH_MAX] and the cut-off is at most
#: MIXED_RANGE_MAX screening lengths (all finite); otherwise it sums in float64, bit for bit. Then
#: every factor of a counted pair's force is a normal float32 with 7 decades to spare: |Z_i Z_j| in
#: [1e-6, 1e6], exp(-r/R_D) >= e^-40 = 4e-18 (exp_nonpositive_f32 gives 0 below e^-87.3),
#: 1/r^2 + 1/(R_D r) in [1e-6, 2e6] and 1/r in [1e-3, 1e3] for r in [a, r_c], so that f/r lies in
#: [1.7e-31, 7.4e14] (float32: 1.2e-38 to 3.4e38) and neither underflow (a silent loss of
#: precision) nor overflow can happen in a row of up to 1e6 pairs. Without a core, 1/r has no
#: bound: a row that overflows float32 (inf, or NaN from inf - inf or 0 inf) is summed again in
#: float64. Reduced units keep all of these O(1): Z_i of order 1, R_D = 0.6-1, r_c = 6-9, a = 0.06.
MIXED_CHARGE_MIN = 1e-3
MIXED_CHARGE_MAX = 1e3
MIXED_LENGTH_MIN = 1e-3
MIXED_LENGTH_MAX = 1e3
MIXED_RANGE_MAX = 40.0


@njit
def _yukawa_mixed_ok(rod_charge, screening, core, cutoff):
    """True when the inputs of the Yukawa sum are where float32 holds them (see :data:`MIXED_CHARGE_MIN`)."""
    ok = MIXED_LENGTH_MIN <= screening <= MIXED_LENGTH_MAX and MIXED_LENGTH_MIN <= cutoff <= MIXED_LENGTH_MAX
    ok = ok and cutoff <= MIXED_RANGE_MAX * screening
    ok = ok and (core == 0.0 or MIXED_LENGTH_MIN <= core <= MIXED_LENGTH_MAX)
    for i in range(rod_charge.shape[0]):
        q = abs(rod_charge[i])
        ok = ok and (q == 0.0 or MIXED_CHARGE_MIN <= q <= MIXED_CHARGE_MAX)  # False for NaN too
    return ok


#: rows of :func:`yukawa_centres_sorted_mixed` per parallel iteration, sharing one float32 scratch
#: buffer: one allocation per 64 rows of a few hundred pairs each, small beside their work
MIXED_ROWS = 64


@inline_sum
def _yukawa_row_f32(centre, rod_charge, i, start, index, inv_s, core2, rc2, buf):
    """:func:`_yukawa_row` in float32: each separation taken in float64 and rounded to float32 (so
    it keeps float32 precision relative to itself wherever the scene is), the law
    (:func:`~.laws.yukawa_force_over_r_f32`) and the sums in float32. ``inv_s``, ``core2``, ``rc2``
    are float32 (``1/R_D``, ``a^2``, ``r_c^2``); ``buf`` a (4, m) float32 scratch array, m at
    least the row's length."""
    s = start[i]
    m = start[i + 1] - s
    # [perf] two loops: the first gathers the neighbours in float64 and rounds their separations
    # and charge products to float32 into buf, the second runs the law on them, 8 float32 lanes a
    # vector with AVX2. One loop doing both ran at the width of its float64 part, 4 lanes. Measured
    # on one core of a Zen 4 (Fig. 2 scene, 1200 and 24 000 rods, interleaved with the float64 sum):
    # 1.86 and 1.58 times faster than float64 for AVX2 (haswell build) against 1.40 and 1.35 with
    # one loop; the host build (AVX-512) 1.84 and 1.71 against 1.14 and 1.11.
    # [perf] The gather reads row i once, writes through 1-D views of buf and takes the entry as
    # unsigned (entries are positions, never negative): with a signed entry numba adds a
    # wraparound test to every load, and with AVX-512 the whole sum then took 1.25 times as long
    # (host build, Zen 4, 24 000 rods; the AVX2 build alike). The same values in buf, so the same
    # forces bit for bit (docs/performance.md 'The Yukawa sum and the neighbour lists')
    xi = centre[i, 0]
    yi = centre[i, 1]
    zi = centre[i, 2]
    qi = rod_charge[i]
    bx = buf[0]
    by = buf[1]
    bz = buf[2]
    bq = buf[3]
    for k in range(m):
        l = np.uint64(index[s + k])
        bx[k] = np.float32(xi - centre[l, 0])
        by[k] = np.float32(yi - centre[l, 1])
        bz[k] = np.float32(zi - centre[l, 2])
        bq[k] = np.float32(qi * rod_charge[l])
    zero = np.float32(0.0)
    fx = zero
    fy = zero
    fz = zero
    for k in range(m):
        dx = buf[0, k]
        dy = buf[1, k]
        dz = buf[2, k]
        r2 = dx * dx + dy * dy + dz * dz
        g = yukawa_force_over_r_f32(r2, buf[3, k], inv_s, core2)
        g = g if r2 < rc2 else zero  # a select, not a branch: the loop vectorises
        fx += g * dx
        fy += g * dy
        fz += g * dz
    return fx, fy, fz


@njit_parallel_sum
def yukawa_centres_sorted_mixed(centre, rod_charge, order, start, index, screening, core, cutoff, lo, hi, out):
    """:func:`yukawa_centres_sorted` with the pair law in float32 (``forces.yukawa.precision = "mixed"``).

    The same arguments and rows (a row does not depend on ``lo, hi``, bit for bit). Each
    separation is taken in float64 and rounded to float32, the law
    (:func:`~.laws.yukawa_force_over_r_f32`) runs on 8 float32 lanes with AVX2 and each row's
    sums (a few hundred pairs) are float32, written to the float64 ``out``
    (:func:`_yukawa_row_f32`). The forces differ from the float64 sum by float32 rounding, a few
    1e-7 of the sum of the pair forces' magnitudes in a row; a pair within float32 rounding (6e-8
    relative) of the cut-off may be counted where the float64 sum leaves it out or the reverse, a
    change of at most the force at the cut-off (``tolerance |Z_i Z_j| / Z_max^2``). Sums in
    float64, bit for bit as :func:`yukawa_centres_sorted`: all rows when the charges or lengths are
    outside what float32 holds (:data:`MIXED_CHARGE_MIN`), and a row whose float32 sum is not
    finite (no core and centres closer than about 1e-13; NaN or inf inputs).
    """
    ok = _yukawa_mixed_ok(rod_charge, screening, core, cutoff)
    inv_s = np.float32(1.0 / screening)
    core2 = np.float32(core * core)
    rc2_32 = np.float32(cutoff * cutoff)
    rc2 = cutoff * cutoff
    n = order.shape[0]
    for b in prange((n + MIXED_ROWS - 1) // MIXED_ROWS):
        t0 = b * MIXED_ROWS
        t1 = min(t0 + MIXED_ROWS, n)
        m = 0
        for t in range(t0, t1):
            m = max(m, start[t + 1] - start[t])
        buf = np.empty((4, m), np.float32)
        for t in range(t0, t1):
            i = order[t]
            if i < lo or i >= hi:
                continue
            fx = fy = fz = np.nan
            if ok:
                fx, fy, fz = _yukawa_row_f32(centre, rod_charge, t, start, index, inv_s, core2, rc2_32, buf)
            if not (math.isfinite(fx) and math.isfinite(fy) and math.isfinite(fz)):
                fx, fy, fz = _yukawa_row(centre, rod_charge, t, start, index, screening, core, rc2)
            out[i, 0] = fx
            out[i, 1] = fy
            out[i, 2] = fz


@njit_parallel
def yukawa_energy(centre, rod_charge, start, index, screening, core, cutoff, lo, hi, out):
    """Energy of :func:`yukawa_centres` by rows, shifted to zero at the cut-off so it is continuous.

    ``out[i]`` (rows ``lo:hi`` of an (n_rods,) float64 array) sums the pairs ``(i, l)`` with
    ``l > i``, so that summed over all rows each pair is counted once. One value per row
    keeps the total independent of how rows are split over threads or ranks.
    """
    rc2 = cutoff * cutoff
    for i in prange(lo, hi):
        acc = 0.0
        for j in range(start[i], start[i + 1]):
            l = index[j]
            if l > i:
                dx = centre[i, 0] - centre[l, 0]
                dy = centre[i, 1] - centre[l, 1]
                dz = centre[i, 2] - centre[l, 2]
                r2 = dx * dx + dy * dy + dz * dz
                if r2 < rc2:
                    zz = rod_charge[i] * rod_charge[l]
                    acc += yukawa_potential(r2, zz, screening, core) - yukawa_potential(rc2, zz, screening, core)
        out[i] = acc
