"""Studies: the ensembles the results page is made from, their summaries and the page itself.

``docs/studies.toml`` lists the studies and claims (:mod:`.spec`); a study's run files give its
summary (:mod:`.summary`); the summaries give every table of docs/results.md (:mod:`.page`). From
Python::

    from selfas_graph.studies import load_studies, run_study, summarise_study
    studies = load_studies("docs/studies.toml")
    run_study(studies.study("fig2"), runs="runs", jobs=2)      # resumable, as `ensemble`
    summary = summarise_study(studies.study("fig2"), runs="runs")
"""

from .spec import Claim, Studies, StudiesError, Study, load_studies
from .summary import STUDY_MEASURES, summarise_study, write_json_atomic

__all__ = [
    "STUDY_MEASURES",
    "Claim",
    "Studies",
    "StudiesError",
    "Study",
    "load_studies",
    "run_study",
    "summarise_study",
    "write_json_atomic",
]


def run_study(study, runs, jobs=1, report=None, pool=None, force=False):
    """Run (or continue) the seeds of ``study`` into ``runs/NAME`` with :class:`selfas_graph.ensemble.Ensemble`."""
    from pathlib import Path

    from ..ensemble import Ensemble

    ens = Ensemble(
        study.scenario,
        seeds=study.seeds,
        folder=Path(runs) / study.name,
        overrides=list(study.overrides),
        t_end=study.t_end,
        first_seed=study.first_seed,
        force=force,
    )
    return ens, ens.run(jobs=jobs, report=report, pool=pool)
