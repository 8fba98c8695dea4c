"""Health checks of a running simulation: broken bonds, runaway steps, non-finite values, the
energy balance; each failure stops the run with a diagnosis that names the likely cause
(docs/model.md 'Work bookkeeping and the energy balance').

:class:`HealthChecks` is a component of :class:`~.simulation.Simulation` (``sim.health``), built
with the parts it reads: the parameters, the state, the integrator and the force field.
"""

from __future__ import annotations

import math

import numpy as np

from .observables import energy_scale

#: a bond whose length is off by more than this after a step is broken: no
#: corrector recovers it meaningfully (typical per-step errors are < 1e-6)
BOND_BREAK = 0.05
#: a tip moving more than this (in rod lengths, along one coordinate: |v_k,d| dt) in one step means
#: the step is far beyond stability: the tip core (width r* ~ 0.06) is crossed in one step
MAX_STEP_DISPLACEMENT = 0.25
#: |lambda dt| below which Adams-Bashforth 4 follows a decay at rate lambda: a brake of rate lambda
#: per unit mass needs dt < AB4_DECAY_LIMIT / lambda (docs/model.md 'The stiff brakes')
AB4_DECAY_LIMIT = 0.3
#: slow forces held longer than this (integrator.slow_every * dt, t0) are the first suspect of a failure
SLOW_HELD_LONG = 0.1
#: the relative round-off of the energies and works the balance adds up, times a margin: a balance
#: below this fraction of their sum is round-off, not an error of the step
ROUND_OFF_ENERGY = 1e-12
#: the stiffest force of a sane scene, the tip core's kappa / r*^2 at kappa = 1, r* = 0.06, is
#: 278, and the paper's scenes stay below 1e4; a failure with a force above this blames the term
#: (out of scale rather than a time-step problem)
FORCE_OUT_OF_SCALE = 1e8


def stiff_brakes(params, dt) -> str:
    """A diagnosis naming a brake too stiff for dt, or "". Tips have unit mass; AB4 follows a decay
    at rate lambda only for lambda dt below about 0.3 (docs/model.md 'The stiff brakes'). The
    ambient brake (rate M_br) is always in the step; the tip brake (rate 2 k_br for a pair, m k_br
    at a junction of m tips) only with integrator.brake = "explicit". ``simulate --dry-run`` names it
    before any step."""
    f, ip = params.forces, params.integrator
    over = []
    if f.ambient_brake is not None and f.ambient_brake.coefficient * dt > AB4_DECAY_LIMIT:
        k = f.ambient_brake.coefficient
        over.append(
            f"the 'ambient_brake' term is too stiff for the step: forces.ambient_brake.coefficient * dt = "
            f"{k * dt:.3g}, and Adams-Bashforth 4 follows a brake only below about {AB4_DECAY_LIMIT:g} "
            f"(the ambient brake is in the step whatever integrator.brake says): a dt below "
            f"{AB4_DECAY_LIMIT / k:.3g}, or a smaller coefficient"
        )
    if ip.brake == "explicit" and f.tip_brake is not None and 2 * f.tip_brake.coefficient * dt > AB4_DECAY_LIMIT:
        k = f.tip_brake.coefficient
        over.append(
            f"the 'tip_brake' term is too stiff for the step: 2 * forces.tip_brake.coefficient * dt = "
            f"{2 * k * dt:.3g} for a pair of tips (more at junctions), and Adams-Bashforth 4 follows a "
            f'brake only below about {AB4_DECAY_LIMIT:g}: integrator.brake = "split" takes it out of the step'
        )
    return "; ".join(over)


class NumericalFailure(RuntimeError):
    """The run went numerically wrong; the message is a diagnosis."""

    def __init__(self, message, step, rods=()):
        super().__init__(message)
        self.step = step
        self.rods = list(rods)


def refuse_after(failure) -> None:
    """Refuse to step a simulation that ``failure`` (a NumericalFailure, or None) stopped: its state is the
    failed one, steps from it would integrate that (NaN within a few steps), and a writer would record a
    later failure in place of the first."""
    if failure is not None:
        raise RuntimeError(
            f"this simulation stopped at step {failure.step} ({failure}); its state is the failed one. Continue "
            f"from the last state that passed the checks, with other settings if need be: "
            f"Simulation.from_snapshot(params, sim.last_good_snapshot)"
        )


