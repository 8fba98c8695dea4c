"""Operations on a running simulation and the triggers that time them.

After each step, :meth:`Simulation.run <.simulation.Simulation.run>` asks every operation's
trigger whether it acts on this time step, in the order the operations are listed; an
operation with ``final = True`` also acts after the last step of a run. The operations are
those of ``sim.operations`` (attached for every run) and those ``run`` builds from its
arguments for one call (``writer``, ``progress``, ``stop``, ``checkpointer``), in this order:
frame writer (or the energy check when nothing is written), the attached operations,
progress display, stop check, checkpointer.

A trigger is a callable ``trigger(timestep) -> bool`` (HOOMD-blue's ``hoomd.trigger``
model): :class:`Periodic` (every ``period`` steps, at ``phase``), :class:`Always`, and
:class:`When` (a predicate of no arguments, e.g. a wall clock or a signal flag). An
operation has a ``trigger`` and ``act(sim, i, n_steps)``; it may also define
``start(sim, n_steps)`` (before the first step of a run), ``flush(sim)`` (hand buffered data
on, before a checkpoint) and ``finish(sim)`` (after the last step of a run). An operation with
``act_steps(first_step, errors)`` is handed the bond errors of every step, a run of steps at a
time, instead of acting on a trigger (:class:`PerStepRows`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from .health import NumericalFailure
from .triggers import Always, Periodic, Trigger, When
from .validate import as_decimal, is_whole_number

__all__ = [
    "RunSummary",
    "RunInterrupted",
    "Trigger",
    "Periodic",
    "Always",
    "When",
    "Operation",
    "PerStepRows",
    "FrameWriter",
    "EnergyCheck",
    "Progress",
    "StopCheck",
    "Checkpoint",
]


@dataclass
class RunSummary:
    """What :meth:`Simulation.run <.simulation.Simulation.run>` returns about the run it made.

    ``steps`` and ``wall_seconds`` are the call's; ``t_start`` and ``t_end`` its simulated times;
    ``max_bond_error`` the largest bond-length error after the constraint so far; ``energy_balance``
    (E - E0 - W) and ``energy_scale`` (kinetic energy + |work|) at its end; ``frames`` the frames
    the writer holds in all (the file's, not this call's alone; 0 without a writer).
    """

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


class RunInterrupted(Exception):
    """The run was asked to stop (a signal); a checkpoint was written if a checkpointer was given."""

    def __init__(self, step):
        super().__init__(f"interrupted at step {step}")
        self.step = step


def stop_status(exc: BaseException) -> str:
    """The status a run file records for a run stopped by ``exc``: "interrupted (Ctrl-C)", "interrupted at
    step N", "failed: numerical failure ..." (the failure names itself), else "failed: Type: message"."""
    if isinstance(exc, KeyboardInterrupt):
        return "interrupted (Ctrl-C)"
    if isinstance(exc, RunInterrupted):
        return str(exc)
    if isinstance(exc, NumericalFailure):
        return f"failed: {exc}"
    return f"failed: {type(exc).__name__}: {exc}" if str(exc) else f"failed: {type(exc).__name__}"


class Operation:
    """Base of the operations: a ``trigger`` and what to do when it fires."""

    trigger: Trigger = Always()
    #: also act after the last step of a run, whatever the trigger says
    final = False

    def start(self, sim, n_steps: int) -> None:
        pass

    def act(self, sim, i: int, n_steps: int) -> None:
        raise NotImplementedError

    def flush(self, sim) -> None:
        pass

    def stopped(self, sim, exc) -> None:
        """The run stops on ``exc`` (Ctrl-C, a numerical failure, an error in an operation or a callback): hand on
        what is buffered (:meth:`flush`)."""
        self.flush(sim)

    def finish(self, sim) -> None:
        pass


class _Hooks(Operation):
    """An operation that defines only some of :class:`Operation`'s methods (its ``trigger`` and
    ``act``), with the others doing nothing."""

    def __init__(self, inner):
        self.inner = inner
        self.trigger = inner.trigger
        self.final = bool(getattr(inner, "final", False))

    def start(self, sim, n_steps):
        getattr(self.inner, "start", lambda *a: None)(sim, n_steps)

    def act(self, sim, i, n_steps):
        self.inner.act(sim, i, n_steps)

    def flush(self, sim):
        getattr(self.inner, "flush", lambda *a: None)(sim)

    def finish(self, sim):
        getattr(self.inner, "finish", lambda *a: None)(sim)


