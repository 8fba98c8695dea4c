"""Export a run file to the formats viewers and analysis packages open: GSD and extended XYZ.

Both hold the tips as particles (tip k belongs to rod k // 2) and, per frame, each tip's
rod role (free, cluster, dead_end, filament: docs/model.md 'Connectivity graph and topology') as its type, the
rod's current and the rod index; the GSD file also has one bond per rod, typed by the
rod's role. Positions are in rod lengths, times in t0 (docs/output.md).

- GSD (HOOMD-blue's format, written with the ``gsd`` package; OVITO, MDAnalysis, freud and
  HOOMD-blue read it): particle types = roles, ``typeid`` per frame; bonds = rods;
  ``particles/charge`` = the tips' magnetic charges; ``log/particles/current``,
  ``log/particles/rod``, ``log/bonds/current`` per frame; ``log/time`` (simulated time) and
  ``log/total_current``. HOOMD boxes are periodic: the box is a cube centred at the origin
  that holds every exported position, so no particle is wrapped.
- Extended XYZ (ASE, OVITO): per atom ``species`` (the role name, OVITO's particle type),
  ``pos``, ``Z`` (0 for every tip, which makes ASE keep them as dummy atoms instead of
  reading the role names as elements), ``role`` (0..3), ``rod``, ``current``, ``magnetic_charge``
  and ``velo`` if saved; per frame ``Time``, ``Step``, ``total_current``, ``pbc="F F F"``.
"""

from __future__ import annotations

import operator
import os
import warnings
from pathlib import Path

import numpy as np

from ..model.graph import ROLE_NAMES
from . import layout
from .atomic import atomic_write
from .h5md import RunFile, RunFileError
from .h5md_format import dangling_link, is_hdf5

FORMATS = ("gsd", "xyz")
#: the suffixes an export's name may end in, by format (what the readers take the format from)
SUFFIXES = {"gsd": (".gsd",), "xyz": (".xyz", ".extxyz")}
#: particle and bond type names, indexed by role code
ROLE_TYPES = [ROLE_NAMES[k] for k in sorted(ROLE_NAMES)]


class ExportError(ValueError):
    """A bad frame selection or output path (the run file is not touched)."""


class ExportExistsError(ExportError):
    """The export's output file exists and ``force`` was not given; ``path`` is the file."""

    def __init__(self, path):
        self.path = Path(path)
        super().__init__(f"{path} exists; pass force=True to overwrite it, or another out= path")


def parse_frames(spec, n_frames) -> np.ndarray:
    """Frame indices from ``all``, ``K``, ``A:B`` or ``A:B:S`` (Python slices) or ``K1,K2,...``
    (also, from Python, an integer, a sequence of integers or a ``slice``); negative numbers count from
    the end."""
    if n_frames == 0:
        raise ExportError("the run has no saved frames")
    if isinstance(spec, slice):  # from Python, as the command line's A:B:S
        if spec.step == 0 or not all(x is None or isinstance(x, int) for x in (spec.start, spec.stop, spec.step)):
            raise ExportError(f"frames={spec!r}: a slice of integers with a step other than 0")
        spec = ":".join("" if x is None else str(x) for x in (spec.start, spec.stop, spec.step))
    if not isinstance(spec, (str, type(None))) and np.ndim(spec) in (0, 1):
        if any(isinstance(k, (bool, np.bool_)) for k in np.atleast_1d(spec).tolist()):
            raise ExportError(f"frames={spec!r}: True or False is not a frame number (True was frame 1)")
        try:  # from Python: a frame number or a sequence of them, written as the command line's list
            spec = ",".join(str(operator.index(k)) for k in np.atleast_1d(spec).tolist())
        except TypeError:
            pass  # refused below with the forms that are valid
    text = "all" if spec is None else str(spec).strip()
    every = np.arange(n_frames)
    if text == "all":
        return every
    try:
        if ":" in text:
            parts = [int(p) if p.strip() else None for p in text.split(":")]
            if len(parts) > 3 or (len(parts) == 3 and parts[2] == 0):
                raise ValueError
            picked = every[slice(*parts)]
        else:
            picked = np.array([int(p) for p in text.split(",")], dtype=np.int64)
    except (ValueError, OverflowError):
        raise ExportError(
            f"frames (--frames) {text!r}: write all, a frame number, a slice A:B or A:B:S, or a list "
            f"K1,K2 (negative numbers count from the end; from Python also a list of integers)"
        ) from None
    if ":" not in text:
        bad = picked[(picked < -n_frames) | (picked >= n_frames)]
        if len(bad):
            raise ExportError(
                f"frames (--frames) {text}: frame {int(bad[0])} out of range; the file has frames 0..{n_frames - 1}"
            )
        picked = picked % n_frames
        twice = [int(k) for i, k in enumerate(picked) if k in picked[:i]]
        if twice:  # a frame twice would be a trajectory that steps back in time
            raise ExportError(f"frames (--frames) {text}: frame {twice[0]} is named twice; give each frame once")
    if not len(picked):
        raise ExportError(f"frames (--frames) {text}: selects no frame of the {n_frames} in the file")
    return np.asarray(picked, dtype=np.int64)


