"""Fractal measures of rod structures: "a trend towards a fractal skeletal structuring" (docs/model.md "Measures of the paper's claims").

Arrays in, arrays out; rod ``i`` has tips at rows ``2 i`` and ``2 i + 1`` of ``position``.
Every measure is a straight-line fit in log-log coordinates and returns a :class:`Fit`: the
dimension, its uncertainty, the range the fit ran over and the number of points in it. A
rod has unit length, so nothing is self-similar below one rod length: every range starts
at one rod length or above.

* :func:`mass_radius_dimension` -- rods whose centre lies within r of the structure's
  centre of mass, N(r) ~ r^D, for r from ``r_min`` (one rod length) to the structure's
  radius of gyration (inside which a chain, a sheet or a block is still "bulk").
* :func:`rg_dimension` -- R_g ~ N^(1/D) over the structures of a frame (or of an ensemble).
* :func:`box_dimension` -- occupied boxes of points sampled along the rods, N(eps) ~ eps^-D,
  on grids that divide the structure's bounding cube, for boxes from one rod length to a
  quarter of the structure.

The uncertainty
---------------
The points of such fits are correlated (N(r) is cumulative; boxes at neighbouring sizes
share points), and a finite object bends the curve near both ends of the range, so the
standard error of the slope alone understates how well a dimension is known. Each fit
therefore reports ``err = sqrt(se^2 + d^2)`` where ``se`` is the standard error of the
least-squares slope and ``d`` the difference between the slopes fitted to the lower and the
upper half of the range of log x (its curvature: how much the answer depends on the range).
For ``rg_dimension`` both are carried to D = 1 / slope. On the hand-built anchors of
``tests/test_claims.py`` (a chain, a square-lattice sheet, a cubic-lattice block) the
dimensions come out 1, 2 and 3 within this uncertainty.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

__all__ = [
    "Fit",
    "box_dimension",
    "log_fit",
    "mass_radius_dimension",
    "radius_of_gyration",
    "rg_dimension",
]

NAN = float("nan")


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
    """

    value: float
    err: float
    fit_range: tuple
    n_points: int
    note: str = ""

    @classmethod
    def undefined(cls, note):
        return cls(NAN, NAN, (NAN, NAN), 0, note)


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
    """(slope, err) with err = sqrt(se^2 + d^2), d the difference of the slopes fitted to the points
    below and above the middle of the range of log x (0 when either half has fewer than 2 distinct x)."""
    x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
    slope, se, _ = log_fit(x, y)
    lx = np.log(x)
    mid = 0.5 * (lx.min() + lx.max())
    lo, hi = lx <= mid + 1e-12, lx >= mid - 1e-12
    curvature = 0.0
    if np.unique(x[lo]).shape[0] >= 2 and np.unique(x[hi]).shape[0] >= 2:
        curvature = abs(log_fit(x[hi], y[hi])[0] - log_fit(x[lo], y[lo])[0])
    return slope, math.sqrt((se if math.isfinite(se) else 0.0) ** 2 + curvature**2)


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


def mass_radius_dimension(position, rods=None, r_min=1.0, r_max=None, n_r=16, min_rods=30):
    """Mass-radius dimension of one structure: rods with centre within r of the centre of mass ~ r^D.

    Parameters
    ----------
    position : (n_tips, 3) float64
    rods : (N,) int, optional
        The structure's rods (default all).
    r_min : float
        Smallest radius fitted (default one rod length).
    r_max : float, optional
        Largest radius fitted (default the structure's radius of gyration).
    n_r : int
        Radii, log-spaced in [r_min, r_max].
    min_rods : int
        Fewer rods give NaN, and so does a radius of gyration below 3 ``r_min``.

    Returns
    -------
    Fit (range in rod lengths).
    """
    a, b = _rods(position, rods)
    n = a.shape[0]
    if n < min_rods:
        return Fit.undefined(f"{n} rods, fewer than {min_rods}")
    c = 0.5 * (a + b)
    d = np.sqrt(((c - c.mean(axis=0)) ** 2).sum(axis=1))
    if r_max is None:
        r_max = float(radius_of_gyration(np.column_stack([a, b]).reshape(-1, 3))[0][0])
    # below a factor 3 the few discrete radii give slopes anywhere from 1 to 5 on compact clusters
    if not r_max >= 3.0 * r_min:
        return Fit.undefined(f"range {r_min:g}..{r_max:.3g} spans less than a factor 3")
    r = np.geomspace(r_min, r_max, n_r)
    count = np.searchsorted(np.sort(d), r, side="right").astype(np.float64)
    ok = count > 0
    if ok.sum() < 3:
        return Fit.undefined("fewer than 3 radii hold a rod")
    slope, err = _slope_uncertainty(r[ok], count[ok])
    return Fit(slope, err, (float(r[ok][0]), float(r_max)), int(ok.sum()))


def rg_dimension(size, rg, min_size=2, min_sizes=3):
    """D from R_g ~ N^(1/D) over structures: the least-squares slope 1/D of log R_g against log N.

    Parameters
    ----------
    size : (S,) int
        Rods in each structure.
    rg : (S,) float
        Their radii of gyration (:func:`radius_of_gyration`).
    min_size : int
        Smaller structures are left out (default 2: free rods are no aggregate).
    min_sizes : int
        Fewer distinct sizes, or sizes spanning less than a factor 2, give NaN.

    Returns
    -------
    Fit (range in rods). Its uncertainty is that of the slope carried to D = 1 / slope.
    """
    size = np.asarray(size, dtype=np.float64).reshape(-1)
    rg = np.asarray(rg, dtype=np.float64).reshape(-1)
    keep = (size >= min_size) & np.isfinite(rg) & (rg > 0)
    size, rg = size[keep], rg[keep]
    if np.unique(size).shape[0] < min_sizes:
        return Fit.undefined(
            f"{np.unique(size).shape[0]} distinct structure sizes >= {min_size}, fewer than {min_sizes}"
        )
    if size.max() < 2 * size.min():
        return Fit.undefined("structure sizes span less than a factor 2")
    order = np.argsort(size, kind="stable")
    slope, err = _slope_uncertainty(size[order], rg[order])
    if not slope > 0:
        return Fit.undefined(f"R_g does not grow with N (slope {slope:.3g})")
    return Fit(1.0 / slope, err / slope**2, (float(size.min()), float(size.max())), int(size.shape[0]))


def box_dimension(position, rods=None, spacing=None, eps_min=1.0, k_min=4, n_eps=10, min_rods=30):
    """Box-counting dimension of points sampled along the rods: occupied boxes N(eps) ~ eps^-D.

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
    if k_max < 2 * k_min:
        return Fit.undefined(
            f"the structure ({side:.3g} rod lengths across) holds less than a factor 2 of box sizes "
            f"between {eps_min:g} and a {k_min}th of it"
        )
    ks = np.unique(np.round(np.geomspace(k_min, k_max, n_eps)).astype(np.int64))
    count = np.empty(ks.shape[0])
    for j, k in enumerate(ks):
        cell = np.minimum(np.floor((pts - lo) * (k / side)).astype(np.int64), k - 1)
        count[j] = np.unique((cell[:, 0] * k + cell[:, 1]) * k + cell[:, 2]).shape[0]
    eps = side / ks
    slope, err = _slope_uncertainty(ks.astype(np.float64), count)
    return Fit(slope, err, (float(eps.min()), float(eps.max())), int(ks.shape[0]))
