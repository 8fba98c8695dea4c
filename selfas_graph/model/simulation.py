"""The simulation: state + force field + integrator, and the run loop.

:class:`Simulation` is the object a script or notebook drives::

    from selfas_graph import load_scenario, Simulation
    sim = Simulation.from_scenario(load_scenario("scenarios/quick.toml"))
    sim.run(t_end=5.0)
    sim.observables()["energy_balance"]
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from ..kernels.pairs import close_pair_count
from ..parallel import RowBlocks
from . import events as ev
from .contacts import ContactTracker
from .graph import FILAMENT, ConnectivityGraph
from .integrator import AdamsBashforth4
from .params import Parameters
from .state import State, StateError, random_state
from .terms import ForceField

#: a bond whose length is off by more than this after a step is broken: no
#: corrector recovers it meaningfully (typical per-step errors are < 1e-6)
BOND_BREAK = 0.05
#: a tip moving more than this (in rod lengths) in one step means the step is
#: far beyond stability: the tip core (width r* ~ 0.06) is crossed in one step
MAX_STEP_DISPLACEMENT = 0.25
#: a force component beyond this (units F_M0) is out of scale rather than a time-step problem:
#: the stiffest force of a sane scene, the tip core's kappa / r*^2 at kappa = 1, r* = 0.06, is
#: 278, and the paper's scenes stay below 1e4; a failure with a force above this blames the term
FORCE_OUT_OF_SCALE = 1e8


class RunInterrupted(Exception):
    """The run was asked to stop (a signal); a checkpoint was written if a checkpointer was given."""

    def __init__(self, step):
        super().__init__(f"interrupted at step {step}")
        self.step = step


class NumericalFailure(RuntimeError):
    """The run went numerically wrong; the message is a diagnosis."""

    def __init__(self, message, step, rods=()):
        super().__init__(message)
        self.step = step
        self.rods = list(rods)


@dataclass
class RunSummary:
    steps: int = 0
    wall_seconds: float = 0.0
    t_start: float = 0.0
    t_end: float = 0.0
    max_bond_error: float = 0.0
    energy_balance: float = float("nan")
    energy_scale: float = float("nan")
    frames: int = 0

    @property
    def steps_per_second(self):
        return self.steps / self.wall_seconds if self.wall_seconds > 0 else float("inf")


class Simulation:
    """Rigid magnetized rods under the scene's force terms.

    One call of :meth:`step` advances every rod by one time step, in the order that
    docs/model.md 'Order of one step' states (forces, Adams-Bashforth update, split
    brake, bond constraint, health check, contact search, events, graph, circuit);
    :meth:`run` adds, after each step, the observers on their triggers (progress
    callback; a frame with observables, events and the graph state every
    ``output.interval``). Contacts present in the initial state are
    recorded as events of step 0 when the simulation is built.

    Parameters
    ----------
    params : Parameters
    state : State, optional
        Initial state; default: the random placement of docs/model.md 'Assumptions and project choices'.
    timing : bool
        Record wall time per force term (``force_field.seconds``).
    comm : MPI communicator or the serial stub, optional
        Ranks that share the force work (``selfas_graph.parallel.world`` under ``mpiexec``;
        default: none, a serial run). Every rank must then make the same calls; each
        ends every step with the same state, bit for bit.
    check_state : bool
        Validate ``state`` and work on a copy of it (:meth:`State.checked`); False adopts the
        object as it is (:meth:`from_snapshot`).

    Raises
    ------
    StateError
        An invalid ``state``, or one whose rod count differs from ``rods.count``.
    """

    def __init__(self, params: Parameters, state: State | None = None, timing: bool = False,
                 comm=None, check_state: bool = True):
        self.params = params
        if state is not None and check_state:
            state = state.checked()
        if state is not None and state.n_rods != params.rods.count:
            raise StateError(f"the state has {state.n_rods} rods but rods.count = {params.rods.count}; make them "
                             f"agree, e.g. params.replace(rods={{'count': {state.n_rods}}})")
        self.state = random_state(params) if state is None else state
        self.force_field = ForceField(params, self.state, timing=timing, blocks=RowBlocks(self.state.n_rods, comm))
        ip = params.integrator
        self.integrator = AdamsBashforth4(self.force_field, ip.dt, exact_bond=ip.bond_force == "exact",
                                          project=ip.position_projection, correct_velocity=ip.velocity_correction,
                                          split_brakes=ip.brake == "split", slow_every=ip.slow_every)
        self.integrator.time_origin = (self.state.step, self.state.time)
        self.max_bond_error = 0.0
        self._energy0 = None
        #: every event so far, as (step, time, kind, a, b) rows in order
        self.events = []
        self.short_circuit_time = None
        self.solution = None
        self.contacts = None
        self.graph = None
        cp = params.contacts
        el = params.forces.electrodes
        if cp.enabled:
            rstar = params.rods.rstar
            self.force_field.extend_tip_range(cp.release_factor * rstar)
            planes = (-0.5 * el.gap, 0.5 * el.gap) if el is not None else None
            fil = params.forces.external_filament
            w_fil = 0.5 * fil.diameter if fil is not None else None
            self.contacts = ContactTracker(self.state.n_tips, rstar, cp.release_factor * rstar, planes, w_fil)
            self.bias = params.circuit.delta_J0 if params.circuit is not None else 0.0
            conductors = {}
            if el is not None:
                half = 0.5 * self.bias * el.gap + 0.0  # + 0.0: no negative zero without a bias
                conductors = {ev.CONDUCTOR_CATHODE: -half + 0.0, ev.CONDUCTOR_ANODE: half}
            if fil is not None:
                conductors[ev.CONDUCTOR_FILAMENT] = None  # psi = -delta_J0 z per contact (docs/model.md 'Circuit')
            self._filament_tip = np.zeros(0, dtype=np.int64)
            self._filament_z = np.zeros(0)
            #: conductor id -> fixed potential (units R0 J0), docs/model.md 'Circuit'
            self.conductor_potential = conductors
            solver = params.circuit.solver if params.circuit is not None else "auto"
            self.graph = ConnectivityGraph(self.state.n_rods, conductors, solver=solver,
                                           rod_resistance=self.state.rod_resistance, contact_resistance=cp.resistance)
            self._update_contacts()

    @classmethod
    def from_scenario(cls, scenario, **kw):
        sim = cls(scenario.params, **kw)
        sim.scenario = scenario  # its text goes into run files written from Python
        return sim

    # ------------------------------------------------------------------ exact restart
    def snapshot(self) -> dict:
        """Everything the next step depends on, as a flat dict of numpy arrays and scalars.

        :meth:`from_snapshot` rebuilds a simulation whose next steps are bitwise those of
        this one (same thread count): state, derivative history, work, neighbour-list
        build positions, contacts, graph, currents, events and the energy reference.
        """
        st, it, ff = self.state, self.integrator, self.force_field
        snap = {
            "position": st.position.copy(), "velocity": st.velocity.copy(),
            "tip_charge": st.tip_charge.copy(), "rod_charge": st.rod_charge.copy(),
            "step": st.step, "time": st.time,
            "hist_v": it.hist_v.copy(), "hist_a": it.hist_a.copy(), "hist_p": it.hist_p.copy(),
            "head": it.head, "count": it.count, "work": it.work.copy(),
            "time_origin_step": it.time_origin[0], "time_origin_time": it.time_origin[1],
            "bond_error_before": it.bond_error_before, "bond_error_after": it.bond_error_after,
            "max_bond_error": self.max_bond_error,
            "energy0": np.nan if self._energy0 is None else self._energy0,
            "events": np.array([tuple(r) for r in self.events], dtype=ev.EVENT_DTYPE),
            "short_circuit_time": np.nan if self.short_circuit_time is None else self.short_circuit_time,
        }
        for name in ("rod_length", "rod_resistance"):
            if getattr(st, name) is not None:
                snap[name] = getattr(st, name).copy()
        snap.update(ff.state_dict())  # currents, neighbour lists, held slow forces
        if self.contacts is not None:
            c = self.contacts
            snap.update(contact_pairs=c.pairs.copy(), on_cathode=c.on_cathode.copy(), on_anode=c.on_anode.copy(),
                        on_filament=c.on_filament.copy(), filament_tip=self._filament_tip.copy(),
                        filament_z=self._filament_z.copy(), has_solution=self.solution is not None)
            for k, v in self.graph.arrays().items():
                snap[f"graph_{k}"] = v.copy()
        return snap

    @classmethod
    def from_snapshot(cls, params: Parameters, snap: dict, timing: bool = False, comm=None) -> "Simulation":
        """Rebuild a simulation from :meth:`snapshot` (see there)."""
        state = State(np.array(snap["position"]), np.array(snap["velocity"]), np.array(snap["tip_charge"]),
                      np.array(snap["rod_charge"]), int(snap["step"]), float(snap["time"]),
                      *(np.array(snap[k]) if k in snap else None for k in ("rod_length", "rod_resistance")))
        sim = cls(params, state=state, timing=timing, comm=comm, check_state=False)
        it, ff = sim.integrator, sim.force_field
        it.hist_v[:], it.hist_a[:], it.hist_p[:] = snap["hist_v"], snap["hist_a"], snap["hist_p"]
        it.head, it.count = int(snap["head"]), int(snap["count"])
        it.work[:] = snap["work"]
        it.time_origin = (int(snap["time_origin_step"]), float(snap["time_origin_time"]))
        it.bond_error_before = float(snap["bond_error_before"])
        it.bond_error_after = float(snap["bond_error_after"])
        sim.max_bond_error = float(snap["max_bond_error"])
        e0 = float(snap["energy0"])
        sim._energy0 = None if math.isnan(e0) else e0
        sct = float(snap["short_circuit_time"])
        sim.short_circuit_time = None if math.isnan(sct) else sct
        sim.events = [tuple(r.item()) for r in np.asarray(snap["events"])]
        ff._bind(state.position, state.velocity)
        if sim.contacts is not None:
            c = sim.contacts
            c.pairs = np.array(snap["contact_pairs"], dtype=np.int64).reshape(-1, 2)
            c.on_cathode[:], c.on_anode[:], c.on_filament[:] = snap["on_cathode"], snap["on_anode"], snap["on_filament"]
            sim._filament_tip = np.array(snap["filament_tip"], dtype=np.int64)
            sim._filament_z = np.array(snap["filament_z"], dtype=np.float64)
            arrays = {k[len("graph_"):]: np.array(v) for k, v in snap.items() if k.startswith("graph_")}
            sim.graph = ConnectivityGraph.from_arrays(state.n_rods, sim.conductor_potential, arrays,
                                                      rod_resistance=state.rod_resistance,
                                                      contact_resistance=params.contacts.resistance)
            sim.graph.solver = params.circuit.solver if params.circuit is not None else "auto"
            if bool(snap["has_solution"]) and params.circuit is not None:
                # the solve is a pure function of the graph arrays, so this is the solution the
                # interrupted run held; the currents in use are restored as saved
                sim.solution = sim.graph.solve()
        ff.load_state_dict(snap)  # currents, neighbour lists, held slow forces (missing ones: rebuilt)
        return sim

    @property
    def dt(self) -> float:
        return self.integrator.dt

    # ------------------------------------------------------------------ stepping
    def step(self, n: int = 1) -> None:
        """Advance by ``n`` steps (raises :class:`NumericalFailure` on breakdown)."""
        if self._energy0 is None:
            self._record_initial_energy()
        for _ in range(n):
            self.integrator.step(self.state)
            self._check()
            if self.contacts is not None:
                self._update_contacts()

    def _filament_potential(self, tip, conductor):
        """Potential of a tip touching the case (ii) filament: -delta_J0 z (docs/model.md 'Circuit')."""
        return -self.bias * float(self.state.position[tip, 2])

    def _update_contacts(self):
        st = self.state
        rows = self.contacts.update(st.position, self.force_field.tip_neighbours(st.position), st.step, st.time)
        moved = self._filament_heights_moved()
        if not rows and not moved:
            return
        if rows:
            rows += self.graph.apply(rows, contact_potential=self._filament_potential)
            self.events.extend(rows)
            for r in rows:
                if r[2] == ev.SHORT_CIRCUIT and self.short_circuit_time is None:
                    self.short_circuit_time = r[1]
        if self.params.circuit is not None and self.graph.changed:
            if self.graph.has_short_circuit:
                self.solution = self.graph.solve()
                # rods off every conductor-to-conductor path carry no current by topology; the
                # solve leaves them round-off currents (measured up to 2e-14 in a Fig. 2 run)
                filament = self.graph.topology().role == FILAMENT
                self.force_field.set_currents(np.where(filament, self.solution.current, 0.0))
            else:
                # no rod lies between two conductor attachments: every current is zero, so the
                # linear solve (about 1 ms at 1200 rods) is skipped until a path exists
                self.solution = None
                self.graph.changed = False
                if len(self.force_field.active_rod):
                    self.force_field.set_currents(np.zeros(self.state.n_rods))
            arr = self.graph.arrays()
            on_fil = arr["conductor_id"] == ev.CONDUCTOR_FILAMENT
            self._filament_tip = arr["conductor_tip"][on_fil]
            self._filament_z = st.position[self._filament_tip, 2].copy()
        if self.params.integrator.restart_on_events:
            self.integrator.reset_history()

    def _filament_heights_moved(self) -> bool:
        """Case (ii): update the potentials of filament contacts that moved along z by more than
        ``circuit.height_tolerance`` since the last solve; True if any did."""
        if not len(self._filament_tip) or self.params.circuit is None:
            return False
        z = self.state.position[self._filament_tip, 2]
        moved = np.abs(z - self._filament_z) > self.params.circuit.height_tolerance
        if not moved.any():
            return False
        for k in self._filament_tip[moved]:
            self.graph.set_contact_potential(int(k), ev.CONDUCTOR_FILAMENT, self._filament_potential(int(k), None))
        return True

    def _check(self):
        st, integ = self.state, self.integrator
        err = integ.bond_error_before
        self.max_bond_error = max(self.max_bond_error, integ.bond_error_after)
        v = st.velocity
        vmax = float(np.abs(v).max(initial=0.0))
        if math.isfinite(err) and err < BOND_BREAK and vmax * self.dt < MAX_STEP_DISPLACEMENT and math.isfinite(vmax):
            return
        self._fail(err, vmax)

    def _fail(self, err, vmax):
        st = self.state
        x, v = st.position, st.velocity
        bad_tip = ~np.isfinite(x).all(axis=1) | ~np.isfinite(v).all(axis=1)
        speed = np.linalg.norm(np.nan_to_num(v, nan=np.inf), axis=1)
        if bad_tip.any():
            what = "a non-finite position or velocity (NaN or inf)"
            tips = np.flatnonzero(bad_tip)
        elif not err < BOND_BREAK:
            what = f"a broken rigid bond (length error {err:.3g} > {BOND_BREAK})"
            r = np.linalg.norm(x[0::2] - x[1::2], axis=1)
            tips = 2 * np.argsort(-np.abs(r - (1.0 if st.rod_length is None else st.rod_length)))[:5]
        else:
            what = f"a runaway step (a tip moved {vmax * self.dt:.3g} rod lengths in one step)"
            tips = np.argsort(-speed)[:5]
        rods = sorted(set(int(k) // 2 for k in tips[:10]))
        term, force = self._out_of_scale_term()
        if term is not None:
            msg = (f"numerical failure at step {st.step} (t = {st.time:.6g}): {what}; rods involved: "
                   f"{rods[:10]}; the '{term}' term's force was already {force:.3g} F_M0 at the last saved state, "
                   f"out of scale (above {FORCE_OUT_OF_SCALE:g}): no time step follows it. Check the parameters "
                   f"of that term and the charges it acts on ({_term_keys(term)}).")
            raise NumericalFailure(msg, st.step, rods)
        dominant = self.force_field.dominant_channel(np.asarray(tips[:10]))
        cause = (f"largest force on them from the '{dominant}' term" if dominant != "none"
                 else "no force term is on, so the integrator alone is at fault")
        stiff = self._stiff_brakes()
        if stiff:
            cause = stiff
        msg = (f"numerical failure at step {st.step} (t = {st.time:.6g}): {what}; rods involved: "
               f"{rods[:10]}; {cause}. "
               f"The time step integrator.dt = {self.dt:g} is the likely cause: try a smaller one "
               f"(the stiff parts are the tip core and the brakes inside r*){self._slow_hint()}.")
        raise NumericalFailure(msg, st.step, rods)

    def _stiff_brakes(self) -> str:
        """A diagnosis naming the explicit brakes too stiff for dt (coefficient * dt > 2), or ""."""
        f, ip = self.params.forces, self.params.integrator
        if ip.brake != "explicit":
            return ""
        over = [(name, b.coefficient) for name, b in (("tip_brake", f.tip_brake), ("ambient_brake", f.ambient_brake))
                if b is not None and b.coefficient * self.dt > 2.0]
        if not over:
            return ""
        name, k = max(over, key=lambda x: x[1])
        return (f"the '{name}' term is too stiff for the step: forces.{name}.coefficient * dt = {k * self.dt:.3g} "
                f"(an explicit brake is stable only below 2; integrator.brake = \"split\" is stable for any)")

    def _out_of_scale_term(self):
        """(channel, force) of a channel whose force at the last sane state (the last frame, or the
        start of the run) exceeds :data:`FORCE_OUT_OF_SCALE`, else (None, 0.0).

        At the failed state every force is huge (the brakes answer the runaway velocities), so
        the culprit is looked for where the run was still sane.
        """
        good = getattr(self, "_last_good", None)
        if good is None:
            return None, 0.0
        ff = self.force_field
        with np.errstate(all="ignore"):
            ff.evaluate(good[0].copy(), good[1].copy(), full=True)
            name, force = ff.dominant_force(np.arange(self.state.n_tips))
        return (name, force) if name != "none" and not force <= FORCE_OUT_OF_SCALE else (None, 0.0)

    # ------------------------------------------------------------------ observables
    def energies(self) -> dict:
        """Kinetic and potential energy of each conservative term (unit tip masses)."""
        st = self.state
        e = {"kinetic": 0.5 * float(np.einsum("ij,ij->", st.velocity, st.velocity))}
        e.update(self.force_field.potential_energy(st.position))
        return e

    def _record_initial_energy(self):
        """E(0) - W(0), the reference of the energy balance, taken before the first step."""
        self._energy0 = sum(self.energies().values()) - float(self.integrator.work.sum())

    def observables(self) -> dict:
        """Scalars and small vectors describing the current state (one row per saved frame)."""
        st = self.state
        obs = {}
        energy = self.energies()
        for k, v in energy.items():
            obs[f"energy/{k}"] = v
        total = sum(energy.values())
        work = dict(zip(self.force_field.nonconservative, self.integrator.work))
        for k, w in work.items():
            obs[f"work/{k}"] = w
        if self._energy0 is None:
            self._energy0 = total - sum(work.values())
        # E(t) - E(0) - W(t): zero up to the integration error (docs/model.md 'Work bookkeeping and the energy balance': brakes
        # and the plasma field do work, tracked per channel by the integrator)
        obs["energy_total"] = total
        obs["energy_balance"] = total - sum(work.values()) - self._energy0
        obs["momentum"] = st.velocity.sum(axis=0)
        obs["bond_error"] = self.integrator.bond_error_before
        obs["contacts"] = float(self.contact_count())
        if self.graph is not None:
            topo = self.graph.topology()
            obs["rods/filament"] = topo.n_filament
            obs["rods/dead_end"] = topo.n_dead_end
            obs["rods/cluster"] = topo.n_cluster
            obs["rods/free"] = topo.n_free
            obs["largest_structure"] = int(topo.structure_size[topo.largest_structure]) if topo.largest_structure >= 0 else 0
            obs["events"] = len(self.events)
            obs["short_circuit"] = float(topo.has_short_circuit)
        if self.params.circuit is not None:
            sol = self.solution
            obs["total_current"] = sol.total_current if sol is not None else 0.0
            obs["effective_resistance"] = sol.effective_resistance if sol is not None else float("inf")
        return obs

    def status(self) -> dict:
        """What a progress display shows: tip contacts, tip-conductor contacts (electrodes, the
        case (ii) filament), the time of the first short circuit (None before it), the total
        current (J0) and the number of rods carrying current."""
        c = self.contacts
        sol = self.solution
        return {
            "contacts": self.contact_count(),
            "electrode_contacts": int(c.on_cathode.sum() + c.on_anode.sum()) if c is not None else 0,
            "filament_contacts": int(c.on_filament.sum()) if c is not None else 0,
            "short_circuit_time": self.short_circuit_time,
            "total_current": float(sol.total_current) if sol is not None else 0.0,
            "current_rods": int(np.count_nonzero(self.force_field.current)),
        }

    def contact_count(self) -> int:
        """Number of tip pairs of different rods in contact (closer than r*, or still held by hysteresis)."""
        if self.contacts is not None:
            return self.contacts.n_contacts
        tnl = self.force_field.tip_neighbours(self.state.position)
        return int(close_pair_count(self.state.position, tnl.start, tnl.index, self.params.rods.rstar))

    # ------------------------------------------------------------------ run loop
    @property
    def frame_interval(self) -> float:
        """Simulated time between saved frames: ``output.interval`` rounded to whole steps."""
        return max(1, int(round(self.params.output.interval / self.dt))) * self.dt

    def steps_for(self, duration: float) -> int:
        """Number of steps that cover ``duration`` (rounded to the nearest step)."""
        return int(round(duration / self.dt))

    def steps_to(self, t_end: float) -> int:
        """Number of steps from the current time to ``t_end``, which must lie a whole number of
        steps ahead (to round-off) and not in the past; ValueError otherwise, naming the times
        that can be reached."""
        t_end, t, dt = float(t_end), self.state.time, self.dt
        if not math.isfinite(t_end):
            raise ValueError(f"t_end = {t_end} is not a finite time")
        x = (t_end - t) / dt
        n = int(round(x))
        # round-off of t_end - t: a few ulps of the step count, and no more than 1e-6 of a step below 1e10 steps
        if abs(x - n) > 1e-6 + 4 * np.finfo(float).eps * abs(x):
            lo = t + math.floor(x) * dt
            raise ValueError(f"t_end = {t_end:.10g} is not a whole number of steps dt = {dt:g} from t = {t:.10g} "
                             f"({x:.6g} steps); the nearest reachable times are {lo:.10g} and {lo + dt:.10g}")
        if n < 0:
            raise ValueError(f"t_end = {t_end:.10g} lies before the current time t = {t:.10g}; a run goes forward only")
        return n

    def run(self, t_end=None, writer=None, progress=None, progress_every=None, checkpointer=None,
            stop=None) -> RunSummary:
        """Run from the current time to ``t_end`` (default ``run.t_end``).

        Can be called again to continue in chunks (``sim.run(1.0); sim.run(2.0)`` takes the
        steps of ``sim.run(2.0)``; a writer gets a frame at the end of each chunk).

        Parameters
        ----------
        t_end : float, optional
            A whole number of steps ahead of the current time (ValueError otherwise, and for
            a time in the past; see :meth:`steps_to`).
        writer : RunWriter-like, optional
            Receives a frame at the start (if it has none yet), every
            ``output.interval`` of simulated time (nearest step), and at the end.
        progress : callable(sim, done, total), optional
            Called every ``progress_every`` steps (default: about 200 times a run).
        checkpointer : object with ``due() -> bool`` and ``write(sim)``, optional
            Asked after every step; when due, the writer's pending per-step rows and
            events are flushed and a checkpoint is written. One is also written at the end.
        stop : callable() -> bool, optional
            Checked after every step; when true, pending data are flushed, a checkpoint
            is written and :class:`RunInterrupted` is raised.

        Returns
        -------
        RunSummary
        """
        t_end = self.params.run.t_end if t_end is None else t_end
        n_steps = self.steps_to(t_end)
        every = max(1, int(round(self.params.output.interval / self.dt)))
        pevery = progress_every or max(1, n_steps // 200)
        summary = RunSummary(t_start=self.state.time)
        rows = min(every, n_steps) + 1  # an output interval longer than the run needs no larger buffer
        self._pending = (np.empty(rows, dtype=np.int64), np.empty(rows), [0])
        if self._energy0 is None:
            self._record_initial_energy()
        self._last_good = (self.state.position.copy(), self.state.velocity.copy())
        if writer is not None and writer.n_frames == 0:
            self._write(writer)
        t0 = time.perf_counter()
        obs = None
        done = 0
        try:
            for i in range(1, n_steps + 1):
                self.step()
                if self.state.step % every == 0 and writer is None:
                    self._check_energy(self.observables())
                if writer is not None:
                    # frames fall on absolute steps that are multiples of `every`, so at most
                    # `every` steps pass between two frames
                    steps, values, nb = self._pending
                    steps[nb[0]] = self.state.step
                    values[nb[0]] = self.integrator.bond_error_before
                    nb[0] += 1
                    if self.state.step % every == 0 or i == n_steps:
                        obs = self._write(writer)
                if progress is not None and (i % pevery == 0 or i == n_steps):
                    progress(self, i, n_steps)
                done = i
                if stop is not None and stop():
                    self._checkpoint(writer, checkpointer)
                    raise RunInterrupted(self.state.step)
                if checkpointer is not None and checkpointer.due():
                    self._checkpoint(writer, checkpointer)
        finally:
            summary.steps = done
            summary.wall_seconds = time.perf_counter() - t0
        if checkpointer is not None:
            self._checkpoint(writer, checkpointer)
        summary.t_end = self.state.time
        summary.max_bond_error = self.max_bond_error
        obs = obs if obs is not None else self.observables()
        summary.energy_balance = float(obs["energy_balance"])
        summary.energy_scale = self.energy_scale(obs)
        summary.frames = writer.n_frames if writer is not None else 0
        return summary

    def _flush_pending(self, writer):
        """Hand the per-step rows and events not yet written to the writer."""
        if writer is None:
            return
        steps, values, nb = getattr(self, "_pending", (None, None, [0]))
        if nb[0]:
            writer.write_per_step(steps[:nb[0]], values[:nb[0]])
            nb[0] = 0
        if self.graph is not None:
            done = getattr(writer, "events_written", 0)
            writer.write_events(self.events[done:])
            writer.events_written = len(self.events)

    def _checkpoint(self, writer, checkpointer):
        if checkpointer is None:
            return
        self._flush_pending(writer)
        if writer is not None:
            writer.flush()
        checkpointer.write(self)

    def _write(self, writer):
        st = self.state
        obs = self.observables()
        # checked before anything of the frame is written (frame 0 too): no NaN reaches the file
        self._check_energy(obs)
        self._last_good = (st.position.copy(), st.velocity.copy())
        self._flush_pending(writer)
        writer.write_frame(st.step, st.time, st.position, st.velocity, obs)
        if self.graph is not None:
            sol = self.solution
            writer.write_graph(st.step, st.time, self.graph.arrays(), self.graph.topology().role,
                               self.force_field.current,
                               sol.potential if sol is not None else np.full(st.n_tips, np.nan),
                               self.conductor_potential)
        writer.flush()
        return obs

    def _slow_hint(self) -> str:
        """With multiple time stepping, the other suspect of a failure (appended to its message)."""
        k = self.params.integrator.slow_every
        if k <= 1:
            return ""
        return (f"; or the slow forces, evaluated every integrator.slow_every = {k} steps, change too much "
                f"in between: try a smaller slow_every (8 or 16 in the shipped scenes)")

    def energy_scale(self, obs) -> float:
        """Energy turned over so far: kinetic energy plus |work| of every non-conservative channel."""
        return abs(obs["energy/kinetic"]) + sum(abs(v) for k, v in obs.items() if k.startswith("work/"))

    def _check_energy(self, obs):
        """Stop when an energy or work is not finite, or the energy balance is off by more than
        ``integrator.energy_tolerance`` of the scale (NaN counts as off).

        Brakes stiffer than the step can follow make the AB4 step pump energy into the
        contact modes that the brake then dissipates: positions and bonds stay sane, but
        the balance E - E0 - W grows to the size of the dissipated work.
        """
        st = self.state
        bad = [k for k, v in obs.items()
               if (k.startswith(("energy", "work/")) or k == "momentum") and not np.isfinite(v).all()]
        if bad:
            terms = [k.split("/", 1)[1] for k in bad if "/" in k and k.split("/", 1)[1] != "kinetic"]
            term = terms[0] if terms else None
            where = (f"the '{term}' term is out of scale: check its parameters and the charges it acts on "
                     f"({_term_keys(term)})" if term else
                     "the state itself is out of scale (velocities or positions beyond double precision)")
            raise NumericalFailure(
                f"numerical failure at step {st.step} (t = {st.time:.6g}): non-finite (NaN or inf) "
                f"{', '.join(bad[:6])}; {where}. Nothing non-finite was written.", st.step)
        tol = self.params.integrator.energy_tolerance
        scale = self.energy_scale(obs)
        err = abs(obs["energy_balance"])
        if scale > 0 and not err <= tol * scale:
            st = self.state
            works = sorted(((abs(v), k[5:]) for k, v in obs.items() if k.startswith("work/")), reverse=True)
            top = works[0][1] if works else "none"
            raise NumericalFailure(
                f"numerical failure at step {st.step} (t = {st.time:.6g}): the energy balance is off by {err:.3g}, "
                f"{err / scale:.0%} of the energy turned over ({scale:.3g}; integrator.energy_tolerance = {tol:g}); "
                f"the largest work is done by the '{top}' term. The time step integrator.dt = {self.dt:g} is likely "
                f"past the stability limit of the stiff contact terms (tip brake k_br, tip core): try half of it"
                f"{self._slow_hint()}.",
                st.step)


#: the scenario keys behind each force channel (for failure messages that name a term)
_CHANNEL_KEYS = {
    "tip_magnetic": "rods.magnetic_charge, rods.tip_stiffness, rods.transition_radius",
    "tip_brake": "forces.tip_brake.coefficient",
    "ambient_brake": "forces.ambient_brake.coefficient",
    "uniform_field": "forces.uniform_field.B, rods.magnetic_charge",
    "plasma_filament": "forces.plasma_filament.current, forces.plasma_filament.radius, rods.magnetic_charge",
    "yukawa": "rods.electric_charge, forces.yukawa.screening_length, forces.yukawa.core_radius",
    "electric_field": "forces.electric_field.E, rods.electric_charge",
    "electrodes": "forces.electrodes.gap, rods.tip_stiffness",
    "electrode_brake": "forces.electrodes, forces.tip_brake.coefficient",
    "current_field": "circuit.delta_J0, rods.magnetic_charge",
    "current_lorentz": "circuit.delta_J0 and the fields the currents sit in",
    "external_filament": "forces.external_filament.current, forces.external_filament.diameter",
    "external_dipole": "forces.external_dipole.*, rods.magnetic_charge, rods.electric_charge",
}


def _term_keys(channel) -> str:
    for name, keys in _CHANNEL_KEYS.items():
        if channel and channel.startswith(name):
            return keys
    return f"forces.{channel}" if channel else "the force terms"
