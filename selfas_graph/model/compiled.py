"""Runs of fast steps in one compiled call (docs/performance.md 'Fast steps in one compiled call').

Between two things that need Python (a slow evaluation, a contact that may change, a list build,
a frame, a checkpoint, a progress line) a run under multiple time stepping makes ``slow_every - 1``
fast steps. :class:`CompiledSteps` hands them to ``kernels/steps.py::fast_steps``, which makes them
as :meth:`Simulation.step <.simulation.Simulation.step>` would, bit for bit, and puts back into the
Python objects what the steps changed there: the state's step and time, the integrator's ring
buffer head, work and bond errors, the health checks' largest bond error, the force field's call
counts; the per-step bond errors go to the caller (the run file's per-step rows).

The compiled steps are used in serial runs below ``kernels/_jit.py::PARALLEL_ROWS`` tips, without
per-term timing, under multiple time stepping, when every fast term is one :data:`FAST_TERMS` names;
otherwise (and under MPI) every step runs in Python. With several numba threads and at least
:data:`TEAM_TIPS` tips they run on all threads (``kernels/steps.py::fast_steps_team``), the same numbers. ``sim.compiled = None`` makes every step of a
simulation in Python (the slow reference of the tests, tests/unit/test_compiled_steps.py).
"""

from __future__ import annotations

import numba
import numpy as np

from ..kernels import step_args as sa
from ..kernels._jit import PARALLEL_ROWS
from ..kernels.step_args import FastStepArgs
from ..kernels.steps import (
    CHANNELS,
    DONE,
    NEEDS_CONTACTS,
    NEEDS_HEALTH,
    NEEDS_STEP,
    SPLIT_BRAKES,
    add_work,
    fast_steps,
    fast_steps_team,
)
from .health import BOND_BREAK, MAX_STEP_DISPLACEMENT
from .integrator import AB4_WEIGHTS

__all__ = ["CompiledSteps", "FAST_TERMS", "DONE", "NEEDS_STEP", "NEEDS_CONTACTS", "NEEDS_HEALTH", "python_steps_reason"]

#: the terms evaluated at every step that the compiled steps know (the slow terms are held)
FAST_TERMS = (
    "tip_brake",
    "ambient_brake",
    "uniform_field",
    "plasma_filament",
    "electric_field",
    "electrodes",
    "external_filament",
    "external_dipole",
    "external_line_charge",
)
#: the steps one call makes at most (the size of its logs)
CHUNK = 256
#: tips from which a run on several numba threads makes its compiled steps on all of them
#: (``kernels/steps.py::fast_steps_team``; docs/performance.md 'Fast steps on both cores'), and the
#: blocks of rods per thread
TEAM_TIPS = 1000
TEAM_CHUNKS = 2

_EMPTY = np.zeros(0)
_EMPTY3 = np.zeros((0, 3))


def python_steps_reason(sim) -> str | None:
    """Why every step of ``sim`` runs in Python (``simulate --dry-run`` names it), or None when its fast
    steps run in compiled calls."""
    ff = sim.force_field
    if ff.mts is None:
        return "no multiple time stepping (integrator.slow_every = 1)"
    if not ff.blocks.serial:
        return "MPI ranks (each step gathers the ranks' rows)"
    if ff.clock.on:
        return "per-term timing is on"
    if ff.n_tips >= PARALLEL_ROWS:
        return f"{ff.n_tips} tips, at least {PARALLEL_ROWS}: each term runs on all threads in its own kernel"
    unknown = [t.name for t in ff.terms if not t.slow and t.name not in FAST_TERMS]
    if unknown:
        return f"fast terms the compiled steps do not know: {', '.join(unknown)}"
    return None


def compiled_steps_for(sim) -> "CompiledSteps | None":
    """The compiled steps of ``sim``, or None when its steps must all run in Python
    (:func:`python_steps_reason` says why)."""
    return None if python_steps_reason(sim) else CompiledSteps(sim)


