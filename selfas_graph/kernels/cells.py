"""Neighbour lists from a cell list, in the compressed-row form of :mod:`.pairs`.

Points are binned into a grid of cubic cells of side ``h >= r / 2`` (:data:`CELLS_PER_RADIUS`);
every pair closer than ``r`` then lies at most ``span = ceil(r / h)`` cells apart along each
axis (2 with cells of side ``r / 2``: 125 cells per point, in 25 runs contiguous in memory).
The list is built in two parallel passes over points, as :func:`.pairs.close_pairs` is: count
each point's neighbours, then fill each row at its prefix-sum offset, so that each
iteration writes only its own row. A row lists its neighbours in the order the cells
are visited (ascending cell, then ascending point index within a cell): a function
of the positions and ``r`` alone, the same for any thread count, on every MPI rank
and after a restart from the positions of the last build. Sorting each row by index
instead would cost 2.3 times the rest of the build (measured at 24 000 rod centres)
and made the Yukawa pair loop no faster on one core.

The candidates are read from copies of the coordinates in cell order (``sx, sy, sz``),
so the inner loop streams through memory instead of jumping between random point
numbers, and the rows are visited in cell order too, so that consecutive iterations
read the same cells (measured on one core: 130 -> 118 ms at 24 000 rod centres, 608 ->
523 ms at 10^5, and 132 -> 95 ms for the 2 10^5 tips, whose sparse grid of 1.1e6 cells
otherwise misses the cache at every point). The counting pass is a branch-free count
that vectorises; the fill pass keeps a branch (a branch-free store measured slower: 8.8
against 6.7 ms for the late Fig. 2 rod centres, each store waiting on the previous). Cutting each
column's run of cells to the slab the radius allows (a square root and two floors per column; the
same rows in the same order) measured slower too, on one Zen 4 core with `bench neighbours --before`:
0.88 times at 6000 rod centres of Fig. 6, 0.50 for its 12 000 tips, whose cells hold a point or two.

Glossary: ``n`` points, ``g`` (3,) int64 cells per axis, ``h`` cell side, ``span`` cells
searched on each side, ``lo`` (3,) float64 the grid's lower corner, ``cell_start``
(g0 g1 g2 + 1,) int64 and ``cell_point`` (n,) int64 the points of each cell in compressed
rows (ascending point index within a cell), ``sx, sy, sz`` (n,) float64
``position[cell_point, d]``.
"""

import math

import numpy as np

from ._jit import inline, njit, njit_parallel, prange


@inline
def _cell_of(position, k, lo, h, g, d):
    """Cell coordinate of point k along axis d, clamped to ``0 .. g[d] - 1``."""
    c = int((position[k, d] - lo[d]) / h)
    return min(max(c, 0), g[d] - 1)


@njit
def bin_points(position, lo, h, g, cell_start, cell_point):
    """Counting sort of the points into cells (serial: O(n), a few ms at 10^5 points).

    Parameters
    ----------
    position : (n, 3) float64, finite
    lo : (3,) float64
    h : float
    g : (3,) int64
    cell_start : (g[0] g[1] g[2] + 1,) int64, overwritten
    cell_point : (n,) int64, overwritten
    """
    n = position.shape[0]
    cell_start[:] = 0
    cell = np.empty(n, dtype=np.int64)
    for k in range(n):
        c = (_cell_of(position, k, lo, h, g, 0) * g[1] + _cell_of(position, k, lo, h, g, 1)) * g[2] + _cell_of(
            position, k, lo, h, g, 2
        )
        cell[k] = c
        cell_start[c + 1] += 1
    for c in range(cell_start.shape[0] - 1):
        cell_start[c + 1] += cell_start[c]
    fill = cell_start[:-1].copy()
    for k in range(n):  # ascending k: points within a cell stay in index order
        cell_point[fill[cell[k]]] = k
        fill[cell[k]] += 1


@inline
def _row_range(position, lo, h, g, k, span, d):
    """Cells ``c - span .. c + span`` (clipped to the grid) around point k's cell along axis d, as a range."""
    c = _cell_of(position, k, lo, h, g, d)
    return range(max(c - span, 0), min(c + span + 1, g[d]))