def steps_between(t: float, t_end, dt: float) -> int:
    """Steps of ``dt`` from ``t`` to ``t_end``, a whole number ahead (to round-off); ValueError otherwise, naming
    the times that can be reached (``Simulation.steps_to``, and an ensemble's check before any seed runs)."""
    t_end = time_value(t_end, "t_end")
    x = (t_end - t) / dt
    n = int(round(x))
    if n < 0 or x < -0.5:
        raise ValueError(f"t_end = {t_end:.10g} lies before the current time t = {t:.10g}; a run goes forward only")
    # round-off of t_end - t: a few ulps of the step count, and no more than 1e-6 of a step below 1e10 steps
    if abs(x - n) > 1e-6 + 4 * math.ulp(1.0) * abs(x):  # math.ulp(1.0): the machine epsilon
        lo = t + math.floor(x) * dt
        raise ValueError(
            f"t_end = {t_end!r} is not a whole number of steps dt = {dt!r} from t = {t!r} "
            f"({x:.12g} steps); the nearest reachable times are {lo!r} and {lo + dt!r}"
        )
    return n


def frame_steps(interval: float, dt: float) -> int:
    """Steps between saved frames: the output ``interval`` rounded to whole steps of ``dt``, at least one."""
    return max(1, int(round(interval / dt)))


def time_value(value, name: str) -> float:
    """``value`` as a finite float time; TypeError naming ``name`` for anything but a real number (a
    bool, a string, a list), ValueError for NaN or infinity. A float32 stands for the decimal it prints
    as, as in a scene file (np.float32(0.2) is 0.2, not 0.20000000298)."""
    try:
        value = as_decimal(value)
    except TypeError:
        raise TypeError(f"{name} must be a time (a real number), got {value!r}") from None
    if not math.isfinite(value):
        raise ValueError(f"{name} = {value} is not a finite time")
    return value


def as_operation(obj, where: str) -> Operation:
    """``obj`` as an :class:`Operation`: itself if it is one, else with the methods it lacks doing
    nothing; TypeError naming ``where`` if it has no callable ``trigger`` and ``act``."""
    if isinstance(obj, Operation):
        return obj
    if not (callable(getattr(obj, "trigger", None)) and callable(getattr(obj, "act", None))):
        raise TypeError(
            f"{where}: an operation needs a trigger (e.g. Periodic(10)) and act(sim, i, n_steps), got {obj!r}"
        )
    return _Hooks(obj)


