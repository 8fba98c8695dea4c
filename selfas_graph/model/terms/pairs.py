"""Pair terms: forces between rods (docs/model.md 'Term 1', 'Term 2', 'Term 6').

The tip-tip magnetic force and the Yukawa repulsion are the expensive sums: they compute
only the rows of the field's block of rods (:meth:`Term.blocked`) and are slow terms under
multiple time stepping. The tip brake shares the tip neighbour list with the contact search.
"""

from __future__ import annotations

import math

import numpy as np

from ...kernels import brakes, yukawa
from ...kernels import tips as kt
from ...kernels import tree as ktree
from ...kernels.cells import take_rows
from .base import Term, fill_cells_shared, share_by_mass


def yukawa_cutoff(z_max: float, screening: float, tolerance: float) -> float:
    """Distance beyond which ``z_max^2 exp(-r/R_D) (1/r^2 + 1/(R_D r)) < tolerance``.

    The force magnitude decreases monotonically in r, so bisection on
    ``[1e-6, 1e6]`` finds the crossing to 1e-12 relative. Returns 0 if no charge.
    """
    if z_max <= 0.0:
        return 0.0

    def f(r):
        return z_max * z_max * math.exp(-r / screening) * (1.0 / r**2 + 1.0 / (screening * r)) - tolerance

    lo, hi = 1e-6, 1e6
    if f(lo) < 0.0:
        return lo
    for _ in range(200):
        mid = math.sqrt(lo * hi)
        if f(mid) > 0.0:
            lo = mid
        else:
            hi = mid
        if hi - lo < 1e-12 * hi:
            break
    return hi


class TipMagneticForce(Term):
    """Term 1. Slow as a whole; with multiple time stepping the force field adds back the fast
    part of the close pairs at every evaluation (:meth:`fast`)."""

    name = "tip_magnetic"
    channels = [("tip_magnetic", True)]
    keys = {"tip_magnetic": ("rods.magnetic_charge", "rods.tip_stiffness", "rods.transition_radius")}
    slow = True

    def __init__(self, p, state):
        self.rstar = p.rods.rstar
        self.kappa = p.rods.tip_stiffness
        tm = p.forces.tip_magnetic
        self.use_tree = tm.method == "tree" or (tm.method == "auto" and state.n_rods >= tm.tree_above)
        self.theta = tm.opening_angle
        self.order = tm.order
        self.group_size = tm.group_size
        self.leaf_size = tm.leaf_size
        self.precision = tm.precision
        #: the energy of a frame by the tree (docs/model.md 'Term 1'), else by the direct sum
        self.tree_energy = state.n_rods >= tm.energy_tree_above
        self._gathered = False

    def compute(self, ctx, out):
        x, y, z = ctx.soa()
        if self.use_tree:
            try:
                tree = self._build_tree(ctx, x, y, z)
            except ValueError:
                if np.isfinite(ctx.position).all():
                    raise
                # NaN or inf positions: no tree can place them; the direct sum passes them on
                # to the forces, where the run's health check stops with a diagnosis
            else:
                self._walk_shared(ctx, tree, self._evaluate, out["tip_magnetic"])
                self._gathered = True
                return
        self._gathered = False
        lo, hi = ctx.blocks.tips
        direct = kt.tip_tip_direct_mixed if self.precision == "mixed" else kt.tip_tip_direct
        direct(x, y, z, ctx.tip_charge, self.rstar, self.kappa, lo, hi, out["tip_magnetic"])

    def _evaluate(self, tree, groups, f):
        ktree.evaluate_tip_tree(tree, self.rstar, self.kappa, self.theta, f, precision=self.precision, groups=groups)

    def _energies(self, tree, groups, e):
        ktree.tip_tree_energy(tree, self.rstar, self.kappa, self.theta, e, groups=groups)

    @staticmethod
    def _walk_shared(ctx, tree, walk, rows):
        """``walk(tree, groups, rows)`` over this rank's run of the tree's target groups, then the
        rows gathered from every rank. The ranks split the groups, runs of tips in Morton order, so
        that each group is walked on one rank only: the same rows bit for bit on any number of ranks
        (docs/performance.md 'Several MPI ranks')."""
        groups, tips = ktree.group_bounds(tree, ctx.blocks.size)
        r = ctx.blocks.rank
        walk(tree, groups[r : r + 2], rows)
        ctx.blocks.gather_runs(rows, tree.index, tips)

    def _build_tree(self, ctx, x, y, z):
        """The tip tree; under MPI each rank computes the moments of a run of cells and the ranks
        exchange them (the work two threads would share), the same tree bit for bit."""
        if ctx.blocks.serial:
            return ktree.build_tip_tree(x, y, z, ctx.tip_charge, self.leaf_size, self.group_size, self.order)
        tree = ktree.plan_tip_tree(x, y, z, ctx.tip_charge, self.leaf_size, self.group_size, self.order)
        fill_cells_shared(ctx.blocks, tree, ktree.fill_cells, (tree.box, tree.centre, tree.radius, tree.moment))
        return ktree.finish_tip_tree(tree)

    def blocked(self, ctx):
        # the tree gathers its own rows (its ranks split groups, not blocks of rods)
        return () if self._gathered else ("tip_magnetic",)

    def fast(self, ctx, r_in, r_out, out):
        """The fast part of the force, pairs closer than ``r_out`` switched off smoothly from ``r_in`` on."""
        nl = ctx.tip_neighbours()
        kt.tip_tip_fast(ctx.position, ctx.tip_charge, nl.start, nl.index, self.rstar, self.kappa, r_in, r_out, out)

    def energy(self, ctx):
        x, y, z = ctx.soa()
        e = np.empty(ctx.n_tips)
        if self.tree_energy and np.isfinite(ctx.position).all():
            # by the tree (kernels/treeenergy.py): its ranks split the target groups as for the force
            self._walk_shared(ctx, self._build_tree(ctx, x, y, z), self._energies, e)
            return {"tip_magnetic": float(e.sum())}
        lo, hi = ctx.blocks.tips
        kt.tip_tip_energy(x, y, z, ctx.tip_charge, self.rstar, self.kappa, lo, hi, e)
        ctx.blocks.gather_rows([e], rows_per_rod=2)
        return {"tip_magnetic": float(e.sum())}


