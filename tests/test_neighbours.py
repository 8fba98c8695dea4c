"""The Verlet neighbour list holds every pair within the cut-off, before and after moves."""
import numpy as np

from selfas_graph.model.neighbours import NeighbourList


def brute_pairs(x, r, exclude_same_rod):
    d = np.linalg.norm(x[:, None] - x[None], axis=-1)
    i, j = np.nonzero(np.triu(d < r, 1))
    keep = (i // 2 != j // 2) if exclude_same_rod else np.ones(len(i), bool)
    return set(zip(i[keep].tolist(), j[keep].tolist()))


def listed(nl):
    return {(k, int(l)) for k in range(len(nl.start) - 1) for l in nl.index[nl.start[k]:nl.start[k + 1]] if k < l}


def test_list_covers_cutoff_through_moves(rng):
    """After random moves below skin/2 the list is reused and still covers the cut-off; beyond, it rebuilds."""
    x = rng.uniform(0, 5, (300, 3))
    nl = NeighbourList(0.6, 0.4, exclude_same_rod=True)
    assert nl.update(x)
    for _ in range(20):
        x = x + rng.normal(scale=0.03, size=x.shape)
        nl.update(x)
        assert brute_pairs(x, 0.6, True) <= listed(nl)
    assert 1 < nl.n_builds < 20


def test_same_rod_pairs_excluded(rng):
    x = rng.uniform(0, 1, (40, 3))
    nl = NeighbourList(2.0, 0.1, exclude_same_rod=True)
    nl.build(x)
    assert all(k // 2 != l // 2 for k, l in listed(nl))
    assert listed(nl) == brute_pairs(x, 2.1, True)


def test_compressed_rows_symmetric(rng):
    x = rng.uniform(0, 3, (100, 3))
    nl = NeighbourList(0.5, 0.1)
    nl.build(x)
    for k in range(100):
        for l in nl.index[nl.start[k]:nl.start[k + 1]]:
            assert k in nl.index[nl.start[l]:nl.start[l + 1]]
