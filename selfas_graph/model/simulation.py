"""The simulation: state + force field + integrator, and the run loop.

:class:`Simulation` is the object a script or notebook drives::

    from selfas_graph import load_scenario, Simulation
    sim = Simulation.from_scenario(load_scenario("scenarios/quick.toml"))
    sim.run(t_end=5.0)
    sim.observables()["energy_balance"]
"""

from __future__ import annotations

import operator
import time

import numpy as np

from ..parallel import RowBlocks
from . import events as ev
from . import operations as op
from . import restart
from .compiled import advance, compiled_steps_for
from .health import BOND_BREAK, FORCE_OUT_OF_SCALE, MAX_STEP_DISPLACEMENT, HealthChecks, NumericalFailure, refuse_after
from .integrator import AdamsBashforth4
from .interrupt import DeferredCtrlC
from .network import Network
from .observables import Observables, energy_scale
from .operations import RunInterrupted, RunSummary
from .params import Parameters
from .placement import random_state
from .state import State
from .state_checks import check_against, check_live
from .terms import ForceField

__all__ = ["Simulation", "RunSummary", "RunInterrupted", "NumericalFailure"]
__all__ += ["BOND_BREAK", "MAX_STEP_DISPLACEMENT", "FORCE_OUT_OF_SCALE"]


