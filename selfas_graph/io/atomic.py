"""Files written whole or not at all: through a temporary file in the same folder, renamed over the
target when complete, so that a kill or a full disk leaves the file the user had (or none), never a
truncated one.

One rule for every such file the package writes (exports, plots, movies, summaries, the results page):
through a symbolic link the file the link names is replaced, not the link.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path


def default_mode() -> int:
    """The permissions a new file gets from ``open``: 0o666 less the process's umask."""
    mask = os.umask(0)
    os.umask(mask)
    return 0o666 & ~mask


def atomic_write(path, write) -> Path:
    """Call ``write(tmp)`` on a temporary path beside ``path`` (its suffix kept, for writers that read the
    format from it), then rename it over ``path``; returns the path written (a link's target). The file
    gets the permissions of one the user creates (``mkstemp`` makes it private, 0o600)."""
    path = Path(path).resolve()  # through a symbolic link: the file it names is replaced, not the link
    suffix = f".part{path.suffix}"
    if len(suffix.encode("utf-8", "surrogateescape")) > 64:  # a long "extension": the writers read short ones
        suffix = ".part"
    fd, tmp = tempfile.mkstemp(prefix=_prefix(path, suffix), suffix=suffix, dir=path.parent)
    os.close(fd)
    try:
        write(Path(tmp))
        os.chmod(tmp, default_mode())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def _prefix(path, suffix) -> str:
    """``.NAME.`` before mkstemp's 8 random characters and ``suffix``, the name cut short where the
    temporary name would be longer than the folder takes (a name the user may give, one the temporary
    file may not lengthen)."""
    try:
        name_max = os.pathconf(path.parent, "PC_NAME_MAX")
    except (OSError, ValueError):
        name_max = 255
    prefix = f".{path.name}."
    room = name_max - 8 - len(suffix.encode("utf-8", "surrogateescape"))
    raw = prefix.encode("utf-8", "surrogateescape")
    if len(raw) <= room:
        return prefix
    return raw[: max(room - 1, 1)].decode("utf-8", "ignore") + "."


def write_text_atomic(path, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` by :func:`atomic_write`."""
    return atomic_write(path, lambda tmp: tmp.write_text(text, encoding="utf-8"))
