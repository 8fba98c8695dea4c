"""Checkpoint files: everything a run needs to continue exactly, written atomically.

A checkpoint is an HDF5 file holding :meth:`Simulation.snapshot` (arrays as datasets,
scalars as attributes of ``/snapshot``; a float entry's NaN or inf, the state's "none" markers, as 0
with its codes in ``nonfinite__KEY``, so that no file holds a NaN) and, in ``/meta``, the scenario text and
overrides, the run's identity (``run_id``, also stored in the run file), the name of
the run file it sits beside, the effective end time and the package version. The root
attribute ``checksum`` is a SHA-256 of every snapshot and meta entry (name, dtype,
shape and bytes), verified on reading: a flipped bit or an edited value is refused.

It is written to ``PATH.tmp``, flushed and fsynced, then renamed over ``PATH``, so a
kill at any moment leaves either the previous checkpoint or the new one, never a torn
file; a write that fails (full disk) removes its ``.tmp`` and leaves the previous
checkpoint in place.
"""

from __future__ import annotations

import hashlib
import json
import os
import time
from pathlib import Path

import h5py
import numpy as np

from . import layout

FORMAT = "selfas-graph checkpoint 1"

#: snapshot arrays that must hold finite numbers for a run to continue from them
FINITE = ("position", "velocity", "hist_v", "hist_a", "hist_p", "work", "current", "tip_charge", "rod_charge")


class CheckpointError(ValueError):
    """A file that is not a readable selfas-graph checkpoint."""


def checkpoint_path(run_path) -> Path:
    """The checkpoint that belongs to a run file: ``RUN.h5`` -> ``RUN.checkpoint.h5``."""
    p = Path(run_path)
    return p.with_name(p.stem + ".checkpoint.h5")


def _digest(snapshot: dict, meta: dict) -> str:
    """SHA-256 over every entry as stored (sorted names; dtype, shape and bytes of each value)."""
    h = hashlib.sha256()
    for part, items in ((layout.CHECKPOINT_SNAPSHOT, snapshot), (layout.CHECKPOINT_META, meta)):
        for key in sorted(items):
            value = items[key]
            if isinstance(value, bytes):
                value = value.decode("utf-8", "surrogateescape")
            arr = np.asarray(value)
            if arr.dtype.kind in "OUS":
                data, kind = str(value).encode("utf-8", "surrogateescape"), "str"
            else:
                arr = np.ascontiguousarray(arr)
                data, kind = arr.tobytes(), f"{arr.dtype.str}{arr.dtype.descr if arr.dtype.fields else ''}{arr.shape}"
            h.update(f"{part}/{key}:{kind}:{len(data)}:".encode("utf-8", "surrogateescape"))
            h.update(data)
    return h.hexdigest()


