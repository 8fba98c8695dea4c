"""The writer of a run file: :class:`RunWriter` (an H5MD 1.1 run file, :mod:`selfas_graph.io.h5md`); what
a writer holds between frames, and :class:`NullWriter` (nothing written), are in :mod:`.pending_rows`."""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

import h5py
import numpy as np

from ..model.circuitlog import CIRCUIT_LOG_DTYPE, circuit_log_array
from ..model.events import CONDUCTOR_NAMES, KIND_NAMES, OPEN_CIRCUIT, SHORT_CIRCUIT, event_array
from ..model.operations import stop_status
from ..model.topology import ROLE_NAMES
from ..model.validate import is_whole_number
from . import layout
from .checkpoint import CheckpointError, checkpoint_path, read_checkpoint
from .h5md_format import (
    CURRENT,
    EVENT_FILE_DTYPE,
    H5MD_VERSION,
    LENGTH,
    POTENTIAL,
    SPACE_MARGIN,
    TIME,
    UNIT_SYSTEM,
    OutputExistsError,
    RunFileError,
    _box,
    _charges,
    _fixed,
    _growable,
    _set_unit,
    _unit_string,
    check_room,
    dangling_link,
    in_use,
    in_use_message,
    not_replaced,
    observable_unit,
)
from .pending_rows import PendingRows
from .run_provenance import run_provenance
from .trim import apply_plan, trim_plan, trim_safely
from .whole_writes import WholeWrites, all_or_nothing
from .writer_binding import bind, check_simulation


def _later_rows_message(f, path, step) -> str:
    """Why a run file that holds rows after ``step`` is not reopened there without ``drop_later``."""
    frames = f[layout.TIP_POSITION_STEP][:]
    later = frames[frames > step]
    if len(later) > 1:
        what = f"{len(later)} frames (steps {int(later[0])} to {int(later[-1])})"
    else:
        what = f"a frame (step {int(later[0])})" if len(later) else "rows of later steps"
    return (
        f"{path} holds {what} after step {step}, which reopening there would remove: give the step the "
        f"simulation is at, RunWriter.reopen(path, sim.state.step), or drop_later=True to remove them"
    )


def _drop_replaced_checkpoint(path):
    """Remove the checkpoint beside a run file just replaced, where it continues that file's replaced run:
    it could never continue the new one (a resume refuses another run's checkpoint), and beside a file
    written from Python, which writes none, it would be taken for the file's own."""
    ckpt = checkpoint_path(path)
    try:
        name = read_checkpoint(ckpt)[1].get("run_name")
    except (CheckpointError, OSError):
        return
    if name == path.name:
        ckpt.unlink(missing_ok=True)


