"""Analysis of saved frames: the diagnostics behind the paper's figures (docs/model.md section 7)
and the measures of its claims (section 7a: :mod:`.moments`, :mod:`.fractal`, :mod:`.skeleton`,
and :func:`.claims.frame_claims`, which reads them from a run file).

Arrays in, arrays out: these functions see one frame's numpy arrays (or a run's
observable arrays) and never open a file; reading run files is the job of
:mod:`selfas_graph.io` and of the ``plot`` command.
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

__all__ = [
    "Timeline",
    "auto_n_phi",
    "bz_profile",
    "disc_flux",
    "flux_through_disc",
    "radial_density",
    "rod_centres",
    "timeline",
]
