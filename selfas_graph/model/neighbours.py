"""Verlet neighbour lists built with scipy's k-d tree.

A list holds every pair closer than ``cutoff + skin`` and is rebuilt only when
some point has moved more than ``skin / 2`` since the last build, so between
rebuilds it still contains every pair closer than ``cutoff``. Pairs are stored
in compressed rows with both directions, the layout the kernels in
:mod:`selfas_graph.kernels.pairs` take.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree


class NeighbourList:
    """Pairs of points within ``cutoff`` (plus a skin), kept up to date lazily.

    Parameters
    ----------
    cutoff : float
        Interaction range the list must cover.
    skin : float
        Extra range; trades rebuild frequency against list length.
    exclude_same_rod : bool
        Drop pairs ``(2 i, 2 i + 1)`` (the two tips of one rod).
    """

    def __init__(self, cutoff: float, skin: float, exclude_same_rod: bool = False):
        self.cutoff = float(cutoff)
        self.skin = float(skin)
        self.exclude_same_rod = exclude_same_rod
        self.start = np.zeros(1, dtype=np.int64)
        self.index = np.zeros(0, dtype=np.int64)
        self.pairs = np.zeros((0, 2), dtype=np.int64)
        self._reference = None
        self.n_builds = 0

    @property
    def reference(self):
        """Positions of the last build (None before the first): with them a list is rebuilt identically."""
        return self._reference

    def update(self, points: np.ndarray) -> bool:
        """Rebuild if needed for ``points`` (n, 3); returns True if rebuilt."""
        ref = self._reference
        if ref is not None and ref.shape == points.shape:
            moved2 = np.einsum("ij,ij->i", points - ref, points - ref).max(initial=0.0)
            if moved2 < (0.5 * self.skin) ** 2:
                return False
        self.build(points)
        return True

    def build(self, points: np.ndarray) -> None:
        n = points.shape[0]
        # beyond ~1e150 squared distances overflow inside the k-d tree; such a state is already
        # broken, and the run's health check stops it after this step with a diagnosis
        if n > 1 and np.isfinite(points).all() and np.abs(points).max() < 1e150:
            pairs = cKDTree(points).query_pairs(self.cutoff + self.skin, output_type="ndarray").astype(np.int64)
        else:
            pairs = np.zeros((0, 2), dtype=np.int64)
        if self.exclude_same_rod and len(pairs):
            pairs = pairs[pairs[:, 0] // 2 != pairs[:, 1] // 2]
        pairs.sort(axis=1)
        self.pairs = pairs
        src = np.concatenate([pairs[:, 0], pairs[:, 1]])
        dst = np.concatenate([pairs[:, 1], pairs[:, 0]])
        order = np.argsort(src, kind="stable")
        self.index = np.ascontiguousarray(dst[order])
        self.start = np.zeros(n + 1, dtype=np.int64)
        np.cumsum(np.bincount(src, minlength=n), out=self.start[1:])
        self._reference = points.copy()
        self.n_builds += 1
