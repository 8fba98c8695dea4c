"""Checkpoint files: everything a run needs to continue exactly, written atomically.

A checkpoint is an HDF5 file holding :meth:`Simulation.snapshot` (arrays as datasets,
scalars as attributes of ``/snapshot``) and, in ``/meta``, the scenario text and
overrides, the run file it belongs to and the package version. It is written to
``PATH.tmp``, flushed to disk, then renamed over ``PATH``, so a kill at any moment
leaves either the previous checkpoint or the new one, never a torn file.
"""
from __future__ import annotations

import json
import os
from pathlib import Path

import h5py
import numpy as np

FORMAT = "selfas-graph checkpoint 1"


class CheckpointError(ValueError):
    """A file that is not a readable selfas-graph checkpoint."""


def checkpoint_path(run_path) -> Path:
    """The checkpoint that belongs to a run file: ``RUN.h5`` -> ``RUN.checkpoint.h5``."""
    p = Path(run_path)
    return p.with_name(p.stem + ".checkpoint.h5")


def write_checkpoint(path, snapshot: dict, meta: dict) -> None:
    """Write ``snapshot`` and ``meta`` to ``path`` atomically (write aside, fsync, rename)."""
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    with h5py.File(tmp, "w") as f:
        f.attrs["format"] = FORMAT
        g = f.create_group("snapshot")
        for key, value in snapshot.items():
            arr = np.asarray(value)
            if arr.ndim == 0 and arr.dtype.fields is None:
                g.attrs[key] = arr.item()
            else:
                g.create_dataset(key, data=arr)
        m = f.create_group("meta")
        for key, value in meta.items():
            m.attrs[key] = value if isinstance(value, (str, int, float)) else json.dumps(value)
        f.flush()
    fd = os.open(tmp, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)
    os.replace(tmp, path)


def read_checkpoint(path) -> tuple[dict, dict]:
    """Return ``(snapshot, meta)`` from a checkpoint file.

    Raises
    ------
    CheckpointError
        Missing file, not HDF5, or not a selfas-graph checkpoint.
    """
    path = Path(path)
    if not path.exists():
        raise CheckpointError(f"{path}: no such checkpoint file")
    try:
        f = h5py.File(path, "r")
    except OSError as exc:
        raise CheckpointError(f"{path}: not a readable HDF5 file ({exc})") from None
    with f:
        if f.attrs.get("format") != FORMAT:
            raise CheckpointError(f"{path}: not a selfas-graph checkpoint (expected format {FORMAT!r})")
        try:
            g = f["snapshot"]
            snap = {k: v for k, v in g.attrs.items()}
            for k in g:
                snap[k] = g[k][()]
            meta = dict(f["meta"].attrs)
        except (KeyError, TypeError, OSError) as exc:
            raise CheckpointError(f"{path}: an incomplete or damaged checkpoint ({exc})") from None
    missing = [k for k in ("position", "velocity", "step", "time", "hist_v", "hist_a") if k not in snap]
    missing += [k for k in ("scenario_text", "overrides", "run_file") if k not in meta]
    if missing:
        raise CheckpointError(f"{path}: an incomplete checkpoint (missing {', '.join(missing)})")
    return snap, meta
