"""The two terms that read the rod currents (docs/model.md 'Term 9', 'Term 10').

The currents of the last circuit solve are kept by the network
(:class:`~selfas_graph.model.network.RodCurrents`); these terms read them in the evaluation's
context (``ctx.currents``, :class:`~selfas_graph.model.terms.context.EvalContext`). The field of the rod currents acts on the magnetic tips (term 9,
:class:`CurrentFieldForce`); the Lorentz force on the currents (term 10,
:class:`CurrentLorentzForce`) feels the rod currents' field and that of every other field
source that is on (:class:`~selfas_graph.model.terms.base.FieldSource`), which it asks for
their field at its quadrature points.
"""

from __future__ import annotations

import numpy as np

from ...kernels import cells
from ...kernels import currents as kc
from ...kernels import currenttree as kt
from ...kernels import lorentz as kl
from .base import Term

#: the kernels of each precision (forces.current_field.precision, forces.current_lorentz.precision)
_FIELD_KERNEL = {"float64": kc.rod_current_field, "mixed": kc.rod_current_field_mixed}
_TIP_KERNEL = {"float64": kc.current_force_on_tips, "mixed": kc.current_force_on_tips_mixed}


#: rods carrying current from which the tree of the currents sums their field faster than the direct
#: sums: 0.90-0.99 times the direct sum's speed with 1009 rods (Fig. 2), 2.5 times with 3150 (Fig. 6),
#: docs/performance.md 'A tree of the rod currents'
TREE_PAYS_FROM = 2000


def tree_note(p, carrying: int) -> str | None:
    """A note for the end of a run of the parameters ``p`` in which ``carrying`` rods carry current:
    where a current term on the direct sums would run faster by the tree (``method = "tree"``,
    :data:`TREE_PAYS_FROM`), which settings to change; else None."""
    direct = [
        name
        for name in ("current_field", "current_lorentz")
        if getattr(p.forces, name, None) is not None and getattr(p.forces, name).method == "direct"
    ]
    if carrying < TREE_PAYS_FROM or not direct:
        return None
    sets = " ".join(f"--set forces.{name}.method=tree" for name in direct)
    return (
        f"{carrying} rods carry current: from about {TREE_PAYS_FROM} on, the tree of the rod currents sums "
        f"their field faster than the direct sums ({sets}; docs/performance.md 'A tree of the rod currents')"
    )


def two_trees_note(p) -> str | None:
    """A note for parameters ``p`` whose two current terms both take the tree but with other leaves or order:
    each evaluation then builds two trees of the rod currents where one would serve both; else None."""
    terms = [getattr(p.forces, name, None) for name in ("current_field", "current_lorentz")]
    if any(t is None or t.method != "tree" for t in terms):
        return None
    (a, b) = terms
    if (a.leaf_size, a.order) == (b.leaf_size, b.order):
        return None
    return (
        f"forces.current_field and forces.current_lorentz take trees of other leaves or order (leaf_size "
        f"{a.leaf_size} and {b.leaf_size}, order {a.order} and {b.order}): each evaluation builds both trees, "
        f"where one serves both terms when the two settings agree"
    )


def wire_radius(p) -> float:
    """The wire radius w = D/2 that regularises the field of the rod currents, D = ``rods.diameter``
    of the parameters ``p`` (docs/model.md 'Term 9', choice A5)."""
    return 0.5 * p.rods.diameter


def tree_field(blocks, tree, points, exclude_rod, opening_angle, wire_radius, out, mixed, group_size=kt.GROUP_SIZE):
    """Overwrite ``out`` (m, 3), C-contiguous, with the field of the rod currents by ``tree`` at every
    one of ``points`` (m, 3) on every rank, each point leaving out the rod ``exclude_rod[p]``
    (:func:`~selfas_graph.kernels.currenttree.current_tree_field`).

    The ranks of ``blocks`` (:class:`~selfas_graph.parallel.RowBlocks`) share the walks: the points are sorted into groups as one rank sorts
    them, each rank walks one run of groups (:func:`~selfas_graph.kernels.currenttree.target_runs`)
    and the runs are gathered (:meth:`~selfas_graph.parallel.RowBlocks.gather_runs`). The field at a
    point is that of its group's walk, so a run is the same bit for bit on any number of ranks. A
    rank that walked the groups of its own rows alone would group them otherwise than one rank does,
    and sum them otherwise."""
    if points.shape[0] == 0:
        return
    targets = kt.sort_targets(points, exclude_rod, group_size)
    bounds, rows = kt.target_runs(targets, blocks.size)
    r = blocks.rank
    kt.evaluate_current_tree(tree, targets, opening_angle, wire_radius, out, mixed, groups=bounds[r : r + 2])
    blocks.gather_runs(out, targets.index, rows)