class RunWriter(WholeWrites, PendingRows):
    """Writes frames and observables of one run, of one simulation (:meth:`check_continues`).

    Parameters
    ----------
    path : path-like
    n_tips : int
    tip_charge : (n_tips,) float64
    rod_charge : (n_rods,) float64
    provenance : dict
        Strings and numbers stored as attributes of ``/parameters/selfas_graph``.
    overwrite : bool
        Replace an existing file; otherwise :class:`OutputExistsError`.
    velocities : bool
        Save velocities with each frame.
    rod_length, rod_resistance : (n_rods,) float64, optional
        Per-rod lengths and resistances (``particles/rods/length``, ``particles/rods/resistance``),
        written only when the scene sets them (absent: every rod has length 1 and resistance R0).
    frame_interval : float, optional
        Simulated time between saved frames. Each frame states in ``observables/dt`` its time since
        the frame before (MDAnalysis' ``Timestep.dt``): this interval, the first frame's too, but
        for a frame at a run's end time off the interval's grid (or a chunk's end in ``sim.run``).
    """

    #: a weak reference to the simulation it takes frames from (:mod:`.writer_binding`), None before the first
    _simulation = None
    #: whether the end time the file stated when opened needs no keeping (a new file's) or is kept already
    _end_kept = True

    def __init__(
        self,
        path,
        n_tips,
        tip_charge,
        rod_charge,
        provenance,
        overwrite=False,
        velocities=True,
        frame_interval=None,
        rod_length=None,
        rod_resistance=None,
    ):
        self.path = Path(path)
        refused = not_replaced(self.path)
        if refused:
            raise (IsADirectoryError if self.path.is_dir() else OutputExistsError)(refused)
        if dangling_link(self.path):
            raise FileNotFoundError(dangling_link(self.path))
        if self.path.exists() and not overwrite:
            raise OutputExistsError(
                f"output file {self.path} exists; pass overwrite=True to overwrite it, or another path"
            )
        if self.path.exists() and in_use(self.path):
            raise OutputExistsError(in_use_message(self.path, "output file", "overwrite=True"))
        if not self.path.parent.exists():
            raise FileNotFoundError(f"the folder of the output file {self.path} does not exist")
        replaced = self.path.exists()
        # default (earliest) format on purpose: the "latest" superblock carries a writer flag that a
        # killed run leaves set, after which HDF5 refuses to open the file without h5clear
        self.f = h5py.File(self.path, "w")
        if replaced:
            _drop_replaced_checkpoint(self.path)
        f = self.f
        h = f.create_group(layout.H5MD)
        h.attrs["version"] = np.array(H5MD_VERSION, dtype=np.int32)
        h.create_group(layout.H5MD_AUTHOR).attrs["name"] = _fixed(
            provenance.get("author", os.environ.get("USER", "unknown"))
        )
        c = h.create_group(layout.H5MD_CREATOR)
        c.attrs["name"] = _fixed("selfas-graph")
        c.attrs["version"] = _fixed(provenance.get("version", "unknown"))
        units = h.create_group(layout.H5MD_UNITS)
        units.attrs["version"] = np.array((1, 0), dtype=np.int32)
        _unit_string(units, "system", UNIT_SYSTEM)
        # creation order tracked: readers that take the first particles group take the tips
        particles = f.create_group(layout.PARTICLES, track_order=True)
        tips = particles.create_group(layout.TIPS)
        _box(tips)
        _charges(tips, tip_charge, "the magnetic charge of each tip, +q_i at tip a and -q_i at tip b of rod i")
        tips.create_dataset(layout.TIP_ROD, data=np.arange(n_tips, dtype=np.int64) // 2)
        rods = particles.create_group(layout.RODS)
        _box(rods)
        _charges(rods, rod_charge, "the screened electric charge Z_i of each rod")
        # H5MD ignores a tuple holding the fill value: HDF5's default, 0, would drop rod 0's bond
        bonds = f.create_group(layout.CONNECTIVITY).create_dataset(
            layout.RODS, data=np.arange(n_tips, dtype=np.int64).reshape(-1, 2), fillvalue=-1
        )
        bonds.attrs["particles_group"] = tips.ref
        for name, values, unit in (("length", rod_length, LENGTH), ("resistance", rod_resistance, "R_0")):
            if values is not None:
                _set_unit(rods.create_dataset(name, data=np.asarray(values, dtype=np.float64)), unit)
        self._elements = {}
        for name in ("position",) + (("velocity",) if velocities else ()):
            g = tips.create_group(name)
            # no unit attribute here: MDAnalysis refuses every unit outside its SI table
            self._elements[name] = (
                _growable(g, "step", (), "<i8"),
                _growable(g, "time", (), "<f8"),
                _growable(g, "value", (n_tips, 3), "<f8"),
            )
        self._obs = {}
        self.frame_interval = frame_interval
        self._last_time = None
        self._continues_from = None
        self.observables = f.create_group(layout.OBSERVABLES)
        g = self.observables.create_group(layout.BOND_ERROR_PER_STEP)
        self._per_step = (_growable(g, "step", (), "<i8"), _growable(g, "value", (), "<f8"))
        _set_unit(self._per_step[1], LENGTH)
        p = f.create_group(layout.PROVENANCE)
        for key, value in provenance.items():
            p.attrs[key] = value
        p.attrs["status"] = "running"
        #: what close() records if no run is written to this writer (a run that starts clears it)
        self.stopped_by = "no run written"
        p.attrs["created"] = time.strftime("%Y-%m-%dT%H:%M:%S%z")
        p.attrs["wall_seconds_total"] = 0.0
        self._start_clock(0.0)
        self.n_frames = 0
        f.flush()

    @classmethod
    def reopen(cls, path, step, t_end=None, frame_interval=None, mpi_ranks=1, drop_later=False):
        """Open an existing run file to continue it after ``step`` (from Python: ``sim.state.step``).

        ``drop_later``: remove first every row written for a later step (frames, observables, events,
        circuit log, graph, per-step series), as a resume from a checkpoint does (a resume from step 0
        drops frame 0 too and writes it again: a kill while it was written could have torn it unseen).
        Without it a file that holds rows after ``step`` is refused (RunFileError), as a file open in
        another writer is always: a step given by mistake would have removed them.
        ``t_end``: the continuation's end time, where it differs from the one the file states (a resume
        with another ``--t-end``, later or earlier): stored in ``parameters_json``, the earlier ones in
        ``t_end_before``.
        ``frame_interval``: the one a new file would state, for a file that has no frame yet (a run
        stopped before its first step). ``mpi_ranks``: the continuation's, recorded in ``resumed_with``
        with its version, commit, CPU and threads where any of them differs from the file's.

        The rows are removed in a copy of the file that then replaces it (``os.replace``): HDF5 shrinks
        a file in place before it rewrites the superblock that states its new end, and a kill between
        the two leaves a file it no longer opens. The copy replaces the file a symbolic link points to;
        the rows are removed in place where the file has other names (hard links) or the copy cannot be
        made (no room, a quota, a folder that is not writable).
        """
        path = Path(path)
        if not is_whole_number(step) or step < 0:
            raise TypeError(f"RunWriter.reopen(step=...): the step to continue after, an integer >= 0, got {step!r}")
        step = int(step)
        if path.exists() and in_use(path):
            raise RunFileError(
                f"{path} is open in another writer or process (a RunWriter not yet closed, a simulation still "
                f"writing it): close it before reopening the file"
            )
        try:
            with h5py.File(path, "r") as f:
                plan = trim_plan(f, step if step > 0 or not drop_later else -1, path)
                if plan and not drop_later:
                    raise RunFileError(_later_rows_message(f, path, step))
        except OSError as exc:
            raise RunFileError(f"{path}: cannot reopen the run file to continue it ({exc})") from None
        if plan:
            plan = trim_safely(path, plan)
        self = cls.__new__(cls)
        self.path = path
        try:
            self.f = h5py.File(self.path, "r+")
        except OSError as exc:
            raise RunFileError(f"{self.path}: cannot reopen the run file to continue it ({exc})") from None
        f = self.f
        apply_plan(f, plan)
        self._elements = {
            name: (f[p]["step"], f[p]["time"], f[p]["value"]) for name, p in layout.TIP_ELEMENTS.items() if p in f
        }
        self.n_frames = f[layout.TIP_POSITION_STEP].shape[0]
        self._last_time = float(f[layout.TIP_POSITION_TIME][-1]) if self.n_frames else None
        self.observables = f[layout.OBSERVABLES]
        self._obs = {}

        def visit(name, obj):
            if isinstance(obj, h5py.Group) and "value" in obj and name != layout.BOND_ERROR_PER_STEP:
                self._obs[name] = (obj["step"], obj["time"], obj["value"])

        self.observables.visititems(visit)
        self.frame_interval = (
            float(self._obs[layout.FRAME_INTERVAL][2][-1])
            if layout.FRAME_INTERVAL in self._obs and self._obs[layout.FRAME_INTERVAL][2].shape[0]
            else frame_interval
        )
        g = self.observables[layout.BOND_ERROR_PER_STEP]
        self._per_step = (g["step"], g["value"])
        self.events_written = f[layout.EVENTS].shape[0] if layout.EVENTS in f else 0
        self.circuit_rows_written = (
            f[layout.CIRCUIT_LOG][layout.CIRCUIT_LOG_COLUMNS[0]].shape[0] if layout.CIRCUIT_LOG in f else 0
        )
        # closed before a run continues it (or after a refused one), the file says what it said
        self.stopped_by = str(f[layout.PROVENANCE].attrs.get("status", "interrupted"))
        f[layout.PROVENANCE].attrs["status"] = "running"
        self._continues_from = step
        self._end_kept = False  # the end time the file states, kept in t_end_before when a run changes it
        self._resumed_with(mpi_ranks)
        if t_end is not None:
            self._new_end_time(float(t_end))
        self._start_clock(float(f[layout.PROVENANCE].attrs.get("wall_seconds_total", 0.0)))
        f.flush()
        return self

    def _resumed_with(self, mpi_ranks=1):
        """Record the version, commit, CPU, thread and MPI rank counts of a continuation when they differ
        from the ones the file holds (``resumed_with``: a JSON list of them, oldest first)."""
        import numba

        from .._version import __version__
        from ..provenance import cpu_model, source_commit

        attrs = self.f[layout.PROVENANCE].attrs
        now = {
            "version": __version__,
            "commit": source_commit(),
            "cpu_model": cpu_model(),
            "numba_threads": numba.get_num_threads(),
            "mpi_ranks": int(mpi_ranks),
        }
        if all(str(attrs.get(k, "")) == str(v) for k, v in now.items()):
            return
        seen = json.loads(attrs.get("resumed_with", "[]"))
        if now not in seen:
            attrs["resumed_with"] = json.dumps(seen + [now])

    def _new_end_time(self, t_end):
        """State the continuation's end time in ``parameters_json`` (the only parameter a resume may
        change) and keep each earlier one, oldest first, in ``t_end_before`` (JSON): the one the file stated
        when it was reopened, once (a run from Python in chunks replaces its own chunks' end times)."""
        attrs = self.f[layout.PROVENANCE].attrs
        params = json.loads(attrs["parameters_json"])
        before = float(params["run"]["t_end"])
        if before == t_end:
            return
        params["run"]["t_end"] = t_end
        attrs["parameters_json"] = json.dumps(params)
        if not self._end_kept:
            attrs["t_end_before"] = json.dumps(json.loads(attrs.get("t_end_before", "[]")) + [before])
            self._end_kept = True

    def run_to(self, t_end) -> None:
        """State ``t_end``, the end time of the run that writes to the file from now on, in ``parameters_json``,
        as ``simulate`` states the one it runs to (docs/output.md): a file written by ``sim.run(2.5, writer=w)``
        states 2.5, not the scenario's ``run.t_end``. Called by the run (``FrameWriter.start``)."""
        self._check_open()
        self._new_end_time(float(t_end))

    def reserve(self) -> int:
        """Bytes the next frame may need at most: one new chunk of every growable dataset, and a margin
        (computed again only when datasets were added)."""
        key = (len(self._obs), layout.GRAPH in self.f, layout.EVENTS in self.f, layout.CIRCUIT_LOG in self.f)
        if getattr(self, "_reserve", (None, 0))[0] != key:
            # before the observables and the graph exist (frame 0), room for their first chunks too
            first = 0 if key[0] and key[1] else 4 << 20
            self._reserve = (key, self._chunk_bytes() + first)
        return self._reserve[1]

    def _chunk_bytes(self) -> int:
        total = SPACE_MARGIN

        def add(name, obj):
            nonlocal total
            if isinstance(obj, h5py.Dataset) and obj.chunks is not None:
                total += int(np.prod(obj.chunks)) * obj.dtype.itemsize

        self.f.visititems(add)
        return total

    def _check_open(self):
        """RunFileError when the writer was closed (after a ``with`` block, or ``close``)."""
        if self.f is None:
            raise RunFileError(
                f"{self.path}: this writer is closed; to write more frames keep it open (one with block "
                f"around every sim.run), or continue the file with RunWriter.reopen"
            )

    def check_continues(self, sim) -> None:
        """Refuse, before a run takes its first step, a simulation ``sim`` whose frames this file cannot take:
        the writer closed, the file's tips of another count, its last frame after the simulation's step (one
        started again), a file reopened (:meth:`reopen`) to continue after another step, or a simulation that
        does not continue what the file holds (:mod:`.writer_binding`: other parameters than the file's apart
        from the end time, a step before the last one written, fewer events, other positions)."""
        self._check_open()
        step, position_shape = sim.state.step, sim.state.position.shape
        shape = self._elements["position"][2].shape[1:]
        if tuple(position_shape) != shape:
            raise ValueError(
                f"{self.path}: the simulation has {position_shape[0]} tips, the file's frames {shape[0]}: this "
                f"writer was made for another simulation"
            )
        if self._continues_from is not None and step != self._continues_from:
            raise ValueError(
                f"{self.path}: reopened to continue after step {self._continues_from}, but the simulation is at "
                f"step {step}: reopen it at the simulation's step, RunWriter.reopen(path, sim.state.step)"
            )
        check_simulation(self, sim)
        self._continues_from = None

    def check_space(self):
        """Raise :class:`DiskFullError` (nothing written) when the next frame may not fit
        (:func:`~.h5md_format.check_room`)."""
        self._check_open()
        check_room(self.path, self.reserve())

    @all_or_nothing
    def write_frame(self, step, t, position, velocity, observables: dict):
        """Append one frame (positions, velocities, observables) and flush to disk."""
        self.check_space()
        for name, arr in (("position", position), ("velocity", velocity)):
            if name in self._elements and np.shape(arr) != self._elements[name][2].shape[1:]:
                # before anything of the frame is written: a frame of another system would leave the
                # file's columns of unequal length
                raise ValueError(
                    f"{self.path}: the {name}s have shape {np.shape(arr)}, the file's frames "
                    f"{self._elements[name][2].shape[1:]}: this writer was made for another simulation"
                )
        if self.frame_interval is not None:
            # the time since the frame before (MDAnalysis' Timestep.dt): the interval but at a run's end
            # time off the frame grid, or a chunk's end in sim.run; the first frame states the interval
            spacing = self.frame_interval if self._last_time is None else t - self._last_time
            observables = {**observables, layout.FRAME_INTERVAL: spacing}
        for name, arr in (("position", position), ("velocity", velocity)):
            if name in self._elements:
                s, tt, v = self._elements[name]
                self._add(s, step)
                self._add(tt, t)
                self._add(v, arr)
        for name, value in observables.items():
            value = np.asarray(value, dtype=np.float64)
            if name not in self._obs:
                g = self._created(self.observables.create_group(name))
                self._obs[name] = (
                    _growable(g, "step", (), "<i8"),
                    _growable(g, "time", (), "<f8"),
                    _growable(g, "value", value.shape, "<f8"),
                )
                _set_unit(self._obs[name][1], TIME)
                _set_unit(self._obs[name][2], observable_unit(name))
            s, tt, v = self._obs[name]
            self._add(s, step)
            self._add(tt, t)
            self._add(v, value)
        self.n_frames += 1
        self._last_time = float(t)

    @all_or_nothing
    def write_per_step(self, steps, values):
        """Append a per-step series (the bond error of every step since the last call)."""
        self.check_space()
        if len(steps):
            self._add(self._per_step[0], np.asarray(steps, dtype=np.int64))
            self._add(self._per_step[1], np.asarray(values, dtype=np.float64))

    @all_or_nothing
    def write_events(self, rows):
        """Append event rows ``(step, time, kind, a, b)``."""
        self._check_open()
        if layout.EVENTS not in self.f:
            ds = self._created(
                self.f.create_dataset(
                    layout.EVENTS, shape=(0,), maxshape=(None,), dtype=EVENT_FILE_DTYPE, chunks=(4096,)
                )
            )
            ds.attrs["kind_names"] = json.dumps({int(k): v for k, v in KIND_NAMES.items()})
            ds.attrs["conductor_names"] = json.dumps({int(k): v for k, v in CONDUCTOR_NAMES.items()})
        if len(rows):
            self._add(self.f[layout.EVENTS], event_array(rows))

    @all_or_nothing
    def write_circuit_log(self, rows):
        """Append circuit-log rows ``(step, time, kind, total_current, rods_in_series, filament_rods)``
        (:mod:`selfas_graph.model.circuitlog`), one column dataset per field."""
        self._check_open()
        if layout.CIRCUIT_LOG not in self.f:
            g = self._created(self.f.create_group(layout.CIRCUIT_LOG))
            for name in layout.CIRCUIT_LOG_COLUMNS:
                _growable(g, name, (), CIRCUIT_LOG_DTYPE[name])
            _set_unit(g["time"], TIME)
            _set_unit(g["total_current"], CURRENT)
            names = {k: KIND_NAMES[k] for k in (SHORT_CIRCUIT, OPEN_CIRCUIT)}
            g["kind"].attrs["kind_names"] = json.dumps(names)
        if len(rows):
            table = circuit_log_array(rows)
            g = self.f[layout.CIRCUIT_LOG]
            for name in layout.CIRCUIT_LOG_COLUMNS:
                self._add(g[name], table[name])

    @all_or_nothing
    def write_graph(self, step, t, arrays, role, current, potential, conductor_potential):
        """Append the graph state of one frame.

        Parameters
        ----------
        arrays : dict from ``ConnectivityGraph.arrays()``
        role : (n_rods,) int8
        current : (n_rods,) float64
        potential : (n_tips,) float64
        conductor_potential : dict conductor id -> fixed potential (None if per contact)
        """
        self._check_open()
        if layout.GRAPH not in self.f:
            g = self._created(self.f.create_group(layout.GRAPH))
            g.attrs["conductor_ids"] = np.array(sorted(conductor_potential), dtype=np.int64)
            # no NaN in the file: a conductor whose potential is set per contact (the case (ii)
            # filament, -delta_J0 z) is flagged in conductor_per_contact, its entry here 0
            ids = sorted(conductor_potential)
            g.attrs["conductor_potentials"] = np.array(
                [0.0 if conductor_potential[c] is None else conductor_potential[c] for c in ids], dtype=np.float64
            )
            g.attrs["conductor_per_contact"] = np.array([conductor_potential[c] is None for c in ids], dtype=np.int8)
            g.attrs["role_names"] = json.dumps(ROLE_NAMES)
            _growable(g, "step", (), "<i8")
            _set_unit(_growable(g, "time", (), "<f8"), TIME)
            _growable(g, "tip_contacts", (2,), "<i8")
            _growable(g, "tip_contacts_count", (), "<i8")
            for name, dt in zip(layout.GRAPH_CONDUCTOR_CONTACTS, ("<i8", "<i8", "<f8")):
                _growable(g, name, (), dt)
            _growable(g, "conductor_contacts_count", (), "<i8")
            _growable(g, "role", role.shape, "i1")
            _set_unit(_growable(g, "current", current.shape, "<f8"), CURRENT)
            _set_unit(_growable(g, "potential", potential.shape, "<f8"), POTENTIAL)
            _growable(g, "floating", potential.shape, "i1")
            _set_unit(g["conductor_potential"], POTENTIAL)
        g = self.f[layout.GRAPH]
        self._add(g["step"], step)
        self._add(g["time"], t)
        tc = arrays["tip_contacts"]
        if len(tc):
            self._add(g["tip_contacts"], tc)
        self._add(g["tip_contacts_count"], len(tc))
        if len(arrays["conductor_tip"]):
            for name in layout.GRAPH_CONDUCTOR_CONTACTS:
                self._add(g[name], arrays[name])
        self._add(g["conductor_contacts_count"], len(arrays["conductor_tip"]))
        self._add(g["role"], role)
        self._add(g["current"], current)
        # a floating tip (on no path between conductors) has no potential: 1 in ``floating`` and 0
        # in ``potential``, so that the file holds no NaN; RunFile.graph gives NaN there again
        floating = ~np.isfinite(potential)
        self._add(g["potential"], np.where(floating, 0.0, potential))
        if "floating" in g:
            self._add(g["floating"], floating.astype(np.int8))

    @classmethod
    def for_simulation(cls, sim, path, overwrite=False, velocities=None, author=None, provenance=None):
        """A writer for a run driven from Python: ``sim.run(t_end, writer=w)`` (in as many
        chunks as wanted), then ``w.close()``; or ``with RunWriter.for_simulation(sim, path) as w``.

        The file is the one ``selfas-graph simulate`` writes (the provenance holds the resolved
        parameters, and the scenario text when the simulation came from a scenario), and
        :class:`RunFile`, ``topology``, ``plot`` and ``export`` read it. ``provenance``: the
        provenance record to store (:func:`run_provenance`; the command line's and ensemble's own),
        else one made here with a new run identity. The one place a writer is made from a
        simulation: a per-rod constant added to the file is added here.
        """
        p = sim.params
        if provenance is None:
            import shlex
            import sys
            import uuid

            provenance = run_provenance(sim, getattr(sim, "scenario", None), shlex.join(sys.argv), uuid.uuid4().hex)
        if author is not None:
            provenance["author"] = author
        writer = cls(
            path,
            sim.state.n_tips,
            sim.state.tip_charge,
            sim.state.rod_charge,
            provenance,
            overwrite=overwrite,
            velocities=p.output.velocities if velocities is None else velocities,
            frame_interval=sim.frame_interval,
            rod_length=sim.state.rod_length,
            rod_resistance=sim.state.rod_resistance,
        )
        bind(writer, sim)  # the simulation whose frames it takes (.writer_binding)
        return writer

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        # None: "finished", unless a run written stopped early (its exception caught inside)
        self.close(status=None if exc_type is None else stop_status(exc))

    def set_attrs(self, **attrs):
        for k, v in attrs.items():
            self.f[layout.PROVENANCE].attrs[k] = v

    def _start_clock(self, before):
        """Count this segment's wall time on top of ``before``, the earlier segments' total."""
        self._wall_before = before
        self._opened = time.monotonic()

    def _wall_total(self):
        return self._wall_before + (time.monotonic() - self._opened)

    def flush(self):
        # wall time of every segment of the run, a killed one up to its last flush (a frame or a
        # checkpoint); ``wall_seconds`` is the run loop's time in the last segment (the lifecycle sets it)
        self.set_attrs(wall_seconds_total=self._wall_total())
        self.f.flush()

    def close(self, status=None):
        """Record ``status`` and close the file. Without one: "finished", or why the last run written
        stopped early (:attr:`stopped_by`, e.g. "failed: ..." after a numerical failure caught in a notebook);
        "no run written" for a new file no run wrote to, a reopened file's status before for one no run continued."""
        if status is None:
            status = self.stopped_by or "finished"
        if self.f:
            self.set_attrs(status=status, wall_seconds_total=self._wall_total())
            self.f.close()
            self.f = None
