"""A run file trimmed to be continued after a step (:meth:`RunWriter.reopen <.run_writer.RunWriter.reopen>`):
which rows of which datasets go (:func:`trim_plan`), and their removal in a copy that then replaces the
file (:func:`trim_in_a_copy`), so that a kill during a resume leaves the file whole.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import h5py

from . import layout
from .h5md_format import RunFileError, _rows_up_to, _truncate, appendable_problems, free_bytes


def trim_plan(f, step, path) -> list:
    """The rows a run file keeps to be continued after ``step``: ``(dataset name, rows)`` for each
    dataset that holds more (frames, observables, per-step series, events, circuit log, graph), from
    the file opened read-only. Raises :class:`RunFileError` for a file that cannot be continued."""
    if layout.TIP_POSITION_STEP not in f:
        raise RunFileError(f"{path}: not a selfas-graph run file")
    problems = appendable_problems(f)
    if problems:
        raise RunFileError(f"{path}: cannot be continued: {'; '.join(problems)}")
    plan = []

    def keep(*columns, strict=True):
        # rows of the frames up to `step`, no more than every column of the group holds
        return min([_rows_up_to(columns[0][:], step, strict)] + [c.shape[0] for c in columns[1:]])

    def cut(datasets, n):
        plan.extend((ds.name, n) for ds in datasets if ds.shape[0] > n)

    # the frames' elements (positions, then velocities, written one after the other) keep the same rows:
    # a kill between the two left the velocities a row short, and they would stay a frame behind
    elements = [(f[p]["step"], f[p]["time"], f[p]["value"]) for p in layout.TIP_ELEMENTS.values() if p in f]
    frames = min(keep(*columns) for columns in elements)
    for columns in elements:
        cut(columns, frames)

    def visit(name, obj):
        if isinstance(obj, h5py.Group) and "value" in obj and name != layout.BOND_ERROR_PER_STEP:
            cut(obj.values(), keep(obj["step"], obj["time"], obj["value"]))

    f[layout.OBSERVABLES].visititems(visit)
    g = f[layout.OBSERVABLES][layout.BOND_ERROR_PER_STEP]
    cut((g["step"], g["value"]), keep(g["step"], g["value"]))
    if layout.EVENTS in f:
        ev = f[layout.EVENTS]
        cut((ev,), keep(ev.fields("step"), strict=False) if ev.shape[0] else 0)
    if layout.CIRCUIT_LOG in f:
        g = f[layout.CIRCUIT_LOG]
        columns = [g[name] for name in layout.CIRCUIT_LOG_COLUMNS]
        cut(columns, keep(*columns, strict=False) if columns[0].shape[0] else 0)
    if layout.GRAPH in f:
        g = f[layout.GRAPH]
        per_frame = layout.GRAPH_PER_FRAME + ((layout.GRAPH_FLOATING,) if layout.GRAPH_FLOATING in g else ())
        n = keep(*(g[name] for name in per_frame))
        m = int(g["tip_contacts_count"][:n].sum())
        k = int(g["conductor_contacts_count"][:n].sum())
        if g["tip_contacts"].shape[0] < m or min(g[name].shape[0] for name in layout.GRAPH_CONDUCTOR_CONTACTS) < k:
            raise RunFileError(f"{path}: the graph data up to step {step} are incomplete (damaged file)")
        cut([g[name] for name in per_frame], n)
        cut((g["tip_contacts"],), m)
        cut([g[name] for name in layout.GRAPH_CONDUCTOR_CONTACTS], k)
    return plan


def apply_plan(f, plan) -> None:
    """Cut each dataset of ``plan`` (from :func:`trim_plan`) to its rows, in the file ``f`` opened for writing."""
    for name, n in plan:
        _truncate(f[name], n)


def room_for_copy(path) -> bool:
    """Whether the folder of ``path`` has room for a copy of it and the copy's trimmed rewrite (unknown: yes)."""
    free = free_bytes(path.parent)
    return free is None or free > 2 * os.path.getsize(path) + 2**24


def trim_in_a_copy(path, plan) -> None:
    """Apply ``plan`` to a copy of the run file beside it, then put the copy in its place: a kill at
    any moment leaves the file as it was or as trimmed, never half-shrunk."""
    tmp = path.with_name(f".{path.name}.resume.part")
    try:
        shutil.copy2(path, tmp)  # the data, and the file's permissions
        with h5py.File(tmp, "r+") as f:
            apply_plan(f, plan)
        with open(tmp, "rb+") as fh:
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


def trim_safely(path, plan) -> list:
    """Apply ``plan`` to the run file ``path`` in a copy that replaces it (:func:`trim_in_a_copy`) where
    it can be; returns the plan still to apply in place: empty, or ``plan`` itself for a file with
    other names (a copy would part them), without room for a copy, or whose copy failed."""
    real = Path(os.path.realpath(path))  # through a symbolic link: the copy replaces the file, not the link
    if os.stat(real).st_nlink > 1 or not room_for_copy(real):
        return plan
    try:
        trim_in_a_copy(real, plan)
    except OSError:  # a quota the free space does not show, a folder that is not writable, a long name
        return plan
    return []