def write_checkpoint(path, snapshot: dict, meta: dict, failed: dict | None = None) -> None:
    """Write ``snapshot`` and ``meta`` to ``path`` atomically (write aside, fsync, rename).

    On any error (e.g. a full disk: ``OSError``) the temporary file is removed and the
    previous checkpoint at ``path``, if any, is left as it was; the error is raised.
    ``failed``: a failure file's group of the failed state (:func:`write_failure`).
    """
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    need = sum(np.asarray(v).nbytes for v in snapshot.values()) + sum(len(str(v)) for v in meta.values()) + (1 << 20)
    need += 2 * sum(np.asarray(v).nbytes for v in (failed or {}).values())
    try:
        st = os.statvfs(path.parent if str(path.parent) else ".")
        free = st.f_bavail * st.f_frsize
    except (OSError, AttributeError):
        free = None
    if free is not None and free < need:
        # refused before the temporary file exists: the previous checkpoint stays, nothing is left behind
        from .h5md import DiskFullError

        raise DiskFullError(
            28,
            f"No space left for a checkpoint ({free / 2**20:.2f} MiB free, about {need / 2**20:.2f} MiB needed)",
            str(tmp),
        )
    meta = {
        k: (v if isinstance(v, (str, int, float, np.integer, np.floating)) else json.dumps(v)) for k, v in meta.items()
    }
    try:
        with h5py.File(tmp, "w") as f:
            f.attrs["format"] = FORMAT
            g = f.create_group(layout.CHECKPOINT_SNAPSHOT)
            stored = {}
            for key, value in _encode_nonfinite(snapshot).items():
                arr = np.asarray(value)
                if arr.ndim == 0 and arr.dtype.fields is None:
                    g.attrs[key] = arr.item()
                else:
                    g.create_dataset(key, data=arr)
            m = f.create_group(layout.CHECKPOINT_META)
            for key, value in meta.items():
                m.attrs[key] = value
            # the digest of what reads back (attributes come back as numpy scalars)
            stored = {k: g.attrs[k] for k in g.attrs}
            stored.update({k: g[k][()] for k in g})
            f.attrs["checksum"] = _digest(stored, dict(m.attrs))
            if failed is not None:
                _write_failed(f.create_group(layout.CHECKPOINT_FAILED), failed)
            f.flush()
        fd = os.open(tmp, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
        os.replace(tmp, path)
    except BaseException:
        try:
            tmp.unlink()
        except OSError:
            pass
        raise
    _fsync_folder(path.parent)


#: codes of ``failed/nonfinite/KEY`` in a failure file: what an entry of the failed state was
NONFINITE_CODES = {"finite": 0, "nan": 1, "+inf": 2, "-inf": 3}
_DECODE = {1: np.nan, 2: np.inf, 3: -np.inf}
#: prefix of a snapshot entry that codes where its float entry KEY holds NaN or inf ("none" markers
#: of the state: no short circuit yet, a tip with no filament potential, a slow force not yet held)
NONFINITE_PREFIX = "nonfinite__"


def _encode_nonfinite(snapshot: dict) -> dict:
    """The snapshot as stored: no NaN or inf in the file. A float entry with non-finite values is
    stored with 0 there and its codes (:data:`NONFINITE_CODES`) as ``nonfinite__KEY``;
    :func:`_decode_nonfinite` restores it, so a resumed run sees the same state."""
    out = {}
    for key, value in snapshot.items():
        arr = np.asarray(value)
        if arr.dtype.kind == "f" and arr.dtype.fields is None and not np.isfinite(arr).all():
            code = nonfinite_code(arr)
            fixed = np.where(code == 0, arr, 0.0).astype(arr.dtype)
            out[key] = fixed if arr.ndim else fixed.item()
            out[NONFINITE_PREFIX + key] = code if arr.ndim else int(code)
        else:
            out[key] = value
    return out


def _decode_nonfinite(snap: dict) -> dict:
    """Inverse of :func:`_encode_nonfinite` on a snapshot as read."""
    out = {k: v for k, v in snap.items() if not k.startswith(NONFINITE_PREFIX)}
    for key, code in snap.items():
        if not key.startswith(NONFINITE_PREFIX) or key[len(NONFINITE_PREFIX) :] not in out:
            continue
        name = key[len(NONFINITE_PREFIX) :]
        code = np.asarray(code)
        value = np.array(out[name], dtype=np.float64 if np.asarray(out[name]).dtype.kind != "f" else None)
        for c, v in _DECODE.items():
            value[code == c] = v
        out[name] = value if value.ndim else float(value)
    return out


def nonfinite_code(arr) -> np.ndarray:
    """int8 array of :data:`NONFINITE_CODES`, the shape of ``arr``: which entries are NaN, +inf, -inf."""
    arr = np.asarray(arr)
    code = np.zeros(arr.shape, dtype=np.int8)
    code[np.isnan(arr)] = NONFINITE_CODES["nan"]
    code[np.isposinf(arr)] = NONFINITE_CODES["+inf"]
    code[np.isneginf(arr)] = NONFINITE_CODES["-inf"]
    return code


def _write_failed(g, failed: dict) -> None:
    """The failed state into group ``g`` without a NaN or inf: each float array with its non-finite
    entries set to 0, their codes in ``nonfinite/KEY`` and the largest finite magnitude in the
    dataset's attribute ``largest_finite``; float scalars likewise (codes in the attribute
    ``nonfinite_scalars``, JSON); other values as they are."""
    scalars = {}
    for key, value in failed.items():
        arr = np.asarray(value)
        is_float = arr.dtype.kind == "f" and arr.dtype.fields is None
        finite = np.isfinite(arr) if is_float else None
        if arr.ndim == 0 and arr.dtype.fields is None:
            if is_float and not finite:
                scalars[key] = "nan" if np.isnan(arr) else "+inf" if arr > 0 else "-inf"
                g.attrs[key] = 0.0
            else:
                g.attrs[key] = arr.item()
            continue
        if not is_float:
            g.create_dataset(key, data=arr)
            continue
        ds = g.create_dataset(key, data=np.where(finite, arr, 0.0))
        ds.attrs["largest_finite"] = float(np.abs(arr[finite]).max()) if finite.any() else 0.0
        if not finite.all():
            g.create_dataset(f"nonfinite/{key}", data=nonfinite_code(arr))
    g.attrs["nonfinite_scalars"] = json.dumps(scalars)
    g.attrs["nonfinite_codes"] = json.dumps(NONFINITE_CODES)


def write_failure(path, last_good: dict, failed: dict, meta: dict) -> None:
    """A failure file: the checkpoint of the last state the run's checks passed (``last_good``, a
    snapshot: finite, verified by :func:`read_checkpoint`, resumable to replay the failure) and, in
    group ``failed``, the state at the failed step without a NaN or inf (:func:`_write_failed`: each
    array's non-finite entries are 0 and coded in ``failed/nonfinite/KEY``). Written atomically."""
    write_checkpoint(path, last_good, meta, failed=failed)


def failure_meta(checkpointer, sim, exc) -> dict:
    """The ``/meta`` of a failure file: the run's checkpoint meta, the step of the last good state
    (``step``, that of the snapshot) and the diagnosis (``failure``, ``failed_step``)."""
    good = sim.last_good_snapshot
    return {
        **checkpointer.meta,
        "step": int(good["step"]) if good is not None else sim.state.step,
        "failed_step": sim.state.step,
        "failure": str(exc),
    }


def _fsync_folder(folder):
    """Make a rename in ``folder`` durable (best effort: not every file system allows it)."""
    try:
        fd = os.open(folder if str(folder) else ".", os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


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
        try:
            if f.attrs.get("format") != FORMAT:
                raise CheckpointError(f"{path}: not a selfas-graph checkpoint (expected format {FORMAT!r})")
            g = f[layout.CHECKPOINT_SNAPSHOT]
            snap = {k: v for k, v in g.attrs.items()}
            for k in g:
                snap[k] = g[k][()]
            meta = dict(f[layout.CHECKPOINT_META].attrs)
            checksum = f.attrs.get("checksum")
        except CheckpointError:
            raise
        except (KeyError, TypeError, ValueError, OSError, RuntimeError, AttributeError) as exc:
            raise CheckpointError(
                f"{path}: an incomplete or damaged checkpoint ({' '.join(str(exc).split())})"
            ) from None
    missing = [k for k in ("position", "velocity", "step", "time", "hist_v", "hist_a") if k not in snap]
    missing += [k for k in ("scenario_text", "overrides") if k not in meta]
    if missing:
        raise CheckpointError(f"{path}: an incomplete checkpoint (missing {', '.join(missing)})")
    if checksum is None:
        raise CheckpointError(
            f"{path}: the checkpoint carries no checksum, so its contents cannot be verified "
            f"(written by an older selfas-graph, or damaged)"
        )
    try:
        ok = isinstance(checksum, str) and _digest(snap, meta) == checksum
    except (TypeError, ValueError, UnicodeError):
        ok = False
    if not ok:
        raise CheckpointError(
            f"{path}: the checkpoint's contents do not match its checksum "
            f"(the file is damaged or was edited); it cannot be resumed from"
        )
    snap = _decode_nonfinite(snap)
    check_snapshot(snap, path)
    return snap, meta


def check_snapshot(snap: dict, path="checkpoint") -> None:
    """Refuse a snapshot that no run can continue from: wrong dtypes or shapes, non-finite state.

    Raises
    ------
    CheckpointError
        Naming the entry and what it should hold.
    """
    from ..model.circuitlog import CIRCUIT_LOG_DTYPE
    from ..model.events import EVENT_DTYPE

    pos = np.asarray(snap["position"])
    if pos.dtype.kind != "f" or pos.ndim != 2 or pos.shape[1] != 3 or pos.shape[0] % 2:
        raise CheckpointError(
            f"{path}: snapshot/position must be a (2 n_rods, 3) float array, got {pos.dtype} {pos.shape}"
        )
    for key in FINITE:
        if key not in snap:
            continue
        arr = np.asarray(snap[key])
        if arr.dtype.kind not in "fiu" or arr.dtype.fields is not None:
            raise CheckpointError(f"{path}: snapshot/{key} must hold numbers, got dtype {arr.dtype}")
        if not np.isfinite(arr).all():
            raise CheckpointError(
                f"{path}: snapshot/{key} holds non-finite values (NaN or inf); the state cannot be continued"
            )
    for key in ("velocity",):
        if np.asarray(snap[key]).shape != pos.shape:
            raise CheckpointError(
                f"{path}: snapshot/{key} has shape {np.asarray(snap[key]).shape}, "
                f"expected {pos.shape} like the positions"
            )
    for key in ("step", "time"):
        v = np.asarray(snap[key])
        if v.ndim != 0 or v.dtype.kind not in "fiu" or not np.isfinite(v):
            raise CheckpointError(f"{path}: snapshot/{key} must be a finite number, got {snap[key]!r}")
    if "events" in snap:
        ev = np.asarray(snap["events"])
        if ev.dtype != EVENT_DTYPE or ev.ndim != 1:
            raise CheckpointError(
                f"{path}: snapshot/events must be a 1-D array of event records "
                f"{EVENT_DTYPE.descr}, got {ev.dtype} {ev.shape}"
            )
    if "circuit_log" in snap:
        log = np.asarray(snap["circuit_log"])
        if log.dtype != CIRCUIT_LOG_DTYPE or log.ndim != 1 or not np.isfinite(log["total_current"]).all():
            raise CheckpointError(
                f"{path}: snapshot/circuit_log must be a 1-D array of finite circuit-log records "
                f"{CIRCUIT_LOG_DTYPE.descr}, got {log.dtype} {log.shape}"
            )


def checkpoint_meta(scenario, run_id, run_name, t_end, version) -> dict:
    """The ``/meta`` of a run's checkpoints: what ``simulate --resume`` needs besides the
    snapshot (the scenario text and overrides, the run identity shared with the run file,
    the run file's name beside the checkpoint, the effective end time)."""
    return {
        "format_note": "selfas-graph checkpoint; continue with selfas-graph simulate --resume",
        "scenario_text": scenario.text,
        "overrides": json.dumps(list(scenario.overrides)),
        "run_id": str(run_id),
        "run_name": str(run_name),
        "run_file": str(run_name),
        "t_end": float(t_end),
        "version": version,
    }


class Checkpointer:
    """Writes the simulation's snapshot to a checkpoint file, the first when it is first asked
    (:func:`~selfas_graph.lifecycle.run_to_file` asks before the first step), then every ``interval``
    wall seconds (0: only on demand).

    The first one comes at once so that a run killed in its first interval (900 s by default)
    can be resumed too.
    """

    def __init__(self, path, interval, meta):
        self.path, self.interval, self.meta = Path(path), float(interval), meta
        self.last = time.monotonic()
        self.written = 0

    def due(self):
        return self.interval > 0 and (self.written == 0 or time.monotonic() - self.last >= self.interval)

    def write(self, sim):
        write_checkpoint(self.path, sim.snapshot(), {**self.meta, "step": sim.state.step})
        self.last = time.monotonic()
        self.written += 1
