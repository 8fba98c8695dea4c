"""The reader of a run file (:mod:`selfas_graph.io.h5md`): :class:`RunFile`, read-only, without any
simulation objects."""

from __future__ import annotations

import functools
import json
import numbers
import operator
import re
from pathlib import Path

import h5py
import numpy as np

from ..model.circuitlog import CIRCUIT_LOG_DTYPE
from ..model.events import EVENT_DTYPE, named_events
from ..model.validate import is_whole_number
from . import layout
from .h5md_format import HDF5_READ_ERRORS, FileInUseError, RunFileError


def _pick_frame(path, n, frame, t, times) -> int:
    """Index of one of ``n`` frames: number ``frame`` (negative counts from the end; default the last)
    or the one nearest time ``t`` (``times()`` gives the frames' times); RunFileError otherwise."""
    if t is not None:
        if frame is not None:
            raise RunFileError(f"frame {frame!r} and time {t!r} both given; name the frame by one of them")
        if isinstance(t, (bool, np.bool_)) or not isinstance(t, numbers.Real) or not np.isfinite(t):
            raise RunFileError(f"time {t!r} names no frame; give a finite simulated time")
        ts = np.asarray(times(), dtype=float)
        # the nearest frame, within the run's frames or at most one frame spacing beyond them: a time
        # further out names no frame of this run (a typo, or another run's time), not its first or last
        reach = float(np.max(np.diff(ts))) if ts.size > 1 else 0.0
        slack = reach + 1e-9 * max(1.0, abs(t))
        if not ts[0] - slack <= t <= ts[-1] + slack:
            raise RunFileError(
                f"{path}: time {t:g} lies outside the run's frames, t = {ts[0]:g} .. {ts[-1]:g}; "
                "give a time between them"
            )
        return int(np.argmin(np.abs(ts - t)))
    try:
        if isinstance(frame, (bool, np.bool_)):
            raise TypeError  # True is not frame 1
        k = -1 if frame is None else operator.index(frame)
    except TypeError:
        raise RunFileError(f"frame {frame!r}: give a frame number (an integer; negative counts from the end)") from None
    if not -n <= k < n:
        raise RunFileError(f"{path}: frame {k} out of range; the file has frames 0..{n - 1}")
    return k % n


def locked_message(path, reason=None) -> str:
    """Why ``path``, locked by another process (HDF5's file lock: ``reason``), is not read, and what to do."""
    why = f" (HDF5 file locking: {reason})" if reason else ""
    return (
        f"{path}: locked by another process, most likely a simulation still writing it{why}; wait for it to "
        "end, or set HDF5_USE_FILE_LOCKING=FALSE to read it anyway"
    )


