"""Ensembles: one scenario run over many seeds, one run file per seed, and statistics over the seeds.

One run of a chaotic system is an anecdote (README, "Ensembles"): a claim is the mean and
standard error over seeds. From Python::

    from selfas_graph.ensemble import Ensemble, format_table
    ens = Ensemble("scenarios/quick.toml", seeds=4, folder="quick_ensemble", t_end=1.0)
    ens.run(jobs=2)                       # seeds 1..4 -> quick_ensemble/seed_0001.h5 ...
    summary = ens.summarise(times=[0.5, 1.0])
    print(format_table(summary))

Seeds are ``first_seed, first_seed + 1, ...`` (``first_seed`` defaults to the scenario's
``scenario.seed``); seed ``s`` is written to ``FOLDER/seed_{s:04d}.h5`` exactly as
``selfas-graph simulate SCENARIO --set scenario.seed=s -o FOLDER/seed_{s:04d}.h5`` would
write it (the same run file, checkpoint and provenance), so one seed can be inspected,
plotted or resumed by hand.

Calling :meth:`Ensemble.run` again runs only what is missing: a seed whose file is
finished at (or beyond) the end time is kept; an interrupted one, or one finished at an
earlier end time, is continued from its checkpoint (``RUN.checkpoint.h5``, as
``simulate --resume``); a failed one is reported and kept. A seed file whose stored
parameters differ from the ensemble's (other than ``run.t_end``) is refused, never reused
or overwritten; ``force=True`` replaces the files that cannot be reused.

The runs go to :class:`selfas_graph.parallel.task_pool`: ``jobs`` spawned processes on
one machine (``cores // jobs`` numba threads each), or the ranks of an MPI launcher.
The same runner serves ``selfas-graph bench percolation`` (:func:`run_tasks`, :func:`run_to_short_circuit`).

The parts, one concept a module: ``plan`` (:class:`Ensemble`, :class:`SeedPlan`), ``parameters``
(whether a seed file belongs to the ensemble), ``folder`` (seed file names, :class:`FolderLock`),
``tasks`` (:func:`run_seed`, :func:`run_to_short_circuit`), ``pool`` (:func:`run_tasks`),
``measures`` (:class:`Frame`, :class:`Measure`, :data:`FRAME_MEASURES`), ``summary``
(:func:`summarise`) and ``tables`` (:func:`format_table`, :func:`write_summary`). Import the
names from here; the names outside ``__all__`` are re-exported as ``name as name``.
"""

from ..model.parameter_match import FREE_PARAMETERS as FREE_PARAMETERS
from ..model.parameter_match import parameter_differences as parameter_differences
from .folder import LOCK_FILE as LOCK_FILE
from .folder import SEED_FILE as SEED_FILE
from .folder import EnsembleError, FolderLock, seed_path
from .folder import make_folder as make_folder
from .measures import FRAME_MEASURES, Frame, Measure, carries_current
from .plan import Ensemble, SeedPlan
from .plan import default_times as default_times
from .pool import run_tasks
from .summary import summarise
from .tables import CSV_EXTRA as CSV_EXTRA
from .tables import SUMMARY_CSV as SUMMARY_CSV
from .tables import SUMMARY_JSON as SUMMARY_JSON
from .tables import format_table, write_summary
from .tasks import run_seed, run_to_short_circuit

__all__ = [
    "Ensemble",
    "EnsembleError",
    "FolderLock",
    "FRAME_MEASURES",
    "Frame",
    "Measure",
    "SeedPlan",
    "carries_current",
    "format_table",
    "run_seed",
    "run_tasks",
    "run_to_short_circuit",
    "seed_path",
    "summarise",
    "write_summary",
]
