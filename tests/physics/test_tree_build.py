"""The stages of the tip tree's build (kernels/treebuild.py) each against a slow reference: the cells
of the sorted Morton keys against a recursive split in Python, the target groups against their
definition, every cell's box, centre, radius and moments against numpy sums over its tips, and the
float32 hi + lo coordinates against the float64 ones. (The tree's forces against the direct sum:
test_tree.py.)"""

import itertools
import math

import numpy as np
import pytest

from selfas_graph.kernels import treebuild as tb
from selfas_graph.kernels.tree import build_tip_tree

#: small inputs: also run with NUMBA_DISABLE_JIT=1, the kernels as Python (.ci/run)
pytestmark = pytest.mark.jit_off_ok


def tips(rng, n=400):
    """Tips in two clusters and a sparse gas, with one pair of tips at the same place (equal keys)."""
    x = np.concatenate(
        [rng.normal(0, 0.3, (n // 2, 3)), rng.normal(3, 1.0, (n // 4, 3)), rng.uniform(-5, 5, (n // 4, 3))]
    )
    x[1] = x[0]
    return x[:, 0].copy(), x[:, 1].copy(), x[:, 2].copy(), rng.uniform(-2, 2, n)


def cells_by_recursion(key, leaf_size):
    """The octree's cells in depth-first preorder, by the rule of build_cells written as a recursion:
    a range of at most ``leaf_size`` keys, or of equal keys, is a leaf; any other is split by the
    octal digit of its highest differing bit, children in increasing digit."""
    start, end, nxt = [], [], []

    def visit(s, e):
        c = len(start)
        start.append(s)
        end.append(e)
        nxt.append(None)
        diff = int(key[s]) ^ int(key[e - 1])
        if e - s > leaf_size and diff:
            shift = 3 * ((diff.bit_length() - 1) // 3)
            digit = (key[s:e] >> shift) & 7
            for d in range(8):
                where = np.flatnonzero(digit == d)
                if len(where):
                    visit(s + int(where[0]), s + int(where[-1]) + 1)
        nxt[c] = len(start)

    visit(0, len(key))
    return np.array(start), np.array(end), np.array(nxt)


@pytest.mark.parametrize("leaf_size", [1, 4, 16, 1000])
def test_cells_are_the_recursive_split(rng, leaf_size):
    x, y, z, _ = tips(rng)
    key = np.empty(len(x), np.int64)
    tb.morton_keys(x, y, z, key)
    key = key[tb.argsort_keys(key)]
    assert np.all(np.diff(key) >= 0)
    start, end, nxt = tb.build_cells(key, leaf_size)
    want = cells_by_recursion(key, leaf_size)
    for got, ref in zip((start, end, nxt), want):
        np.testing.assert_array_equal(got, ref)
    leaves = nxt == np.arange(len(start)) + 1
    # every tip in exactly one leaf; a leaf holds at most leaf_size tips or tips of one key
    assert np.array_equal(
        np.sort(np.concatenate([np.arange(s, e) for s, e in zip(start[leaves], end[leaves])])), np.arange(len(x))
    )
    big = (end - start)[leaves] > leaf_size
    assert all(key[s] == key[e - 1] for s, e in zip(start[leaves][big], end[leaves][big]))


@pytest.mark.parametrize("group_size", [1, 8, 64, 10_000])
def test_groups_are_the_largest_cells_within_the_size(rng, group_size):
    """The groups cover the tips once, in order; each is a cell of at most group_size tips or a leaf,
    and the cell above it (if any) is larger than group_size."""
    x, y, z, _ = tips(rng)
    key = np.empty(len(x), np.int64)
    tb.morton_keys(x, y, z, key)
    start, end, nxt = tb.build_cells(key[tb.argsort_keys(key)], 4)
    group = tb.target_groups(start, end, nxt, group_size)
    np.testing.assert_array_equal(np.concatenate([np.arange(start[g], end[g]) for g in group]), np.arange(len(x)))
    parent = np.full(len(start), -1)
    for c in range(len(start)):
        parent[c + 1 : nxt[c]][parent[c + 1 : nxt[c]] < c] = c  # the nearest cell whose subtree holds it
    for g in group:
        assert end[g] - start[g] <= group_size or nxt[g] == g + 1
        assert parent[g] < 0 or end[parent[g]] - start[parent[g]] > group_size


def detracer(s, n):
    """The traceless tensor of order n of the offset s, (-1)^n |s|^(2n+1) d^n(1/|s|), from its
    pairings: sum over k pairs of indices of (-1)^k (2n-2k-1)!! |s|^(2k) delta...delta s...s."""
    s2 = float(s @ s)
    out = np.zeros((3,) * n)
    for idx in itertools.product(range(3), repeat=n):
        total = 0.0
        for k in range(n // 2 + 1):
            coef = (-1) ** k * math.prod(range(2 * n - 2 * k - 1, 0, -2)) * s2**k
            for pairs in _pairings(list(range(n)), k):
                paired = {i for p in pairs for i in p}
                if all(idx[a] == idx[b] for a, b in pairs):
                    total += coef * math.prod(s[idx[i]] for i in range(n) if i not in paired)
        out[idx] = total
    return out


def _pairings(items, k):
    """Every set of k disjoint pairs from items."""
    if k == 0:
        yield ()
        return
    for i, a in enumerate(items):
        for j in range(i + 1, len(items)):
            rest = items[i + 1 : j] + items[j + 1 :]
            for more in _pairings(rest, k - 1):
                yield ((a, items[j]),) + more


#: the stored components of each order, in the layout of kernels/tree.py's TipTree
STORED = {
    0: [()],
    1: [(0,), (1,), (2,)],
    2: [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2)],
    3: [(0, 0, 0), (0, 0, 1), (0, 0, 2), (0, 1, 1), (0, 1, 2), (1, 1, 1), (1, 1, 2)],
    4: [
        (0, 0, 0, 0),
        (0, 0, 0, 1),
        (0, 0, 0, 2),
        (0, 0, 1, 1),
        (0, 0, 1, 2),
        (0, 1, 1, 1),
        (0, 1, 1, 2),
        (1, 1, 1, 1),
        (1, 1, 1, 2),
    ],
}


@pytest.mark.parametrize("order", [2, 3, 4])
def test_cell_moments_are_the_sums_over_their_tips(rng, order):
    """Every cell's box (numpy min and max), centre (its middle), radius (the farthest tip from the
    centre) and moments (sums of q times the traceless tensor of the offset, order by order, those above
    ``order`` zero) against sums in numpy. Tolerance: sums of up to 400 terms of size up to
    max|q| (2 r)^4, cancelling; the kernel adds them in another order, so 1e-12 of that size."""
    x, y, z, q = tips(rng, 200)
    t = build_tip_tree(x, y, z, q, leaf_size=8, group_size=16, order=order)
    pos = np.stack([t.x, t.y, t.z], 1)
    for c in range(len(t.start)):
        p, qc = pos[t.start[c] : t.end[c]], t.charge[t.start[c] : t.end[c]]
        lo, hi = p.min(0), p.max(0)
        np.testing.assert_array_equal(t.box[c], np.concatenate([lo, hi]))
        np.testing.assert_array_equal(t.centre[c], 0.5 * (lo + hi))
        offset = p - t.centre[c]
        r = np.sqrt((offset**2).sum(1)).max()
        assert t.radius[c] == pytest.approx(r, rel=1e-15)
        want = []
        for n in range(5):
            tensors = sum(qk * detracer(sk, n) for qk, sk in zip(qc, offset)) if n <= order else np.zeros((3,) * n)
            want += [tensors[i] for i in STORED[n]]
        scale = np.abs(qc).max() * max(1.0, 2 * r) ** 4 * len(qc)
        np.testing.assert_allclose(t.moment[c], want, rtol=0, atol=1e-12 * scale)


def test_hi_and_lo_hold_the_coordinates_to_48_bits(rng):
    """hi is the float32 rounding of x - origin and hi + lo that difference to float32's precision of
    the remainder: |hi + lo - (x - origin)| <= 2^-48 |x - origin| (the remainder is below half an ulp
    of hi, 2^-24 |hi|, and its float32 rounding keeps 24 bits of it)."""
    x, y, z, _ = tips(rng)
    x[5] = 1e-40  # a remainder below float32's smallest normal
    origin = np.array([0.3, -0.2, 100.0])
    near32 = np.empty((6, len(x)), np.float32)
    tb.split_hi_lo(x, y, z, origin, near32)
    for d, c in enumerate((x, y, z)):
        u = c - origin[d]
        np.testing.assert_array_equal(near32[d], u.astype(np.float32))
        err = np.abs(near32[d].astype(np.float64) + near32[3 + d].astype(np.float64) - u)
        assert np.all(err <= 2.0**-48 * np.abs(u) + 1e-45), err.max()