def output_path(run_path, out, fmt, force=False) -> Path:
    """The export's path (default: the run's name with the format's suffix), checked: never the
    input file or any other HDF5 file (its checkpoint), never a name without the format's suffix
    (:data:`SUFFIXES`), never an existing file without ``force`` (:class:`ExportExistsError`), never a
    symbolic link to nothing (:func:`~.h5md_format.dangling_link`), in an existing folder."""
    run_path = Path(run_path)
    path = Path(out) if out is not None else run_path.with_suffix("." + fmt)
    if dangling_link(path):
        raise ExportError(dangling_link(path))
    if path.exists() and (path.resolve() == run_path.resolve() or os.path.samefile(path, run_path)):
        raise ExportError(f"{path} is the run file itself; choose another output with -o")
    if path.is_dir():
        raise ExportError(f"{path} is a directory; give a file name with -o")
    if path.is_file() and is_hdf5(path):
        # never replaced, force or not: a run file or its checkpoint (an export is GSD or XYZ)
        raise ExportError(f"{path} is an HDF5 file (a run file or checkpoint?); an export never replaces one")
    suffix = path.suffix.lower()
    if suffix not in SUFFIXES[fmt]:
        other = next((f for f, ends in SUFFIXES.items() if suffix in ends), None)
        said = f"names a {suffix} file, but the format is {fmt}" if other else f"does not end in {_or(SUFFIXES[fmt])}"
        raise ExportError(f"{path} {said}; give a name ending in {_or(SUFFIXES[fmt])}")
    if path.exists() and not force:
        raise ExportExistsError(path)
    if not path.parent.exists():
        raise ExportError(f"the folder of the output file {path} does not exist")
    return path


def _or(words) -> str:
    return " or ".join(words)


class _Frames:
    """Per-frame data of a run: positions, roles and currents of the rods, matched by step."""

    def __init__(self, run: RunFile):
        self.run = run
        self.n_tips = run.n_tips
        self.n_rods = self.n_tips // 2
        self.bonds = run.bonds
        self.charge = run.tip_charge
        self.steps = run.step
        self.times = run.time
        self.has_velocity = layout.TIP_VELOCITY_VALUE in run.f
        self.graph_steps = run.graph_steps
        self.total_current = None
        if layout.TOTAL_CURRENT in run.observable_names():
            g = run.f[layout.observable(layout.TOTAL_CURRENT)]
            self.total_current = dict(zip(g["step"][:].tolist(), g["value"][:].tolist()))

    def __call__(self, k):
        run = self.run
        step = int(self.steps[k])
        role = np.zeros(self.n_rods, dtype=np.int64)
        current = np.zeros(self.n_rods)
        j = int(np.searchsorted(self.graph_steps, step))
        if j < len(self.graph_steps) and self.graph_steps[j] == step:
            role = run.f[layout.graph("role")][j].astype(np.int64)
            current = run.f[layout.graph("current")][j].astype(np.float64)
        total = self.total_current.get(step, 0.0) if self.total_current is not None else 0.0
        return {
            "step": step,
            "time": float(self.times[k]),
            "position": run.f[layout.TIP_POSITION_VALUE][k],
            "velocity": run.f[layout.TIP_VELOCITY_VALUE][k] if self.has_velocity else None,
            "role": role,
            "current": current,
            "total_current": float(total),
        }

    def box_edge(self, frames) -> float:
        """Edge of a cube centred at the origin holding every position of the frames (1 L margin)."""
        ds = self.run.f[layout.TIP_POSITION_VALUE]
        reach = max(float(np.abs(ds[int(k)]).max(initial=0.0)) for k in frames)
        return 2.0 * reach + 2.0


def write_gsd(run: RunFile, path, frames):
    import gsd.hoomd

    data = _Frames(run)
    edge = data.box_edge(frames)
    rod_of_tip = np.arange(data.n_tips) // 2

    def write(tmp):
        with gsd.hoomd.open(str(tmp), mode="w") as out:
            for k in frames:
                d = data(int(k))
                f = gsd.hoomd.Frame()
                f.configuration.step = d["step"]
                f.configuration.dimensions = 3
                f.configuration.box = [edge, edge, edge, 0.0, 0.0, 0.0]
                f.particles.N = data.n_tips
                f.particles.types = ROLE_TYPES
                f.particles.typeid = d["role"][rod_of_tip].astype(np.uint32)
                f.particles.position = np.asarray(d["position"], dtype=np.float32)
                if d["velocity"] is not None:
                    f.particles.velocity = np.asarray(d["velocity"], dtype=np.float32)
                f.particles.charge = data.charge.astype(np.float32)
                f.bonds.N = data.n_rods
                f.bonds.types = ROLE_TYPES
                f.bonds.typeid = d["role"].astype(np.uint32)
                f.bonds.group = data.bonds.astype(np.int32)
                f.log = {
                    "particles/current": d["current"][rod_of_tip],
                    "particles/rod": rod_of_tip.astype(np.int64),
                    "bonds/current": d["current"],
                    "time": np.array([d["time"]]),
                    "total_current": np.array([d["total_current"]]),
                }
                out.append(f)

    atomic_write(path, write)


