"""The force field: the container of the terms that are on (docs/model.md 'Force terms').

A :class:`ForceField` is built from the scenario's ``[forces]`` tables; only
the listed terms are constructed, so a term the scene does not use costs
nothing (no buffer, no kernel call, no neighbour list). Each term writes its
force into its own *channel* buffer; the field sums the channels and, for the
non-conservative channels, the power ``sum_k F_k . v_k`` that the integrator
turns into work. Conservative channels report a potential energy instead.

The expensive terms (tip-tip sum, Yukawa, the two current terms) compute only the
rows of the field's :class:`~selfas_graph.parallel.RowBlocks` block of rods and say
so through :meth:`Term.blocked <selfas_graph.model.terms.base.Term.blocked>`;
:meth:`ForceField.evaluate` then fills in the other ranks' rows (the gather over
ranks), so every channel is complete on every rank. With one rank the block is every
rod and nothing is communicated. Their energies are computed as one value per row,
gathered the same way and summed over all rows on every rank: the same float whatever
the number of ranks.

The terms receive what they use in an evaluation as one
:class:`~selfas_graph.model.terms.context.EvalContext` (``context``), built once with the field
and bound to each evaluation's positions and velocities. It carries the rod currents of their
owner, the network's :class:`~selfas_graph.model.network.RodCurrents` (``currents``), of which the
field keeps no copy. The field holds what else changes during a run besides the state: the
neighbour lists (:class:`~selfas_graph.model.terms.context.PairLists`), and with multiple time
stepping the held slow forces (:class:`~selfas_graph.model.terms.mts.MultipleTimeStepping`);
:meth:`ForceField.state_dict` and :meth:`ForceField.load_state_dict` save and restore them for
exact restarts. Wall time per term, when asked for, is measured by a
:class:`~selfas_graph.model.terms.timing.TermClock` around each call.
"""

from __future__ import annotations

import numpy as np

from ...kernels.integrate import channel_sum, channel_sum_power
from ...parallel import RowBlocks
from ..neighbours import NeighbourList
from ..network import RodCurrents
from ..params import Parameters
from .base import FieldSource, Term
from .context import EvalContext, PairLists
from .currents import CurrentLorentzForce, wire_radius
from .mts import MultipleTimeStepping
from .pairs import TipMagneticForce, YukawaForce
from .registry import term_classes
from .timing import TermClock


