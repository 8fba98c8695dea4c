"""The pieces of the run file format (H5MD 1.1, :mod:`selfas_graph.io.h5md`) that its writer and
reader share: the reduced units' symbols and the units of observables, the events' dtype in the file,
growable datasets, the errors, the free space a write needs, and the check that a file can be continued."""

from __future__ import annotations

import errno
import os
from pathlib import Path

import h5py
import numpy as np

from ..model.events import EVENT_DTYPE, KIND_NAMES
from . import layout

H5MD_VERSION = (1, 1)

#: symbols of the reduced unit system (docs/model.md 'Reduced units'; docs/output.md lists them)
UNIT_SYSTEM = "reduced"
LENGTH, TIME, CHARGE, ENERGY, CURRENT, POTENTIAL = "L", "t_0", "Z_M0e", "F_M0 L", "J_0", "R_0 J_0"


def observable_unit(name):
    """The reduced unit of an observable, or None for counts and flags."""
    if name.startswith(("energy", "work/")):
        return ENERGY
    return {
        "momentum": "m L t_0-1",
        "bond_error": LENGTH,
        "bond_error_per_step": LENGTH,
        "dt": TIME,
        "total_current": CURRENT,
        "effective_resistance": "R_0",
        "effective_conductance": "R_0-1",
    }.get(name)


def _fixed(text):
    """A fixed-length string (H5MD asks for them in attributes) of at least one byte: ASCII, or
    tagged UTF-8 where the text is not ASCII (an author's name), so that readers decode it."""
    data = str(text).encode("utf-8")
    size = max(1, len(data))
    return np.array(data, dtype=f"S{size}" if data.isascii() else h5py.string_dtype("utf-8", size))


#: the events' dtype in the file: ``kind`` an HDF5 enumeration of the names in KIND_NAMES
EVENT_FILE_DTYPE = np.dtype(
    [
        (name, h5py.enum_dtype({v: k for k, v in KIND_NAMES.items()}, basetype="<i4"))
        if name == "kind"
        else (name, EVENT_DTYPE[name])
        for name in EVENT_DTYPE.names
    ]
)


def _unit_string(obj, name, text):
    """A string attribute of the H5MD units module: scalar, variable-length, ASCII (the module asks this
    of ``system`` and of every ``unit``; the ``h5md`` group's own strings are fixed-length)."""
    obj.attrs.create(name, str(text), dtype=h5py.string_dtype("ascii"))


def _set_unit(obj, unit):
    if unit is not None:
        _unit_string(obj, "unit", unit)


def _charges(group, values, quantity):
    """The H5MD 1.1 element ``charge`` of a particles group: its values in units Z_M0 e, ``type`` =
    ``effective`` (H5MD 1.1: a charge whose meaning the model gives, here the magnetic charge of a tip or
    the screened electric charge of a rod, docs/model.md) and ``quantity``, which of the two it is."""
    ds = group.create_dataset("charge", data=np.asarray(values, dtype=np.float64))
    _set_unit(ds, CHARGE)
    ds.attrs["type"] = _fixed("effective")
    ds.attrs["quantity"] = _fixed(quantity)
    return ds


def _box(group):
    box = group.create_group(layout.BOX)
    box.attrs["dimension"] = np.int32(3)
    box.attrs["boundary"] = np.array([b"none"] * 3)


class OutputExistsError(FileExistsError):
    """The output file exists and overwriting was not asked for."""


class RunFileError(ValueError):
    """A file that is not a readable selfas-graph run."""


class FileInUseError(RunFileError):
    """A run file another process holds (HDF5's file lock): readable once that process ends."""


#: what h5py raises when a damaged file's metadata is read (the error comes only when the part is read)
HDF5_READ_ERRORS = (OSError, RuntimeError, KeyError)


def raised_in_hdf5(exc) -> bool:
    """Whether ``exc`` was raised in h5py (HDF5 read errors are :data:`HDF5_READ_ERRORS` there)."""
    tb = exc.__traceback__
    while tb is not None:
        name = tb.tb_frame.f_code.co_filename  # h5py's modules, or its compiled ones ("h5py/h5o.pyx")
        if f"{os.sep}h5py{os.sep}" in name or name.startswith(f"h5py{os.sep}"):
            return True
        tb = tb.tb_next
    return False


class DiskFullError(OSError):
    """Too little free space for the next write; raised before anything of it is written."""


#: free space kept beyond the largest write a frame can make (HDF5 metadata, the file system's own)
SPACE_MARGIN = 1 << 20


def free_bytes(folder) -> int | None:
    """Bytes the calling user may still write in ``folder`` (None where the file system cannot tell)."""
    try:
        st = os.statvfs(folder if str(folder) else ".")
    except (OSError, AttributeError):
        return None
    return st.f_bavail * st.f_frsize