def write_xyz(run: RunFile, path, frames):
    data = _Frames(run)
    edge = data.box_edge(frames)
    rod_of_tip = np.arange(data.n_tips) // 2
    names = np.array(ROLE_TYPES)

    def write(tmp):
        with open(tmp, "w", encoding="ascii") as out:
            for k in frames:
                d = data(int(k))
                role = d["role"][rod_of_tip]
                props = "species:S:1:pos:R:3:Z:I:1:role:I:1:rod:I:1:current:R:1:magnetic_charge:R:1"
                if d["velocity"] is not None:
                    props += ":velo:R:3"
                out.write(f"{data.n_tips}\n")
                out.write(
                    f'Lattice="{edge:.17g} 0 0 0 {edge:.17g} 0 0 0 {edge:.17g}" Origin="{-edge / 2:.17g} '
                    f'{-edge / 2:.17g} {-edge / 2:.17g}" Properties={props} Time={float(d["time"])!r} '
                    f'Step={d["step"]} total_current={float(d["total_current"])!r} pbc="F F F"\n'
                )
                x, v = d["position"], d["velocity"]
                columns = [
                    names[role],
                    x[:, 0],
                    x[:, 1],
                    x[:, 2],
                    np.zeros(data.n_tips, dtype=np.int64),
                    role,
                    rod_of_tip,
                    d["current"][rod_of_tip],
                    data.charge,
                ]
                fmt = "%s %.17g %.17g %.17g %d %d %d %.17g %.17g"
                if v is not None:
                    columns += [v[:, 0], v[:, 1], v[:, 2]]
                    fmt += " %.17g %.17g %.17g"
                table = np.rec.fromarrays(columns)
                np.savetxt(out, table, fmt=fmt)

    atomic_write(path, write)


def export_run(run_path, format=None, out=None, frames=None, force=False, *, fmt=None) -> tuple[Path, int]:
    """Export a run file (its path, or an open :class:`~.run_reader.RunFile`); returns the output
    path and the number of frames written.

    ``format`` is "gsd" or "xyz" (the command's ``--format``; ``fmt=``, its name before 0.4.3, is
    still taken, with a DeprecationWarning); ``frames`` "all" (default), a frame number, "A:B[:S]",
    "K1,K2", or a list of frame numbers; ``out`` the output path (default: the run's name with the
    format's suffix), which must not exist unless ``force``.

    Raises
    ------
    RunFileError
        The input is not a readable run file.
    ExportError
        Bad ``format``, ``frames`` or output path; nothing is written then.
    """
    if fmt is not None:
        if format is not None:
            raise TypeError("export_run: give format= alone (fmt= is its old name)")
        warnings.warn("export_run(fmt=...) is now export_run(format=...)", DeprecationWarning, stacklevel=2)
        format = fmt
    if format is None:
        raise TypeError(f"export_run(run_path, format): the format is missing; valid: {', '.join(FORMATS)}")
    if format not in FORMATS:
        raise ExportError(f"format {format!r} is not known; valid: {', '.join(FORMATS)}")
    if isinstance(run_path, RunFile):
        run_path = run_path.path
    with RunFile(run_path) as run:
        picked = parse_frames(frames, run.n_frames)
        path = output_path(run_path, out, format, force=force)
        (write_gsd if format == "gsd" else write_xyz)(run, path, picked)
        bare = picked[~np.isin(run.step[picked], run.graph_steps)]
    if bare.size:
        warnings.warn(MissingGraphWarning(path, bare), stacklevel=2)
    return path, len(picked)


class MissingGraphWarning(UserWarning):
    """Exported frames had no graph record (a run written without graph data, or a frame whose record
    a kill tore off): their rods are typed ``free`` with no current, which is not what they were.
    ``frames`` holds their numbers."""

    def __init__(self, path, frames):
        self.path, self.frames = Path(path), np.asarray(frames, dtype=np.int64)
        shown = ", ".join(str(int(k)) for k in self.frames[:5]) + (", ..." if self.frames.size > 5 else "")
        n = self.frames.size
        super().__init__(
            f"{self.path}: {n} frame{'s' if n > 1 else ''} ({shown}) had no graph record in the run file; "
            "their rods are written as free, with no current"
        )


__all__ = [
    "export_run",
    "parse_frames",
    "output_path",
    "write_gsd",
    "write_xyz",
    "ExportError",
    "ExportExistsError",
    "MissingGraphWarning",
    "SUFFIXES",
    "FORMATS",
    "ROLE_TYPES",
    "RunFileError",
]
