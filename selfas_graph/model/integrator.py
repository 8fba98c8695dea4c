"""Explicit 4-step Adams-Bashforth with the rigid-bond constraint (paper Sec. 2, docs/model.md 'Rigid rods and time integration').

The state ``y = (x, v)`` obeys ``dx/dt = v``, ``dv/dt = a(x, v)`` where ``a`` is
the force per unit mass plus the rigid-bond force. :meth:`AdamsBashforth4.step` is the
"forces -> Adams-Bashforth update -> split brake -> bond constraint" part of the step
whose order docs/model.md 'Order of one step' states. Its update is Adams-Bashforth 4,
``y_{n+1} = y_n + dt/24 (55 f_n - 59 f_{n-1} + 37 f_{n-2} - 9 f_{n-3})``, once four
derivatives are in the history, and a classical RK4 step otherwise (self-starting: the
first three steps, and the first three after :meth:`reset_history`). With
``integrator.slow_every = K > 1`` (multiple time stepping) the slow forces (far tip pairs,
Yukawa, rod-current terms) are evaluated on every K-th step and extrapolated (or held) in
between; the stiff short-range forces are fresh every step. With ``integrator.brake =
"split"`` the stiff brakes, left out of the update, act on the velocities through their
exact solution over dt, pair after pair. The work of each non-conservative channel
advances with the same weights as the positions (AB4 or RK4), so the energy balance
``E(t) - E(0) - W(t)`` measures only the integration error.

The largest bond-length error before the constraint (the step's own error) and
after it (what remains in the state) are recorded for every step, and so is the largest
velocity component after it (what the run's health check reads).

The update, the bond check, the constraint and the second check run as two kernels
(``ab4_step``, ``constrain_bonds_checked``), bit for bit the five calls they replace: at 2400
tips a kernel call costs more in dispatch than its loop (measured in docs/log/performance-2025-2026.md
'Less serial work per step').
"""

from __future__ import annotations

import numpy as np

from ..kernels.integrate import ab4_step, axpy
from ..kernels.rigid import bond_acceleration, bond_length_error, constrain_bonds_checked

AB4_WEIGHTS = np.array([55.0, -59.0, 37.0, -9.0]) / 24.0


def same_time_step(d: dict, dt: float) -> bool:
    """Whether the state dict ``d`` (its step, time and time origin) was made at the time step ``dt``: its
    step's time counted from its origin at ``dt`` (as :meth:`AdamsBashforth4.time_at`) is its time. True
    for a dict without a step or time origin."""
    if "step" not in d or "time_origin_step" not in d:
        return True
    steps = int(d["step"]) - int(d["time_origin_step"])
    return float(d["time_origin_time"]) + steps * dt == float(d["time"])