def check_room(path, need) -> None:
    """Raise :class:`DiskFullError` (nothing written) when the folder of ``path`` has less free space
    than ``need`` bytes, or the file system refuses ``path`` that much room (a quota or a file-size
    limit). Quotas the file system does not report either are caught when a write fails."""
    path = Path(path)
    free = free_bytes(path.parent)
    if free is not None and free < need:
        raise DiskFullError(
            28,
            f"{free / 2**20:.2f} MiB free in {path.parent or '.'}, the next frame may need {need / 2**20:.2f} MiB",
        )
    # a quota or a file-size limit does not show in the free space: ask the file system for the
    # room (posix_fallocate), then give it back; HDF5 has written everything up to the size seen
    try:
        fd = os.open(path, os.O_WRONLY)
    except OSError:
        return
    try:
        size = os.fstat(fd).st_size
        try:
            os.posix_fallocate(fd, size, need)
        except OSError as exc:
            if exc.errno in (errno.EOPNOTSUPP, errno.EINVAL, errno.ENOSYS, errno.ENODEV):
                return  # a file system without fallocate: failed writes are caught when they happen
            raise DiskFullError(
                exc.errno,
                f"{exc.strerror}: {path} cannot grow by the {need / 2**20:.2f} MiB the next frame may need",
            ) from None
        finally:
            if os.fstat(fd).st_size != size:
                os.ftruncate(fd, size)
    finally:
        os.close(fd)


def is_io_error(exc) -> bool:
    """True for a failed write of the operating system (full disk, quota, a vanished folder), as
    raised directly (OSError with an errno) or wrapped by HDF5 (its message carries the errno)."""
    if isinstance(exc, OSError) and exc.errno is not None:
        return True
    text = str(exc)
    return isinstance(exc, (OSError, RuntimeError)) and ("errno = " in text or "write failed" in text)


