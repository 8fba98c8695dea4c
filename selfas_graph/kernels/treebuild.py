"""Build of the tip tree (:mod:`.tree`): Morton keys and their sort, the cells, and the upward pass
that gives every cell its box, expansion centre, radius and multipole moments (docs/model.md 'Term 1').

The stages and the moments are described in :mod:`.tree`'s docstring; :func:`.tree.build_tip_tree`
calls them in order (:func:`morton_keys`, :func:`argsort_keys`, :func:`build_cells`,
:func:`target_groups`, then :func:`cell_moments` over runs of cells and :func:`split_hi_lo`).
"""

import math

import numpy as np

from ._jit import inline, njit, njit_parallel, njit_rows, prange

#: bits of the Morton key per axis; also the depth cap of the tree
KEY_BITS = 21
#: stored moments per cell: M, P (3), Q (5 independent), O (7 independent), H (9 independent)
N_MOMENT = 25


@njit
def _spread_bits(v):
    """Put bit i of a 21-bit integer at bit 3 i (the usual Morton magic numbers)."""
    v &= 0x1FFFFF
    v = (v | (v << 32)) & 0x1F00000000FFFF
    v = (v | (v << 16)) & 0x1F0000FF0000FF
    v = (v | (v << 8)) & 0x100F00F00F00F00F
    v = (v | (v << 4)) & 0x10C30C30C30C30C3
    v = (v | (v << 2)) & 0x1249249249249249
    return v


@njit_rows
def morton_keys(x, y, z, out):
    """63-bit Morton keys of points over the cube that holds them all.

    Serial below ``_jit.PARALLEL_ROWS`` points: in parallel, its six extrema and the key loop are each a
    parallel region, and waking the idle threads for them cost more than the loop (Zen 5, 48 000 tips,
    2 threads: 0.46 against 0.16 ms on one). The keys are integers, the same in either build.

    Parameters
    ----------
    x, y, z : (n,) float64
        Finite coordinates.
    out : (n,) int64
        Overwritten with the keys. The cube's side is the largest extent; an
        extent of 0 or inf gives all keys 0 (one leaf: the direct sum).
    """
    n = x.shape[0]
    x0, y0, z0 = x.min(), y.min(), z.min()
    extent = max(x.max() - x0, y.max() - y0, z.max() - z0)
    top = float((1 << KEY_BITS) - 1)
    scale = (1 << KEY_BITS) / extent if 0.0 < extent < np.inf else 0.0
    if not scale < np.inf:  # a subnormal extent
        scale = 0.0
    for i in prange(n):
        ix = int(min(max((x[i] - x0) * scale, 0.0), top))
        iy = int(min(max((y[i] - y0) * scale, 0.0), top))
        iz = int(min(max((z[i] - z0) * scale, 0.0), top))
        out[i] = (_spread_bits(ix) << 2) | (_spread_bits(iy) << 1) | _spread_bits(iz)


#: bits per digit of :func:`argsort_keys` (6 passes over 63-bit keys, counts of 2048 fit in L1)
RADIX_BITS = 11


