"""The triggers that time the operations of a run (:mod:`.operations`), after HOOMD-blue's
``hoomd.trigger``: a callable ``trigger(timestep) -> bool``."""

from __future__ import annotations

from .validate import is_whole_number

__all__ = ["Trigger", "Periodic", "Always", "When"]


class Trigger:
    """Decides whether an operation acts at a time step."""

    def __call__(self, timestep: int) -> bool:
        raise NotImplementedError


def _period(period, who) -> int:
    """``period`` as a whole number of steps >= 1; TypeError naming ``who`` otherwise (it was changed silently)."""
    if not is_whole_number(period) or period < 1:
        raise TypeError(f"{who}(period=...): a whole number of steps >= 1, got {period!r}")
    return int(period)


class Periodic(Trigger):
    """True when ``timestep % period == phase``."""

    def __init__(self, period: int, phase: int = 0):
        self.period = _period(period, "Periodic")
        if not is_whole_number(phase):
            raise TypeError(f"Periodic(phase=...): a whole number of steps, got {phase!r}")
        self.phase = int(phase) % self.period

    def __call__(self, timestep: int) -> bool:
        return timestep % self.period == self.phase

    def __repr__(self) -> str:
        return f"Periodic(period={self.period}, phase={self.phase})"


class Always(Trigger):
    """True at every time step."""

    def __call__(self, timestep: int) -> bool:
        return True


class When(Trigger):
    """True when ``predicate()`` is, asked on the time steps that are multiples of ``period`` (default:
    every step); a period lets the steps between run without Python (:mod:`.compiled`)."""

    def __init__(self, predicate, period: int = 1):
        if not callable(predicate):
            raise TypeError(f"When(predicate, ...): a callable that returns true or false, got {predicate!r}")
        self.predicate = predicate
        self.period = _period(period, "When")
        self.phase = 0

    def __call__(self, timestep: int) -> bool:
        return timestep % self.period == 0 and bool(self.predicate())