class AdamsBashforth4:
    """AB4 on positions and velocities of rigid two-tip rods.

    Parameters
    ----------
    force_field : ForceField
    dt : float
    exact_bond : bool
        Exact bond force (True) or the paper's Eq. (9) (False).
    project, correct_velocity : bool
        Apply the position projection / the velocity correction after each step.
    split_brakes : bool
        Leave the stiff brakes out of the update and apply them exactly to the velocities after it
        (docs/model.md 'The stiff brakes').
    slow_every : int
        K: evaluate the slow forces every K steps and extrapolate them in between (1: every step;
        docs/model.md 'Multiple time stepping (`integrator.slow_every`)').
    """

    def __init__(
        self, force_field, dt, exact_bond=True, project=True, correct_velocity=True, split_brakes=False, slow_every=1
    ):
        self.ff = force_field
        self.dt = float(dt)
        self.exact_bond = bool(exact_bond)
        self.project = bool(project)
        self.correct_velocity = bool(correct_velocity)
        self.split_brakes = bool(split_brakes)
        self.slow_every = int(slow_every)
        n = force_field.n_tips
        n_ch = len(force_field.nonconservative)
        # ring buffers of derivatives; slot (head - j) % 4 holds f_{n-j}
        self.hist_v = np.zeros((4, n, 3))
        self.hist_a = np.zeros((4, n, 3))
        self.hist_p = np.zeros((4, n_ch))
        self.head = -1
        self.count = 0
        #: (step, time) from which time is counted as time0 + (step - step0) dt, free of summed round-off
        self.time_origin = (0, 0.0)
        self.work = np.zeros(n_ch)
        self.bond_error_before = 0.0
        self.bond_error_after = 0.0
        #: the largest velocity component |v_k,d| after the last step (NaN if one is NaN)
        self.speed_max = 0.0
        self._tmp = [np.zeros((n, 3)) for _ in range(4)]
        self._p = np.zeros(n_ch)
        #: the history slots of f_n, f_{n-1}, f_{n-2}, f_{n-3} for each head
        self.slots = [np.array([(h - j) % 4 for j in range(4)], dtype=np.int64) for h in range(4)]

    def reset_history(self):
        """Forget the derivative history; the next three steps are RK4 again."""
        self.count = 0

    def state_dict(self) -> dict:
        """Derivative history, work per channel, time origin and bond errors: what the next
        steps depend on besides the state (arrays and plain values)."""
        return {
            "hist_v": self.hist_v.copy(),
            "hist_a": self.hist_a.copy(),
            "hist_p": self.hist_p.copy(),
            "head": self.head,
            "count": self.count,
            "work": self.work.copy(),
            "time_origin_step": self.time_origin[0],
            "time_origin_time": self.time_origin[1],
            "bond_error_before": self.bond_error_before,
            "bond_error_after": self.bond_error_after,
        }

    def load_state_dict(self, d: dict) -> None:
        """Restore :meth:`state_dict` (also as read back from a checkpoint)."""
        self.hist_v[:], self.hist_a[:], self.hist_p[:] = d["hist_v"], d["hist_a"], d["hist_p"]
        self.head, self.count = int(d["head"]), int(d["count"])
        self.work[:] = d["work"]
        self.time_origin = (int(d["time_origin_step"]), float(d["time_origin_time"]))
        if not same_time_step(d, self.dt):
            # a snapshot continued at another time step than it was made with (from_snapshot's new_dt):
            # the time counts on from the snapshot's, not from the run's origin at the new dt
            self.time_origin = (int(d["step"]), float(d["time"]))
        self.bond_error_before = float(d["bond_error_before"])
        self.bond_error_after = float(d["bond_error_after"])

    def acceleration(self, position, velocity, out, power, full=True, step=None, starting=False):
        """Tip accelerations (forces plus rigid bonds) at (position, velocity).

        ``full=False``: the slow forces are those held from the last full evaluation
        (multiple time stepping, see :meth:`step`); ``starting``: a step of the RK4 start.
        """
        force = self.ff.evaluate(position, velocity, power, full=full, step=step, starting=starting)
        bond_acceleration(force, velocity, position, self.exact_bond, out)
        return out

    def step(self, state):
        """Advance ``state`` (in place) by one time step."""
        x, v = state.position, state.velocity
        self.head = (self.head + 1) % 4
        h = self.head
        self.hist_v[h] = v
        # multiple time stepping: the slow forces are evaluated on every slow_every-th step (counted
        # from step 0, so a resumed run keeps the pattern) and in the self-starting RK4 steps; in
        # between they are extrapolated (the current terms are also recomputed after new currents)
        full = state.step % self.slow_every == 0 or self.count < 3
        self.acceleration(x, v, self.hist_a[h], self.hist_p[h], full=full, step=state.step, starting=self.count < 3)
        self.count = min(self.count + 1, 4)
        ell = state.bond_length()
        # the bond error of the updated positions is the step's own; the brakes below change velocities only
        if self.count == 4:
            slots = self.slots[h]
            self.work += self.dt * (AB4_WEIGHTS @ self.hist_p[slots])
            self.bond_error_before = ab4_step(x, v, self.hist_v, self.hist_a, slots, self.dt, ell)
        else:
            self._rk4(x, v, self.hist_v[h], self.hist_a[h], self.hist_p[h])
            self.bond_error_before = bond_length_error(x, ell)
        if self.split_brakes:
            self.ff.split_brakes(x, v, self.dt, self.work)
        # without the projection the positions keep their error: the same value as before
        self.bond_error_after, self.speed_max = constrain_bonds_checked(x, v, self.project, self.correct_velocity, ell)
        state.step += 1
        state.time = self.time_at(state.step)

    def time_at(self, step) -> float:
        """The time of step ``step``: counted from the time origin, so that it does not drift as a sum."""
        return self.time_origin[1] + (step - self.time_origin[0]) * self.dt

    def finish_compiled(self, state, n, head, bond_before, bond_after, speed) -> None:
        """Take over the ``n`` steps a compiled call made (:mod:`.compiled`): the ring buffer's head, the
        last step's bond errors and largest speed, and the state's step and time."""
        self.head = head
        self.bond_error_before, self.bond_error_after, self.speed_max = bond_before, bond_after, speed
        state.step += n
        state.time = self.time_at(state.step)

    def _rk4(self, x, v, v1, a1, p1):
        dt = self.dt
        xs, vs, a_k, acc_v = self._tmp
        p = self._p
        acc_a = np.array(a1)
        acc_v[:] = v1
        work = p1.copy()
        vk, ak = v1, a1
        for c, w in ((0.5, 2.0), (0.5, 2.0), (1.0, 1.0)):
            axpy(x, vk, c * dt, xs)
            axpy(v, ak, c * dt, vs)
            self.acceleration(xs, vs, a_k, p)
            acc_v += w * vs
            acc_a += w * a_k
            work += w * p
            vk, ak = vs.copy(), a_k.copy()
        axpy(x, acc_v, dt / 6.0, x)
        axpy(v, acc_a, dt / 6.0, v)
        with np.errstate(over="ignore", invalid="ignore"):  # a runaway start: the health check names it
            self.work += dt / 6.0 * work
