"""What a force term reads and writes during one evaluation: :class:`EvalContext`, and the
neighbour lists it hands out (:class:`PairLists`).

A term keeps only the constants of its construction (its parameters). Everything else it uses
comes in an :class:`EvalContext`: the positions and velocities of this evaluation, the tip and
rod charges, the rows this process computes (:class:`~selfas_graph.parallel.RowBlocks`), the
rod currents (the network's :class:`~selfas_graph.model.network.RodCurrents`, not a copy), the
neighbour lists, work buffers and the count of kernel calls. The
:class:`~selfas_graph.model.terms.forcefield.ForceField` builds one context and binds each
evaluation's arrays into it (:meth:`EvalContext.bind`): no object is made per step.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from ...kernels import currenttree as kct
from ...kernels.rigid import rod_centres
from ...parallel import RowBlocks
from ..neighbours import NeighbourList
from ..network import RodCurrents
from .base import fill_cells_shared


def shared_current_tree(blocks, position, active_rod, current, leaf_size=kct.LEAF_SIZE, order=kct.ORDER):
    """:func:`~selfas_graph.kernels.currenttree.build_current_tree` on every rank of ``blocks``
    (:class:`~selfas_graph.parallel.RowBlocks`), the ranks sharing the moments of its cells: each
    plans the tree, computes the moments of one run of cells and the runs are gathered
    (:func:`~selfas_graph.model.terms.base.fill_cells_shared`): the same tree bit for bit."""
    if blocks.serial:
        return kct.build_current_tree(position, active_rod, current, leaf_size, order)
    tree = kct.plan_current_tree(position, active_rod, current, leaf_size, order)
    fill_cells_shared(blocks, tree, kct.fill_current_cells, (tree.centre, tree.radius, tree.moment))
    return tree


class PairLists:
    """The two neighbour lists of a force field: tip pairs of different rods, and rod centres.

    Parameters
    ----------
    tip_range : float
        The tip list's range, r* (widened by :meth:`extend_tip_range`).
    skin : float
        ``neighbours.skin``.
    blocks : RowBlocks
        Under MPI each rank builds its rows of the tip list and the rows are gathered.
    centre_range : float or None
        The centre list's range (the Yukawa cut-off); None: no centre list.
    centre_skin : float or None
        ``neighbours.centre_skin``, the centre list's skin; None: ``skin``.
    """

    def __init__(
        self,
        tip_range: float,
        skin: float,
        blocks: RowBlocks,
        centre_range: float | None = None,
        centre_skin: float | None = None,
    ):
        self.tip_range = float(tip_range)
        self.skin = skin
        self.blocks = blocks
        self.tip: NeighbourList | None = None
        self.centre: NeighbourList | None = None
        if centre_range is not None:
            # under MPI a rank sums the Yukawa rows of its block only: it lists only those rows
            # (half the build and the memory on 2 ranks; each row the same bit for bit)
            rows = None if blocks.serial else blocks.rods
            self.centre = NeighbourList(centre_range, skin if centre_skin is None else centre_skin, rows=rows)

    def tips(self, position) -> NeighbourList:
        """The tip list, up to date for ``position`` (n_tips, 3); built at its first use."""
        self.tip_list().update(position)
        return self.tip

    def tip_list(self) -> NeighbourList:
        """The tip list as it is, made (not built) if there is none yet."""
        if self.tip is None:
            # every rank needs the whole tip list (contacts, brakes, close pairs); under MPI each builds
            # the rows of its block and the rows are gathered (parallel.py RowBlocks.gather_list)
            self.tip = NeighbourList(self.tip_range, self.skin, exclude_same_rod=True, share=self.blocks)
        return self.tip

    def centres(self, centre) -> NeighbourList:
        """The centre list, up to date for ``centre`` (n_rods, 3)."""
        self.centre.update(centre)
        return self.centre

    def extend_tip_range(self, radius: float) -> None:
        """Make the tip list cover ``radius``; a wider range drops the list, rebuilt at its next use."""
        if radius > self.tip_range:
            self.tip_range = float(radius)
            self.tip = None


@dataclass(eq=False)
class EvalContext:
    """What the terms use during one evaluation of the force field.

    Not frozen: the force field keeps one context and rebinds its positions and velocities at each
    evaluation (:meth:`bind`), so that a step makes no new object; the other fields are fixed
    objects, whose contents their owners change (the currents, the lists, the buffers).

    Attributes
    ----------
    position, velocity : (n_tips, 3) float64
        The arrays of this evaluation (bound by :meth:`bind`; a split brake changes ``velocity`` in place).
    tip_charge : (n_tips,) float64
    rod_charge : (n_rods,) float64
    blocks : RowBlocks
        The rods whose rows this process computes in the expensive terms.
    currents : RodCurrents
        The rod currents of the last circuit solve (``currents.current``, ``currents.active_rod``).
    lists : PairLists
        The neighbour lists (:meth:`tip_neighbours`, :meth:`centre_neighbours`).
    calls : Counter
        Kernel evaluations per term; the terms that count their own calls add to it.
    """

    tip_charge: np.ndarray
    rod_charge: np.ndarray
    blocks: RowBlocks
    currents: RodCurrents
    lists: PairLists
    calls: Counter = field(default_factory=Counter)
    #: an energy taken off the frame grid: it reads the lists without moving their rebuilds (ForceField.potential_energy)
    keep_lists: bool = False
    position: np.ndarray | None = None
    velocity: np.ndarray | None = None
    _soa: tuple | None = None
    _centre: np.ndarray | None = None
    _buffers: dict = field(default_factory=dict)
    #: the trees of the rod currents of this binding: (currents, leaf size, order, tree) entries, a tuple
    #: replaced (never changed in place), so that a copy of this context keeps its own
    _current_trees: tuple = ()

    @property
    def n_tips(self) -> int:
        return self.tip_charge.shape[0]

    @property
    def n_rods(self) -> int:
        return self.rod_charge.shape[0]

    def bind(self, position, velocity) -> None:
        """Make ``position`` and ``velocity`` the arrays of the next term calls (not copied)."""
        self.position = position
        self.velocity = velocity
        self._soa = None
        self._centre = None
        self._current_trees = ()

    def soa(self) -> tuple:
        """The positions as three contiguous (n_tips,) arrays x, y, z (computed once per binding)."""
        if self._soa is None:
            self._soa = tuple(np.ascontiguousarray(self.position[:, d]) for d in range(3))
        return self._soa

    def centre(self) -> np.ndarray:
        """Rod centres (n_rods, 3) (computed once per binding)."""
        if self._centre is None:
            self._centre = np.empty((self.position.shape[0] // 2, 3))
            rod_centres(self.position, self._centre)
        return self._centre

    def current_tree(self, leaf_size=kct.LEAF_SIZE, order=kct.ORDER):
        """The multipole tree of the rod currents at :attr:`position` with ``leaf_size`` rods a leaf and
        moments up to ``order`` (:func:`~selfas_graph.kernels.currenttree.build_current_tree`), built
        once per binding, set of currents and settings, and shared by terms 9 and 10 where their
        settings agree (under MPI the ranks share the moments of its cells); None while no rod
        carries current or a position is not finite (the direct sums then carry the NaN to the run's
        health check)."""
        rc = self.currents
        for current, leaf, moments, tree in self._current_trees:
            if current is rc.current and (leaf, moments) == (leaf_size, order):
                return tree
        tree = None
        if len(rc.active_rod) and np.isfinite(self.position).all():
            tree = shared_current_tree(self.blocks, self.position, rc.active_rod, rc.current, leaf_size, order)
        # entries of earlier currents are dropped: a set of currents replaces the one before
        kept = tuple(e for e in self._current_trees if e[0] is rc.current)
        self._current_trees = kept + ((rc.current, leaf_size, order, tree),)
        return tree

    def buffer(self, name: str, rows: int) -> np.ndarray:
        """A work buffer (rows, 3) float64 kept under ``name`` between evaluations; contents undefined."""
        buf = self._buffers.get(name)
        if buf is None or buf.shape[0] != rows:
            buf = self._buffers[name] = np.zeros((rows, 3))
        return buf

    def tip_neighbours(self):
        """Tip pairs of different rods within the tip range (plus skin), up to date for :attr:`position`."""
        return self.lists.tips(self.position)

    def centre_neighbours(self):
        """Rod centres within the centre range (plus skin), up to date for :attr:`position`; with
        :attr:`keep_lists` set, without rebuilding the list the forces read (:meth:`NeighbourList.for_reading`)."""
        if self.keep_lists:
            return self.lists.centre.for_reading(self.centre())
        return self.lists.centres(self.centre())
