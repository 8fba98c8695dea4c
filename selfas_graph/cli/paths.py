"""Checks of the files a subcommand is about to write, shared by ``simulate`` and ``plot``.

A target must be a regular file or not exist yet (never a device such as /dev/null, a
folder, a FIFO, a symbolic link to nothing), must not be one of the command's own inputs (a scenario, a run file),
and must have a name the file system accepts; every refusal is a :class:`CliError`
(exit 2) naming the path and what to do.
"""

from __future__ import annotations

import errno
import os
import stat
from pathlib import Path

from ..io.checkpoint import CheckpointError, read_checkpoint
from ..io.h5md_format import dangling_link, in_use, in_use_message, is_hdf5
from .main import CliError


def same_file(a, b) -> bool:
    """True if ``a`` and ``b`` name one existing file (hard links and symlinks included)."""
    try:
        return os.path.samefile(a, b)
    except (OSError, ValueError):
        return False


def check_target(
    path, what="output file", force=False, inputs=(), keep_hdf5=False, name_option="-o", resuming=False
) -> Path:
    """Refuse a path that cannot or must not be written; returns it as a Path.

    Parameters
    ----------
    path : path-like
    what : str
        How the messages name the file ("output file", "checkpoint file").
    force : bool
        An existing regular file may be replaced.
    inputs : iterable of path-like
        Files the command reads: never a target, not even with ``force``.
    keep_hdf5 : bool
        An existing HDF5 file (a run file, a checkpoint, a failure file) is never replaced, not even with
        ``force``: for the commands that write something else (plots, movies).
    name_option : str
        The option that names the file, for the advice when it exists (``--movie`` for a movie).
    resuming : bool
        The file is a run continued in place (``--resume``): the advice when it is in use says so.
    """
    path = Path(path)
    if "\x00" in str(path):
        raise CliError(f"the {what} path {str(path)!r} contains a NUL character")
    if path.name in ("", ".", ".."):
        raise CliError(f"the {what} path {path} names a folder, not a file; give a file name such as run.h5")
    try:
        st = os.stat(path)
    except (FileNotFoundError, NotADirectoryError):
        st = None
        if os.path.islink(path):
            raise CliError(dangling_link(path, what)) from None
    except OSError as exc:
        if exc.errno == errno.ENAMETOOLONG:
            raise CliError(
                f"the {what} path {str(path)[:60]}... is too long for the file system "
                f"({len(path.name)} characters in its last name); give a shorter one"
            ) from None
        raise CliError(f"the {what} path {path} cannot be used: {exc.strerror}") from None
    if st is not None:
        if stat.S_ISDIR(st.st_mode):
            raise CliError(f"the {what} path {path} is a directory")
        if not stat.S_ISREG(st.st_mode):
            raise CliError(
                f"the {what} path {path} is not a regular file (a device, pipe or socket); "
                f"give the name of a file to write"
            )
        for source in inputs:
            if source is not None and same_file(path, source):
                raise CliError(
                    f"the {what} {path} is the input {source} of this command; "
                    f"give another name (it would be destroyed, even with --force)"
                )
        if keep_hdf5 and is_hdf5(path):
            raise CliError(
                f"the {what} {path} is an HDF5 file (a run file, checkpoint or failure file?); this command never "
                f"replaces one, even with --force: give another name"
            )
        if not force:
            raise CliError(
                f"{what} {path} exists; pass --force to overwrite it or {name_option} to choose another name"
            )
        if in_use(path):
            raise CliError(in_use_message(path, what, None if resuming else "--force"))
    elif len(path.name.encode("utf-8", "surrogateescape")) > name_max(path.parent):
        raise CliError(
            f"the {what} name {path.name[:40]}... is too long for the file system "
            f"({len(path.name)} characters); give a shorter one"
        )
    return path


def check_folder(path, what="output file") -> None:
    """Refuse a target whose folder does not exist or cannot be written to (CliError, exit 2), before
    any work: found only when the file is saved, the refusal would come as an I/O error (exit 4)."""
    parent = Path(path).parent
    if not parent.is_dir():
        raise CliError(f"the folder {parent} of the {what} does not exist")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise CliError(f"the folder {parent} of the {what} is not writable")


def name_max(folder) -> int:
    """The longest file name (in bytes) the file system of ``folder`` takes (255 where it does not say)."""
    try:
        return os.pathconf(folder if str(folder) else ".", "PC_NAME_MAX")
    except (OSError, ValueError):
        return 255


def status_note(status) -> str:
    """What a reader of a run file should know of a run that did not finish ("" for a finished one)."""
    if status == "finished":
        return ""
    if status.startswith("interrupted"):
        return f" (the run was {status}; simulate --resume continues it)"
    if status == "running":
        return " (the run has not finished: it is still running, or was killed; simulate --resume continues it)"
    return f" (the run {status})" if status.startswith("failed") else f" (run status: {status})"


def through_link(out: Path) -> Path:
    """The run file a symbolic link names (the link itself when it names nothing): the file is written
    through the link, so its checkpoint and failure file go beside the file written, not beside the
    link (where a checkpoint link would be replaced by a file and the run's own folder keep a stale one)."""
    try:
        return Path(os.path.realpath(out)) if out.is_symlink() and out.exists() else out
    except OSError:  # a name too long for the file system, a folder that cannot be read: said by the checks after
        return out


def checkpoint_owner(ckpt):
    """The name of the run file the checkpoint ``ckpt`` continues (its ``run_name``), or None (no such
    file, not a checkpoint, no name recorded)."""
    if not ckpt.is_file():
        return None
    try:
        name = read_checkpoint(ckpt)[1].get("run_name")
    except (CheckpointError, OSError):
        return None
    return str(name) if name else None