@njit
def argsort_keys(key):
    """Stable argsort of non-negative int64 keys below 2**63 (Morton keys): ``np.argsort(key, kind="stable")``.

    Least-significant-digit radix sort, :data:`RADIX_BITS` bits a pass, all digit counts taken in
    one pass over the keys, and a pass skipped where every key has the same digit (the high bits of
    a flat scene's keys). Ties keep the order of the tips, so that the result is one permutation
    whatever the platform. Measured on a Zen 4 (numpy 2.4, whose quicksort there is not the SIMD
    one): 2.6 against 11 ms for numpy's argsort at 2e5 Morton keys, 0.6 against 2.1 ms at 48 000.
    """
    n = key.shape[0]
    passes = -(-63 // RADIX_BITS)
    size = 1 << RADIX_BITS
    mask = size - 1
    count = np.zeros((passes, size), np.int64)
    for i in range(n):
        k = key[i]
        for p in range(passes):
            count[p, (k >> (RADIX_BITS * p)) & mask] += 1
    index = np.arange(n)
    cur = key.copy()
    spare_index = np.empty(n, np.int64)
    spare_key = np.empty(n, np.int64)
    for p in range(passes):
        shift = RADIX_BITS * p
        if n == 0 or count[p, (cur[0] >> shift) & mask] == n:
            continue  # one digit for all: the pass would not move a key
        total = 0
        for d in range(size):  # exclusive prefix sums: the first place of each digit
            c = count[p, d]
            count[p, d] = total
            total += c
        for i in range(n):
            d = (cur[i] >> shift) & mask
            j = count[p, d]
            count[p, d] = j + 1
            spare_key[j] = cur[i]
            spare_index[j] = index[i]
        cur, spare_key = spare_key, cur
        index, spare_index = spare_index, index
    return index


@njit
def _first_with_digit(key, lo, hi, shift, digit):
    """First i in [lo, hi) with ``(key[i] >> shift) & 7 >= digit`` (keys sorted, common prefix)."""
    while lo < hi:
        mid = (lo + hi) // 2
        if ((key[mid] >> shift) & 7) >= digit:
            hi = mid
        else:
            lo = mid + 1
    return lo


@njit
def build_cells(key, leaf_size):
    """Octree cells over sorted Morton keys, in depth-first preorder.

    Parameters
    ----------
    key : (n,) int64
        Sorted keys, n >= 1.
    leaf_size : int
        A range of at most this many tips is a leaf.

    Returns
    -------
    start, end, next : (n_cells,) int64
        Tip range of each cell and the index of the cell after its subtree.
    """
    n = key.shape[0]
    cap = 2 * n + 1  # every inner cell has >= 2 children, so fewer than 2 n cells
    start = np.empty(cap, np.int64)
    end = np.empty(cap, np.int64)
    parent = np.empty(cap, np.int64)
    # depth-first stack: each split pushes at most 8 ranges and pops one, and
    # there are at most KEY_BITS splits on any path
    stack = np.empty((8 * KEY_BITS + 8, 3), np.int64)
    stack[0, 0] = 0
    stack[0, 1] = n
    stack[0, 2] = -1
    sp = 1
    nc = 0
    bounds = np.empty(9, np.int64)
    while sp > 0:
        sp -= 1
        s = stack[sp, 0]
        e = stack[sp, 1]
        c = nc
        nc += 1
        start[c] = s
        end[c] = e
        parent[c] = stack[sp, 2]
        diff = key[s] ^ key[e - 1]
        if e - s <= leaf_size or diff == 0:
            continue
        top = 0
        while (diff >> (top + 1)) != 0:
            top += 1
        shift = (top // 3) * 3
        bounds[0] = s
        bounds[8] = e
        for digit in range(1, 8):
            bounds[digit] = _first_with_digit(key, bounds[digit - 1], e, shift, digit)
        for digit in range(7, -1, -1):  # reversed, so the first child is popped first
            if bounds[digit + 1] > bounds[digit]:
                stack[sp, 0] = bounds[digit]
                stack[sp, 1] = bounds[digit + 1]
                stack[sp, 2] = c
                sp += 1
    size = np.ones(nc, np.int64)
    for c in range(nc - 1, 0, -1):  # children come after their parent in preorder
        size[parent[c]] += size[c]
    nxt = np.arange(nc) + size
    return start[:nc].copy(), end[:nc].copy(), nxt


@inline
def bounding_box(x, y, z, s, e):
    """``(xl, yl, zl, xh, yh, zh)``: the box of the points ``s:e`` (``e > s``) of ``x, y, z``."""
    xl = xh = x[s]
    yl = yh = y[s]
    zl = zh = z[s]
    for i in range(s + 1, e):
        xl = min(xl, x[i])
        xh = max(xh, x[i])
        yl = min(yl, y[i])
        yh = max(yh, y[i])
        zl = min(zl, z[i])
        zh = max(zh, z[i])
    return xl, yl, zl, xh, yh, zh


@inline
def add_moments(row, base, q, sx, sy, sz, order):
    """Add the moments of a charge ``q`` at offset ``s`` from a cell's centre to ``row[base:]``, up to
    ``order`` (2: M, P, Q; 3: and O; 4: and H), in the layout of :class:`.tree.TipTree` (the
    normalisation in :mod:`.multipole`); :func:`cell_moments` and the tree of the rod currents
    (:mod:`.currenttree`, a row per channel) sum them."""
    s2 = sx * sx + sy * sy + sz * sz
    row[base] += q
    row[base + 1] += q * sx
    row[base + 2] += q * sy
    row[base + 3] += q * sz
    row[base + 4] += q * (3.0 * sx * sx - s2)
    row[base + 5] += q * 3.0 * sx * sy
    row[base + 6] += q * 3.0 * sx * sz
    row[base + 7] += q * (3.0 * sy * sy - s2)
    row[base + 8] += q * 3.0 * sy * sz
    if order >= 3:
        t = 3.0 * q * s2
        row[base + 9] += q * 15.0 * sx * sx * sx - 3.0 * t * sx
        row[base + 10] += q * 15.0 * sx * sx * sy - t * sy
        row[base + 11] += q * 15.0 * sx * sx * sz - t * sz
        row[base + 12] += q * 15.0 * sx * sy * sy - t * sx
        row[base + 13] += q * 15.0 * sx * sy * sz
        row[base + 14] += q * 15.0 * sy * sy * sy - 3.0 * t * sy
        row[base + 15] += q * 15.0 * sy * sy * sz - t * sz
    if order >= 4:
        u = 15.0 * q * s2
        v = 3.0 * q * s2 * s2
        xx = sx * sx
        yy = sy * sy
        row[base + 16] += 105.0 * q * xx * xx - 6.0 * u * xx + 3.0 * v
        row[base + 17] += 105.0 * q * xx * sx * sy - 3.0 * u * sx * sy
        row[base + 18] += 105.0 * q * xx * sx * sz - 3.0 * u * sx * sz
        row[base + 19] += 105.0 * q * xx * yy - u * (xx + yy) + v
        row[base + 20] += 105.0 * q * xx * sy * sz - u * sy * sz
        row[base + 21] += 105.0 * q * sx * yy * sy - 3.0 * u * sx * sy
        row[base + 22] += 105.0 * q * sx * yy * sz - u * sx * sz
        row[base + 23] += 105.0 * q * yy * yy - 6.0 * u * yy + 3.0 * v
        row[base + 24] += 105.0 * q * yy * sy * sz - 3.0 * u * sy * sz


@njit_parallel
def cell_moments(x, y, z, charge, start, end, order, box, centre, radius, moment):
    """Bounding box, expansion centre, radius and multipole moments of every cell.

    Parameters
    ----------
    x, y, z, charge : (n_tips,) float64
        Tips in Morton order.
    start, end : (n_cells,) int64
        Tip range of each cell.
    order : int
        2 (quadrupole), 3 (octupole) or 4 (hexadecapole); the columns above the order are zero.
    box : (n_cells, 6) float64
    centre : (n_cells, 3) float64
    radius : (n_cells,) float64
    moment : (n_cells, N_MOMENT) float64
        Overwritten (layout in :class:`.tree.TipTree`).
    """
    for c in prange(start.shape[0]):
        s = start[c]
        e = end[c]
        xl, yl, zl, xh, yh, zh = bounding_box(x, y, z, s, e)
        box[c, 0] = xl
        box[c, 1] = yl
        box[c, 2] = zl
        box[c, 3] = xh
        box[c, 4] = yh
        box[c, 5] = zh
        cx = 0.5 * (xl + xh)
        cy = 0.5 * (yl + yh)
        cz = 0.5 * (zl + zh)
        centre[c, 0] = cx
        centre[c, 1] = cy
        centre[c, 2] = cz
        b2 = 0.0
        mc = moment[c]
        mc[:] = 0.0
        for i in range(s, e):
            sx = x[i] - cx
            sy = y[i] - cy
            sz = z[i] - cz
            b2 = max(b2, sx * sx + sy * sy + sz * sz)
            add_moments(mc, 0, charge[i], sx, sy, sz, order)
        radius[c] = math.sqrt(b2)


@njit_parallel
def split_hi_lo(x, y, z, origin, near32):
    """Coordinates relative to ``origin`` as float32 pairs hi + lo (rows of ``near32``, :class:`.tree.TipTree`).

    hi is the float32 rounding of ``x - origin``, lo the float32 rounding of the rest: together
    they hold about 48 bits, so that ``(hi_k - hi_l) + (lo_k - lo_l)`` keeps float32 precision
    relative to the distance of two tips, not to their distance from the origin.
    """
    for i in prange(x.shape[0]):
        u = x[i] - origin[0]
        v = y[i] - origin[1]
        w = z[i] - origin[2]
        near32[0, i] = np.float32(u)
        near32[1, i] = np.float32(v)
        near32[2, i] = np.float32(w)
        near32[3, i] = np.float32(u - np.float64(near32[0, i]))
        near32[4, i] = np.float32(v - np.float64(near32[1, i]))
        near32[5, i] = np.float32(w - np.float64(near32[2, i]))


@njit
def target_groups(start, end, nxt, group_size):
    """Cells evaluated together: the largest cells with at most ``group_size`` tips, or leaves."""
    n_cells = start.shape[0]
    group = np.empty(n_cells, np.int64)
    ng = 0
    c = 0
    while c < n_cells:
        if end[c] - start[c] <= group_size or nxt[c] == c + 1:
            group[ng] = c
            ng += 1
            c = nxt[c]
        else:
            c += 1
    return group[:ng].copy()