class TipBrakeForce(Term):
    name = "tip_brake"
    channels = [("tip_brake", False)]
    keys = {"tip_brake": ("forces.tip_brake.coefficient",)}

    def __init__(self, p, state):
        self.rstar = p.rods.rstar
        self.k = p.forces.tip_brake.coefficient
        self.split_mode = p.integrator.brake == "split"

    def compute(self, ctx, out):
        if self.split_mode:
            out["tip_brake"].fill(0.0)
            return
        nl = ctx.tip_neighbours()
        brakes.tip_brake(ctx.position, ctx.velocity, nl.start, nl.index, self.rstar, self.k, out["tip_brake"])

    def split(self, ctx, dt):
        nl = ctx.tip_neighbours()
        work, braked = brakes.brake_close_pairs(ctx.position, ctx.velocity, nl.start, nl.index, self.rstar, self.k, dt)
        return {"tip_brake": work} if braked else {}


class YukawaForce(Term):
    name = "yukawa"
    channels = [("yukawa", True)]
    keys = {"yukawa": ("rods.electric_charge", "forces.yukawa.screening_length", "forces.yukawa.core_radius")}
    slow = True

    def __init__(self, p, state):
        y = p.forces.yukawa
        self.screening = y.screening_length
        self.core = y.core_radius
        self.precision = y.precision
        zmax = float(np.abs(state.rod_charge).max(initial=0.0))
        self.cutoff = yukawa_cutoff(zmax, y.screening_length, y.tolerance)

    def compute(self, ctx, out):
        if self.cutoff == 0.0:  # no rod is charged: the term is zero
            out["yukawa"].fill(0.0)
            return
        nl = ctx.centre_neighbours()
        nl.cell_order = True  # from the next build on, the list comes with its rows numbered by cell
        order, start, index = nl.sorted_rows
        f = ctx.buffer("yukawa_centre", ctx.n_rods)
        lo, hi = ctx.blocks.rods
        # [perf] the sum reads copies in cell order (kernels/yukawa.py yukawa_centres_sorted: the same
        # forces bit for bit as yukawa_centres over the list, 1.3 times faster at 24 000 rods)
        kernel = yukawa.yukawa_centres_sorted_mixed if self.precision == "mixed" else yukawa.yukawa_centres_sorted
        sorted_centre = ctx.buffer("yukawa_sorted_centre", ctx.n_rods)
        take_rows(ctx.centre(), order, sorted_centre)
        kernel(
            sorted_centre,
            ctx.rod_charge[order],
            order,
            start,
            index,
            self.screening,
            self.core,
            self.cutoff,
            lo,
            hi,
            f,
        )
        share_by_mass(f[lo:hi], out["yukawa"][2 * lo : 2 * hi])

    def blocked(self, ctx):
        return ("yukawa",) if self.cutoff > 0.0 else ()

    def energy(self, ctx):
        if self.cutoff == 0.0:
            return {"yukawa": 0.0}
        nl = ctx.centre_neighbours()
        lo, hi = ctx.blocks.rods
        e = np.empty(ctx.n_rods)
        yukawa.yukawa_energy(
            ctx.centre(), ctx.rod_charge, nl.start, nl.index, self.screening, self.core, self.cutoff, lo, hi, e
        )
        ctx.blocks.gather_rows([e], rows_per_rod=1)
        return {"yukawa": float(e.sum())}
