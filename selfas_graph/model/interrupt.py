"""A Ctrl-C held to the end of a step: :class:`DeferredCtrlC`.

Python raises ``KeyboardInterrupt`` wherever the interpreter is when SIGINT arrives (Ctrl-C in a
terminal, "interrupt kernel" in a notebook): in the middle of a step, the integrator's history, the
positions and the event log would be left out of step with each other, and in the middle of a frame
the run file's datasets of unequal length. :meth:`Simulation.run <.simulation.Simulation.run>` and
:meth:`Simulation.step <.simulation.Simulation.step>` record the signal instead and raise
``KeyboardInterrupt`` at the next step boundary: the end of the batch of compiled steps it lands in (at
most 256) or of the next operation (docs/output.md "Writing a run file from Python"). A second Ctrl-C
raises at once, to stop a step or a callback that hangs.
"""

from __future__ import annotations

import signal
import threading

__all__ = ["DeferredCtrlC"]


class DeferredCtrlC:
    """The first SIGINT recorded, not raised, for the duration of a ``with`` block; :meth:`check` raises it.
    A second one raises ``KeyboardInterrupt`` where it lands: the first puts Python's handler back.

    The handler is set only in the main thread (no other can set one) and only where the handler in
    place is Python's own (``signal.default_int_handler``): a handler of the caller's (the command
    line's :class:`~selfas_graph.lifecycle.StopOnSignal`, a user's) keeps its behaviour. The one found
    is put back at the end of the block, unless something else replaced this one meanwhile.
    """

    def __init__(self):
        #: a SIGINT arrived and :meth:`check` has not raised it yet
        self.requested = False
        self._installed = False

    def __enter__(self):
        if (
            threading.current_thread() is threading.main_thread()
            and signal.getsignal(signal.SIGINT) is signal.default_int_handler
        ):
            signal.signal(signal.SIGINT, self._record)
            self._installed = True
        return self

    def _record(self, signum, frame):
        self.requested = True
        if signal.getsignal(signal.SIGINT) == self._record:  # the next Ctrl-C stops a hung step or callback
            signal.signal(signal.SIGINT, signal.default_int_handler)

    def check(self) -> None:
        """Raise ``KeyboardInterrupt`` if a SIGINT arrived since the block began (or the last check)."""
        if self.requested:
            self.requested = False
            raise KeyboardInterrupt

    def __exit__(self, *exc):
        if self._installed:
            self._installed = False
            if signal.getsignal(signal.SIGINT) == self._record:
                signal.signal(signal.SIGINT, signal.default_int_handler)
