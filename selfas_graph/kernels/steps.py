"""Runs of fast steps in one compiled call (docs/model.md 'Order of one step', 'Multiple time stepping
(`integrator.slow_every`)'; docs/performance.md 'Fast steps in one compiled call').

Under multiple time stepping most steps evaluate only the fast terms and extrapolate the held slow
forces. :func:`fast_steps` runs such steps one after another, each in the order of the Python step
(``model/integrator.py::AdamsBashforth4.step`` with ``model/terms/forcefield.py::ForceField.evaluate``,
then the health check and the contact test of ``model/simulation.py::Simulation.step``), by calling
the kernels the Python step calls, with the same arguments: the same numbers bit for bit. It
returns at the first step that needs Python:

- ``NEEDS_STEP``: before a step that must run in Python (a slow evaluation, a slow term made stale
  by new currents, the RK4 start, or a tip neighbour list due for a rebuild, found before the step
  or, for the split tip brake, after its update: the step is then undone, positions and velocities
  put back);
- ``NEEDS_CONTACTS``: after a step whose contact test needs Python (the quiet-step test
  ``contacts.py::contacts_unchanged`` is not sure, a filament contact moved along z, or the list is
  due for a rebuild at the new positions);
- ``NEEDS_HEALTH``: after a step that fails the run's health check (Python then raises the diagnosis);
- ``DONE``: after ``n_max`` steps.

What the Python step accumulates in other objects is logged per step for the caller
(``model/compiled.py``): the bond error before the constraint (the run file's per-step rows), the
power of each non-conservative channel and the split brakes' work (the integrator's work, summed
there with numpy's matrix product, as the Python step sums it).

The O(n) kernels are called in their serial builds (``njit_rows``'s ``serial``): the caller uses
this path below ``_jit.PARALLEL_ROWS`` tips only, where the Python step calls those builds too.

**On several threads** (:func:`fast_steps_team`, docs/performance.md 'Fast steps on both cores'). A
step is a sequence of phases (:data:`DUE` ... :data:`CONTACTS`), each a set of tasks that may run in
any order on any thread: the rods in blocks (forces, update, constraint, the pair search of the split
tip brake, the contact test, each reading all positions but writing the rows of its block only), the
channels' powers by groups of three, the split brakes as one task (they act pair after pair, in order).
``kernels/team.py`` forks the threads once per call and hands out the tasks; the call's control flow
(:func:`_lead`) runs on one of them and decides between phases from what the tasks left in
``partial`` and ``counts`` (per block: the largest displacement, bond error and velocity, the pairs
found, the contact test's counts), combining them as the kernels over all rows would: the maxima the
same, the contact counts the same sums. Every number is computed by the same operations as on one
thread; :func:`fast_steps` is the same code on the calling thread with one block.
"""

import math

import numpy as np

from . import team
from ._jit import njit, njit_parallel, prange
from .step_args import (
    LIM_BOND_BREAK,
    LIM_HEIGHT_TOL,
    LIM_MAX_BOND,
    LIM_MAX_MOVE,
    LIM_NETWORK,
    SC_HALF_SKIN2,
    SC_POLE_SPLIT,
    SC_TIP_BRAKE_SPLIT,
    SC_WALL_SPLIT,
    Scratch,
)
from .step_tasks import (
    BRAKES,
    CONSTRAIN,
    CONTACTS,
    DUE,
    FORCES,
    P_BOND,
    P_BOND_AFTER,
    P_DUE,
    P_DUE_AFTER,
    P_DUE_SPLIT,
    P_SPEED,
    PAIRS,
    PHASES_PER_STEP,
    UNDO,
    UPDATE,
    run_tasks,
)

DONE, NEEDS_STEP, NEEDS_CONTACTS, NEEDS_HEALTH = 0, 1, 2, 3

#: the channels a run of fast steps writes, by their place in the ``channel`` argument of :func:`fast_steps`
CHANNELS = (
    "tip_magnetic",
    "tip_brake",
    "ambient_brake",
    "plasma_filament",
    "electrodes",
    "electrode_brake",
    "external_filament",
    "external_monopoles",
    "external_monopole_brake",
    "external_line_charge",
)
#: the split brakes whose work is logged, in the order of the terms (the column of ``brake_work``)
SPLIT_BRAKES = ("tip_brake", "electrode_brake", "external_monopole_brake")


@njit
def _all_plus_zero(a):
    """Whether every element of the C-contiguous array ``a`` is +0.0 (the bits of +0.0 are all 0)."""
    bits = a.reshape(-1).view(np.int64)
    for k in range(bits.shape[0]):
        if bits[k] != 0:
            return False
    return True


@njit
def fast_steps(args):
    """Up to ``args.n_max`` fast steps from ``args.step``, in place; returns ``(steps, reason, head,
    max_bond_error, bond_error_after, speed_max)`` with ``reason`` one of the module's codes.

    ``args`` is a :class:`~.step_args.FastStepArgs` (``model/compiled.py::CompiledSteps.advance`` builds it;
    its docstring lists the arrays and values).
    """
    s, result, result_f = _prepare(args, 1)
    _join(args, s, result, result_f)
    return result[0], result[1], result[2], result_f[0], result_f[1], result_f[2]