def _scalars(p, terms, mts, network) -> np.ndarray:
    """(N_SCALARS,) float64: the scalars of the fast terms and tests, at the places
    ``kernels/step_args.py`` names (NaN or 0 for a term the scene does not have)."""
    tb = terms.get("tip_brake")
    el = terms.get("electrodes")
    fil = terms.get("external_filament")
    dip = terms.get("external_dipole")
    amb = terms.get("ambient_brake")
    split = p.integrator.brake == "split"
    tip = mts.tip_term
    nan = np.nan
    scalars = {
        sa.SC_AMBIENT_K: amb.k if amb is not None else 0.0,
        sa.SC_RSTAR: p.rods.rstar,
        sa.SC_KAPPA: p.rods.tip_stiffness,
        sa.SC_TIP_BRAKE_K: tb.k if tb is not None and not split else nan,
        sa.SC_TIP_BRAKE_SPLIT: tb.k if tb is not None and split else 0.0,
        sa.SC_CATHODE_Z: el.z[0] if el is not None else nan,
        sa.SC_ANODE_Z: el.z[1] if el is not None else nan,
        sa.SC_WALL_K: (0.0 if el.split_mode else el.k) if el is not None else 0.0,
        sa.SC_WALL_SPLIT: el.k if el is not None and el.split_mode else 0.0,
        sa.SC_FILAMENT_CURRENT: fil.current if fil is not None else 0.0,
        sa.SC_FILAMENT_W: fil.w if fil is not None else 0.0,
        sa.SC_POLE_K: (0.0 if dip.split_mode else dip.k) if dip is not None else 0.0,
        sa.SC_POLE_SPLIT: dip.k if dip is not None and dip.split_mode else 0.0,
        sa.SC_FAST_INNER: mts.fast_range[0] if tip is not None else 0.0,
        sa.SC_FAST_OUTER: mts.fast_range[1] if tip is not None else 0.0,
        sa.SC_HALF_SKIN2: (0.5 * p.neighbours.skin) ** 2,
        sa.SC_RELEASE: network.tracker.release if network is not None else 0.0,
    }
    return np.array([scalars[k] for k in range(sa.N_SCALARS)])


