"""Neighbour lists from a cell list, in the compressed-row form of :mod:`.pairs`.

Points are binned into a grid of cubic cells of side ``h >= r``; every pair closer
than ``r`` then lies in the same or in adjacent cells (27 cells per point). The list
is built in two parallel passes over points, as :func:`.pairs.close_pairs` is: count
each point's neighbours, then fill each row at its prefix-sum offset, so that each
iteration writes only its own row. A row lists its neighbours in the order the cells
are visited (ascending cell, then ascending point index within a cell): a function
of the positions and ``r`` alone, the same for any thread count, on every MPI rank
and after a restart from the positions of the last build. Sorting each row by index
instead would cost 2.3 times the rest of the build (measured at 24 000 rod centres)
and made the Yukawa pair loop no faster on one core.

The candidates are read from a copy of the positions in cell order, so the inner
loop streams through memory instead of jumping between random point numbers, and the
rows are visited in cell order too, so that consecutive iterations read the same cells
(measured on one core: 130 -> 118 ms at 24 000 rod centres, 608 -> 523 ms at 10^5, and
132 -> 95 ms for the 2 10^5 tips, whose sparse grid of 1.1e6 cells otherwise misses
the cache at every point).

Glossary: ``n`` points, ``g`` (3,) int64 cells per axis, ``h`` cell side, ``lo``
(3,) float64 the grid's lower corner, ``cell_start`` (g0 g1 g2 + 1,) int64 and
``cell_point`` (n,) int64 the points of each cell in compressed rows (ascending
point index within a cell), ``sorted_position`` (n, 3) float64 ``position[cell_point]``.
"""

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
def _visit(position, sorted_position, lo, h, g, cell_start, cell_point, r2max, exclude_same_rod, k, row, c0):
    """Count the neighbours of point k; with ``row`` non-empty, also write them from ``c0`` on."""
    cx = _cell_of(position, k, lo, h, g, 0)
    cy = _cell_of(position, k, lo, h, g, 1)
    cz = _cell_of(position, k, lo, h, g, 2)
    xk = position[k, 0]
    yk = position[k, 1]
    zk = position[k, 2]
    c = c0
    for ax in range(max(cx - 1, 0), min(cx + 2, g[0])):
        for ay in range(max(cy - 1, 0), min(cy + 2, g[1])):
            base = (ax * g[1] + ay) * g[2]
            # the cells cz-1 .. cz+1 along the last axis are contiguous in cell_point
            j0 = cell_start[base + max(cz - 1, 0)]
            j1 = cell_start[base + min(cz + 2, g[2])]
            for j in range(j0, j1):
                dx = xk - sorted_position[j, 0]
                dy = yk - sorted_position[j, 1]
                dz = zk - sorted_position[j, 2]
                l = cell_point[j]
                if dx * dx + dy * dy + dz * dz < r2max and l != k and not (exclude_same_rod and l // 2 == k // 2):
                    if row.shape[0] > 0:
                        row[c] = l
                    c += 1
    return c - c0


@njit_parallel
def _row_counts(position, sorted_position, lo, h, g, cell_start, cell_point, r2max, exclude_same_rod, counts):
    none = np.empty(0, dtype=np.int64)
    for t in prange(position.shape[0]):
        k = cell_point[t]  # points in cell order: neighbouring iterations read the same cells
        counts[k] = _visit(
            position, sorted_position, lo, h, g, cell_start, cell_point, r2max, exclude_same_rod, k, none, 0
        )


@njit_parallel
def _row_fill(position, sorted_position, lo, h, g, cell_start, cell_point, r2max, exclude_same_rod, start, index):
    for t in prange(position.shape[0]):
        k = cell_point[t]
        _visit(position, sorted_position, lo, h, g, cell_start, cell_point, r2max, exclude_same_rod, k, index, start[k])


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


def cell_grid(position, radius, max_cells):
    """Grid for :func:`neighbour_rows`: lower corner, cell side >= radius, cells per axis.

    The side grows beyond ``radius`` when the points are spread so far apart that
    cells of side ``radius`` would number more than ``max_cells`` (a larger side
    only makes the search test more pairs, never miss one).

    Parameters
    ----------
    position : (n, 3) float64, finite, n >= 1
    radius : float > 0
    max_cells : int >= 1

    Returns
    -------
    lo : (3,) float64, h : float, g : (3,) int64
    """
    lo = position.min(axis=0)
    extent = position.max(axis=0) - lo
    h = float(radius)
    while np.prod(np.floor(extent / h) + 1.0) > max_cells:
        h *= 2.0
    g = (np.floor(extent / h) + 1.0).astype(np.int64)
    return lo, h, g


def neighbour_rows(position, radius, exclude_same_rod=False, max_cells=None):
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
        Cap on the grid size (default ``max(8 n, 1000)``: memory O(n) however far apart the points are).

    Returns
    -------
    start : (n + 1,) int64
    index : (start[n],) int64
        The neighbours of point k are ``index[start[k]:start[k + 1]]``;
        both directions of every pair are listed.
    """
    position = np.ascontiguousarray(position, dtype=np.float64)
    n = position.shape[0]
    start = np.zeros(n + 1, dtype=np.int64)
    if n < 2:
        return start, np.zeros(0, dtype=np.int64)
    if max_cells is None:
        max_cells = max(8 * n, 1000)
    lo, h, g = cell_grid(position, radius, max_cells)
    cell_start = np.empty(int(np.prod(g)) + 1, dtype=np.int64)
    cell_point = np.empty(n, dtype=np.int64)
    bin_points(position, lo, h, g, cell_start, cell_point)
    sorted_position = position[cell_point]
    counts = np.empty(n, dtype=np.int64)
    r2max = float(radius) * float(radius)
    ex = bool(exclude_same_rod)
    _row_counts(position, sorted_position, lo, h, g, cell_start, cell_point, r2max, ex, counts)
    np.cumsum(counts, out=start[1:])
    index = np.empty(start[-1], dtype=np.int64)
    _row_fill(position, sorted_position, lo, h, g, cell_start, cell_point, r2max, ex, start, index)
    return start, index