class _CurrentTreeTerm(Term):
    """What terms 9 and 10 share when they sum the rod currents by the tree: its settings, taken from the
    term's parameters ``tp`` (``forces.current_field`` or ``forces.current_lorentz``), the context's tree of
    those settings (one tree serves both terms where leaf_size and order agree), and the walk."""

    def _take_tree_settings(self, tp):
        self.use_tree = tp.method == "tree"
        self.opening_angle = tp.opening_angle
        self.leaf_size, self.order, self.group_size = tp.leaf_size, tp.order, tp.group_size

    def _tree(self, ctx):
        """The context's tree of this term's settings, or None (the direct sum)."""
        return ctx.current_tree(self.leaf_size, self.order) if self.use_tree else None

    def _tree_field(self, ctx, tree, points, exclude_rod, out):
        """:func:`tree_field` of ``tree`` at ``points`` with this term's settings and precision."""
        mixed = self.precision == "mixed"
        tree_field(
            ctx.blocks, tree, points, exclude_rod, self.opening_angle, self.wire_radius, out, mixed, self.group_size
        )


class CurrentFieldForce(_CurrentTreeTerm):
    """Term 9: q_k times the field of all other rods' currents (``ctx.currents``, wire radius D/2).
    No kernel call while no rod carries current. ``forces.current_field.precision`` picks the
    float64 or the mixed-precision kernel, ``forces.current_field.method`` the direct sum or the tree
    of the currents (``ctx.current_tree()``, docs/model.md 'The rod currents by a tree')."""

    name = "current_field"
    channels = [("current_field", False)]
    keys = {"current_field": ("circuit.delta_J0", "rods.resistance", "rods.magnetic_charge")}
    slow = True
    uses_currents = True
    counts_own_calls = True

    def __init__(self, p, state):
        self.precision = p.forces.current_field.precision
        self.kernel = _TIP_KERNEL[self.precision]
        self.wire_radius = wire_radius(p)
        self._take_tree_settings(p.forces.current_field)
        self._gathered = False

    def compute(self, ctx, out):
        f = out["current_field"]
        f.fill(0.0)
        rc = ctx.currents
        if len(rc.active_rod):
            lo, hi = ctx.blocks.tips
            tree = self._tree(ctx)
            self._gathered = tree is not None
            if tree is None:
                self.kernel(ctx.position, ctx.tip_charge, rc.active_rod, rc.current, self.wire_radius, lo, hi, f)
            else:
                own_rod = np.arange(ctx.n_tips, dtype=np.int64) // 2
                self._tree_field(ctx, tree, ctx.position, own_rod, f)
                f *= ctx.tip_charge[:, None]
            ctx.calls[self.name] += 1

    def blocked(self, ctx):
        # the tree gathers its own rows (its ranks split groups of tips, not blocks of rods)
        return ("current_field",) if len(ctx.currents.active_rod) and not self._gathered else ()


