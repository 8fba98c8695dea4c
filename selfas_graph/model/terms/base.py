"""What a force term is: the :class:`Term` interface, the :class:`FieldSource` interface of the
terms that are sources of a magnetic field, and the helpers the terms share.

A term is built from the scene's :class:`~selfas_graph.model.params.Parameters` and the
:class:`~selfas_graph.model.state.State`; it keeps only constants. Everything that changes
during a run (positions, velocities, currents, neighbour lists, buffers) comes in the
evaluation's :class:`~selfas_graph.model.terms.context.EvalContext`, passed as ``ctx`` by the
:class:`~selfas_graph.model.terms.forcefield.ForceField` that calls the term.
"""

from __future__ import annotations

import numpy as np

from ...kernels.rigid import share_by_mass  # noqa: F401 (the terms' helper, kept importable here)
from ...kernels.tree import cell_bounds


class Term:
    """One force term of docs/model.md 'Force terms'.

    Class attributes
    ----------------
    name : str
        The term's field of :class:`~selfas_graph.model.params.ForceParams` (its scenario table).
    channels : list of (str, bool)
        The force buffers the term writes, and whether each is conservative (has an energy).
    slow : bool
        With multiple time stepping (``integrator.slow_every > 1``) the term is evaluated only on
        full evaluations and its force held (or extrapolated) in between: the smooth, costly
        long-range sums. Other terms are evaluated every step.
    uses_currents : bool
        The term reads the rod currents: new currents make its held force stale.
    counts_own_calls : bool
        The term counts its kernel calls in ``ctx.calls`` itself (only when it calls a kernel);
        for the others the field counts every ``compute``.
    keys : dict of str to tuple of str
        For each channel, the scenario keys its force depends on, which a failure's diagnosis
        names when that channel is out of scale (``tests/unit/test_terms.py`` checks every one
        names a parameter).
    """

    name = ""
    channels: list = []
    slow = False
    uses_currents = False
    counts_own_calls = False
    keys: dict = {}

    def compute(self, ctx, out):  # pragma: no cover - interface
        """Write the term's force on every tip into ``out[channel]`` (n_tips, 3) for each of its
        channels, at the positions and velocities of ``ctx``, an
        :class:`~selfas_graph.model.terms.context.EvalContext`."""
        raise NotImplementedError

    def energy(self, ctx):
        """{channel: potential energy} of the conservative channels at ``ctx.position`` (None: none)."""
        return None

    def blocked(self, ctx):
        """Channels whose last ``compute`` filled only the rows of ``ctx.blocks`` (default: none)."""
        return ()

    def split(self, ctx, dt):
        """Apply this term's stiff brake exactly over ``dt`` (``integrator.brake = "split"``).

        Modifies ``ctx.velocity`` in place and returns {channel: work done}; the work is the
        change of kinetic energy of the tips it touched, exactly.
        """
        return {}


class FieldSource:
    """A term whose source also makes a magnetic field that other terms feel.

    The Lorentz force on rod currents (docs/model.md 'Term 10') sums, at its quadrature points,
    the field of the rod currents and of every field source that is on, in the order the terms
    are summed (1-8, 11, 9, 10; docs/model.md 'Force terms').
    """

    def field_at(self, points, out):  # pragma: no cover - interface
        """Overwrite ``out`` (m, 3) with the source's magnetic field at ``points`` (m, 3) (units B0)."""
        raise NotImplementedError


def fill_cells_shared(blocks, tree, fill, arrays):
    """Fill the cells of a planned tree (the tip tree's or the rod currents') on every rank of
    ``blocks`` (:class:`~selfas_graph.parallel.RowBlocks`): each rank calls ``fill(tree, c0, c1)`` on
    one run of cells of about equal work (:func:`~selfas_graph.kernels.tree.cell_bounds`, from
    ``tree.start`` and ``tree.end``) and the runs of each of ``arrays`` (per-cell rows) are gathered.
    A cell is filled from its own points alone, so the tree is the same bit for bit on any number
    of ranks."""
    bounds = cell_bounds(tree, blocks.size)
    r = blocks.rank
    fill(tree, bounds[r], bounds[r + 1])
    cells = np.arange(tree.start.shape[0])
    for a in arrays:
        blocks.gather_runs(a, cells, bounds)


def kinetic(velocity, tips):
    """Kinetic energy of the given tips (unit masses): the exact work of a split brake is its change."""
    return kinetic_of(velocity[tips])


def kinetic_of(velocity):
    """Kinetic energy of the tips whose velocities are the rows of ``velocity`` (unit masses)."""
    return 0.5 * float(np.einsum("ij,ij->", velocity, velocity))