@njit_parallel
def _row_counts(
    position, sx, sy, sz, lo, h, g, span, cell_start, cell_point, r2max, exclude_same_rod, row_lo, row_hi, counts
):
    """Row lengths: candidates closer than ``sqrt(r2max)``, less the point itself and (with
    ``exclude_same_rod``) the other tip of its rod when that is in range; 0 for the points
    outside ``row_lo <= k < row_hi``.

    The candidate loop is a branch-free count over contiguous runs of the sorted coordinates
    (``sx, sy, sz``), which LLVM vectorises; the two exclusions are corrected once per row.
    """
    n = position.shape[0]
    for t in prange(n):
        k = cell_point[t]  # points in cell order: neighbouring iterations read the same cells
        if k < row_lo or k >= row_hi:
            counts[k] = 0
            continue
        xk = position[k, 0]
        yk = position[k, 1]
        zk = position[k, 2]
        c = 0
        zr = _row_range(position, lo, h, g, k, span, 2)
        for ax in _row_range(position, lo, h, g, k, span, 0):
            for ay in _row_range(position, lo, h, g, k, span, 1):
                base = (ax * g[1] + ay) * g[2]  # the cells along the last axis are contiguous
                for j in range(cell_start[base + zr.start], cell_start[base + zr.stop]):
                    dx = xk - sx[j]
                    dy = yk - sy[j]
                    dz = zk - sz[j]
                    c += 1 if dx * dx + dy * dy + dz * dz < r2max else 0
        c -= 1  # the point itself, always a candidate at distance 0 (r2max > 0)
        m = k ^ 1  # the other tip of the same rod
        if exclude_same_rod and m < n:
            dx = xk - position[m, 0]
            dy = yk - position[m, 1]
            dz = zk - position[m, 2]
            c -= 1 if dx * dx + dy * dy + dz * dz < r2max else 0
        counts[k] = c


@njit_parallel
def _row_fill(
    position,
    sx,
    sy,
    sz,
    lo,
    h,
    g,
    span,
    cell_start,
    cell_point,
    r2max,
    exclude_same_rod,
    row_lo,
    row_hi,
    start,
    index,
    start_t,
    index_t,
):
    """Write each row at its offset ``start[k]``, candidates in the order :func:`_row_counts` visits them.

    The test is on the same squared distances as in :func:`_row_counts` (the same expression on
    the same numbers), so each row gets exactly its counted length. With ``index_t`` non-empty,
    also write the same rows numbered by cell at ``start_t[t]``: row t is that of point
    ``cell_point[t]``, and a neighbour is written as its place j in the cell order. Points outside
    ``row_lo <= k < row_hi`` have empty rows.
    """
    n = position.shape[0]
    both = index_t.shape[0] > 0
    for t in prange(n):
        k = cell_point[t]
        if k < row_lo or k >= row_hi:
            continue
        xk = position[k, 0]
        yk = position[k, 1]
        zk = position[k, 2]
        half = k >> 1 if exclude_same_rod else -1  # no point index is negative
        c = start[k]
        c_t = start_t[t] if both else 0
        zr = _row_range(position, lo, h, g, k, span, 2)
        for ax in _row_range(position, lo, h, g, k, span, 0):
            for ay in _row_range(position, lo, h, g, k, span, 1):
                base = (ax * g[1] + ay) * g[2]
                for j in range(cell_start[base + zr.start], cell_start[base + zr.stop]):
                    dx = xk - sx[j]
                    dy = yk - sy[j]
                    dz = zk - sz[j]
                    l = cell_point[j]
                    if dx * dx + dy * dy + dz * dz < r2max and l != k and (l >> 1) != half:
                        index[c] = l
                        c += 1
                        if both:
                            index_t[c_t] = j
                            c_t += 1


@njit
def bounds(position):
    """Lower and upper corner of the points, (3,) float64 each (one pass; numpy's ``min(axis=0)``
    on an (n, 3) array took 90 us for 2400 points, a tenth of a tip-list build)."""
    lo = position[0].copy()
    hi = position[0].copy()
    for k in range(1, position.shape[0]):
        for d in range(3):
            lo[d] = min(lo[d], position[k, d])
            hi[d] = max(hi[d], position[k, d])
    return lo, hi


