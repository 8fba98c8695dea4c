"""HDF5 output after H5MD 1.1 (https://www.nongnu.org/h5md/h5md.html), and its reader.

The layout of a run file (every dataset path and group name) is listed and named in
:mod:`selfas_graph.io.layout`. ``/parameters/selfas_graph`` holds as attributes: scenario_text,
parameters_json, version, command_line, seed, mpi_ranks, numba_threads, created, status, commit
(git commit of the source, "+dirty" if changed), cpu_model, numba_cpu (the CPU numba compiled for
and its widest vectors), wall_seconds_total (wall time of the run's segments, a killed one's up to its last frame or
checkpoint; wall_seconds and steps_done: the run loop's time and steps, last segment),
resumed_with (JSON: version, commit, CPU, threads, MPI ranks of continuations that differ), t_end_before (JSON:
the end times the run was started or continued with before a resume moved it; parameters_json
states the last). ``/graph`` attributes:
conductor_ids, conductor_potentials (0 where conductor_per_contact is 1: a potential set per
contact, the case (ii) filament), conductor_per_contact, role_names. A floating tip (on no path
between conductors) has 1 in ``graph/floating`` and 0 in ``graph/potential``; :meth:`RunFile.graph`
gives NaN there (files before 0.4 hold NaN in potential instead).

Every dimensionful dataset carries a ``unit`` attribute in the reduced units (the symbols below, docs/output.md), except
the positions, velocities and their times (MDAnalysis' H5MD reader refuses any unit string
outside its table of SI units, even with ``convert_units=False``; docs/output.md) and the fields
of the compound ``events`` (its ``time`` is in t0). The
``particles`` group tracks creation order, so readers that take its first subgroup
(MDAnalysis) take ``tips``. Files written before the units, ``connectivity``, the rods' box and
``observables/dt`` existed lack them; :class:`RunFile` reads both.

Only one process writes. Every frame is followed by a flush, so a run that is
killed keeps everything up to its last saved frame. ``status`` is "running"
until the run ends, then "finished" or "failed: <reason>".

The format lives in five modules, all re-exported here (import the names from this module):
:mod:`~selfas_graph.io.h5md_format` (units, the events' dtype, growable datasets, errors, free
space, :func:`appendable_problems`), :mod:`~selfas_graph.io.run_provenance` (:func:`run_provenance`),
:mod:`~selfas_graph.io.run_writer` (:class:`RunWriter`), :mod:`~selfas_graph.io.pending_rows`
(:class:`NullWriter`) and :mod:`~selfas_graph.io.run_reader` (:class:`RunFile`).
"""

from .h5md_format import CHARGE as CHARGE
from .h5md_format import CURRENT as CURRENT
from .h5md_format import ENERGY as ENERGY
from .h5md_format import EVENT_FILE_DTYPE as EVENT_FILE_DTYPE
from .h5md_format import H5MD_VERSION as H5MD_VERSION
from .h5md_format import HDF5_READ_ERRORS as HDF5_READ_ERRORS
from .h5md_format import LENGTH as LENGTH
from .h5md_format import POTENTIAL as POTENTIAL
from .h5md_format import SPACE_MARGIN as SPACE_MARGIN
from .h5md_format import TIME as TIME
from .h5md_format import UNIT_SYSTEM as UNIT_SYSTEM
from .h5md_format import DiskFullError as DiskFullError
from .h5md_format import OutputExistsError as OutputExistsError
from .h5md_format import RunFileError as RunFileError
from .h5md_format import appendable_problems as appendable_problems
from .h5md_format import free_bytes as free_bytes
from .h5md_format import hdf5_damage as hdf5_damage
from .h5md_format import is_io_error as is_io_error
from .h5md_format import not_replaced as not_replaced
from .h5md_format import observable_unit as observable_unit
from .h5md_format import raised_in_hdf5 as raised_in_hdf5
from .pending_rows import NullWriter as NullWriter
from .run_provenance import run_provenance as run_provenance
from .run_reader import RunFile as RunFile
from .run_writer import RunWriter as RunWriter