class ForceField:
    """The force terms of one scene, with their buffers and neighbour lists.

    Parameters
    ----------
    params : Parameters
    state : State
        Supplies the per-tip and per-rod constants (charges) and the sizes.
    timing : bool
        Accumulate wall time per term in ``self.seconds`` (for benchmarks; :class:`TermClock`).
    blocks : RowBlocks, optional
        The rods whose rows this process computes in the expensive terms (default: all of
        them, a serial run).
    currents : RodCurrents, optional
        The rod currents the current terms read: the network's (``Network.currents``) in a run
        with contacts; default: zero currents of the field's own (a scene without a network,
        or a field driven by :meth:`set_currents` in tests and tools).

    Attributes
    ----------
    terms : list of the active term objects, in the order they are summed (1-8, 11, 9, 10; docs/model.md 'Force terms')
    channels : list of (name, conservative)
    field_sources : the terms that are also sources of a magnetic field (FieldSource), in term order
    context : EvalContext, what the terms read and write in an evaluation (bound to its arrays)
    currents : RodCurrents, the rod currents of the last circuit solve (not a copy: their owner's)
    wire_radius : float, w = D/2 of the rod currents' field
    mts : MultipleTimeStepping or None (``integrator.slow_every = 1``)
    calls : Counter of kernel evaluations per term (tests count these; ``context.calls``)
    clock : TermClock, the wall time per term when ``timing`` (``seconds``)
    """

    def __init__(
        self,
        params: Parameters,
        state,
        timing: bool = False,
        blocks: RowBlocks | None = None,
        currents: RodCurrents | None = None,
    ):
        self.params = params
        self.blocks = RowBlocks(state.n_rods) if blocks is None else blocks
        if self.blocks.n_rods != state.n_rods:
            raise ValueError(f"the row blocks cover {self.blocks.n_rods} rods, the state has {state.n_rods}")
        self.tip_charge = state.tip_charge
        self.rod_charge = state.rod_charge
        self.n_tips = state.n_tips
        self.n_rods = state.n_rods
        self.terms = [cls(params, state) for name in params.forces.active() for cls in term_classes(name)]
        self.channels = [c for t in self.terms for c in t.channels]
        self.field_sources = [t for t in self.terms if isinstance(t, FieldSource)]
        for t in self.terms:
            if isinstance(t, CurrentLorentzForce):
                # its field sources, every term that makes a magnetic field, in the order of the terms
                t.field_sources = tuple(self.field_sources)
        self.nonconservative = [name for name, cons in self.channels if not cons]
        self.conservative = [name for name, cons in self.channels if cons]
        #: the channel buffers as the rows of one array, summed in one pass (kernels.integrate.channel_sum);
        #: this and the two below are read by the compiled steps (model/compiled.py)
        self.channel_block = np.zeros((len(self.channels), self.n_tips, 3))
        self.out = {name: self.channel_block[j] for j, (name, _) in enumerate(self.channels)}
        self._split_terms = [t for t in self.terms if type(t).split is not Term.split]
        #: a non-conservative channel's slot in the work and power arrays
        self.work_index = {name: j for j, name in enumerate(self.nonconservative)}
        #: the rows of the non-conservative channels in the channel block, whose powers evaluate returns
        self.powered = np.array(
            [j for j, (_, conservative) in enumerate(self.channels) if not conservative], dtype=np.int64
        )
        self.total = np.zeros((self.n_tips, 3))
        yukawa = next((t for t in self.terms if isinstance(t, YukawaForce) and t.cutoff > 0.0), None)
        self.lists = PairLists(
            params.rods.rstar,
            params.neighbours.skin,
            self.blocks,
            yukawa.cutoff if yukawa is not None else None,
            params.neighbours.centre_skin,
        )
        self.wire_radius = wire_radius(params)
        self.currents = RodCurrents(self.n_rods) if currents is None else currents
        if self.currents.n_rods != self.n_rods:
            raise ValueError(f"the currents cover {self.currents.n_rods} rods, the state has {self.n_rods}")
        self.context = EvalContext(self.tip_charge, self.rod_charge, self.blocks, self.currents, self.lists)
        self.calls = self.context.calls
        # each term's compute, the gather and the tip term's fast part, timed if asked (else the calls themselves)
        self.clock = TermClock(timing)
        self._compute = [self.clock.wrap(t.name, t.compute) for t in self.terms]
        self._gather = self.clock.wrap("gather", self.blocks.gather_rows)
        # multiple time stepping (integrator.slow_every > 1): the slow terms' channels keep their
        # last evaluation; the tip term's far part is kept apart from its fast close pairs
        self.multiple_time_stepping = params.integrator.slow_every > 1
        self.mts = None
        if self.multiple_time_stepping:
            tip_term = next((t for t in self.terms if isinstance(t, TipMagneticForce)), None)
            self.mts = MultipleTimeStepping(params, self.terms, self.out, tip_term, self.clock)
            if tip_term is not None:
                self.extend_tip_range(self.mts.fast_range[1])

    @property
    def timing(self) -> bool:
        """Whether wall time per term is measured (``seconds``)."""
        return self.clock.on

    @property
    def seconds(self):
        """Wall time per term, a Counter (empty unless ``timing``; the benchmarks read and clear it)."""
        return self.clock.seconds

    @property
    def position(self) -> np.ndarray | None:
        """The positions of the last evaluation (``context.position``)."""
        return self.context.position

    @property
    def velocity(self) -> np.ndarray | None:
        """The velocities of the last evaluation (``context.velocity``)."""
        return self.context.velocity

    @property
    def current(self) -> np.ndarray:
        """Rod currents of the last circuit solve, (n_rods,) float64 (``currents.current``)."""
        return self.currents.current

    @property
    def active_rod(self) -> np.ndarray:
        """The rods that carry current, sorted (``currents.active_rod``)."""
        return self.currents.active_rod

    def currents_changed(self) -> None:
        """The owner of the currents changed them: the held current forces are computed again at
        the next evaluation (multiple time stepping; nothing to do without it).

        A solve that gives the same currents again, bit for bit (an event in a structure that
        carries none), is not reported: the held current forces stay valid, as between any two full
        evaluations (late in the Fig. 2 scene half the solves; docs/performance.md).
        """
        if self.mts is not None:
            self.mts.currents_changed()

    def set_currents(self, current):
        """Write rod currents ``(n_rods,)`` float64 into :attr:`currents`, used from the next evaluation
        on (for a field driven without a network: tests, tools). Rods whose current is exactly zero
        are left out of the current kernels."""
        if self.currents.set(current):
            self.currents_changed()

    def bind(self, position, velocity) -> None:
        """Bind ``position`` and ``velocity`` (n_tips, 3) into :attr:`context` (e.g. before
        :meth:`load_state_dict`, or to call a term by hand); :meth:`evaluate` does it itself."""
        self.context.bind(position, velocity)

    def tip_neighbours(self, position=None) -> NeighbourList:
        """Tip pairs of different rods closer than the tip range (plus skin), up to date for ``position``.

        The range is r*, or the contact release radius once :meth:`extend_tip_range`
        was called, so that the brake and the contact search share one list.
        """
        return self.lists.tips(self.context.position if position is None else position)

    def extend_tip_range(self, radius: float) -> None:
        """Make the tip neighbour list cover ``radius`` (the contact release radius)."""
        self.lists.extend_tip_range(radius)

    def centre_neighbours(self) -> NeighbourList:
        """Rod centres within the Yukawa cut-off (plus skin), up to date for the bound positions."""
        return self.context.centre_neighbours()

    # -- evaluation -------------------------------------------------------------------------------
    def evaluate(self, position, velocity, power=None, full=True, step=None, starting=False):
        """Total force on every tip at (position, velocity).

        Parameters
        ----------
        position, velocity : (n_tips, 3) float64
        power : (len(nonconservative),) float64, optional
            Filled with ``sum_k F_k . v_k`` of each non-conservative channel.
        full : bool
            With multiple time stepping: False evaluates only the fast terms, the fast part
            of the tip-tip force and the slow terms whose inputs changed (new currents), and
            adds the other slow forces as extrapolated (or held) from their last evaluations.
            Ignored (always full) without it.
        step : int, optional
            The step this evaluation starts (None inside the RK4 stages): the clock of the
            extrapolation.
        starting : bool
            The step is one of the integrator's RK4 start: every slow term that a full evaluation
            computes is computed (``integrator.current_every`` skips none).

        Returns
        -------
        (n_tips, 3) float64
            The summed force (a buffer owned by the field; copy it to keep it).
        """
        ctx = self.context
        ctx.bind(position, velocity)
        mts = self.mts
        full = full or mts is None
        serial, out, calls = self.blocks.serial, self.out, self.calls
        blocked = []
        refreshed = []
        for t, compute in zip(self.terms, self._compute):
            if t.slow:
                if not (full or t.name in mts.stale):  # without mts, full is always True
                    continue
                if mts is not None and mts.skips(t.name, step, starting):  # integrator.current_every
                    continue
                refreshed.append(t.name)
            compute(ctx, out)
            if not t.counts_own_calls:
                calls[t.name] += 1
            if not serial:
                blocked.extend(t.blocked(ctx))
        if not serial:
            self._gather([out[name] for name in blocked], rows_per_rod=2)
        if mts is not None:
            mts.complete(ctx, refreshed, full, step)
        total = self.total
        # ((0 + c_0) + c_1) + ..., in channel order; with the power of each non-conservative channel
        # summed as np.einsum("ij,ij->", f, velocity) sums it
        if power is None:
            channel_sum(total, self.channel_block)
        else:
            channel_sum_power(total, self.channel_block, velocity, self.powered, power)
        return total

    def held_forces(self) -> dict:
        """The slow forces held between full evaluations (multiple time stepping), by name; views, not
        copies; {} without multiple time stepping (:meth:`MultipleTimeStepping.held_forces`)."""
        return {} if self.mts is None else self.mts.held_forces()

    # -- the field's own state, for exact restarts -------------------------------------------------
    def state_dict(self) -> dict:
        """What the next evaluations depend on besides the positions, velocities and rod currents (the
        network saves those, ``Network.state_dict``), as a flat dict of copies (the checkpoint's keys):
        the build positions and build counts of the neighbour lists (``tip_nl_*``, ``centre_nl_*``) and,
        with multiple time stepping, the held slow forces (``mts_*``, :meth:`MultipleTimeStepping.state_dict`)."""
        d = {}
        if self.mts is not None:
            d.update(self.mts.state_dict())
        for name, nl in (("tip_nl", self.lists.tip), ("centre_nl", self.lists.centre)):
            if nl is not None:  # tip_nl_reference, tip_nl_builds, ... (NeighbourList.state_dict)
                d.update({f"{name}_{k}": v for k, v in nl.state_dict().items()})
        return d

    def load_state_dict(self, d: dict) -> None:
        """Put back what :meth:`state_dict` returned (``d`` may hold other keys too).

        Keys that are missing (a checkpoint of other settings or an older version) leave that part
        as built: a neighbour list is then built at its next use, and without matching held forces
        every slow term is computed at the next evaluation.
        """
        tip = self.lists.tip_list() if "tip_nl_reference" in d else None
        for name, nl in (("tip_nl", tip), ("centre_nl", self.lists.centre)):
            if nl is not None:
                nl.load_state_dict({k[len(name) + 1 :]: v for k, v in d.items() if k.startswith(f"{name}_")})
        if self.mts is not None:
            self.mts.load_state_dict(d)

    def split_brakes(self, position, velocity, dt, work):
        """``integrator.brake = "split"``: apply every stiff brake exactly over ``dt`` (velocity in place).

        ``work`` (len(nonconservative),) is incremented by each brake's work.
        """
        ctx = self.context
        ctx.bind(position, velocity)
        for t in self._split_terms:
            for channel, w in t.split(ctx, dt).items():
                work[self.work_index[channel]] += w

    def potential_energy(self, position, keep_lists=False) -> dict:
        """Potential energy of each conservative channel at ``position``; ``keep_lists``: without moving
        where the neighbour lists are rebuilt (the same values)."""
        ctx = self.context
        ctx.bind(position, np.zeros_like(position) if ctx.velocity is None else ctx.velocity)
        energy = {}
        ctx.keep_lists = keep_lists
        try:
            for t in self.terms:
                e = t.energy(ctx)
                if e:
                    energy.update(e)
        finally:
            ctx.keep_lists = False
        return energy

    def channel_keys(self, channel) -> str:
        """The scenario keys that channel ``channel``'s force depends on (its term's ``keys``), those of
        tables the scene leaves out dropped, for a failure's diagnosis; ``forces.CHANNEL`` for a channel
        no term names keys for, "the force terms" for none."""
        if not channel:
            return "the force terms"
        for term in self.terms:
            if channel in term.keys:
                present = [k for k in term.keys[channel] if _present(self.params, k)]
                if "rods.electric_charge" in present and self.params.rods.electric_charge.distribution == "magnetic":
                    # the scene draws each rod's electric charge as its magnetic one (docs/model.md 'Rods')
                    i = present.index("rods.electric_charge")
                    present[i] = "rods.magnetic_charge (rods.electric_charge follows it)"
                return ", ".join(present)
        return f"forces.{channel}"

    def dominant_channel(self, rows) -> str:
        """Name of the channel with the largest force on the given tips (for failure diagnoses);
        a non-finite force (NaN or inf) counts as the largest."""
        return self.dominant_force(rows)[0]

    def dominant_force(self, rows) -> tuple[str, float]:
        """(channel, largest force component) of the channel with the largest force on the given
        tips; NaN counts as inf. ("none", 0.0) without channels or where every force on them is zero."""
        best, name = 0.0, "none"
        for ch, _ in self.channels:
            m = float(np.nan_to_num(np.abs(self.out[ch][rows]), nan=np.inf).max(initial=0.0))
            if m > best:
                best, name = m, ch
        return name, best

    def describe(self) -> dict:
        """Resolved settings derived from the parameters (e.g. the Yukawa cut-off radius)."""
        d = {"terms": [t.name for t in self.terms]}
        for t in self.terms:
            if isinstance(t, TipMagneticForce):
                d["tip_magnetic_sum"] = (
                    f"tree (order {t.order}, opening angle {t.theta:g}, leaves of up to {t.leaf_size} tips, "
                    f"groups of up to {t.group_size} tips, "
                    f"{t.precision} near field)"
                    if t.use_tree
                    else "direct"
                )
            if isinstance(t, YukawaForce):
                d["yukawa_cutoff"] = t.cutoff
            if t.name in ("current_field", "current_lorentz"):
                d[f"{t.name}_sum"] = (
                    f"tree (order {t.order}, opening angle {t.opening_angle:g}, leaves of up to {t.leaf_size} rods, "
                    f"groups of {t.group_size} points, {t.precision} near rods)"
                    if t.use_tree
                    else "direct"
                )
        return d


def _present(params, key) -> bool:
    """Whether the dotted ``key`` names a setting of ``params``, not one of a table the scene leaves out
    (a setting may itself be None: a derived default, as ``rods.transition_radius``)."""
    obj = params
    for part in key.split(".")[:-1]:
        obj = getattr(obj, part, None)
        if obj is None:
            return False
    return True