@njit
def max_displacement2(position, reference):
    """Largest squared distance between a row of ``position`` and the same row of ``reference``.

    One pass over both arrays instead of three numpy passes (difference, row dot products,
    maximum): measured 3 against 25 us for 2400 tips on one core, and a Verlet list checks it
    3 times per step. Each row is summed as ``(dx^2 + dz^2) + dy^2``, the order in which numpy 2's
    ``np.einsum("ij,ij->i", d, d)``, the check it replaces, sums three columns (equal on 2e5 random
    rows; any other order differs in the last bit in a fifth of them), so that the rebuild
    decisions, and with them the runs, stay the same bit for bit. Returns inf when a row holds NaN
    (a list built then lists nothing and the run's health check stops the run), 0 for no rows.

    Parameters
    ----------
    position, reference : (n, 3) float64
    """
    m = 0.0
    for i in range(position.shape[0]):
        dx = position[i, 0] - reference[i, 0]
        dy = position[i, 1] - reference[i, 1]
        dz = position[i, 2] - reference[i, 2]
        d2 = (dx * dx + dz * dz) + dy * dy
        if d2 != d2:
            return np.inf
        m = max(m, d2)
    return m


@njit
def take_rows(source, order, out):
    """``out[t] = source[order[t]]`` for the rows of an (n, 3) array (the copies in cell order that
    :func:`.yukawa.yukawa_centres_sorted` reads): numpy's ``source[order]`` took 420 us for 24 000
    rows in a random order against 32 us here (Zen 4); the same numbers, copied."""
    for t in range(order.shape[0]):
        i = order[t]
        out[t, 0] = source[i, 0]
        out[t, 1] = source[i, 1]
        out[t, 2] = source[i, 2]


#: cells per search radius along each axis: cells of side ``radius / 2`` and the 5 x 5 x 5 cells
#: around a point's own (25 contiguous runs) hold 0.58 of the candidates of side ``radius`` and
#: 3 x 3 x 3 cells; measured on one core, rod-centre lists (radius 6.86) 20-25 % faster to build at
#: 1200-24 000 rods. Where the grid cap makes the cells larger, fewer are visited (:func:`neighbour_rows`).
CELLS_PER_RADIUS = 2


def cell_grid(position, side, max_cells):
    """Grid for :func:`neighbour_rows`: lower corner, cell side >= ``side``, cells per axis.

    The side doubles beyond ``side`` while the points are spread so far apart that
    cells of that side would number more than ``max_cells`` (a larger side
    only makes the search test more pairs, never miss one).

    Parameters
    ----------
    position : (n, 3) float64, finite, n >= 1
    side : float > 0
    max_cells : int >= 1

    Returns
    -------
    lo : (3,) float64, h : float, g : (3,) int64
    """
    lo, hi = bounds(position)
    extent = [float(hi[d] - lo[d]) for d in range(3)]
    h = float(side)
    while math.prod(math.floor(e / h) + 1.0 for e in extent) > max_cells:
        h *= 2.0
    g = np.array([math.floor(e / h) + 1 for e in extent], dtype=np.int64)
    return lo, h, g


#: the largest point number an int32 holds: a list's entries are int32 up to it (:func:`list_dtype`)
INT32_MAX = 2**31 - 1


def list_dtype(n):
    """The integer type of the entries (point numbers) of a list of ``n`` points: int32 up to
    2^31 - 1 points, else int64. The row offsets stay int64.

    [perf] The same numbers in half the bytes; the kernels give the same results bit for bit (their
    sums may be reordered by the compiler, so this is measured: tests/unit/test_neighbours.py, and
    ``bench same_as_commit`` on the shipped scenes, docs/performance.md). On
    the rod-centre lists of the Fig. 2 scene at 1200-24 000 rods (one thread of a Zen 4, against
    int64 entries; ``selfas-graph bench neighbours --before``): the mixed Yukawa sum (the scenes')
    1.09-1.15 times faster on the host build and 1.01-1.05 on the AVX2 build, the float64 sum
    1.06-1.11 and 0.98-1.01, the list's build 1.00-1.11 and 1.00-1.06. int32 offsets as well made
    the AVX2 float64 sum 0.92 times as fast (its loop bounds), so they stay int64. A list takes
    about half the memory (docs/performance.md 'The Yukawa sum and the neighbour lists').
    """
    return np.int32 if n <= INT32_MAX else np.int64


