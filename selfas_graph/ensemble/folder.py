"""The ensemble's folder: the names of its seed files, its creation, and its lock while an ensemble runs in it."""

from __future__ import annotations

import os
import time
from pathlib import Path

#: file name of seed ``s`` in the ensemble's folder
SEED_FILE = "seed_{:04d}.h5"


class EnsembleError(ValueError):
    """Bad input or a seed file that cannot be used (the CLI reports it with exit code 2); ``kind`` says
    what is wrong with a seed file where the advice depends on it: "in_use" (another process writes
    it), "past_end" (run past this end time), "" otherwise."""

    def __init__(self, message, kind=""):
        super().__init__(message)
        self.kind = kind


def seed_path(folder, seed) -> Path:
    """The run file of ``seed`` in ``folder``: ``folder/seed_0001.h5`` for seed 1."""
    return Path(folder) / SEED_FILE.format(int(seed))


#: lock file of a running ensemble in its folder
LOCK_FILE = ".ensemble.lock"


class FolderLock:
    """The exclusive lock of an ensemble's folder, held while an ensemble runs seeds in it (a context manager).

    An OS lock on ``FOLDER/.ensemble.lock`` (``flock``; ``msvcrt.locking`` on Windows): the
    kernel drops it when the process ends, however it ends, so a lock file left by a crash is
    stale and simply taken over. Its text names the holder (process id, host, start time) for the
    message of a second ensemble, which is refused at once. The file is removed on release.
    """

    def __init__(self, folder):
        self.folder = Path(folder)
        self.path = self.folder / LOCK_FILE
        self.fd = None

    def acquire(self) -> "FolderLock":
        """Take the lock; EnsembleError naming the folder and the holder if another process has it."""
        while True:
            try:
                fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
            except OSError as exc:
                raise EnsembleError(f"cannot lock the output folder {self.folder}: {exc.strerror or exc}") from None
            if not _try_lock(fd):
                holder = _read_holder(fd)
                os.close(fd)
                raise EnsembleError(
                    f"the output folder {self.folder} is in use by another ensemble ({holder}); wait for it to "
                    f"end (or stop it), or give another folder with -o"
                )
            try:  # the holder before may have removed the file after this opened it: lock the file there now
                same = os.path.samestat(os.fstat(fd), os.stat(self.path))
            except OSError:
                same = False
            if same:
                break
            os.close(fd)
        import socket

        text = f"pid {os.getpid()} on {socket.gethostname()}, since {time.strftime('%Y-%m-%d %H:%M:%S')}\n"
        os.ftruncate(fd, 0)
        os.lseek(fd, 0, os.SEEK_SET)
        os.write(fd, text.encode())
        self.fd = fd
        return self

    def release(self) -> None:
        if self.fd is None:
            return
        try:
            os.unlink(self.path)  # while still held: a waiting process then finds it gone and retries
        except OSError:
            pass
        os.close(self.fd)
        self.fd = None

    def __enter__(self):
        return self.acquire()

    def __exit__(self, *exc):
        self.release()
        return False


def _try_lock(fd) -> bool:
    try:
        import fcntl
    except ImportError:  # Windows
        import msvcrt

        try:
            msvcrt.locking(fd, msvcrt.LK_NBLCK, 1)
            return True
        except OSError:
            return False
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        return True
    except OSError:
        return False


def _read_holder(fd) -> str:
    try:
        os.lseek(fd, 0, os.SEEK_SET)
        text = os.read(fd, 200).decode("utf-8", "replace").strip()
    except OSError:
        text = ""
    return text or "a process that has not written its name yet"


def own_file(path) -> Path:
    """``path``, a file an ensemble names itself in its folder (its summary, table, plot), checked before it
    is written: never a symbolic link, which would make the ensemble write where no one named (a run
    file elsewhere, or a new file anywhere), and never anything but a regular file. EnsembleError
    otherwise, naming it and what to do."""
    path = Path(path)
    if path.is_symlink():
        raise EnsembleError(
            f"{path} is a symbolic link (to {os.readlink(path)}); an ensemble writes its own files in its folder, "
            "never through a link: remove the link, or give another folder"
        )
    if path.exists() and not path.is_file():
        raise EnsembleError(f"{path} is not a regular file; remove it, or give another folder")
    return path


def make_folder(folder) -> Path:
    """Create ``folder`` (and its parents) if missing; EnsembleError if that is impossible."""
    folder = Path(folder)
    if folder.is_symlink() and not folder.exists():
        raise EnsembleError(
            f"the output folder {folder} is a symbolic link to {os.readlink(folder)}, which does not exist; "
            f"create that folder or give another one"
        )
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise EnsembleError(f"cannot create the output folder {folder}: {exc.strerror or exc}") from None
    return folder
