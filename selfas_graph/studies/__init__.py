"""Studies: the ensembles the results page is made from, their summaries and the page itself.

``docs/studies.toml`` lists the studies and claims (:mod:`.spec`); a study's run files give its
summary (:mod:`.summary`); the summaries give every table of docs/results.md (:mod:`.page`, with the
statistics of :mod:`.stats` and the verdicts of :mod:`.verdicts`). From Python::

    from selfas_graph.studies import load_studies, run_study, summarise_study
    studies = load_studies("docs/studies.toml")
    run_study(studies.study("fig2"), runs="runs", jobs=2)      # resumable, as `ensemble`
    run_studies([studies.study(n) for n in ("conv_dt", "conv_slow1")], runs="runs", jobs=2)  # one pool
    summary = summarise_study(studies.study("fig2"), runs="runs")
"""

from .spec import Claim, Studies, StudiesError, Study, later_version, load_studies
from .summary import STUDY_MEASURES, summarise_study, write_json_atomic

__all__ = [
    "STUDY_MEASURES",
    "Claim",
    "Studies",
    "StudiesError",
    "Study",
    "later_version",
    "load_studies",
    "run_studies",
    "run_study",
    "summarise_study",
    "write_json_atomic",
]


def study_ensemble(study, runs, force=False, older_than=""):
    """The :class:`selfas_graph.ensemble.Ensemble` of ``study``: its seeds in ``runs/NAME``; a seed
    file made by a version older than ``older_than`` (``Studies.trajectories_since``), or than the study's
    own ``trajectories_since`` where that is later, is not reused."""
    from pathlib import Path

    from ..ensemble import Ensemble

    return Ensemble(
        study.scenario,
        seeds=study.seeds,
        folder=Path(runs) / study.name,
        overrides=list(study.overrides),
        t_end=study.t_end,
        first_seed=study.first_seed,
        force=force,
        older_than=later_version(study.trajectories_since, older_than),
    )


def run_study(study, runs, jobs=1, report=None, pool=None, force=False, older_than=""):
    """Run (or continue) the seeds of ``study`` into ``runs/NAME`` with :class:`selfas_graph.ensemble.Ensemble`
    (``older_than``: as :func:`study_ensemble`)."""
    ens = study_ensemble(study, runs, force, older_than)
    return ens, ens.run(jobs=jobs, report=report, pool=pool)


def run_studies(studies, runs, jobs=1, report=None, pool=None, force=False, announce=None, older_than=""):
    """Run (or continue) the seeds of several ensemble studies in one pool of ``jobs`` workers, so
    that no worker waits for the last seeds of one study before the next study starts.

    Every study's folder is created and locked (:class:`~selfas_graph.ensemble.FolderLock`) for the
    whole run; their seed files are planned first, and an unusable one anywhere stops everything
    before it starts (:class:`~selfas_graph.ensemble.EnsembleError` listing them). The seeds are
    handed out in the order of ``studies``; ``announce([(ensemble, plan), ...])``, if given, is called
    once they are planned, before anything runs. Returns ``[(ensemble, results)]``, the results in
    each ensemble's task order (None: never started). ``older_than``: as :func:`study_ensemble`.
    """
    import contextlib

    from ..ensemble import EnsembleError, FolderLock, make_folder, run_seed, run_tasks
    from ..parallel import task_pool

    ensembles = [study_ensemble(s, runs, force, older_than) for s in studies]
    with contextlib.ExitStack() as stack:
        for e in ensembles:
            make_folder(e.folder)
            stack.enter_context(FolderLock(e.folder))
        planned, problems = [], []
        for e in ensembles:
            try:
                planned.append(e.plan())
            except EnsembleError as exc:
                problems.append(str(exc))
        if problems:
            raise EnsembleError("\n".join(problems))
        if announce is not None:
            announce(list(zip(ensembles, planned)))
        tasks = [e.tasks(p) for e, p in zip(ensembles, planned)]
        flat = [t for ts in tasks for t in ts]
        if pool is None:
            with task_pool(jobs) as own:
                results = run_tasks(run_seed, flat, own, report)
        else:
            results = run_tasks(run_seed, flat, pool, report)
    out, k = [], 0
    for e, ts in zip(ensembles, tasks):
        out.append((e, results[k : k + len(ts)]))
        k += len(ts)
    return out