class Simulation:
    """Rigid magnetized rods under the scene's force terms.

    One step advances every rod in the order docs/model.md 'Order of one step' states (forces,
    Adams-Bashforth update, split brake, bond constraint, health check, then the
    :class:`~.network.Network`: contact search, events, graph, circuit); :meth:`step` makes ``n`` and
    :meth:`run` is the step loop, acting after each step the operations whose trigger fires
    (:mod:`.operations`: frames, progress, stop check, checkpoints, and those in :attr:`operations`).
    The fast steps between two that need Python run in one compiled call (:attr:`compiled`,
    :mod:`.compiled`), bit for bit. Contacts present in the initial state are events of step 0.
    Components: :attr:`network` (None with ``contacts.enabled = false``), :attr:`force_field`,
    :attr:`integrator`, :attr:`health` (:class:`~.health.HealthChecks`) and :attr:`observe`
    (:class:`~.observables.Observables`); the methods of the last two are also the simulation's.

    Parameters
    ----------
    params : Parameters
    state : State, optional
        Initial state; default: the random placement of docs/model.md 'Assumptions and project choices'.
    timing : bool
        Record wall time per force term (``force_field.seconds``).
    comm : MPI communicator or the serial stub, optional
        Ranks that share the force work (``parallel.world`` under ``mpiexec``; default: a serial run).
        Every rank must then make the same calls; each ends every step with the same state, bit for bit.
        A run with a writer gives one on every rank: rank 0 the file's, the others
        ``selfas_graph.io.pending_rows.NullWriter()`` (the frames' energies are sums over the ranks).
    check_state : bool
        Validate ``state`` and work on a copy (:meth:`State.checked`); False adopts it (:meth:`from_snapshot`).

    Raises
    ------
    StateError
        An invalid ``state``, or one whose rod count differs from ``rods.count``.
    """

    def __init__(
        self, params: Parameters, state: State | None = None, timing: bool = False, comm=None, check_state: bool = True
    ):
        if not isinstance(params, Parameters):
            raise TypeError(
                f"Simulation(params): a Parameters (Parameters.from_dict(d) for a dict), got {type(params).__name__}"
            )
        self.params = params
        if state is not None:
            if not isinstance(state, State):
                raise TypeError(f"Simulation(state=...): a State (State.from_rods(...)), got {type(state).__name__}")
            state = state.checked() if check_state else state
            check_against(params, state, values=check_state)
        self.state = random_state(params) if state is None else state
        #: contacts, graph, conductor potentials, circuit and the rod currents (None when contacts.enabled is false)
        self.network = Network.from_params(params, self.state) if params.contacts.enabled else None
        self.force_field = ForceField(
            params,
            self.state,
            timing=timing,
            blocks=RowBlocks(self.state.n_rods, comm),
            currents=self.network.currents if self.network is not None else None,
        )
        ip = params.integrator
        self.integrator = AdamsBashforth4(
            self.force_field,
            ip.dt,
            exact_bond=ip.bond_force == "exact",
            project=ip.position_projection,
            correct_velocity=ip.velocity_correction,
            split_brakes=ip.brake == "split",
            slow_every=ip.slow_every,
        )
        self.integrator.time_origin = (self.state.step, self.state.time)
        self.health = HealthChecks(params, self.state, self.integrator, self.force_field)
        self.observe = Observables(params, self.state, self.force_field, self.integrator, self.network)
        #: every event so far, as (step, time, kind, a, b) rows in order; ``circuit_log``: rows of :mod:`.circuitlog`
        self.events, self.circuit_log = [], []
        self.short_circuit_time = None
        #: operations attached for every :meth:`run` (:mod:`.operations`), acted after the frame writer
        self.operations = []
        self._ops = ()
        #: the NumericalFailure that stopped this simulation (its state is then the failed one), or None
        self.failure = None
        if self.network is not None:
            self.force_field.extend_tip_range(self.network.tracker.release)  # the contact search's pairs
            self.update_network()
        self.compiled = compiled_steps_for(self)  # the fast steps in one call (.compiled); None: in Python

    @classmethod
    def from_scenario(cls, scenario, **kw):
        if not isinstance(getattr(scenario, "params", None), Parameters):
            raise TypeError(f"Simulation.from_scenario: a Scenario (load_scenario), got {type(scenario).__name__}")
        sim = cls(scenario.params, **kw)
        sim.scenario = scenario  # its text goes into run files written from Python
        return sim

    # ------------------------------------------------------------------ the network's parts
    @property
    def graph(self) -> Network | None:
        """The network (topology, arrays, solve), under the name of selfas-graph 0.2."""
        return self.network

    @property
    def contacts(self):
        """The network's contacts, a :class:`~.contactset.ContactSet` (None without contacts)."""
        return self.network.contacts if self.network is not None else None

    @property
    def solution(self):
        """The last circuit solution (None before a short circuit, and without a circuit)."""
        return self.network.solution if self.network is not None else None

    @property
    def conductor_potential(self) -> dict:
        """Conductor id -> fixed potential (units R0 J0), None where given per contact."""
        return self.network.conductor_potential if self.network is not None else {}

    # ------------------------------------------------------------------ exact restart
    def snapshot(self) -> dict:
        """Everything the next step depends on, as a flat dict of numpy arrays and scalars.

        :meth:`from_snapshot` rebuilds a simulation whose next steps are bitwise those of this one (same
        thread count): the union of the components' states (:meth:`State.state_dict`,
        :meth:`AdamsBashforth4.state_dict`, the force field's, :meth:`Network.state_dict`), the largest
        bond error, the energy reference, the run's events, its circuit log and the time of its first
        short circuit (NaN: none yet).
        """
        return restart.snapshot(self)

    @classmethod
    def from_snapshot(
        cls, params: Parameters, snap: dict, timing: bool = False, comm=None, new_dt: bool = False
    ) -> "Simulation":
        """Rebuild a simulation from :meth:`snapshot` (see there), at the snapshot's time step: another
        ``integrator.dt`` is refused (ValueError) unless ``new_dt`` (the history then forgotten: RK4 again)."""
        return restart.from_snapshot(cls, params, snap, timing=timing, comm=comm, new_dt=new_dt)

    @property
    def dt(self) -> float:
        return self.integrator.dt

    # ------------------------------------------------------------------ the components' methods
    def energies(self) -> dict:
        """Kinetic and potential energy of each conservative term (:meth:`.Observables.energies`)."""
        return self.observe.energies()

    def observables(self) -> dict:
        """Scalars and small vectors describing the current state (:meth:`.Observables.observables`)."""
        return self.observe.observables(len(self.events))

    def status(self) -> dict:
        """What a progress display shows (:meth:`.Observables.status`)."""
        return self.observe.status(self.short_circuit_time)

    def contact_count(self) -> int:
        """Tip pairs of different rods in contact (:meth:`.Observables.contact_count`)."""
        return self.observe.contact_count()

    energy_scale = staticmethod(energy_scale)

    def check_energy(self, obs) -> None:
        """Stop when the energy balance is off or not finite (:meth:`.HealthChecks.check_energy`)."""
        self.health.check_energy(obs)

    _check_energy = check_energy  # the name of selfas-graph 0.2

    @property
    def max_bond_error(self) -> float:
        """The largest bond-length error after the constraint so far (``health.max_bond_error``)."""
        return self.health.max_bond_error

    @property
    def last_good_snapshot(self) -> dict | None:
        """:meth:`snapshot` of the last state that passed the checks of :meth:`run` at its start or at a
        frame (None before a run): finite, so a failure file can hold it in place of the failed one."""
        return self.health.last_good_snapshot

    # ------------------------------------------------------------------ stepping
    def step(self, n: int = 1) -> None:
        """Advance by ``n`` steps, an integer >= 0 (raises :class:`NumericalFailure` on breakdown)."""
        try:
            n = operator.index(n)
        except TypeError:
            raise TypeError(f"Simulation.step(n): n is a whole number of steps, got {n!r}") from None
        if n < 0:
            raise ValueError(f"Simulation.step(n): n is a number of steps >= 0, got {n}")
        refuse_after(self.failure)
        check_live(self.state)
        if self.observe.energy0 is None:
            self.observe.record_initial_energy()
        done = 0
        try:
            with DeferredCtrlC() as ctrl_c:  # a Ctrl-C stops after the batch of steps it lands in (.interrupt)
                while done < n:
                    done += advance(self, n - done)
                    ctrl_c.check()
        except NumericalFailure as exc:
            self.failure = exc
            raise
        ctrl_c.check()  # one that came after the last check, before the handler was put back

    def python_step(self) -> None:
        """One step in Python (:mod:`.compiled` makes fast steps in one call, the same numbers)."""
        self.integrator.step(self.state)
        self.health.after_step()
        if self.network is not None:
            self.update_network()

    def update_network(self):
        """The network's part of a step (after :meth:`python_step`'s, or compiled ones): events into the
        log; new currents (in the store the force field reads) make the held current forces stale."""
        st = self.state
        news = self.network.update(st.position, self.force_field.tip_neighbours(st.position), st.step, st.time)
        if not news.changed:
            return
        self.events.extend(news.events)
        self.circuit_log.extend(news.circuit)
        if self.short_circuit_time is None and news.circuit and news.circuit[0][2] == ev.SHORT_CIRCUIT:
            self.short_circuit_time = news.circuit[0][1]
        if news.currents_changed:
            self.force_field.currents_changed()
        if self.params.integrator.restart_on_events:
            self.integrator.reset_history()

    # ------------------------------------------------------------------ run loop
    @property
    def frame_steps(self) -> int:
        """Steps between saved frames: ``output.interval`` rounded to whole steps, at least one."""
        return op.frame_steps(self.params.output.interval, self.dt)

    @property
    def frame_interval(self) -> float:
        """Simulated time between saved frames: :attr:`frame_steps` steps."""
        return self.frame_steps * self.dt

    def steps_for(self, duration: float) -> int:
        """Number of steps that cover ``duration`` (rounded to the nearest step)."""
        return int(round(duration / self.dt))

    def steps_to(self, t_end: float) -> int:
        """Steps from the current time to ``t_end``, a whole number of steps ahead (to round-off), not in the
        past; ValueError otherwise, naming the times that can be reached."""
        return op.steps_between(self.state.time, t_end, self.dt)

    def run(
        self, t_end=None, writer=None, progress=None, progress_every=None, checkpointer=None, stop=None, check_every=1
    ) -> RunSummary:
        """Run from the current time to ``t_end`` (default ``run.t_end``).

        Can be called again to continue in chunks (``sim.run(1.0); sim.run(2.0)`` takes the steps of
        ``sim.run(2.0)``; a writer gets a frame at the end of each chunk). The arguments become operations
        for this call (:mod:`.operations`); those in :attr:`operations` act in every call.

        Parameters
        ----------
        t_end : float, optional
            A whole number of steps ahead of the current time (ValueError otherwise; :meth:`steps_to`).
        writer : RunWriter-like, optional
            Receives a frame at the start (if it has none yet), every ``output.interval`` of simulated
            time (nearest step), and at the end (:class:`~.operations.FrameWriter`).
        progress : callable(sim, done, total), optional; called every ``progress_every`` steps (about 200 a run)
        checkpointer : object with ``due() -> bool`` and ``write(sim)``, optional
            When due, the writer's pending rows and events are flushed and a checkpoint is written;
            one is also written at the end.
        stop : callable() -> bool, optional
            When true, pending data are flushed, a checkpoint is written and :class:`RunInterrupted` raised
            (on Ctrl-C and on a NumericalFailure the pending data are flushed too, and the writer told why).
            A Ctrl-C (SIGINT in the main thread, with Python's own handler in place) stops the run at the end
            of the batch of compiled steps it lands in (at most 256) or of the next operation (:mod:`.interrupt`),
            then raises ``KeyboardInterrupt``: ``run`` again continues with the steps the run would have taken.
            A second Ctrl-C raises at once.
        check_every : int
            ``checkpointer`` and ``stop`` are asked after the steps that are multiples of this (default
            every step; ``integrator.slow_every`` lets the fast steps between run in one call).

        Returns a :class:`RunSummary`.
        """
        refuse_after(self.failure)
        check_live(self.state)
        t_end = self.params.run.t_end if t_end is None else t_end
        n_steps = self.steps_to(t_end)
        every = self.frame_steps
        summary = RunSummary(t_start=self.state.time)
        ops = op.run_operations(
            self, writer, every, n_steps, progress, progress_every, checkpointer, stop, check_every, t_end
        )
        if self.observe.energy0 is None:
            self.observe.record_initial_energy()
        self.health.keep_last_good(self.snapshot())
        self._ops = ops
        t0 = time.perf_counter()
        # a Ctrl-C (SIGINT under Python's own handler) is raised after the batch of steps it lands in and the
        # operations after it, frames among them (.interrupt): a run continued from there takes the same steps
        with DeferredCtrlC() as ctrl_c:
            try:
                for operation in ops:
                    operation.start(self, n_steps)
                ctrl_c.check()
                (per_step, rows), i = op.per_step_rows(ops), 0
                while i < n_steps:
                    # the steps up to the next one after which an operation acts, compiled where they can be
                    i += advance(self, op.steps_to_next_act(ops, self.state.step, n_steps - i), rows)
                    for operation in ops:
                        if operation in per_step:
                            continue
                        if operation.trigger(self.state.step) or (operation.final and i == n_steps):
                            operation.act(self, i, n_steps)
                    summary.steps = i
                    ctrl_c.check()
                for operation in ops:
                    operation.finish(self)
            except BaseException as exc:  # what the steps before it buffered is written (Ctrl-C, a failure, a bug)
                if isinstance(exc, NumericalFailure):
                    self.failure = exc
                if not isinstance(exc, OSError):  # a failed write: writing again would fail again
                    op.stopped(ops, self, exc)
                raise
            finally:
                summary.wall_seconds = time.perf_counter() - t0
                self._ops = ()
        summary.t_end, summary.max_bond_error = self.state.time, self.health.max_bond_error
        frames = next((o for o in ops if isinstance(o, op.FrameWriter)), None)
        obs = frames.last_observables if frames is not None and n_steps else None
        obs = obs if obs is not None else self.observables()
        summary.energy_balance, summary.energy_scale = float(obs["energy_balance"]), float(energy_scale(obs))
        summary.frames = writer.n_frames if writer is not None else 0
        ctrl_c.check()  # one that came after the last step: the run is whole, the caller still stops
        return summary

    def flush_operations(self) -> None:
        """Every operation of the running :meth:`run` hands its buffered data on (before a checkpoint)."""
        for operation in self._ops:
            operation.flush(self)

    def flush_output(self, writer) -> None:
        """Hand ``writer`` its buffered per-step rows, events and circuit-log rows (e.g. up to a failure)."""
        net = self.network is not None
        writer.flush_pending(self.events if net else None, self.circuit_log if net else None)

    def write_frame(self, writer):
        """Check the observables, then write a frame with them (and the graph state); returns them."""
        st = self.state
        obs = self.observables()
        # checked before anything of the frame is written (frame 0 too): no NaN reaches the file
        self.check_energy(obs)
        self.health.keep_last_good(self.snapshot())
        self.flush_output(writer)
        writer.write_frame(st.step, st.time, st.position, st.velocity, obs)
        if self.network is not None:
            net, sol = self.network, self.network.solution
            writer.write_graph(
                st.step,
                st.time,
                net.arrays(),
                net.topology().role,
                self.force_field.current,
                sol.potential if sol is not None else np.full(st.n_tips, np.nan),
                net.conductor_potential,
            )
        writer.flush()
        return obs