class RunFile:
    """Read-only access to a run file, without any simulation objects.

    The frames are the rows whose step, time and positions (and velocities, where saved) were all
    written: ``torn_frame`` is true when a kill while a frame was appended left some of them a row
    longer than the others (a resume drops that row). They are those the file held when it was opened:
    of a run still being written, open it again to read later frames.

    Parameters
    ----------
    path : path-like

    Raises
    ------
    RunFileError
        If the file is missing, not HDF5, or not written by selfas-graph.
    """

    def __init__(self, path):
        self.path = Path(path)
        if not self.path.exists():
            raise RunFileError(f"{self.path}: no such file")
        if self.path.is_dir():
            raise RunFileError(f"{self.path}: a directory, not a run file")
        try:
            self._f = h5py.File(self.path, "r")
        except OSError as exc:
            reason = " ".join(str(exc).split())  # h5py's messages can span lines
            if re.search(r"\block", reason.lower()) or "already open for write" in reason.lower():
                raise FileInUseError(locked_message(self.path, reason)) from None
            raise RunFileError(f"{self.path}: not a readable HDF5 file ({reason})") from None
        required = (
            layout.PROVENANCE,
            layout.TIP_POSITION_VALUE,
            layout.TIP_POSITION_STEP,
            layout.TIP_POSITION_TIME,
            layout.TIP_CHARGE,
            layout.ROD_CHARGE,
            layout.OBSERVABLES,
        )
        missing = [name for name in required if not isinstance(self.f.get(name), (h5py.Dataset, h5py.Group))]
        if missing or "parameters_json" not in self.f[layout.PROVENANCE].attrs:
            fmt = self.f.attrs.get("format")
            self.f.close()
            if isinstance(fmt, (str, bytes)) and "checkpoint" in (fmt.decode() if isinstance(fmt, bytes) else fmt):
                name = self.path.name
                if name.endswith(".failure.h5"):
                    what, run = "the failed state of a run", name.removesuffix(".failure.h5") + ".h5"
                else:
                    what, run = "the state to resume a run from", name.removesuffix(".checkpoint.h5") + ".h5"
                raise RunFileError(
                    f"{self.path}: a checkpoint ({what}), not a run file; give the run file it belongs to "
                    f"({run}, beside it)"
                )
            raise RunFileError(
                f"{self.path}: an HDF5 file, but not a selfas-graph run "
                f"(missing {', '.join(missing) or 'parameters_json'})"
            )
        self.meta = dict(self.f[layout.PROVENANCE].attrs)
        n = self.f[layout.TIP_POSITION_VALUE].shape
        rows = [
            self.f[name].shape[0] if self.f[name].ndim else -1
            for name in (layout.TIP_POSITION_STEP, layout.TIP_POSITION_TIME)
        ]
        if len(n) != 3 or n[2] != 3 or min(rows) < 0 or max(rows + [n[0]]) - min(rows + [n[0]]) > 1:
            self.f.close()
            raise RunFileError(f"{self.path}: the positions are not laid out as (frames, tips, 3)")
        lengths = rows + [n[0]]
        if layout.TIP_VELOCITY in self.f:  # written after the positions: a kill between leaves it shorter
            g = self.f[layout.TIP_VELOCITY]
            cols = [g.get(k) for k in (layout.STEP, layout.TIME, layout.VALUE)]
            if all(isinstance(c, h5py.Dataset) and c.ndim for c in cols):  # else damaged: read, they say so
                lengths += [c.shape[0] for c in cols]
        self._frames = min(lengths)
        self.torn_frame = max(lengths) > self._frames
        kinds = {name: self.f[f"{layout.TIP_POSITION}/{name}"].dtype.kind for name in ("step", "time", "value")}
        if kinds["step"] not in "iu" or kinds["time"] != "f" or kinds["value"] != "f":
            self.f.close()
            raise RunFileError(
                f"{self.path}: the positions' step, time and value datasets must hold integers, "
                f"numbers and numbers (found dtype kinds {kinds['step']}, {kinds['time']}, "
                f"{kinds['value']})"
            )

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def close(self):
        self._f.close()

    @property
    def f(self) -> h5py.File:
        """The open HDF5 file (RunFileError once the run file was closed)."""
        if not self._f:
            raise RunFileError(
                f"{self.path}: the run file is closed; read it inside its with block, or open it again with RunFile"
            )
        return self._f

    @property
    def status(self) -> str:
        """How the run stands: "finished", "interrupted at step N", "interrupted (Ctrl-C)" (a run driven from
        Python), "failed: ...", or "running" (still running, or killed before it could say otherwise)."""
        return str(self.meta.get("status", "unknown"))

    @property
    def parameters(self) -> dict:
        return json.loads(self.meta["parameters_json"])

    @functools.cached_property
    def contact_resistance(self) -> float:
        """The run's ``contacts.resistance`` (0: ideal contacts, and in files without the key)."""
        try:
            return float((self.parameters.get("contacts") or {}).get("resistance") or 0.0)
        except (TypeError, ValueError, AttributeError):
            return 0.0

    @property
    def scenario_text(self) -> str:
        return self.meta["scenario_text"]

    @property
    def n_frames(self) -> int:
        return self._frames

    @property
    def time(self) -> np.ndarray:
        return self.f[layout.TIP_POSITION_TIME][: self._frames]

    @property
    def step(self) -> np.ndarray:
        return self.f[layout.TIP_POSITION_STEP][: self._frames]

    def frame_index(self, frame=None, t=None) -> int:
        """Index of a frame given by number (negative counts from the end) or nearest time."""
        n = self.n_frames
        if n == 0:
            raise RunFileError(f"{self.path}: the run has no saved frames{self._later_frames()}")
        try:
            return _pick_frame(self.path, n, frame, t, lambda: self.time)
        except RunFileError as exc:
            raise RunFileError(f"{exc}{self._later_frames()}") from None

    def _later_frames(self) -> str:
        """ "; it holds N frames now: ..." where frames were written since this RunFile was opened (it reads
        the frames it found then), or ""."""
        try:
            now = int(self.f[layout.TIP_POSITION_STEP].shape[0])
        except HDF5_READ_ERRORS:
            return ""
        if now <= self._frames:
            return ""
        return (
            f" when this RunFile was opened; the file holds {now} frames now: open it again to read the frames "
            "written since"
        )

    def frame(self, index=None, t=None):
        """One saved frame as a :class:`~selfas_graph.io.frame.SavedFrame`: by index (negative counts
        from the end; default the last) or nearest time ``t``; its graph data are those of the same step."""
        from .frame import SavedFrame

        return SavedFrame(self, self.frame_index(index, t))

    def position(self, frame=None, t=None) -> np.ndarray:
        """The tips' positions (n_tips, 3) of a frame: by number (negative counts from the end; default the
        last) or nearest time ``t``, as :meth:`frame_index`."""
        return self.f[layout.TIP_POSITION_VALUE][self.frame_index(frame, t)]

    def velocity(self, frame=None, t=None) -> np.ndarray:
        """The tips' velocities of a frame, chosen as by :meth:`position`."""
        if layout.TIP_VELOCITY not in self.f:
            raise RunFileError(f"{self.path}: velocities were not saved (output.velocities = false)")
        return self.f[layout.TIP_VELOCITY_VALUE][self.frame_index(frame, t)]

    @property
    def tip_charge(self) -> np.ndarray:
        return self.f[layout.TIP_CHARGE][:]

    @property
    def rod_charge(self) -> np.ndarray:
        return self.f[layout.ROD_CHARGE][:]

    @property
    def rod_length(self) -> np.ndarray:
        """Length of each rod (units L); ones when the run had equal rods."""
        if layout.ROD_LENGTH in self.f:
            return self.f[layout.ROD_LENGTH][:]
        return np.ones(self.f[layout.ROD_CHARGE].shape[0])

    @property
    def rod_resistance(self) -> np.ndarray:
        """Resistance of each rod (units R0); ones when the run had R0 = 1 for every rod."""
        if layout.ROD_RESISTANCE in self.f:
            return self.f[layout.ROD_RESISTANCE][:]
        return np.ones(self.f[layout.ROD_CHARGE].shape[0])

    @property
    def n_tips(self) -> int:
        return self.f[layout.TIP_POSITION_VALUE].shape[1]

    @property
    def bonds(self) -> np.ndarray:
        """(n_rods, 2) the tips of each rod: ``/connectivity/rods``, or the same pairs for older files."""
        ds = self.f.get(layout.CONNECTIVITY_RODS)
        if isinstance(ds, h5py.Dataset) and ds.shape == (self.n_tips // 2, 2):
            return ds[:]
        return np.arange(self.n_tips, dtype=np.int64).reshape(-1, 2)

    @property
    def has_graph(self) -> bool:
        return self._graph_records > 0

    @functools.cached_property
    def _graph_records(self) -> int:
        """The graph records all of whose rows were written (0 without graph data), counted once: a kill
        while a record was appended can leave its step and time without the rest (a resume drops that
        record, as a torn frame row)."""
        g = self.f.get(layout.GRAPH)
        if not (isinstance(g, h5py.Group) and all(isinstance(g.get(n), h5py.Dataset) for n in layout.GRAPH_DATASETS)):
            return 0
        names = layout.GRAPH_PER_FRAME + ((layout.GRAPH_FLOATING,) if layout.GRAPH_FLOATING in g else ())
        n = min(g[name].shape[0] for name in names)
        tips = np.cumsum(g["tip_contacts_count"][:n])
        conductors = np.cumsum(g["conductor_contacts_count"][:n])
        held = min(g[name].shape[0] for name in layout.GRAPH_CONDUCTOR_CONTACTS)
        while n and (tips[n - 1] > g["tip_contacts"].shape[0] or conductors[n - 1] > held):
            n -= 1
        return n

    @property
    def graph_steps(self) -> np.ndarray:
        """The steps of the frames saved with graph data (empty without any)."""
        return self.f[layout.GRAPH_STEP][: self._graph_records] if self.has_graph else np.zeros(0, dtype=np.int64)

    def events(self, until_step=None) -> np.ndarray:
        """Event records (structured array, fields step, time, kind, a, b), optionally up to a step."""
        if layout.EVENTS not in self.f:
            return np.zeros(0, dtype=EVENT_DTYPE)
        if until_step is not None and not is_whole_number(until_step):
            raise RunFileError(f"events(until_step=...): a step number (an integer), got {until_step!r}")
        e = self.f[layout.EVENTS][:].astype(EVENT_DTYPE)  # the kind an enumeration in newer files, integers before
        return e if until_step is None else e[e["step"] <= until_step]

    def circuit_log(self, until_step=None) -> np.ndarray | None:
        """The circuit log (structured array ``model.circuitlog.CIRCUIT_LOG_DTYPE``: step, time, kind,
        total_current, rods_in_series, filament_rods), optionally up to a step; None for a file
        without one (written before it existed, or by a run without contacts)."""
        g = self.f.get(layout.CIRCUIT_LOG)
        if not isinstance(g, h5py.Group) or not all(
            isinstance(g.get(n), h5py.Dataset) for n in layout.CIRCUIT_LOG_COLUMNS
        ):
            return None
        columns = [g[name][:] for name in layout.CIRCUIT_LOG_COLUMNS]
        log = np.zeros(min(len(c) for c in columns), dtype=CIRCUIT_LOG_DTYPE)
        for name, c in zip(layout.CIRCUIT_LOG_COLUMNS, columns):
            log[name] = c[: len(log)]
        return log if until_step is None else log[log["step"] <= until_step]

    def named_events(self, until_step=None) -> list:
        """The events as :class:`selfas_graph.model.events.Event` tuples, kinds as ``EventKind``."""
        return named_events(self.events(until_step))

    def graph_frame_index(self, frame=None, t=None) -> int:
        if not self.has_graph:
            raise RunFileError(
                f"{self.path}: the file has no graph data (the run had contacts.enabled = false, "
                f"or was written before any frame)"
            )
        n = self._graph_records
        return _pick_frame(self.path, n, frame, t, lambda: self.f[layout.GRAPH_TIME][:n])

    def graph_of_frame(self, index) -> dict:
        """The graph record of the run's frame ``index`` (as :meth:`frame_index` numbers the frames),
        found by its step, with ``frame`` set to ``index``: after a frame whose record a kill tore, the
        records are not numbered as the frames. RunFileError where the frame has none."""
        k = self.frame_index(frame=index)
        if not self.has_graph:
            self.graph_frame_index(k)  # raises the reader's explanation
        step = int(self.f[layout.TIP_POSITION_STEP][k])
        record = self.graph_record_of_step(step)
        if record is None:
            raise RunFileError(f"{self.path}: no graph data saved at frame {k} (step {step})")
        return self.graph(frame=record) | {"frame": k}

    def graph_record_of_step(self, step) -> int | None:
        """The graph record saved at ``step``, or None (no graph data, or none at that step)."""
        match = np.flatnonzero(self.graph_steps == step) if self.has_graph else ()
        return int(match[0]) if len(match) else None

    def graph(self, frame=None, t=None) -> dict:
        """The graph state of graph record ``frame`` (or the record nearest ``t``): contact arrays, roles,
        currents, potentials, step and time. The records are the frames' but where a kill tore one (a
        frame's own record: :meth:`graph_of_frame`)."""
        k = self.graph_frame_index(frame, t)
        g = self.f[layout.GRAPH]
        tc_count = g["tip_contacts_count"][:]
        cc_count = g["conductor_contacts_count"][:]
        t0, t1 = int(tc_count[:k].sum()), int(tc_count[: k + 1].sum())
        c0, c1 = int(cc_count[:k].sum()), int(cc_count[: k + 1].sum())
        ids = g.attrs["conductor_ids"]
        pots = np.array(g.attrs["conductor_potentials"], dtype=np.float64)
        if "conductor_per_contact" in g.attrs:  # files before 0.4 hold NaN there instead
            pots[np.asarray(g.attrs["conductor_per_contact"], dtype=bool)] = np.nan
        potential = g["potential"][k]
        if "floating" in g:  # files before 0.4 hold NaN for floating tips instead
            potential = np.where(g["floating"][k] != 0, np.nan, potential)
        return {
            "frame": k,
            "step": int(g["step"][k]),
            "time": float(g["time"][k]),
            "tip_contacts": g["tip_contacts"][t0:t1].reshape(-1, 2),
            "conductor_tip": g["conductor_tip"][c0:c1],
            "conductor_id": g["conductor_id"][c0:c1],
            "conductor_potential": g["conductor_potential"][c0:c1],
            "role": g["role"][k],
            "current": g["current"][k],
            "potential": potential,
            "conductors": {int(c): (None if np.isnan(p) else float(p)) for c, p in zip(ids, pots)},
        }

    def observable_names(self):
        """Names of all observables, nested ones as ``group/name`` (e.g. ``energy/kinetic``)."""
        names = []
        self.f[layout.OBSERVABLES].visit(
            lambda name: names.append(name[: -len("/value")]) if name.endswith("/value") else None
        )
        return sorted(names)

    def observable(self, name):
        """(time, value) arrays of a per-frame observable, or (step, value) for per-step series."""
        if name not in self.observable_names():  # a group of observables (energy) is not one
            raise RunFileError(f"{self.path}: no observable {name!r}; present: {', '.join(self.observable_names())}")
        g = self.f[layout.OBSERVABLES][name]
        if "time" not in g:
            return g["step"][:], g["value"][:]
        # a per-frame series: its rows up to the last frame (a kill can leave a row of a frame it tore)
        rows = min(g["time"].shape[0], g["value"].shape[0])
        if not self._frames:
            rows = 0
        elif "step" in g:
            last = self.f[layout.TIP_POSITION_STEP][self._frames - 1]
            rows = min(rows, int(np.searchsorted(g["step"][:rows], last, side="right")))
        return g["time"][:rows], g["value"][:rows]