class HealthChecks:
    """The checks a simulation runs after every step (:meth:`after_step`) and on every frame
    (:meth:`check_energy`); each failure raises :class:`NumericalFailure` with a diagnosis.

    Parameters
    ----------
    params : Parameters
    state : State
        Advanced in place by the integrator (the same object all run long).
    integrator : AdamsBashforth4
        Its bond errors and largest speed after each step; its time step.
    force_field : ForceField
        Evaluated at the last good state to find a term out of scale.

    Attributes
    ----------
    max_bond_error : float
        The largest bond-length error after the constraint so far.
    last_good_snapshot : dict or None
        The simulation's snapshot of the last state that passed the checks of a run at its start or
        at a frame (None before a run): finite, so a failure file can hold it in place of the failed one.
    """

    def __init__(self, params, state, integrator, force_field):
        self.params = params
        self.state = state
        self.integrator = integrator
        self.force_field = force_field
        self.max_bond_error = 0.0
        self.last_good_snapshot = None
        self._last_good = None

    @property
    def dt(self) -> float:
        return self.integrator.dt

    def keep_last_good(self, snapshot: dict) -> None:
        """Keep the state that has just passed the checks (the run's start, each frame), and its
        ``snapshot``: the failure diagnosis evaluates its forces, and a failure file stores the
        snapshot (finite, resumable)."""
        self._last_good = (self.state.position.copy(), self.state.velocity.copy())
        self.last_good_snapshot = snapshot

    def after_step(self):
        """Stop with a diagnosis on a broken bond, a runaway step or a non-finite position or
        velocity; else record the step's bond error."""
        integ = self.integrator
        err = integ.bond_error_before
        self.max_bond_error = max(self.max_bond_error, integ.bond_error_after)
        vmax = integ.speed_max  # max |v_k,d| after the step, NaN if one is NaN (np.abs(v).max())
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
            what = f"a broken rigid bond (length error {err:.3g} >= {BOND_BREAK})"
            # the step's projection has given every bond its length again, so the bond errors now are
            # round-off and tell no rod: the tips that moved most since the last state that passed
            good = self._last_good
            moved = speed if good is None or good[0].shape != x.shape else np.linalg.norm(x - good[0], axis=1)
            tips = np.argsort(-moved)[:5]
        else:
            what = f"a runaway step (a tip moved {vmax * self.dt:.3g} rod lengths along one axis in one step)"
            tips = np.argsort(-speed)[:5]
        rods = sorted(set(int(k) // 2 for k in tips[:10]))
        term, force = self._out_of_scale_term()
        if term is not None:
            msg = (
                f"numerical failure at step {st.step} (t = {st.time:.6g}): {what}; rods involved: "
                f"{rods[:10]}; the '{term}' term's force was already {force:.3g} F_M0 at the last saved state, "
                f"out of scale (above {FORCE_OUT_OF_SCALE:g}): no time step follows it. Check the parameters "
                f"of that term and the charges it acts on ({self.force_field.channel_keys(term)})."
            )
            raise NumericalFailure(msg, st.step, rods)
        dominant = self.force_field.dominant_channel(np.asarray(tips[:10]))
        cause = (
            f"largest force on them from the '{dominant}' term"
            if dominant != "none"
            else "no force acts on them (no term is on, or every force on them is zero), so the step alone is at fault"
        )
        stiff = stiff_brakes(self.params, self.dt)
        if stiff:
            cause = stiff
        advice = (
            f"The time step integrator.dt = {self.dt:g} is the likely cause: try a smaller one "
            f"(the stiff parts are the tip core and the brakes inside r*){self._slow_hint()}."
        )
        if dominant == "tip_magnetic" and not stiff:
            advice += self._core_hint()
        if slow := self._slow_first():
            advice = f"{slow[:1].upper()}{slow[1:]}."
        if err >= BOND_BREAK and not (self.integrator.project or self.integrator.correct_velocity):
            # measured: the quick scene fails at t = 0.042 with dt = 1e-3, 1e-4 and 1e-5 alike
            advice = (
                "integrator.position_projection and integrator.velocity_correction are both off, so nothing "
                "takes out the drift of the bond lengths (the split brakes add velocity along the rods at every "
                "step, whatever its length, and a smaller step does not help): turn either back on."
            )
        msg = f"numerical failure at step {st.step} (t = {st.time:.6g}): {what}; rods involved: {rods[:10]}; {cause}. {advice}"
        raise NumericalFailure(msg, st.step, rods)

    def _core_hint(self) -> str:
        """Where the tip-tip force failed the step: how long two tips falling together take to cross the
        core r* (docs/model.md 'Term 1'), against dt. From rest far away, a pair of charges q falls to
        r* with the energy q^2 / r*, a speed of about q sqrt(2 / r*) for unit masses, and crosses the
        core in r* / v: a step that is not a small part of that cannot follow the fall, and a tiny r*
        asks for a tiny step."""
        rstar = self.params.rods.rstar
        q = float(np.max(np.abs(self.state.tip_charge), initial=0.0))
        if not (q > 0 and rstar > 0):
            return ""
        speed = q * math.sqrt(2.0 / rstar)
        crossing = rstar / speed
        if self.dt < 0.5 * crossing:  # the quick scene runs at 0.19 of it (r* = 0.06, q up to 2, dt = 1e-3)
            return ""
        return (
            f" Two tips falling together reach about {speed:.3g} at the core r* = {rstar:g} "
            f"(rods.transition_radius, or rods.diameter) and cross it in about {crossing:.3g}: a step must be a "
            f"small part of that (dt below about {0.2 * crossing:.2g}), or r* larger."
        )

    def _coarse_split(self) -> str:
        """With integrator.brake = "split": a diagnosis naming the tip brake when its splitting from the
        step is coarse (coefficient * dt above :data:`AB4_DECAY_LIMIT`), or "". The split brake is stable
        at any step, but the step moves the tips with velocities the brake then takes away: the splitting
        error grows with k_br dt and does not vanish until k_br dt is well below 1 (docs/model.md 'The
        stiff brakes': the quick scene 0.6 % off at k_br dt = 0.1, 16 % and 35 % at 1 and 10)."""
        f = self.params.forces
        if self.params.integrator.brake != "split" or f.tip_brake is None:
            return ""
        k = f.tip_brake.coefficient
        if k * self.dt <= AB4_DECAY_LIMIT:
            return ""
        return (
            f"the split tip brake is stable at any step but accurate only for forces.tip_brake.coefficient * dt "
            f"well below 1 (here {k * self.dt:.3g}, at integrator.dt = {self.dt:g}): a dt below "
            f"{AB4_DECAY_LIMIT / k:.3g}, or a smaller coefficient"
        )

    def _out_of_scale_term(self):
        """(channel, force) of a channel whose force at the last sane state (the last frame, or the
        start of the run) exceeds :data:`FORCE_OUT_OF_SCALE`, else (None, 0.0).

        At the failed state every force is huge (the brakes answer the runaway velocities), so
        the culprit is looked for where the run was still sane.
        """
        good = self._last_good
        if good is None:
            return None, 0.0
        ff = self.force_field
        with np.errstate(all="ignore"):
            ff.evaluate(good[0].copy(), good[1].copy(), full=True)
            name, force = ff.dominant_force(np.arange(self.state.n_tips))
        return (name, force) if name != "none" and not force <= FORCE_OUT_OF_SCALE else (None, 0.0)

    def _slow_first(self) -> str:
        """The diagnosis when the slow forces are held far longer than any shipped scene holds them
        (integrator.slow_every * dt of 0.008-0.024 t0 there): past :data:`SLOW_HELD_LONG` t0 they, not
        dt, are the first suspect (a smaller dt leaves them as stale: the quick scene at slow_every =
        1000 is 53 % off at dt = 1e-3 and at 5e-4 alike), else ""."""
        k = self.params.integrator.slow_every
        if k * self.dt < SLOW_HELD_LONG:
            return ""
        return (
            f"the slow forces are evaluated every integrator.slow_every = {k} steps ({k * self.dt:.3g} t0) and "
            f"change too much in between: try slow_every = {max(1, min(16, k // 2))} or less (the shipped scenes "
            f"hold them for 0.008-0.024 t0), and integrator.current_every a multiple of it, or 0"
        )

    def _slow_hint(self) -> str:
        """With multiple time stepping, the other suspect of a failure (appended to its message)."""
        k = self.params.integrator.slow_every
        if k <= 1:
            return ""
        return (
            f"; or the slow forces, evaluated every integrator.slow_every = {k} steps, change too much "
            f"in between: try a smaller slow_every ({max(1, k // 2)})"
            + (
                f" with integrator.current_every = {m} a multiple of it, or 0"
                if (m := self.params.integrator.current_every)
                else ""
            )
        )

    def check_energy(self, obs):
        """Stop when an energy or work is not finite, or the energy balance is off by more than
        ``integrator.energy_tolerance`` of the scale (NaN counts as off).

        Brakes stiffer than the step can follow make the AB4 step pump energy into the
        contact modes that the brake then dissipates: positions and bonds stay sane, but
        the balance E - E0 - W grows to the size of the dissipated work.
        """
        st = self.state
        bad = [
            k
            for k, v in obs.items()
            if (k.startswith(("energy", "work/")) or k == "momentum") and not np.isfinite(v).all()
        ]
        if bad:
            terms = [k.split("/", 1)[1] for k in bad if "/" in k and k.split("/", 1)[1] != "kinetic"]
            term = terms[0] if terms else None
            where = (
                f"the '{term}' term is out of scale: check its parameters and the charges it acts on "
                f"({self.force_field.channel_keys(term)})"
                if term
                else "the state itself is out of scale (velocities or positions beyond double precision)"
            )
            raise NumericalFailure(
                f"numerical failure at step {st.step} (t = {st.time:.6g}): non-finite (NaN or inf) "
                f"{', '.join(bad[:6])}; {where}. Nothing non-finite was written.",
                st.step,
            )
        tol = self.params.integrator.energy_tolerance
        scale = energy_scale(obs)
        err = abs(obs["energy_balance"])
        # the balance cannot be known better than the round-off of the energies it adds up (a potential
        # energy far from the origin is large beside the energy turned over): no failure below that
        floor = ROUND_OFF_ENERGY * sum(abs(float(v)) for k, v in obs.items() if k.startswith(("energy", "work/")))
        if scale > 0 and not err <= max(tol * scale, floor):
            st = self.state
            works = sorted(((abs(v), k[5:]) for k, v in obs.items() if k.startswith("work/")), reverse=True)
            top = (
                f"the largest work is done by the '{works[0][1]}' term"
                if works and works[0][0] > 0
                else "no term does work"
            )
            stiff = stiff_brakes(self.params, self.dt) or self._coarse_split()
            if slow := self._slow_first():
                cause = slow
            elif stiff:
                cause = f"{stiff}{self._slow_hint()}"
            else:
                core = self._core_hint().rstrip(".")  # the message ends with its own full stop
                cause = (
                    f"The time step integrator.dt = {self.dt:g} is likely past the stability limit of the stiff "
                    f"terms (the tip brake and tip core, or a strong field): try half of it{self._slow_hint()}"
                    + (f".{core}" if core else "")
                )
            tight = (
                f" (or integrator.energy_tolerance = {tol:g} asks for more than the integrator's own error; "
                f"the default is 0.1)"
                if tol < 1e-3
                else ""
            )
            raise NumericalFailure(
                f"numerical failure at step {st.step} (t = {st.time:.6g}): the energy balance is off by {err:.3g}, "
                f"{err / scale:.0%} of the energy turned over ({scale:.3g}; integrator.energy_tolerance = {tol:g}); "
                f"{top}. {cause[:1].upper()}{cause[1:]}{tight}.",
                st.step,
            )
