"""Verlet neighbour lists built from a cell list (:mod:`selfas_graph.kernels.cells`).

A list holds every pair closer than ``cutoff + skin`` and is rebuilt only when
some point has moved more than ``skin / 2`` since the last build, so between
rebuilds it still contains every pair closer than ``cutoff``. Pairs are stored
in compressed rows with both directions, the layout the kernels in
:mod:`selfas_graph.kernels.yukawa` and :mod:`selfas_graph.kernels.brakes` take. The rows come straight out of the cell
list's two passes; measured at 24 000 rod centres (cut-off plus skin 6.86, 5.0e6
directed pairs) on one core, 118 ms per build against 465 ms for scipy's k-d tree
``query_pairs`` followed by a sort into rows (523 against 2738 ms at 10^5 rods).

A list with ``cell_order`` set (the Yukawa term sets it on the rod-centre list) also keeps its
rows numbered by cell (:attr:`NeighbourList.sorted_rows`), written by the same build, for a sum
that reads its inputs from copies in cell order (``kernels/yukawa.py::yukawa_centres_sorted``).
"""

from __future__ import annotations

import numpy as np

from ..kernels.cells import list_dtype, max_displacement2, neighbour_rows


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
    cell_order : bool
        Also make :attr:`sorted_rows` at every build (an attribute: a term may set it on a list
        it is handed).
    rows : (int, int), optional
        List only the rows of the points ``rows[0] <= k < rows[1]`` (the others empty): an MPI
        rank's block, when only its rows are summed (``kernels/cells.py::neighbour_rows``).
    share : RowBlocks, optional
        Under MPI, for a list every rank needs whole: each rank builds the rows of its block
        (``rows_per_rod`` rows per rod) and :meth:`~selfas_graph.parallel.RowBlocks.gather_list`
        joins them, the same list bit for bit as one whole build, in about half its time on 2 ranks.
    """

    def __init__(
        self,
        cutoff: float,
        skin: float,
        exclude_same_rod: bool = False,
        cell_order: bool = False,
        rows=None,
        share=None,
        rows_per_rod: int = 2,
    ):
        if share is not None and not share.serial:
            if rows is not None or cell_order:
                raise ValueError("a shared list is built whole, without rows or cell order")
            lo, hi = share.rods
            rows = (rows_per_rod * lo, rows_per_rod * hi)
        else:
            share = None
        self.share, self.rows_per_rod = share, rows_per_rod
        self.rows = None if rows is None else (int(rows[0]), int(rows[1]))
        self.cutoff = float(cutoff)
        self.skin = float(skin)
        self.exclude_same_rod = exclude_same_rod
        #: the list in compressed rows: int64 offsets, int32 entries (``kernels/cells.py::list_dtype``)
        self.start = np.zeros(1, dtype=np.int64)
        self.index = np.zeros(0, dtype=list_dtype(0))
        self.cell_order = cell_order
        self._pairs = None
        self._sorted = (np.zeros(0, dtype=np.int64), self.start.copy(), self.index.copy())
        self._reference = None
        self.n_builds = 0

    @property
    def reference(self):
        """Positions of the last build (None before the first): with them a list is rebuilt identically."""
        return self._reference

    @property
    def pairs(self) -> np.ndarray:
        """Each listed pair once, ``(m, 2)`` int64 with ``k < l``, sorted by (k, l); made on first use."""
        if self._pairs is None:
            n = self.start.shape[0] - 1
            k = np.repeat(np.arange(n, dtype=np.int64), np.diff(self.start))
            once = self.index > k
            k, l = k[once], self.index[once].astype(np.int64)
            order = np.lexsort((l, k))
            self._pairs = np.ascontiguousarray(np.stack([k[order], l[order]], axis=1))
        return self._pairs

    @property
    def sorted_rows(self):
        """``(order, start, index)``: the points in cell order and the rows renumbered by it
        (``neighbour_rows(..., cell_order=True)``). Made by every build once :attr:`cell_order` is
        set, else by building the same list again on first use.

        Row t is the row of point ``order[t]`` in the same order, its neighbours given by their
        places in ``order``: a kernel that reads copies of its inputs in that order
        (``centre[order]``) reads each row's neighbours from a few contiguous stretches of memory.
        """
        if self._sorted is None:  # built without cell_order: the same build again, with them
            _, _, self._sorted = neighbour_rows(
                self._reference,
                self.cutoff + self.skin,
                self.exclude_same_rod,
                cell_order=True,
                rows=None if self.share is not None else self.rows,
            )
        return self._sorted

    def covers(self, points: np.ndarray) -> bool:
        """Whether the list, as it is, holds every pair of ``points`` (n, 3) within the cutoff: no point
        has moved half the skin since the build."""
        ref = self._reference
        # [perf] one kernel pass, the same value as three numpy passes
        return ref is not None and ref.shape == points.shape and max_displacement2(points, ref) < (0.5 * self.skin) ** 2

    def update(self, points: np.ndarray) -> bool:
        """Rebuild if needed for ``points`` (n, 3); returns True if rebuilt."""
        if self.covers(points):
            return False
        self.build(points)
        return True

    def for_reading(self, points: np.ndarray) -> "NeighbourList":
        """A list for ``points`` that leaves this one as it is: this one if it covers them, else one built
        for them alone (the same list a rebuild here would make). For a reading that must not move the
        point where the forces' list is rebuilt, and so the trajectory."""
        if self.covers(points):
            return self
        other = NeighbourList(
            self.cutoff,
            self.skin,
            self.exclude_same_rod,
            rows=None if self.share is not None else self.rows,
            share=self.share,
            rows_per_rod=self.rows_per_rod,
        )
        other.build(points)
        return other

    def build(self, points: np.ndarray) -> None:
        """Rebuild from ``points`` (n, 3) float64."""
        points = np.ascontiguousarray(points, dtype=np.float64)
        n = points.shape[0]
        # a NaN, inf or astronomically far point means the state is already broken: list nothing
        # rather than bin it (its cell is undefined); the run's health check stops the run after
        # this step with a diagnosis
        if n > 1 and np.isfinite(points).all() and np.abs(points).max() < 1e150:
            self.start, self.index, *cell_rows = neighbour_rows(
                points, self.cutoff + self.skin, self.exclude_same_rod, cell_order=self.cell_order, rows=self.rows
            )
            self._sorted = cell_rows[0] if cell_rows else None
            if self.share is not None:
                self.start, self.index = self.share.gather_list(self.start, self.index, self.rows_per_rod)
        else:
            self.start = np.zeros(n + 1, dtype=np.int64)
            self.index = np.zeros(0, dtype=list_dtype(n))
            self._sorted = (np.arange(n, dtype=np.int64), self.start.copy(), self.index.copy())
        self._pairs = None
        self._reference = points.copy()
        self.n_builds += 1

    def state_dict(self) -> dict:
        """The positions of the last build and the build count ({} before the first build): a list
        rebuilt from them is the same list."""
        if self._reference is None:
            return {}
        return {"reference": self._reference.copy(), "builds": self.n_builds}

    def load_state_dict(self, d: dict) -> None:
        """Rebuild from :meth:`state_dict` (nothing for an empty one)."""
        if "reference" in d:
            self.build(np.array(d["reference"]))
            self.n_builds = int(d["builds"])