class CompiledSteps:
    """The arguments of ``fast_steps`` for one simulation, and the bookkeeping after a call.

    Built once per :class:`~.simulation.Simulation` (its arrays are the simulation's own, not
    copies); :meth:`advance` takes the arrays that change from one call to the next (neighbour
    list, contacts) afresh.
    """

    def __init__(self, sim):
        self.sim = sim
        ff, integ, st = sim.force_field, sim.integrator, sim.state
        p = sim.params
        terms = {t.name: t for t in ff.terms}
        index = {name: j for j, (name, _) in enumerate(ff.channels)}
        self.channel = np.array([index.get(c, -1) for c in CHANNELS], dtype=np.int64)
        mts = ff.mts
        tip = mts.tip_term
        if tip is None:
            self.channel[CHANNELS.index("tip_magnetic")] = -1
        tb = terms.get("tip_brake")
        el = terms.get("electrodes")
        dip = terms.get("external_dipole")
        line = terms.get("external_line_charge")
        split = p.integrator.brake == "split"
        self.scalars = _scalars(p, terms, mts, sim.network)
        pl = terms.get("plasma_filament")
        self.plasma = np.array(pl.args, dtype=np.float64) if pl is not None else _EMPTY
        self.el = el
        self.decay_poles = np.zeros(3)
        if dip is not None:
            # the decay of ExternalDipoleForce.split, exp(-k n dt) for n poles touched, as numpy computes it
            self.decay_poles[1:] = np.exp(-dip.k * np.array([1.0, 2.0]) * integ.dt)
            self.source, self.source_charge = dip.source, dip.source_charge
        else:
            self.source, self.source_charge = _EMPTY3, _EMPTY
        if line is not None and not line.slow:
            self.line = np.array(line.line, dtype=np.float64)
            self.nodes, self.weights = line.nodes, line.weights
        else:  # no line charge, or a slow one: held with the slow forces
            self.channel[CHANNELS.index("external_line_charge")] = -1
            self.line, self.nodes, self.weights = _EMPTY, _EMPTY, _EMPTY
        # the held slow forces, in the order MultipleTimeStepping extrapolates them
        keys = list(mts.held_forces())
        self.held = np.array([-1 if k == "tip_far" else index[k] for k in keys], dtype=np.int64)
        self.held_keys = keys
        n, n_rods = st.n_tips, st.n_rods
        self.tip_far = mts.tip_far if tip is not None else np.zeros((n, 3))
        self.tip_fast = mts.tip_fast if tip is not None else np.zeros((n, 3))
        if mts.extrapolate and keys:
            self.rate, self.base = mts.rate_block, mts.base_block
        else:
            self.rate = self.base = np.zeros((len(keys), n, 3))
        # where the Python step asks the tip list for an update: evaluation, split tip brake, contact test
        self.lists = np.array(
            [
                tip is not None or (tb is not None and not split),
                tb is not None and split,
                sim.network is not None,
            ]
        )
        self.slot_table = np.array(integ.slots, dtype=np.int64)
        self.split_channel = np.array([ff.work_index.get(c, -1) for c in SPLIT_BRAKES], dtype=np.int64)
        #: the rows of f_n, f_{n-1}, f_{n-2}, f_{n-3} of step i in the powers oldest first
        self._windows = np.arange(CHUNK)[:, None] + np.array([3, 2, 1, 0])[None, :]
        self.fast_names = [t.name for t in ff.terms if not t.slow and not t.counts_own_calls]
        self.centre = np.zeros((n_rods, 3))
        self.centre_force = np.zeros((n_rods, 3))
        self.before, self.after = np.zeros((n, 3)), np.zeros((n, 3))
        self.save_x, self.save_v = np.zeros((n, 3)), np.zeros((n, 3))
        self.bond_before = np.zeros(CHUNK)
        self.power_log = np.zeros((CHUNK, len(ff.nonconservative)))
        self.brake_work = np.zeros((CHUNK, 3))
        self.brake_hit = np.zeros((CHUNK, 3), dtype=bool)
        self._no_tips = np.zeros(0, dtype=np.int64)
        #: whether a Python step has filled the channels the compiled steps leave as they are (the uniform
        #: and electric fields, the split tip brake's zeros): not yet in a simulation rebuilt from a snapshot,
        #: whose channels start at zero (:func:`advance` makes its first step in Python)
        self.primed = False
        #: (9,) float64 to time the phases of the calls (``kernels/step_args.py::FastStepArgs.phase_time``,
        #: ``bench profile --team --phases``; the CPU's cycle counter, x86-64 only); empty: no timing
        self.phase_time = _EMPTY

    def ready(self) -> bool:
        """Whether the next step can be a compiled one as far as Python's state goes: a Python step has
        filled the constant channels (:attr:`primed`), the AB4 history is full, no slow term is stale, the
        tip list is built (the step count is the kernel's to check)."""
        sim = self.sim
        ff = sim.force_field
        if not self.primed or sim.integrator.count < 4 or ff.mts.stale or ff.lists.tip is None:
            return False
        return ff.lists.tip.reference is not None and ff.lists.tip.reference.shape == sim.state.position.shape

    def advance(self, n_max: int):
        """Up to ``n_max`` (at most :data:`CHUNK`) compiled steps; returns ``(steps, reason)`` (reasons
        of ``kernels/steps.py``), the bond errors before the constraint of those steps in
        ``bond_before[:steps]``. After ``NEEDS_CONTACTS`` the caller runs the network's update of the
        last step, after ``NEEDS_HEALTH`` the health check (which raises), after ``NEEDS_STEP`` a
        Python step."""
        sim = self.sim
        st, integ, ff, net = sim.state, sim.integrator, sim.force_field, sim.network
        mts, health = ff.mts, sim.health
        el = self.el
        if el is not None and el.split_mode and el.k != 0.0 and el.decay_dt != integ.dt:
            return 0, NEEDS_STEP  # the electrode brake's decay is made by its first split step
        if self.phase_time.shape not in ((0,), (9,)):
            raise ValueError(f"phase_time must be empty or (9,) float64, not of shape {self.phase_time.shape}")
        decay_walls = el.decay if el is not None and el.decay is not None else np.zeros(3)
        nl = ff.lists.tip
        n_max = min(int(n_max), CHUNK)
        (pairs, on_c, on_a, on_f, fil_tip, fil_z), limits = self._contact_args(net, st.n_tips)
        # the positions sa.LIM_NETWORK ... sa.LIM_HEIGHT_TOL, then LIM_BOND_BREAK, LIM_MAX_MOVE, LIM_MAX_BOND
        limits = np.array(limits + (BOND_BREAK, MAX_STEP_DISPLACEMENT, health.max_bond_error))
        hist_p0 = integ.hist_p.copy()
        head0 = integ.head
        args = FastStepArgs(
            x=st.position,
            v=st.velocity,
            hist_v=integ.hist_v,
            hist_a=integ.hist_a,
            hist_p=integ.hist_p,
            head=integ.head,
            slot_table=self.slot_table,
            step=st.step,
            n_max=n_max,
            slow_every=integ.slow_every,
            dt=integ.dt,
            length=st.bond_length(),
            exact_bond=integ.exact_bond,
            project=integ.project,
            correct_velocity=integ.correct_velocity,
            block=ff.channel_block,
            total=ff.total,
            powered=ff.powered,
            channel=self.channel,
            tip_charge=st.tip_charge,
            rod_charge=st.rod_charge,
            scalars=self.scalars,
            plasma=self.plasma,
            decay_walls=decay_walls,
            decay_poles=self.decay_poles,
            source=self.source,
            source_charge=self.source_charge,
            line=self.line,
            nodes=self.nodes,
            weights=self.weights,
            held=self.held,
            tip_far=self.tip_far,
            tip_fast=self.tip_fast,
            rate=self.rate,
            base=self.base,
            base_step=mts.base_step_array(),
            extrapolate=bool(mts.extrapolate),
            lists=self.lists,
            start=nl.start,
            index=nl.index,
            reference=nl.reference,
            pairs=pairs,
            on_cathode=on_c,
            on_anode=on_a,
            on_filament=on_f,
            filament_tip=fil_tip,
            filament_z=fil_z,
            centre=self.centre,
            centre_force=self.centre_force,
            before=self.before,
            after=self.after,
            save_x=self.save_x,
            save_v=self.save_v,
            bond_before=self.bond_before,
            power_log=self.power_log,
            brake_work=self.brake_work,
            brake_hit=self.brake_hit,
            limits=limits,
            phase_time=self.phase_time,
        )
        threads = numba.get_num_threads()
        if threads > 1 and st.n_tips >= TEAM_TIPS:
            result = fast_steps_team(threads, TEAM_CHUNKS * threads, args)
        else:
            result = fast_steps(args)
        done, reason, head, max_bond, err_after, speed = result
        if done:
            self._account(done, head0, hist_p0)
            integ.finish_compiled(st, done, head, float(self.bond_before[done - 1]), float(err_after), float(speed))
            health.max_bond_error = float(max_bond)
            ff.context.bind(st.position, st.velocity)
        return done, reason

    def _contact_args(self, net, n_tips):
        """The contact test's arguments: the contacts as the search holds them (tip pairs, the flags of
        the tips on the cathode, anode and filament), the filament contacts whose heights the circuit
        follows (tips and heights), and the test's scalars (on or off, the planes, the filament's
        radius, the height tolerance); a scene without contacts gives empty ones, the test off."""
        if net is None:
            off = np.zeros(n_tips, dtype=bool)
            return (np.zeros((0, 2), dtype=np.int64), off, off, off, self._no_tips, _EMPTY), (
                0.0,
                np.nan,
                np.nan,
                np.nan,
                0.0,
            )
        tr = net.tracker
        el = tr.electrodes if tr.electrodes is not None else (np.nan, np.nan)
        fr = tr.filament_radius if tr.filament_radius is not None else np.nan
        circuit_heights = net.circuit and len(net.filament_tip)
        fil_tip = np.asarray(net.filament_tip, dtype=np.int64) if circuit_heights else self._no_tips
        fil_z = np.asarray(net.filament_z, dtype=np.float64) if circuit_heights else _EMPTY
        limits = (1.0, float(el[0]), float(el[1]), float(fr), net.height_tolerance)
        return (*net.contacts.search_arrays, fil_tip, fil_z), limits

    def _account(self, done, head0, hist_p0):
        """The work of the steps made, added as the Python step adds it (``kernels/steps.py::add_work``):
        the AB4 sums of the channels' powers by numpy's product, one stacked call (the same numbers as
        one call per step, the windows being the same contiguous (4, n_power) blocks), then each split
        brake's work; and the fast terms' call counts."""
        integ = self.sim.integrator
        # the powers f_{n-3} ... f_n of every step, oldest first: three from the ring, then the log
        seq = np.concatenate([hist_p0[[(head0 - j) % 4 for j in (2, 1, 0)]], self.power_log[:done]])
        ab4_work = integ.dt * np.matmul(AB4_WEIGHTS, seq[self._windows[:done]])
        add_work(integ.work, ab4_work, self.brake_work, self.brake_hit, self.split_channel)
        calls = self.sim.force_field.calls
        for name in self.fast_names:
            calls[name] += done