def neighbour_rows(position, radius, exclude_same_rod=False, max_cells=None, cell_order=False, rows=None):
    """All ordered pairs closer than ``radius`` as compressed rows (order: see the module docstring).

    Parameters
    ----------
    position : (n, 3) float64
        Finite points (the caller checks; a NaN point would land in a clamped cell
        and be nobody's neighbour, but its cell index is undefined).
    radius : float > 0
    exclude_same_rod : bool
        Leave out the pairs ``(2 i, 2 i + 1)``, the two tips of one rod.
    max_cells : int, optional
        Cap on the grid size (default ``max(16 n, 1000)``: memory O(n), 128 bytes per point,
        however far apart the points are). At 8 n the tips of the late Fig. 2 state (2400 tips,
        radius 0.78) got cells of twice the radius and 8 times the candidates: 1.47 against
        0.88 ms per build on one core.
    cell_order : bool
        Also return the rows numbered by cell, written in the same fill pass (one more store per
        listed pair; renumbering the list afterwards, reading its rows in random order, took as
        long as a Yukawa sum at 24 000 rods).
    rows : (int, int), optional
        ``(row_lo, row_hi)``: list only the rows of the points ``row_lo <= k < row_hi`` (their
        neighbours among all points), the other rows empty; each listed row is the row of the whole
        list, bit for bit. An MPI rank needs only the rows of its block of rods (the Yukawa sum).

    Returns
    -------
    start : (n + 1,) int64
    index : (start[n],) int32 (int64 from 2^31 points, :func:`list_dtype`)
        The neighbours of point k are ``index[start[k]:start[k + 1]]``;
        both directions of every pair are listed.
    cell_rows : tuple, with ``cell_order`` only
        ``(order, start_t, index_t)``: the points in cell order (``cell_point``, int64) and the rows
        renumbered by it (of the types of ``start`` and ``index``): row t is the row of point
        ``order[t]``, in the same order, each neighbour l written as its place in ``order`` (``t``
        with ``order[t] = l``).
    """
    position = np.ascontiguousarray(position, dtype=np.float64)
    n = position.shape[0]
    start = np.zeros(n + 1, dtype=np.int64)
    if n < 2:
        empty = np.zeros(0, dtype=list_dtype(n))
        if cell_order:
            return start, empty, (np.arange(n, dtype=np.int64), start.copy(), empty.copy())
        return start, empty
    if max_cells is None:
        max_cells = max(16 * n, 1000)
    radius = float(radius)
    lo, h, g = cell_grid(position, radius / CELLS_PER_RADIUS, max_cells)
    span = math.ceil(radius / h)  # cells to search on each side: a pair closer than radius is at most this far apart
    cell_start = np.empty(int(np.prod(g)) + 1, dtype=np.int64)
    cell_point = np.empty(n, dtype=np.int64)
    bin_points(position, lo, h, g, cell_start, cell_point)
    sx, sy, sz = (np.ascontiguousarray(position[cell_point, d]) for d in range(3))
    counts = np.empty(n, dtype=np.int64)
    r2max = radius * radius
    ex = bool(exclude_same_rod)
    row_lo, row_hi = (0, n) if rows is None else (int(rows[0]), int(rows[1]))
    _row_counts(position, sx, sy, sz, lo, h, g, span, cell_start, cell_point, r2max, ex, row_lo, row_hi, counts)
    np.cumsum(counts, out=start[1:])
    index = np.empty(start[-1], dtype=list_dtype(n))
    start_t = np.zeros(n + 1 if cell_order else 1, dtype=np.int64)
    index_t = np.empty(start[-1] if cell_order else 0, dtype=list_dtype(n))
    if cell_order:
        np.cumsum(counts[cell_point], out=start_t[1:])
    _row_fill(
        position, sx, sy, sz, lo, h, g, span, cell_start, cell_point, r2max, ex, row_lo, row_hi,
        start, index, start_t, index_t,
    )  # fmt: skip
    return (start, index, (cell_point, start_t, index_t)) if cell_order else (start, index)
