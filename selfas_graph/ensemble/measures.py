"""The per-frame measures of a summary: :class:`Frame` (a saved frame with its cached measures),
:class:`Measure`, :data:`FRAME_MEASURES` and :func:`carries_current`."""

from __future__ import annotations

import dataclasses
import functools
import math
from typing import Callable

import numpy as np

from ..analysis.claims import frame_claims
from ..analysis.diagnostics import flux_through_rim, rod_centres
from ..io.frame import SavedFrame
from ..io.h5md import RunFileError
from ..io.scenario import scenario_from_text
from ..model.topology import FILAMENT


class Frame(SavedFrame):
    """One saved frame of a run file (:class:`~selfas_graph.io.frame.SavedFrame`), with what the
    measures need computed once (lazily).

    Adds to the saved frame: ``centres`` (rod centres), ``channel`` (the plasma channel of the scene),
    ``rho`` (their distance from its axis, or the z axis), ``flux_radius``, ``claims``
    (``frame_claims(run, index)``).
    """

    def __init__(self, run, index, params, flux_radius=None):
        super().__init__(run, index, params)
        self._flux_radius = flux_radius

    @functools.cached_property
    def centres(self):
        return rod_centres(self.position)

    @functools.cached_property
    def channel(self):
        """The plasma channel the measures refer to, ``{"axis": (x0, y0), "radius": R_plas}``: the run's
        plasma filament, or, in a null model that switched it off (``--set forces.plasma_filament=false``),
        the channel its scenario file states, so that "within R_plas" means the same region in both;
        None where neither has one."""
        if self.plasma:
            return {"axis": tuple(self.plasma["axis"]), "radius": float(self.plasma["radius"])}
        try:
            stated = scenario_from_text(self.run.scenario_text).params.forces.plasma_filament
        except (KeyError, ValueError):  # no scenario text, or one this version cannot read
            return None
        return None if stated is None else {"axis": tuple(stated.axis), "radius": float(stated.radius)}

    @functools.cached_property
    def rho(self):
        ax = self.channel["axis"] if self.channel else (0.0, 0.0)
        return np.hypot(self.centres[:, 0] - ax[0], self.centres[:, 1] - ax[1])

    @property
    def flux_radius(self):
        """Disc radius of the mid-plane flux: given, or the half-diagonal of the placement box in x-y."""
        if self._flux_radius is not None:
            return float(self._flux_radius)
        (x0, x1), (y0, y1) = self.params["placement"]["box"][:2]
        return float(np.hypot(max(abs(x0), abs(x1)), max(abs(y0), abs(y1))))

    @functools.cached_property
    def claims(self):
        return frame_claims(self.run, self.index)


@dataclasses.dataclass(frozen=True)
class Measure:
    """A number per frame: ``fn(frame) -> float`` (NaN when it does not apply), with its unit and meaning.

    ``err(frame) -> float``, if given, is the value's own uncertainty (a fit's): the standard
    error over seeds then adds it (:func:`~selfas_graph.analysis.ensemble_stats.mean_sem_fits`).
    ``grouped``: the measure describes seeds whose circuit carries a current (:func:`carries_current`);
    its mean, standard error and count are those of that group alone, with its median and range
    (:func:`~selfas_graph.analysis.ensemble_stats.grouped_summary`).
    """

    name: str
    unit: str
    doc: str
    fn: Callable[[Frame], float]
    err: Callable[[Frame], float] | None = None
    grouped: bool = False


def carries_current(f) -> float:
    """1.0 if a current flows through the circuit at the frame (rods in current-carrying filaments,
    or a nonzero total current where the frame has no graph), 0.0 if not, NaN if unknown."""
    rods = _filament_rods(f)
    if math.isfinite(rods):
        return float(rods > 0)
    j = _total_current(f)
    return float(j != 0.0) if math.isfinite(j) else math.nan


def _filament_rods(f):
    return math.nan if f.graph is None else float(np.count_nonzero(f.graph["role"] == FILAMENT))


def _total_current(f):
    try:
        t, v = f.run.observable("total_current")
    except RunFileError:
        return math.nan
    k = int(np.argmin(np.abs(t - f.time)))
    return float(v[k])


def _inside_plasma(f):
    return float(np.mean(f.rho < f.channel["radius"])) if f.channel else math.nan


def _midplane_flux(f):
    if f.graph is None:
        return math.nan
    current = np.asarray(f.graph["current"], dtype=np.float64)
    if not np.any(current):
        return 0.0
    return flux_through_rim(f.flux_radius, 0.0, f.position, None, current, f.wire_radius)


#: the per-frame measures of a summary, in table order (a new one: ARCHITECTURE.md 'How to add a measure of a
#: saved frame', which names the other lists it goes in)
FRAME_MEASURES = [
    Measure("filament_rods", "rods", "rods in current-carrying filaments", _filament_rods, grouped=True),
    Measure(
        "total_current", "J0", "current through the circuit (observable total_current)", _total_current, grouped=True
    ),
    Measure("inside_R_plas", "fraction", "fraction of rod centres within R_plas of the plasma axis", _inside_plasma),
    Measure(
        "median_axis_distance", "L", "median distance of rod centres from the axis", lambda f: float(np.median(f.rho))
    ),
    Measure(
        "midplane_flux",
        "Phi_0",
        "flux of the rod currents' B_z through the disc z = 0 of radius flux_radius "
        "(default: the placement box's half-diagonal)",
        _midplane_flux,
        grouped=True,
    ),
    Measure(
        "moment_J_z",
        "J0 L^2",
        "m_J,z of all rod currents about the z axis",
        lambda f: float(f.claims["moment_J_z"]),
        grouped=True,
    ),
]
FRAME_MEASURES += [
    Measure(
        k, u, d, lambda f, k=k: float(f.claims[k]), err=(lambda f, k=k: float(f.claims[k + "_err"])) if fit else None
    )
    for k, u, d, fit in (
        ("largest_structure_rods", "rods", "rods in the largest structure", False),
        ("largest_moment_ratio", "rod moments", "largest structure's |m_q| over mean |q| L (a rod of length L)", False),
        (
            "fractal_dimension",
            "1",
            "mass-radius dimension of the largest structure (NaN, not testable, while its R_g < 4 L)",
            True,
        ),
        ("rg_dimension", "1", "R_g ~ N^(1/D) dimension over the structures of the frame", True),
        ("cycle_rank", "loops", "cycle rank of the contact graph (E - V + C)", False),
    )
]