def advance(sim, n_max: int, rows=None) -> int:
    """Make up to ``n_max`` steps of ``sim``: compiled ones while they can run, and the Python step
    (:meth:`Simulation.python_step <.simulation.Simulation.python_step>`) where one is needed; returns
    how many were made.

    ``rows(first_step, errors)``, if given, receives the bond errors before the constraint of the steps
    made (the run file's per-step rows), each before the Python part of its step (the contact update,
    or the diagnosis of a failed step, whose own row is not handed on, as after a failed Python step).
    A step the compiled call left undone (the split brake needed a list build) is made in Python at
    once: what the attempt left in the integrator's ring buffer and the channels is then overwritten.
    """
    cs = sim.compiled
    done = reason = 0
    if cs is not None and n_max > 1 and cs.ready():
        first = sim.state.step + 1
        done, reason = cs.advance(n_max)
        if done and rows is not None:
            rows(first, cs.bond_before[: done - 1 if reason == NEEDS_HEALTH else done])
        if reason == NEEDS_HEALTH:
            sim.health.after_step()  # raises the diagnosis of the failed step
        elif reason == NEEDS_CONTACTS and sim.network is not None:
            sim.update_network()
        if reason != NEEDS_STEP:
            return done
    sim.python_step()
    if cs is not None:
        cs.primed = True
    if rows is not None:
        rows(sim.state.step, (sim.integrator.bond_error_before,))
    return done + 1