@njit
def fast_steps_team(threads, chunks, args):
    """:func:`fast_steps` on ``threads`` threads (``kernels/team.py``), the rods in ``chunks`` blocks: the
    same numbers bit for bit, on any number of threads."""
    s, result, result_f = _prepare(args, chunks)
    _fork(threads, args, s, result, result_f)
    return result[0], result[1], result[2], result_f[0], result_f[1], result_f[2]


@njit_parallel
def _fork(threads, args, s, result, result_f):
    """:func:`_join` on ``threads`` threads. (A function of its own: numba's parallel loop takes a named
    tuple from the function's arguments, not from the result of a call.)"""
    for _ in prange(threads):
        _join(args, s, result, result_f)


@njit
def _prepare(args, chunks):
    """The scratch of a call: ``(s, result, result_f)``, the :class:`~.step_args.Scratch` of the tasks
    (with the control block of ``team.py``) and the call's results (ints: steps, reason, head; floats:
    largest bond error, bond error, speed)."""
    n_max, slow_every = args.n_max, args.slow_every
    ctl = np.zeros(team.control_size(PHASES_PER_STEP * max(1, min(n_max, slow_every)) + 1), dtype=np.int64)
    chunks = max(1, min(chunks, args.x.shape[0] // 2))
    n_pairs = args.index.shape[0] if args.scalars[SC_TIP_BRAKE_SPLIT] != 0.0 else 0
    s = Scratch(
        ctl=ctl,
        partial=np.zeros((chunks, 6)),
        counts=np.zeros((chunks, 4), dtype=np.int64),
        zero=np.zeros(args.held.shape[0], dtype=np.bool_),
        pair_k=np.empty(n_pairs, dtype=np.int64),
        pair_l=np.empty(n_pairs, dtype=np.int64),
        chunks=chunks,
    )
    return s, np.zeros(3, dtype=np.int64), np.zeros(3)


@njit
def _join(args, s, result, result_f):
    """One thread's part of a call: the first to come leads (:func:`_lead`), the others work on the
    phases it opens until it closes the call (the arguments as :func:`_prepare` returns them)."""
    ctl = s.ctl
    if team.fetch_add(ctl, team.JOINED, 1) == 0:
        timed = args.phase_time.shape[0] > 0
        t0 = team.ticks() if timed else 0
        done, reason, head, max_bond, err_after, speed = _lead(args, s)
        if timed:
            args.phase_time[0] += team.ticks() - t0
        result[0], result[1], result[2] = done, reason, head
        result_f[0], result_f[1], result_f[2] = max_bond, err_after, speed
        team.close(ctl)
        return
    seen = 0
    while team.load(ctl, team.CLOSED) == 0:
        p = team.load(ctl, team.OPENED)
        if p == seen:
            continue
        run_tasks(p, args, s)
        seen = p


@njit
def _phase(p, kind, tasks, w0, w1, w2, args, s):
    """Open phase ``p`` of ``kind`` with ``tasks`` tasks (words ``w0``-``w2``), work on it and wait until it is done
    (its ticks added to ``args.phase_time[kind]`` when that is given)."""
    timed = args.phase_time.shape[0] > 0
    t0 = team.ticks() if timed else 0
    team.open_phase(s.ctl, p, tasks, kind, w0, w1, w2)
    run_tasks(p, args, s)
    team.wait(s.ctl, p)
    if timed:
        args.phase_time[kind] += team.ticks() - t0


@njit
def _largest(partial, column):
    """The largest of a column of ``partial``, as the kernels take a maximum (a NaN is passed over)."""
    m = 0.0
    for c in range(partial.shape[0]):
        m = max(m, partial[c, column])
    return m


@njit
def _lead(args, s):
    """The steps of a call in the Python step's order, each part a phase of tasks (``step_tasks.py::run_tasks``); the
    decisions between them from the tasks' results."""
    x, held, rate, base, base_step = args.x, args.held, args.rate, args.base, args.base_step
    scalars, limits, lists, filament_tip, filament_z = (
        args.scalars,
        args.limits,
        args.lists,
        args.filament_tip,
        args.filament_z,
    )
    head, step, n_max, slow_every, dt = args.head, args.step, args.n_max, args.slow_every, args.dt
    bond_before, power_log, brake_work, brake_hit, hist_p = (
        args.bond_before,
        args.power_log,
        args.brake_work,
        args.brake_hit,
        args.hist_p,
    )
    partial, counts, zero, chunks = s.partial, s.counts, s.zero, s.chunks
    tb_split, half_skin2 = scalars[SC_TIP_BRAKE_SPLIT], scalars[SC_HALF_SKIN2]
    network = limits[LIM_NETWORK] == 1.0
    height_tol = limits[LIM_HEIGHT_TOL]
    bond_break, max_move, max_bond = limits[LIM_BOND_BREAK], limits[LIM_MAX_MOVE], limits[LIM_MAX_BOND]
    groups = (args.powered.shape[0] + 2) // 3
    err_after = 0.0
    speed = 0.0
    done = 0
    p = 0
    checked = False  # the tip list's update test already made at the current positions
    # held forces whose rate and base are all +0 (the current terms while no rod carries current):
    # rate * s + base is then +0 on every step, written on the first step of the call only
    if args.extrapolate:
        for j in range(held.shape[0]):
            zero[j] = base_step[j] >= 0 and _all_plus_zero(rate[j]) and _all_plus_zero(base[j])
    while done < n_max:
        # the Python step runs the slow evaluations, the RK4 start and the list builds
        if step % slow_every == 0:
            return done, NEEDS_STEP, head, max_bond, err_after, speed
        # (not again when the contact test of the step before found the list fresh at these positions)
        if lists[0] and not checked:
            p += 1
            _phase(p, DUE, chunks, 0, 0, 0, args, s)
            if not _largest(partial, P_DUE) < half_skin2:
                return done, NEEDS_STEP, head, max_bond, err_after, speed
        checked = False
        h = (head + 1) % 4
        p += 1
        _phase(p, FORCES, chunks, h, step, done, args, s)
        p += 1
        _phase(p, UPDATE, groups + chunks, h, step, done, args, s)
        err_before = _largest(partial, P_BOND)
        for c in range(3):
            brake_hit[done, c] = False
            brake_work[done, c] = 0.0
        if tb_split != 0.0:
            if not _largest(partial, P_DUE_SPLIT) < half_skin2:
                # the split brake would rebuild the list here: undo the step, Python takes it
                p += 1
                _phase(p, UNDO, chunks, h, step, done, args, s)
                return done, NEEDS_STEP, head, max_bond, err_after, speed
            p += 1
            _phase(p, PAIRS, chunks, h, step, done, args, s)
        if tb_split != 0.0 or scalars[SC_WALL_SPLIT] != 0.0 or scalars[SC_POLE_SPLIT] != 0.0:
            p += 1
            _phase(p, BRAKES, 1, h, step, done, args, s)
        p += 1
        _phase(p, CONSTRAIN, chunks, h, step, done, args, s)
        err_after = _largest(partial, P_BOND_AFTER)
        speed = 0.0
        for c in range(chunks):
            if partial[c, P_SPEED] != partial[c, P_SPEED]:
                speed = math.nan
                break
            speed = max(speed, partial[c, P_SPEED])
        for c in range(power_log.shape[1]):
            power_log[done, c] = hist_p[h, c]
        bond_before[done] = err_before
        head = h
        step += 1
        done += 1
        # -- HealthChecks.after_step
        if err_after > max_bond:
            max_bond = err_after
        if not (
            math.isfinite(err_before) and err_before < bond_break and speed * dt < max_move and math.isfinite(speed)
        ):
            return done, NEEDS_HEALTH, head, max_bond, err_after, speed
        # -- the network's contact test (Network.update on a step without news)
        if network:
            if lists[2]:
                if not _largest(partial, P_DUE_AFTER) < half_skin2:
                    return done, NEEDS_CONTACTS, head, max_bond, err_after, speed
                checked = True
            p += 1
            _phase(p, CONTACTS, chunks, h, step, done, args, s)
            n_known = 0
            n_close = 0
            for c in range(chunks):
                if counts[c, 1] == 0:
                    return done, NEEDS_CONTACTS, head, max_bond, err_after, speed
                n_known += counts[c, 2]
                n_close += counts[c, 3]
            if n_known != n_close:
                return done, NEEDS_CONTACTS, head, max_bond, err_after, speed
            for j in range(filament_tip.shape[0]):
                if abs(x[filament_tip[j], 2] - filament_z[j]) > height_tol:
                    return done, NEEDS_CONTACTS, head, max_bond, err_after, speed
    return done, DONE, head, max_bond, err_after, speed


@njit
def add_work(work, ab4_work, brake_work, brake_hit, split_channel):
    """The integrator's work of a run of steps, added in the Python step's order: for each step its AB4
    sum of the channels' powers (``ab4_work[i]``, as numpy's product gives it), then the work of each
    split brake that acted (``brake_work[i, j]`` into channel ``split_channel[j]``, -1: none).

    Parameters
    ----------
    work : (n_power,) float64, added to in place
    ab4_work : (n_steps, n_power) float64
    brake_work : (n_steps, 3) float64; brake_hit : (n_steps, 3) bool; split_channel : (3,) int64
    """
    for i in range(ab4_work.shape[0]):
        for c in range(work.shape[0]):
            work[c] += ab4_work[i, c]
        for j in range(split_channel.shape[0]):
            if split_channel[j] >= 0 and brake_hit[i, j]:
                work[split_channel[j]] += brake_work[i, j]
