"""Analysis of saved frames: the diagnostics behind the paper's figures (docs/model.md 'Figure diagnostics')
and the measures of its claims (section 7a: :mod:`.moments`, :mod:`.fractal`, :mod:`.skeleton`,
and :func:`.claims.frame_claims`, which reads them from a run file), and the topology of a saved frame
(:func:`.frame_topology.frame_topology`, what ``selfas-graph topology`` prints).

Arrays in, arrays out: these functions see one frame's numpy arrays (or a run's
observable arrays) and never open a file (the two readers of a frame take a run file opened by
:mod:`selfas_graph.io`); reading run files is the job of :mod:`selfas_graph.io` and of the ``plot`` command.
"""

from .diagnostics import (
    Timeline,
    auto_n_phi,
    bz_profile,
    disc_flux,
    flux_through_disc,
    radial_density,
    rod_centres,
    timeline,
)
from .ensemble_stats import (
    censored_times,
    grouped_summary,
    kaplan_meier,
    km_quantile,
    mean_sem,
    mean_sem_fits,
    wilson_interval,
)
from .episodes import CircuitEpisodes, circuit_episodes

__all__ = [
    "CircuitEpisodes",
    "circuit_episodes",
    "Timeline",
    "auto_n_phi",
    "censored_times",
    "grouped_summary",
    "mean_sem_fits",
    "kaplan_meier",
    "km_quantile",
    "mean_sem",
    "wilson_interval",
    "bz_profile",
    "disc_flux",
    "flux_through_disc",
    "radial_density",
    "rod_centres",
    "timeline",
]
