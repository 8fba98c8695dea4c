"""Wall time per force term, for the benchmarks (``Simulation(timing=True)``, ``force_field.seconds``).

A :class:`TermClock` wraps a call once, when the force field is built: a clock that is off hands
the call back unchanged, so an untimed evaluation does no timing work at all.
"""

from __future__ import annotations

import time
from collections import Counter


class TermClock:
    """Accumulates the wall time of wrapped calls under their names in :attr:`seconds`.

    Parameters
    ----------
    on : bool
        False: :meth:`wrap` returns the call itself and :attr:`seconds` stays empty.
    """

    def __init__(self, on: bool = False):
        self.on = bool(on)
        #: seconds per name (a term's name, ``gather``, ``tip_magnetic_fast``)
        self.seconds = Counter()

    def wrap(self, name: str, call):
        """``call``, or when the clock is on a call that adds its wall time to ``seconds[name]``."""
        if not self.on:
            return call
        seconds = self.seconds

        def timed(*args, **kwargs):
            t0 = time.perf_counter()
            try:
                return call(*args, **kwargs)
            finally:
                seconds[name] += time.perf_counter() - t0

        return timed