def _growable(group, name, shape, dtype):
    """A dataset growing along its first axis, in uncompressed chunks of about 1 MiB.

    No compression on purpose: a compressed chunk is rewritten whole at every append, so a
    kill during that write can leave it undecodable, losing frames written long before; an
    uncompressed chunk is appended in place (seen in tests/validation/test_restart.py's kill test).
    """
    rows = max(1, min(1024, 2**20 // max(1, int(np.prod(shape)) * 8)))
    return group.create_dataset(name, shape=(0,) + shape, maxshape=(None,) + shape, dtype=dtype, chunks=(rows,) + shape)


def _append(ds, value):
    n = ds.shape[0]
    value = np.asarray(value)
    k = 1 if value.shape == ds.shape[1:] else value.shape[0]
    ds.resize(n + k, axis=0)
    ds[n : n + k] = value
    return n


def _truncate(ds, n):
    if ds.shape[0] > n:
        ds.resize(n, axis=0)


def _rows_up_to(steps, step, strict=True) -> int:
    """How many leading rows of a step column belong to a run continued after ``step``.

    The rows must be at most ``step`` and increasing (strictly for frames, non-decreasing for
    events): a row torn by a kill (its size flushed, its data not: a zero or a stale step)
    ends the kept rows even where a binary search would skip over it.
    """
    s = np.asarray(steps)
    good = s <= step
    if len(s) > 1:
        d = np.diff(s)
        good[1:] &= (d > 0) if strict else (d >= 0)
    bad = np.flatnonzero(~good)
    return int(bad[0]) if len(bad) else len(s)


def hdf5_damage(exc) -> str | None:
    """What to say of a read error ``exc`` that h5py raised (damaged metadata: ``cannot read it: ... (a damaged
    file?)``), or None for an error raised elsewhere, which the caller raises again."""
    return f"cannot read it: {exc} (a damaged file?)" if raised_in_hdf5(exc) else None


def unreadable_part(f) -> str | None:
    """Why HDF5 cannot read all of the open file ``f`` that a continuation touches, or None.

    Damaged metadata (bytes written over a B-tree node or an object header) shows only when the part is
    read, from inside h5py, possibly in the middle of a run: every object, its attributes and the last
    row of every dataset (the path in its chunk index where rows are appended) are read here, up front.
    """

    def touch(name, obj):
        dict(obj.attrs)
        if isinstance(obj, h5py.Dataset) and obj.shape and obj.shape[0]:
            obj[-1]

    try:
        dict(f.attrs)
        f.visititems(touch)
    except HDF5_READ_ERRORS as exc:
        why = hdf5_damage(exc)
        if why is None:
            raise
        return why
    return None


def appendable_problems(f) -> list:
    """What keeps an open run file from being continued: a part HDF5 cannot read
    (:func:`unreadable_part`), datasets that cannot grow, wrong dtypes.

    Checked read-only before :meth:`RunWriter.reopen` changes anything (an empty list: none).
    """
    damage = unreadable_part(f)
    if damage:
        return [damage]
    problems = []

    def check(name, kind=None, dtype=None):
        ds = f.get(name)
        if ds is None:
            return
        if not isinstance(ds, h5py.Dataset):
            problems.append(f"{name} is not a dataset")
        elif ds.chunks is None or ds.maxshape[0] is not None or ds.ndim < 1:
            problems.append(f"{name} is not an appendable (chunked, unlimited) dataset")
        elif dtype is not None and ds.dtype != dtype:
            problems.append(f"{name} has dtype {ds.dtype}, expected {np.dtype(dtype)}")
        elif kind is not None and ds.dtype.kind not in kind:
            problems.append(f"{name} has dtype {ds.dtype}, expected {'integers' if kind == 'iu' else 'numbers'}")

    for group in ("particles/tips/position", layout.TIP_VELOCITY):
        check(f"{group}/step", "iu")
        check(f"{group}/time", "f")
        check(f"{group}/value", "f")
    obs = f.get(layout.OBSERVABLES)
    if isinstance(obs, h5py.Group):

        def visit(name, obj):
            if isinstance(obj, h5py.Group) and "value" in obj:
                check(f"{layout.observable(name)}/{layout.STEP}", "iu")
                check(f"{layout.observable(name)}/{layout.VALUE}", "f")
                if name != layout.BOND_ERROR_PER_STEP:
                    check(f"{layout.observable(name)}/{layout.TIME}", "f")

        obs.visititems(visit)
    check(layout.EVENTS, dtype=EVENT_DTYPE)
    g = f.get(layout.GRAPH)
    if isinstance(g, h5py.Group):
        for name in (
            "step",
            "tip_contacts_count",
            "conductor_contacts_count",
            "tip_contacts",
            "conductor_tip",
            "conductor_id",
            "role",
        ):
            check(layout.graph(name), "iu")
        for name in ("time", "current", "potential", "conductor_potential"):
            check(layout.graph(name), "f")
    return problems


def in_use_message(path, what, force) -> str:
    """Why ``path``, which :func:`in_use` found open in another process, is not replaced; ``what`` names
    the file, ``force`` the option that replaces an existing one (``--force``, ``overwrite=True``), or
    None for a run continued in place (a resume), which neither replaces it nor takes another name."""
    where = (
        f"{what} {path} is open in another process (a simulation still writing it?), or in this one (a "
        f"RunFile or RunWriter not yet closed: close it, or use it in a with block)"
    )
    if force is None:
        return f"{where}; it is not continued while open: wait for that process to end or close it, then resume"
    return f"{where}; it is not replaced, even with {force}: wait for that process to end, or give another name"


def dangling_link(path, what="output") -> str | None:
    """Why ``path``, a symbolic link to nothing, is not written (through it a file would be made where it
    points, or the link itself replaced: neither is what was named), or None when it is no such link."""
    path = Path(path)
    if not (path.is_symlink() and not path.exists()):
        return None
    return (
        f"the {what} path {path} is a symbolic link to {os.readlink(path)}, which does not exist; "
        f"give the file the link should point to, or another name"
    )


#: the names beside a run file that belong to it: a run file never takes one (``RUN.checkpoint.h5``, ``RUN.failure.h5``)
COMPANION_SUFFIXES = (".checkpoint.h5", ".failure.h5")


#: the suffixes of a run file: another file that is not HDF5 (a scene, an export, a figure) is never replaced
RUN_SUFFIXES = (".h5", ".hdf5", ".h5md")


def not_replaced(path) -> str | None:
    """Why a run file is not written to ``path`` even where replacing is asked for (``overwrite=True``,
    ``--force``), or None: a name of a run's checkpoint or failed state, a folder, a checkpoint, or a file
    that is not HDF5 and not named as a run file (a scene, an export, a figure). What ``--force`` is for,
    an earlier or a damaged run file (or any HDF5 or ``.h5`` file), is replaced."""
    path = Path(path)
    if path.name.endswith(COMPANION_SUFFIXES):
        return f"{path} is the name of a run's checkpoint or failed state; give the run file another name"
    if path.is_dir():
        return f"{path} is a folder; give a file name such as run.h5"
    if not path.is_file() or path.stat().st_size == 0:
        return None
    if not is_hdf5(path):
        if path.suffix.lower() in RUN_SUFFIXES:
            return None
        return f"{path} exists and is not a run file (a scenario, an export?); it is not replaced: give another name"
    try:
        with h5py.File(path, "r") as f:
            kind = str(f.attrs.get("format", ""))
    except OSError:  # HDF5 that does not open: a run file torn by a kill is replaced
        return None
    if kind.startswith("selfas-graph checkpoint"):
        return f"{path} is a run's checkpoint (what it resumes from); it is not replaced: give another name"
    return None


def is_hdf5(path) -> bool:
    """Whether ``path`` is an HDF5 file (a run file, a checkpoint, a failure file): one a command that writes
    something else never replaces."""
    try:
        return bool(h5py.is_hdf5(path))
    except OSError:
        return False


def in_use(path) -> bool:
    """True if another process holds a lock on the file ``path``: HDF5 locks a file it has open
    (``flock``, exclusive for a writer, shared for a reader) until it closes it, so a running
    simulation's run file is in use until the run ends. False where locks are not available."""
    try:
        import fcntl
    except ImportError:  # not a POSIX system
        return False
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return True
    except OSError:  # no flock on this file system
        return False
    else:
        fcntl.flock(fd, fcntl.LOCK_UN)
        return False
    finally:
        os.close(fd)
