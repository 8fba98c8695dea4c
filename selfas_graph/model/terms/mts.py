"""Multiple time stepping, ``integrator.slow_every = K > 1``
(docs/model.md 'Multiple time stepping (`integrator.slow_every`)').

The slow terms (:attr:`Term.slow <selfas_graph.model.terms.base.Term.slow>`: the far tip
pairs, the Yukawa sum, the rod-current terms) are evaluated on full evaluations only; in
between, their forces are held, or extrapolated linearly in time from their last two full
evaluations. The tip-tip force is split: its close pairs (within the fast range) are
evaluated at every step, its far part (``tip_far``) is held. A slow term whose inputs
changed (new currents) is *stale* and is computed at the next evaluation, full or not. With
``integrator.current_every = M`` (a multiple of K) the terms that read the currents are computed only
on the full evaluations of every M-th step, and extrapolated on the others; also when stale, and on
every full evaluation until their rate is taken from two evaluations after the last change of the
currents (new currents start a base with no rate: a jump, not a trend), and in the RK4 start steps.
"""

from __future__ import annotations

import numpy as np

from ...kernels.integrate import extrapolate_all


class MultipleTimeStepping:
    """The held slow forces of one :class:`~selfas_graph.model.terms.forcefield.ForceField`.

    Parameters
    ----------
    params : Parameters
    terms : list of Term
        The field's terms; the slow ones are held.
    out : dict of (n_tips, 3) arrays
        The field's channel buffers (the slow channels are held in place there).
    tip_term : TipMagneticForce or None
        The tip-tip term, whose fast part is evaluated at every step.
    clock : TermClock, optional
        Times the fast part as ``tip_magnetic_fast`` when it is on.
    """

    def __init__(self, params, terms, out, tip_term=None, clock=None):
        ip = params.integrator
        self.slow_every = ip.slow_every
        self.out = out
        self.tip_term = tip_term
        if tip_term is not None:
            rstar = params.rods.rstar
            #: close tip pairs: full force below r_in, switched off smoothly up to r_out
            self.fast_range = ((ip.fast_range - 1.0) * rstar, ip.fast_range * rstar)
            self.tip_far = np.zeros_like(out["tip_magnetic"])
            #: the fast part of the tip-tip force (also written by the compiled steps, model/compiled.py)
            self.tip_fast = np.zeros_like(out["tip_magnetic"])
            self._fast = tip_term.fast if clock is None else clock.wrap("tip_magnetic_fast", tip_term.fast)
        #: slow term name -> the held arrays it refreshes (``held_forces`` keys)
        self.slow_keys = {
            t.name: (["tip_far"] if t is tip_term else [c for c, _ in t.channels]) for t in terms if t.slow
        }
        #: slow terms whose inputs changed (new currents): computed at the next evaluation, full or not
        self.stale = set(self.slow_keys)
        self._uses_currents = [t.name for t in terms if t.slow and t.uses_currents]
        #: steps between the full evaluations of the terms that read the currents (``current_every``, or K)
        self.current_every = ip.current_every or ip.slow_every
        #: each held array's own interval between evaluations: the longest gap across which a rate is taken is twice it
        self._interval = {
            key: (self.current_every if name in self._uses_currents else self.slow_every)
            for name, keys in self.slow_keys.items()
            for key in keys
        }
        #: the held arrays by name (fixed objects, written in place): what held_forces returns
        self._held = {
            key: (self.tip_far if key == "tip_far" else self.out[key])
            for keys in self.slow_keys.values()
            for key in keys
        }
        self.extrapolate = ip.slow_extrapolation
        if self.extrapolate:
            #: bases and rates as the rows of two blocks, so that one kernel call extrapolates them all; with
            #: base_step (the step of each base, None before one) read by the compiled steps
            keys = list(self._held)
            self._held_arrays = tuple(self._held[k] for k in keys)
            self.base_block = np.zeros((len(keys),) + self._held_arrays[0].shape) if keys else None
            self.rate_block = np.zeros_like(self.base_block) if keys else None
            self._base = {k: self.base_block[j] for j, k in enumerate(keys)}
            self._rate = {k: self.rate_block[j] for j, k in enumerate(keys)}
            self.base_step = {k: None for k in self._base}
            #: whether a held array's rate was taken over a gap of evaluations (not zeroed by a start,
            #: a long gap or new currents): with current_every a term whose rate
            #: is not is computed at every full evaluation (:meth:`skips`)
            self._rated = {k: False for k in self._base}
            self._steps = np.full(len(keys), np.nan)

    def skips(self, name, step, starting=False) -> bool:
        """Whether the full evaluation at ``step`` leaves the slow term ``name`` to be extrapolated
        (``integrator.current_every``): a term that reads the currents, off its pattern (every M-th step,
        counted from step 0 as K is), not stale and, with extrapolation, with a rate taken since the last
        change of the currents. Never in the RK4 start (``starting``) or its stages (``step`` None)."""
        if self.current_every == self.slow_every or step is None or starting:
            return False
        if name not in self._uses_currents or name in self.stale or step % self.current_every == 0:
            return False
        return not self.extrapolate or all(self._rated[k] for k in self.slow_keys[name])

    def currents_changed(self) -> None:
        """New rod currents: the slow terms that read them are computed at the next evaluation."""
        self.stale.update(self._uses_currents)

    def complete(self, ctx, refreshed, full, step) -> None:
        """After the terms ran on ``ctx`` (an :class:`~selfas_graph.model.terms.context.EvalContext`):
        add the tip-tip fast part, extrapolate (or keep) the held forces.

        ``refreshed`` lists the slow terms computed in this evaluation; ``full`` and ``step`` are
        those of :meth:`ForceField.evaluate <selfas_graph.model.terms.forcefield.ForceField.evaluate>`.
        """
        # the held arrays of the terms computed because the currents changed: no rate (a jump)
        jumped = [k for name in self.stale if name in refreshed for k in self.slow_keys[name]]
        self.stale.clear()
        fast = None
        tip_fresh = "tip_magnetic" in refreshed
        if self.tip_term is not None:
            fast = self.tip_fast
            self._fast(ctx, *self.fast_range, fast)
            if tip_fresh:
                np.subtract(self.out["tip_magnetic"], fast, out=self.tip_far)
        if self.extrapolate:
            self._extrapolate(
                [k for name in refreshed for k in self.slow_keys[name]] if refreshed else (), full, step, jumped
            )
        if fast is not None and not tip_fresh:
            np.add(self.tip_far, fast, out=self.out["tip_magnetic"])

    def _extrapolate(self, refreshed, full, step, jumped=()):
        """Linear extrapolation in time of each held slow force from its last two evaluations.

        A force just ``refreshed`` becomes the new base; its rate is the difference from the
        previous base over the steps between them when both were full evaluations at step
        starts at most two of its intervals apart (K, or M = ``current_every`` for the current
        terms), else zero: after an RK4 start, and for the arrays in ``jumped`` (computed because
        the currents changed, before a fast step or a full one: a jump, not a trend).
        The others are extrapolated to ``step``.
        """
        steps = self._steps  # steps since each held force's base, NaN: left as it is
        extrapolated = False
        for j, (key, arr) in enumerate(self._held.items()):
            base, rate, prev = self._base[key], self._rate[key], self.base_step[key]
            steps[j] = np.nan
            if key in refreshed:
                gap = None if (prev is None or step is None or not full) else step - prev
                if key in jumped:
                    gap = None  # new currents: a jump, not a trend
                if gap is not None and 0 < gap <= 2 * self._interval[key]:
                    np.subtract(arr, base, out=rate)
                    rate /= gap
                    self._rated[key] = True
                else:
                    rate.fill(0.0)
                    self._rated[key] = False
                base[:] = arr
                self.base_step[key] = step if full else None
            elif prev is not None and step is not None:
                steps[j] = step - prev
                extrapolated = True
        if extrapolated:
            # rate * (step - prev) + base of each, as np.multiply(rate, steps, out=arr); arr += base
            extrapolate_all(self._held_arrays, self.rate_block, self.base_block, steps)

    def held_forces(self) -> dict:
        """The slow forces held between full evaluations, by name (the slow channels and ``tip_far``,
        the tip-tip force less its fast part); views, not copies."""
        return dict(self._held)

    def base_step_array(self) -> np.ndarray:
        """(n_held,) int64: the step of each held force's base, in the order of :meth:`held_forces`
        (the bases' rows are in that order), -1 where there is none yet or no extrapolation."""
        if not self.extrapolate:
            return np.full(len(self._held), -1, dtype=np.int64)
        return np.array([-1 if b is None else b for b in self.base_step.values()], dtype=np.int64)

    def state_dict(self) -> dict:
        """What the next evaluations depend on besides the state, as copies: held forces, the stale
        terms and, with extrapolation, bases, rates and their steps (flat, checkpoint keys ``mts_*``)."""
        snap = {f"mts_held_{k}": v.copy() for k, v in self.held_forces().items()}
        snap["mts_stale"] = np.array([name in self.stale for name in self.slow_keys], dtype=bool)
        if self.extrapolate:
            snap.update({f"mts_base_{k}": v.copy() for k, v in self._base.items()})
            snap.update({f"mts_rate_{k}": v.copy() for k, v in self._rate.items()})
            snap["mts_base_step"] = self.base_step_array()
            snap["mts_rated"] = np.array(list(self._rated.values()), dtype=bool)
        return snap

    def load_state_dict(self, snap: dict) -> bool:
        """Put back what :meth:`state_dict` returned; False (every slow term then computed at the next
        evaluation) when ``snap`` was taken with other settings, e.g. without multiple time stepping."""
        mine = self.state_dict()
        optional = {"mts_rated"}  # checkpoints before current_every lack it
        if set(mine) - set(snap) - optional or np.shape(snap["mts_stale"]) != mine["mts_stale"].shape:
            return False
        for k, v in self.held_forces().items():
            v[:] = snap[f"mts_held_{k}"]
        self.stale = {name for name, flag in zip(self.slow_keys, np.asarray(snap["mts_stale"])) if flag}
        if self.extrapolate:
            for k in self._base:
                self._base[k][:] = snap[f"mts_base_{k}"]
                self._rate[k][:] = snap[f"mts_rate_{k}"]
            steps = np.asarray(snap["mts_base_step"])
            self.base_step = {k: (None if b < 0 else int(b)) for k, b in zip(self._base, steps)}
            rated = np.asarray(snap["mts_rated"]) if "mts_rated" in snap else (steps >= 0)
            self._rated = {k: bool(r) for k, r in zip(self._base, rated)}
        return True
