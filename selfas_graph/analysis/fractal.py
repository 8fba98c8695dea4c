"""Fractal measures of rod structures: "a trend towards a fractal skeletal structuring" (docs/model.md "Measures of the paper's claims").

Arrays in, arrays out; rod ``i`` has tips at rows ``2 i`` and ``2 i + 1`` of ``position``.
Every measure is a straight-line fit in log-log coordinates and returns a :class:`Fit`: the
dimension, its uncertainty, the standard error of the slope, the range the fit ran over
and the number of points in it. A rod has unit length, so nothing is self-similar below
one rod length: every range starts at one rod length or above.

* :func:`mass_radius_dimension` -- the mass (rod length) within r of a point of the
  structure, averaged over the points of the structure within R_g / 2 of its centre of
  mass, M(r) ~ r^D, for r from ``r_min`` (one rod length) to the radius of gyration R_g
  (a "sandbox" count: every centre lies on the structure).
* :func:`rg_dimension` -- R_g ~ N^(1/D) over the structures of a frame (or of an ensemble)
  whose R_g is at least one rod length.
* :func:`box_dimension` -- occupied boxes of points sampled along the rods, N(eps) ~ eps^-D.
  Not a claim measure: at these sizes it is biased low (see its docstring).

Not testable at this size
-------------------------
A fit whose abscissa spans less than a factor :data:`MIN_RANGE` (4, 0.6 decades of length)
returns NaN with a note saying so. 4 is where the anchors of ``tests/unit/test_fractal.py`` (a
compact blob of 1000 rods has R_g = 4.5 L) are still recovered within their tolerances;
below it a compact cluster gave anything from 2 to 4.5. For :func:`rg_dimension` the range
is that of R_g (a length), not of N.

Why the mass is not counted from the centre of mass
---------------------------------------------------
Up to 0.3.0 the mass-radius dimension counted rod centres within r of the centre of mass.
That point need not lie on the structure: a network wound around the plasma axis, a
random walk, a structure hanging from the anode in two lobes have their centre of mass in
a hole, N(r) is 0 or 1 at the smallest radii and rises faster than r^3 as the spheres
reach the structure. Fig. 2 runs gave 2.4-3.1 and the 2800-rod Fig. 6 structure 4.7; a
lattice random walk of 1000 rods gave 2.6 (D = 2), a compact lattice ball 3.15 from the
few rod centres within one rod length of its centre. Centres on the structure cannot see
a hole; averaging over the points of the inner half (by R_g) of the structure removes the
scatter of one centre, and keeps spheres up to r = R_g mostly inside it (for a ball the
spheres about centres within R_g / 2 lie inside up to r = 0.8 R_g), where an average over
every point lets the spheres about boundary points saturate and biases a compact blob
low by 0.3-0.5 at these sizes.

The uncertainty
---------------
The points of such fits are correlated (M(r) is cumulative; boxes at neighbouring sizes
share points), and a finite object bends the curve near both ends of the range, so the
standard error of the slope alone understates how well a dimension is known. Each fit
therefore reports ``err = sqrt(se^2 + d^2)`` where ``se`` is the standard error of the
least-squares slope and ``d`` the difference between the slopes fitted to the lower and the
upper half of the range of log x (its curvature: how much the answer depends on the range).
For ``rg_dimension`` both are carried to D = 1 / slope. ``se`` is reported on its own too.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from scipy.spatial import cKDTree

__all__ = [
    "MIN_RANGE",
    "Fit",
    "box_dimension",
    "log_fit",
    "mass_radius_dimension",
    "radius_of_gyration",
    "rg_dimension",
    "rod_points",
]

NAN = float("nan")

#: fewest factor the abscissa of a fit must span (module notes, "Not testable at this size")
MIN_RANGE = 4.0


@dataclasses.dataclass(frozen=True)
class Fit:
    """A dimension from a log-log fit.

    Attributes
    ----------
    value : float
        The dimension (NaN when the fit is undefined: too few rods, points or range).
    err : float
        Its uncertainty (see the module notes).
    fit_range : (float, float)
        The range of the abscissa fitted (r, N or eps; NaN, NaN when undefined).
    n_points : int
        Points in the fit.
    note : str
        Why the value is NaN, or "".
    se : float
        The standard error of the least-squares slope alone, carried to the dimension (part of
        ``err``; NaN with fewer than 3 points).
    """

    value: float
    err: float
    fit_range: tuple
    n_points: int
    note: str = ""
    se: float = NAN

    @classmethod
    def undefined(cls, note):
        return cls(NAN, NAN, (NAN, NAN), 0, note, NAN)


def log_fit(x, y):
    """Least squares of log y against log x: (slope, standard error of the slope, intercept).

    The standard error is ``sqrt(sum r^2 / (n - 2) / sum (lx - mean)^2)``; NaN for n < 3.
    """
    lx, ly = np.log(np.asarray(x, dtype=np.float64)), np.log(np.asarray(y, dtype=np.float64))
    n = lx.shape[0]
    if n < 2:
        return NAN, NAN, NAN
    mx = lx.mean()
    sxx = float(((lx - mx) ** 2).sum())
    if sxx == 0.0:
        return NAN, NAN, NAN
    slope = float(((lx - mx) * (ly - ly.mean())).sum() / sxx)
    intercept = float(ly.mean() - slope * mx)
    if n < 3:
        return slope, NAN, intercept
    resid = ly - (intercept + slope * lx)
    se = math.sqrt(float((resid**2).sum()) / (n - 2) / sxx)
    return slope, se, intercept


def _slope_uncertainty(x, y):
    """(slope, err, se) with err = sqrt(se^2 + d^2), d the difference of the slopes fitted to the points
    below and above the middle of the range of log x (0 when either half has fewer than 2 distinct x)."""
    x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
    slope, se, _ = log_fit(x, y)
    lx = np.log(x)
    mid = 0.5 * (lx.min() + lx.max())
    lo, hi = lx <= mid + 1e-12, lx >= mid - 1e-12
    curvature = 0.0
    if np.unique(x[lo]).shape[0] >= 2 and np.unique(x[hi]).shape[0] >= 2:
        curvature = abs(log_fit(x[hi], y[hi])[0] - log_fit(x[lo], y[lo])[0])
    return slope, math.sqrt((se if math.isfinite(se) else 0.0) ** 2 + curvature**2), se


def _rods(position, rods):
    position = np.asarray(position, dtype=np.float64).reshape(-1, 3)
    a, b = position[0::2], position[1::2]
    if rods is not None:
        rods = np.asarray(rods, dtype=np.int64).reshape(-1)
        a, b = a[rods], b[rods]
    return a, b


def radius_of_gyration(position, structure=None, n_structures=None):
    """Radius of gyration of each structure, its rods taken as uniform unit-mass segments.

    ``R_g^2 = (1/N) sum_i (|c_i - c|^2 + |s_i|^2 / 12)`` with c_i the rod centres, c their mean
    and s_i the rod axes; a straight chain of N touching rods has R_g = N / sqrt(12).

    Parameters
    ----------
    position : (n_tips, 3) float64
    structure : (n_rods,) int, optional
        Structure labels (-1: in none); default: all rods are one structure.
    n_structures : int, optional

    Returns
    -------
    rg : (n_structures,) float64
    size : (n_structures,) int64
        Rods in each structure.
    """
    a, b = _rods(position, None)
    c = 0.5 * (a + b)
    own = ((b - a) ** 2).sum(axis=1) / 12.0
    structure = np.zeros(c.shape[0], dtype=np.int64) if structure is None else np.asarray(structure, dtype=np.int64)
    n_s = int(structure.max(initial=-1)) + 1 if n_structures is None else int(n_structures)
    keep = structure >= 0
    lab = structure[keep]
    size = np.bincount(lab, minlength=n_s)
    safe = np.maximum(size, 1)
    cm = np.stack([np.bincount(lab, weights=c[keep, d], minlength=n_s) for d in range(3)], axis=1) / safe[:, None]
    d2 = ((c[keep] - cm[lab]) ** 2).sum(axis=1) + own[keep]
    rg = np.sqrt(np.bincount(lab, weights=d2, minlength=n_s) / safe)
    return np.where(size > 0, rg, NAN), size.astype(np.int64)


def rod_points(position, rods=None, per_rod=8):
    """Points spread evenly along the rods, ``per_rod`` per mean rod length L: a rod of length l_i is
    cut into ``max(1, round(per_rod * l_i))`` equal pieces (``per_rod`` for the rods of length 1 of
    the paper's scenes), and each piece gives its midpoint.

    Each point stands for L / ``per_rod`` of rod length (the mean rod length is the unit of mass), so
    counts of points are rod lengths without the steps of counting whole rods, also where the rods'
    lengths differ (``rods.length``).

    Returns
    -------
    (sum of the pieces, 3) float64, rod by rod
    """
    a, b = _rods(position, rods)
    axis = b - a
    pieces = np.maximum(1, np.rint(per_rod * np.sqrt((axis * axis).sum(axis=1)))).astype(np.int64)
    rod = np.repeat(np.arange(a.shape[0]), pieces)
    k = np.arange(rod.shape[0]) - np.repeat(np.cumsum(pieces) - pieces, pieces)
    t = (k + 0.5) / pieces[rod]
    return a[rod] + t[:, None] * axis[rod]


def mass_radius_dimension(
    position,
    rods=None,
    r_min=1.0,
    r_max=None,
    n_r=12,
    min_rods=30,
    min_range=MIN_RANGE,
    centre_within=0.5,
    per_rod=8,
    max_centres=1000,
):
    """Mass-radius dimension of one structure, counted about centres on it: M(r) ~ r^D.

    M(r) is the rod length within r of a centre, averaged over the centres: the points along
    the rods (:func:`rod_points`) that lie within ``centre_within`` R_g of the structure's
    centre of mass (at most ``max_centres`` of them, a fixed draw, so the answer does not
    change between calls). Module notes: why not about the centre of mass.

    Parameters
    ----------
    position : (n_tips, 3) float64
    rods : (N,) int, optional
        The structure's rods (default all).
    r_min : float
        Smallest radius fitted (default one rod length).
    r_max : float, optional
        Largest radius fitted (default the structure's radius of gyration R_g).
    n_r : int
        Radii, log-spaced in [r_min, r_max].
    min_rods : int
        Fewer rods give NaN.
    min_range : float
        An r_max below ``min_range`` r_min gives NaN (not testable at this size).
    centre_within : float
        Centres are the points within this many R_g of the centre of mass.
    per_rod : int
        Points per rod.
    max_centres : int
        At most this many centres.

    Returns
    -------
    Fit (range in rod lengths).
    """
    a, b = _rods(position, rods)
    n = a.shape[0]
    if n < min_rods:
        return Fit.undefined(f"{n} rods, fewer than {min_rods}")
    tips = np.column_stack([a, b]).reshape(-1, 3)
    rg = float(radius_of_gyration(tips)[0][0])
    r_max = rg if r_max is None else float(r_max)
    if not r_max >= min_range * r_min:
        return Fit.undefined(
            f"range {r_min:g}..{r_max:.3g} L spans less than a factor {min_range:g}: not testable at this size"
        )
    x = rod_points(tips, None, per_rod)
    near = np.flatnonzero(np.sqrt(((x - x.mean(axis=0)) ** 2).sum(axis=1)) <= centre_within * rg)
    if near.shape[0] == 0:
        return Fit.undefined(f"no point of the structure within {centre_within:g} R_g of its centre of mass")
    if near.shape[0] > max_centres:  # a fixed draw: the same frame always gives the same answer
        near = np.sort(np.random.default_rng(0).choice(near, max_centres, replace=False))
    r = np.geomspace(r_min, r_max, n_r)
    mass = cKDTree(x[near]).count_neighbors(cKDTree(x), r).astype(np.float64) / (near.shape[0] * per_rod)
    slope, err, se = _slope_uncertainty(r, mass)
    return Fit(slope, err, (float(r_min), float(r_max)), int(n_r), se=se)


def rg_dimension(size, rg, min_size=2, min_sizes=3, rg_min=1.0, min_range=MIN_RANGE):
    """D from R_g ~ N^(1/D) over structures: the least-squares slope 1/D of log R_g against log N.

    The fit assumes that every structure is the same kind of object at a different size.
    Structures with R_g below ``rg_min`` (one rod length: two or three rods at an angle) are
    left out, and so the fit needs R_g to span a factor ``min_range``: where small structures
    are open chains and large ones compact, the slope mixes the two: off-lattice compact blobs
    of 13-1600 rods, whose density still grows with size, give 3.6 +- 0.7 over R_g = 1.25-5.1 L
    (``tests/unit/test_fractal.py``), consistent with 3 only through its large uncertainty.

    Parameters
    ----------
    size : (S,) int
        Rods in each structure.
    rg : (S,) float
        Their radii of gyration (:func:`radius_of_gyration`).
    min_size : int
        Smaller structures are left out (default 2: free rods are no aggregate).
    min_sizes : int
        Fewer distinct sizes give NaN.
    rg_min : float
        Structures with a smaller R_g are left out.
    min_range : float
        R_g spanning less than this factor gives NaN (not testable at this size).

    Returns
    -------
    Fit (range in rods). Its uncertainty and standard error are those of the slope carried to D = 1 / slope.
    """
    size = np.asarray(size, dtype=np.float64).reshape(-1)
    rg = np.asarray(rg, dtype=np.float64).reshape(-1)
    keep = (size >= min_size) & np.isfinite(rg) & (rg >= rg_min)
    size, rg = size[keep], rg[keep]
    if np.unique(size).shape[0] < min_sizes:
        return Fit.undefined(
            f"{np.unique(size).shape[0]} distinct sizes of structures with >= {min_size} rods and "
            f"R_g >= {rg_min:g} L, fewer than {min_sizes}"
        )
    if not rg.max() >= min_range * rg.min():
        return Fit.undefined(
            f"R_g spans {rg.min():.3g}..{rg.max():.3g} L, less than a factor {min_range:g}: not testable at this size"
        )
    order = np.argsort(size, kind="stable")
    slope, err, se = _slope_uncertainty(size[order], rg[order])
    if not slope > 0:
        return Fit.undefined(f"R_g does not grow with N (slope {slope:.3g})")
    return Fit(
        1.0 / slope,
        err / slope**2,
        (float(size.min()), float(size.max())),
        int(size.shape[0]),
        se=se / slope**2 if math.isfinite(se) else NAN,
    )


def box_dimension(position, rods=None, spacing=None, eps_min=1.0, k_min=4, n_eps=10, min_rods=30, min_range=MIN_RANGE):
    """Box-counting dimension of points sampled along the rods: occupied boxes N(eps) ~ eps^-D.

    Not a claim measure (dropped from :mod:`.claims`, CHANGELOG 'Unreleased'): on the anchors of
    ``tests/unit/test_fractal.py`` it is biased low by more than its uncertainty at the sizes of
    the runs: 1.7-1.8 for a 2-D sheet of 600-1400 rods, 2.2-2.6 for compact blobs and 1.6-1.8
    for DLA clusters (D = 2.5) of 500-2000 rods, turned at random to the grid. Boxes of one
    rod length are threaded by single rods (1-D) and the partly filled boxes at the
    boundary count as full at large eps; both flatten the curve, and a decade of boxes that
    avoids both needs structures far larger than these. Kept for comparison.

    The grids cover the structure's bounding cube (side S, its largest extent) with k^3 boxes
    of side eps = S / k, for integers k log-spaced from ``k_min`` to S / ``eps_min``: boxes
    from one rod length up to a quarter of the structure. On such grids a straight chain, a
    plane sheet and a solid block fill exactly k, k^2 and k^3 boxes at every k.

    Parameters
    ----------
    position : (n_tips, 3) float64
    rods : (N,) int, optional
        The structure's rods (default all).
    spacing : float, optional
        Points every ``spacing`` along each rod (default ``eps_min / 8``).
    eps_min : float
        Smallest box (default one rod length).
    k_min : int
        Fewest boxes along the side (the largest box is S / k_min).
    n_eps : int
        At most this many box sizes.
    min_rods : int
        Fewer rods give NaN.
    min_range : float
        Box sizes spanning less than this factor give NaN (not testable at this size).

    Returns
    -------
    Fit (range of eps in rod lengths).
    """
    a, b = _rods(position, rods)
    n = a.shape[0]
    if n < min_rods:
        return Fit.undefined(f"{n} rods, fewer than {min_rods}")
    spacing = eps_min / 8.0 if spacing is None else spacing
    m = max(2, int(math.ceil(1.0 / spacing)))
    t = (np.arange(m) + 0.5) / m
    pts = (a[:, None, :] + t[None, :, None] * (b - a)[:, None, :]).reshape(-1, 3)
    lo = pts.min(axis=0)
    side = float((pts.max(axis=0) - lo).max())
    k_max = int(side // eps_min)
    if k_max < min_range * k_min:
        return Fit.undefined(
            f"the structure ({side:.3g} rod lengths across) holds less than a factor {min_range:g} of box sizes "
            f"between {eps_min:g} and a {k_min}th of it: not testable at this size"
        )
    ks = np.unique(np.round(np.geomspace(k_min, k_max, n_eps)).astype(np.int64))
    count = np.empty(ks.shape[0])
    for j, k in enumerate(ks):
        cell = np.minimum(np.floor((pts - lo) * (k / side)).astype(np.int64), k - 1)
        count[j] = np.unique((cell[:, 0] * k + cell[:, 1]) * k + cell[:, 2]).shape[0]
    eps = side / ks
    slope, err, se = _slope_uncertainty(ks.astype(np.float64), count)
    return Fit(slope, err, (float(eps.min()), float(eps.max())), int(ks.shape[0]), se=se)