class CurrentLorentzForce(_CurrentTreeTerm):
    """Term 10: J_i s_i x B_tot on current-carrying rods, by Gauss-Legendre quadrature along each rod.

    B_tot = the currents of all other rods (``ctx.currents``, :meth:`current_field`) + every field source that is
    on (:attr:`field_sources`, in term order: the uniform field, the plasma filament, the external
    filament and the dipole's monopoles). Only current-carrying rods are visited, and of them
    only those in the field's block of rods (the field at their points still sums over every
    current). ``forces.current_lorentz.precision`` sets the arithmetic of the rod currents' field
    at the quadrature points (float64, or mixed); the other sources stay float64.
    """

    name = "current_lorentz"
    channels = [("current_lorentz", False)]
    # the currents, and the fields they sit in (those of the scene's terms that are on)
    keys = {
        "current_lorentz": (
            "circuit.delta_J0",
            "rods.resistance",
            "forces.uniform_field.B",
            "forces.plasma_filament.current",
            "forces.external_filament.current",
            "forces.external_dipole.magnetic_charge",
        )
    }
    slow = True
    uses_currents = True
    counts_own_calls = True

    def __init__(self, p, state):
        self.t, self.wt = kl.gauss_legendre_01(p.forces.current_lorentz.quadrature_points)
        self.precision = p.forces.current_lorentz.precision
        #: pairs of current-carrying rods with centres closer than this take the adapted rule
        self.near_range = p.forces.current_lorentz.near_range
        self.panel_t, self.panel_w = kl.gauss_legendre_01(kl.NEAR_PANEL_POINTS)
        self.wire_radius = wire_radius(p)
        self._take_tree_settings(p.forces.current_lorentz)
        #: the terms that are sources of a magnetic field (FieldSource), in term order: handed in by the
        #: force field that holds this term, once every term is built
        self.field_sources = ()

    def compute(self, ctx, out):
        f = out["current_lorentz"]
        f.fill(0.0)
        active = ctx.currents.active_rod
        if not len(active):
            return
        ctx.calls[self.name] += 1
        # active_rod is sorted (network.RodCurrents.set), so the rods of this block are one slice of it
        r_lo, r_hi = np.searchsorted(active, ctx.blocks.rods)
        mine = active[r_lo:r_hi]
        ng = len(self.t)
        if self.use_tree and not ctx.blocks.serial:
            # under MPI the tree is asked for every rod's points, the ranks sharing the walks
            # (tree_field): a rank whose block holds no rod carrying current takes its share too
            every = ctx.buffer("gl_points_all", len(active) * ng)
            kl.quadrature_points(ctx.position, active, self.t, every)
            every_field = ctx.buffer("gl_field_all", len(active) * ng)
            self.current_field(ctx, every, every_field, exclude_rod=np.repeat(active, ng))
            if not len(mine):
                return
            pts = every[r_lo * ng : r_hi * ng]
            field = every_field[r_lo * ng : r_hi * ng]
        else:
            if not len(mine):
                return
            pts = ctx.buffer("gl_points", len(mine) * ng)
            kl.quadrature_points(ctx.position, mine, self.t, pts)
            field = ctx.buffer("gl_field", len(mine) * ng)
            self.current_field(ctx, pts, field, exclude_rod=np.repeat(mine, ng))
        extra = ctx.buffer("gl_extra", len(pts))
        for source in self.field_sources:
            source.field_at(pts, extra)
            field += extra
        kl.lorentz_force_on_rods(ctx.position, mine, ctx.currents.current, field, self.t, self.wt, f)
        if self.near_range > 0.0:
            self._near_pairs(ctx, active, mine, f)

    def _near_pairs(self, ctx, active, mine, f):
        """The adapted rule for the pairs closer than ``near_range`` (kernels/lorentz.py
        ``lorentz_near_correction``): the plain rule's share of each such pair is replaced."""
        pos = ctx.position
        centre = 0.5 * (pos[2 * active] + pos[2 * active + 1])
        if not np.isfinite(centre).all():
            return  # no cell grid places NaN; the run's health check stops with a diagnosis
        start, index = cells.neighbour_rows(centre, self.near_range)
        r_lo = int(np.searchsorted(active, mine[0]))
        kl.lorentz_near_correction(
            pos,
            active,
            ctx.currents.current,
            start,
            index,
            r_lo,
            r_lo + len(mine),
            self.t,
            self.wt,
            self.panel_t,
            self.panel_w,
            self.wire_radius,
            f,
        )

    def current_field(self, ctx, points, out, exclude_rod):
        """Overwrite ``out`` (m, 3) with the field of the rod currents at ``points`` (m, 3), leaving out
        at each point the rod ``exclude_rod[p]`` ((m,) int64; -1: none), e.g. the rod the point is on;
        in the term's precision (``"mixed"``: float32 law, float64 sums;
        :func:`~selfas_graph.kernels.currents.rod_current_field_mixed`) and by its method (the tree:
        :func:`~selfas_graph.kernels.currenttree.current_tree_field`)."""
        rc = ctx.currents
        tree = self._tree(ctx)
        if tree is not None:
            self._tree_field(ctx, tree, points, exclude_rod, out)
            return
        _FIELD_KERNEL[self.precision](
            points, exclude_rod, ctx.position, rc.active_rod, rc.current, self.wire_radius, out
        )

    def blocked(self, ctx):
        return ("current_lorentz",) if len(ctx.currents.active_rod) else ()
