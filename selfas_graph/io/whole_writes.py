"""A writer's writes made whole or undone: :class:`WholeWrites`, mixed into :class:`~.run_writer.RunWriter`.

A frame is many appends (positions, velocities, every observable, the groups of a first frame). An
exception in the middle of one (a ``KeyboardInterrupt`` raised by a signal handler of the caller's, a
bug in a callback that h5py runs) left the datasets of unequal length and, in a first frame, groups
in the file that the writer had not recorded: every later frame then failed ("name already exists").
Each write method decorated with :func:`all_or_nothing` now logs what it appends and creates and, if it
does not finish, removes them again: the file and the writer are as they were before the call. If the
undo fails too (a second interrupt during it), the writer refuses every later write, naming why.
"""

from __future__ import annotations

import functools

from .h5md_format import RunFileError, _append, _truncate


def all_or_nothing(method):
    """Decorate a write method of a :class:`WholeWrites`: what it appended and created is undone if it
    raises (anything, ``KeyboardInterrupt`` included), and the exception raised again."""

    @functools.wraps(method)
    def whole(self, *args, **kwargs):
        self._check_whole()
        if self._undo is not None:  # called by another write: the outer one undoes both
            return method(self, *args, **kwargs)
        self._undo = ([], [], dict(self._obs))
        try:
            return method(self, *args, **kwargs)
        except BaseException:
            self._roll_back(method.__name__)
            raise
        finally:
            self._undo = None

    return whole


class WholeWrites:
    """What :func:`all_or_nothing` needs of a writer: an open h5py file ``f``, its observables' datasets
    ``_obs`` (name -> datasets) and ``_check_open``; the writes append with :meth:`_add` and note each group
    or dataset they create with :meth:`_created`."""

    #: while a write runs: (appended datasets and their lengths before, created names, ``_obs`` before)
    _undo = None
    #: why a write could not be undone (the writer then refuses every later write), or None
    _torn = None

    def _add(self, ds, value) -> None:
        """Append ``value`` to ``ds`` (one row or several), logged to be undone."""
        if self._undo is not None:
            self._undo[0].append((ds, ds.shape[0]))
        _append(ds, value)

    def _created(self, obj):
        """Log ``obj`` (a group or dataset just created by the running write) to be removed on an undo."""
        if self._undo is not None:
            self._undo[1].append(obj.name)
        return obj

    def _check_whole(self) -> None:
        self._check_open()
        if self._torn is not None:
            raise RunFileError(
                f"{self.path}: {self._torn}, and undoing it failed; this writer takes no more writes. Close it "
                f"(the file keeps what came before) and continue it with RunWriter.reopen(path, step)"
            )

    def _roll_back(self, what: str) -> None:
        appended, created, obs = self._undo
        try:
            for ds, n in reversed(appended):
                if ds.id.valid:
                    _truncate(ds, n)
            for name in reversed(created):
                if name in self.f:
                    del self.f[name]
            self._obs = obs
        except BaseException:
            self._torn = f"{what} was interrupted"
            raise