def run_operations(
    sim, writer, every, n_steps, progress, progress_every, checkpointer, stop, check_every, t_end=None
) -> list:
    """The operations of one :meth:`Simulation.run <.simulation.Simulation.run>` call (to ``t_end``), in their
    order (module docstring): those its arguments make around the attached ``sim.operations``."""
    _check_arguments(sim, writer, progress, checkpointer, stop, check_every, progress_every)
    frames = FrameWriter(writer, every, t_end) if writer is not None else None
    ops = [PerStepRows(writer, every), frames] if writer is not None else [EnergyCheck(every)]
    ops += [as_operation(o, f"sim.operations[{k}]") for k, o in enumerate(sim.operations)]
    if progress is not None:
        ops.append(Progress(progress, progress_every or max(1, n_steps // 200), first_step=sim.state.step))
    checkpoint = Checkpoint(checkpointer, check_every) if checkpointer is not None else None
    if stop is not None:
        ops.append(StopCheck(stop, checkpoint, check_every))
    if checkpoint is not None:
        ops.append(checkpoint)
    return ops


def _check_arguments(sim, writer, progress, checkpointer, stop, check_every, progress_every=None) -> None:
    """Refuse before any step what would fail only after one: a closed writer, one whose file another
    simulation (or another step) continues, callbacks that cannot be called."""
    for name, fn in (("progress", progress), ("stop", stop)):
        if fn is not None and not callable(fn):
            raise TypeError(f"run({name}=...): a callable, got {fn!r}")
    if checkpointer is not None and not (
        callable(getattr(checkpointer, "due", None)) and hasattr(checkpointer, "write")
    ):
        raise TypeError(f"run(checkpointer=...): an object with due() and write(sim), got {checkpointer!r}")
    for name, every in (("check_every", check_every), ("progress_every", progress_every or 1)):
        if not is_whole_number(every) or every < 1:
            raise TypeError(f"run({name}=...): a whole number of steps >= 1, got {every!r}")
    if writer is not None and not callable(getattr(writer, "write_frame", None)):
        raise TypeError(
            f"run(writer=...): a writer, RunWriter.for_simulation(sim, path), not a path or other object; "
            f"got {writer!r}"
        )
    if writer is not None and hasattr(writer, "check_continues"):
        writer.check_continues(sim)


class PerStepRows(Operation):
    """Hands the writer the bond error of every step; the writer buffers the rows until the
    next frame or checkpoint (``writer.buffer_per_step``, ``writer.flush_pending``). The rows come
    by :meth:`act_steps`, a run of steps at a time (:func:`per_step_rows`); ``run`` does not call
    :meth:`act` of an operation that takes them so."""

    def __init__(self, writer, every: int):
        self.writer = writer
        self.every = every

    def start(self, sim, n_steps):
        # frames fall at least every `every` steps: the buffer never holds more rows
        self.writer.reserve_per_step(min(self.every, n_steps) + 1)

    def act_steps(self, first_step, errors):
        """The rows of a run of compiled steps from ``first_step`` on (their bond errors ``errors``)."""
        for j, err in enumerate(errors):
            self.writer.buffer_per_step(first_step + j, float(err))


class FrameWriter(Operation):
    """Saves a frame (positions, velocities, observables, the graph) every ``output.interval``
    and at the end of a run, and one at the start if the writer has none yet.

    The frame's observables are checked first (:meth:`Simulation.check_energy`): no NaN
    reaches the file.
    """

    final = True

    def __init__(self, writer, every: int, t_end=None):
        self.writer = writer
        self.trigger = Periodic(every)
        self.t_end = t_end
        #: the observables of the last frame written in the steps of this run
        self.last_observables = None

    def start(self, sim, n_steps):
        self.last_observables = None
        self.writer.stopped_by = None
        if self.t_end is not None and callable(getattr(self.writer, "run_to", None)):
            self.writer.run_to(time_value(self.t_end, "t_end"))  # the end time the run goes to, as simulate states it
        if self.writer.n_frames == 0:
            sim.write_frame(self.writer)

    def act(self, sim, i, n_steps):
        # frames fall on absolute steps that are multiples of `every`, so at most `every`
        # steps pass between two frames
        self.last_observables = sim.write_frame(self.writer)

    def flush(self, sim):
        sim.flush_output(self.writer)
        self.writer.flush()

    def stopped(self, sim, exc):
        """Write what the steps before ``exc`` buffered (the events and per-step rows up to a failure), and
        tell the writer why the run stopped: its ``close()`` then records that status, not "finished"."""
        self.flush(sim)
        self.writer.stopped_by = stop_status(exc)


class EnergyCheck(Operation):
    """Checks the energy balance every ``output.interval`` when no frame is written (a frame
    checks its own observables)."""

    def __init__(self, every: int):
        self.trigger = Periodic(every)

    def act(self, sim, i, n_steps):
        sim.check_energy(sim.observables())


class Progress(Operation):
    """Calls ``callback(sim, done, total)`` every ``every`` steps of the run and after its last."""

    final = True

    def __init__(self, callback, every: int, first_step: int = 0):
        self.callback = callback
        self.trigger = Periodic(every, phase=first_step)

    def act(self, sim, i, n_steps):
        self.callback(sim, i, n_steps)


class Checkpoint(Operation):
    """Writes a checkpoint when ``checkpointer.due()`` (a wall clock, asked every ``every`` steps) and
    after the last step, each time after every operation has flushed its buffered data."""

    def __init__(self, checkpointer, every: int = 1):
        self.checkpointer = checkpointer
        self.trigger = When(checkpointer.due, every)

    def act(self, sim, i, n_steps):
        sim.flush_operations()
        self.checkpointer.write(sim)

    def finish(self, sim):
        self.act(sim, None, None)


class StopCheck(Operation):
    """Stops the run when ``stop()`` is true (asked every ``every`` steps): hands every operation's buffered data
    on, writes a checkpoint (with ``checkpoint``, a :class:`Checkpoint`) and raises :class:`RunInterrupted`."""

    def __init__(self, stop, checkpoint: Checkpoint | None = None, every: int = 1):
        self.trigger = When(stop, every)
        self.checkpoint = checkpoint

    def act(self, sim, i, n_steps):
        if self.checkpoint is not None:
            self.checkpoint.act(sim, i, n_steps)
        else:
            sim.flush_operations()
        raise RunInterrupted(sim.state.step)


def steps_to_next_act(ops, step: int, remaining: int) -> int:
    """Steps from ``step`` to the first one after which an operation of ``ops`` may act (at most
    ``remaining``, the run's last step, where the final operations act): exact for :class:`Periodic`
    and :class:`When` triggers (the steps their predicate is asked on), 1 for any other; an operation with ``act_steps`` (:class:`PerStepRows`) takes the rows
    of a run of steps at once and does not count."""
    h = remaining
    for operation in ops:
        if hasattr(operation, "act_steps"):
            continue
        t = operation.trigger
        h = min(h, (t.phase - step - 1) % t.period + 1 if isinstance(t, (Periodic, When)) else 1)
    return max(h, 1)


def stopped(ops, sim, exc) -> None:
    """Every operation of a run that ``exc`` (Ctrl-C, a numerical failure, an error in an operation or a
    callback) stops hands on what it buffered."""
    for operation in ops:
        operation.stopped(sim, exc)


def per_step_rows(ops):
    """``(operations, rows)``: the operations of ``ops`` that take a run of steps' rows at once
    (``act_steps``), and a ``rows(first_step, errors)`` handing them on (None without any)."""
    per_step = [o for o in ops if hasattr(o, "act_steps")]
    if not per_step:
        return per_step, None
    return per_step, lambda first, errors: [o.act_steps(first, errors) for o in per_step]
