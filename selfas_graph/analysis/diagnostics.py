"""Diagnostics of one frame, as in the paper's figures (docs/model.md 'Figure diagnostics').

Functions over plain arrays (no files, no h5py), in reduced units (docs/model.md
'Reduced units': lengths in L, fields in B0, fluxes in B0 L^2 with Phi_0 = 4 pi):

* :func:`radial_density` -- rod centres per unit volume in cylindrical shells
  around the z axis (paper Figs. 3, 7, 9);
* :func:`bz_profile` -- B_z of the rod currents only on a plane z = const,
  averaged over azimuth (Figs. 4, 10), through the term-9 kernel
  :func:`selfas_graph.kernels.currents.rod_current_field`;
* :func:`flux_through_disc` -- the flux of that B_z through discs of radius R
  centred on the z axis, in units of Phi_0 or of an external dipole's flux
  (Figs. 5, 11); :func:`disc_flux` is its radial quadrature on its own;
* :func:`timeline` -- rods in filaments and total current over time, and the
  short-circuit time (first SHORT_CIRCUIT event).

Layout (docs/model.md 'Rods'): rod ``i`` has tip a at row ``2 i`` and tip b at row
``2 i + 1`` of ``position``; its current is positive from tip a to tip b.

Accuracy of the field diagnostics
---------------------------------
Two approximations, each with its own knob:

* Azimuthal average (``n_phi``): the trapezoid rule on ``n_phi`` equally spaced
  angles. It is exact for azimuthal harmonics below ``n_phi`` and converges
  geometrically for sources away from the sampling circle, but a rod that lies in
  or crosses the plane makes a peak of width ~ the wire radius w, which the
  samples must resolve. The default (``n_phi=None``) therefore spaces the samples
  at most one wire radius apart on the largest circle (at least 64 of them).
  Measured on the last frame of ``scenarios/quick.toml`` at t = 2 (300 rods, 45 in
  filaments, w = 0.03, r up to 7), worst plane z = 0, against n_phi = 4096:
  n_phi = 64 is off by 64 % of max |B_z| and 15 % of max |flux|, 256 by 7 % and
  0.3 %, 1024 by 1e-4 and 1e-4; the automatic choice there is 1472.
* Radial quadrature of the flux (``n_r``, ``dr_max``): composite Gauss-Legendre
  with ``n_r`` nodes on panels no wider than ``dr_max``, between consecutive
  requested radii. It is exact when ``r B_z(r)`` is a polynomial of degree
  ``<= 2 n_r - 1`` on each panel (a uniform field gives ``pi R^2 B`` to round-off).
  With the defaults (8 nodes per panel of at most 0.25 L) the flux of a ring of
  128 unit rods agrees with the Stokes line integral of its exact vector potential
  to rounding (<= 4e-15 relative) for discs inside the ring, wider than it, or on
  planes 1 L away, and to 2e-12 for a disc in the ring's plane whose edge is 0.2 L
  from the wire (``tests/unit/test_diagnostics.py``, azimuthal mean made exact there);
  on the quick.toml frame above, refining to 16 nodes per 0.05 L changes the flux
  by 1e-4 of its maximum, which is the rods near the plane, not smooth curvature.
"""

from __future__ import annotations

import dataclasses
import operator

import numpy as np

from ..kernels.currents import rod_current_field
from ..kernels.lorentz import gauss_legendre_01
from ..model.events import SHORT_CIRCUIT

__all__ = [
    "Timeline",
    "auto_n_phi",
    "bz_profile",
    "disc_flux",
    "flux_through_disc",
    "flux_through_rim",
    "radial_density",
    "rod_centres",
    "timeline",
]

#: magnetic flux quantum in reduced units, Phi_0 = 4 pi B0 L^2 (docs/model.md 'Reduced units')
PHI_0 = 4.0 * np.pi

#: fewest azimuthal samples of the automatic ``n_phi`` (see the module docstring)
MIN_N_PHI = 64
#: sample spacing of the automatic ``n_phi`` when the wire radius is zero: the wire
#: radius of the paper's rods, D / 2 = 0.03 L
DEFAULT_ARC_SPACING = 0.03
#: field points per call of the kernel, to bound the temporaries (2^20 points: 24 MB)
_POINTS_PER_CALL = 1 << 20


# --------------------------------------------------------------------------- validation
def _positions(position) -> np.ndarray:
    """Tip positions as a C-contiguous (n_tips, 3) float64 array with n_tips even."""
    position = np.ascontiguousarray(position, dtype=np.float64)
    if position.ndim != 2 or position.shape[1] != 3 or position.shape[0] % 2:
        raise ValueError(f"position must have shape (n_tips, 3) with n_tips = 2 n_rods, got {position.shape}")
    return position


def _radii(r, name) -> np.ndarray:
    r = np.ascontiguousarray(r, dtype=np.float64)
    if r.ndim != 1:
        raise ValueError(f"{name} must be one-dimensional, got shape {r.shape}")
    if not np.all(np.isfinite(r)) or np.any(r < 0.0):
        raise ValueError(f"{name} must be finite and >= 0")
    return r


def _positive_int(n, name) -> int:
    if isinstance(n, (bool, np.bool_)):
        raise TypeError(f"{name} must be a whole number >= 1, got {n!r}")
    try:
        n = operator.index(n)
    except TypeError:
        raise TypeError(f"{name} must be a whole number >= 1, got {n!r}") from None
    if n < 1:
        raise ValueError(f"{name} must be >= 1, got {n}")
    return n


def _sources(position, active_rod, current, wire_radius):
    """Validate the source arrays of the rod-current field before the numba call.

    numba does not bounds-check, so shapes and indices are checked here.
    ``active_rod=None`` selects the rods with nonzero current.
    """
    position = _positions(position)
    n_rods = position.shape[0] // 2
    current = np.ascontiguousarray(current, dtype=np.float64)
    if current.shape != (n_rods,):
        raise ValueError(f"current must have shape (n_rods,) = ({n_rods},), got {current.shape}")
    if active_rod is None:
        active_rod = np.flatnonzero(current != 0.0)
    elif np.asarray(active_rod).dtype == bool:
        raise TypeError("active_rod holds rod indices, not a mask: pass np.flatnonzero(mask)")
    elif np.asarray(active_rod).size and not np.issubdtype(np.asarray(active_rod).dtype, np.integer):
        raise TypeError(f"active_rod must hold integer rod indices, got dtype {np.asarray(active_rod).dtype}")
    active_rod = np.ascontiguousarray(active_rod, dtype=np.int64)
    if active_rod.ndim != 1:
        raise ValueError(f"active_rod must be one-dimensional, got shape {active_rod.shape}")
    if active_rod.size:
        if active_rod.min() < 0 or active_rod.max() >= n_rods:
            raise ValueError(f"active_rod holds indices outside [0, {n_rods})")
        if np.unique(active_rod).size != active_rod.size:
            raise ValueError("active_rod must hold distinct rod indices")
    wire_radius = float(wire_radius)
    if not np.isfinite(wire_radius) or wire_radius < 0.0:
        raise ValueError(f"wire_radius must be finite and >= 0, got {wire_radius}")
    return position, active_rod, current, wire_radius


def auto_n_phi(r_max, wire_radius) -> int:
    """Azimuthal samples spaced at most one wire radius apart on the circle of radius ``r_max``.

    ``max(MIN_N_PHI, ceil(2 pi r_max / h))`` with ``h = wire_radius``, or
    ``DEFAULT_ARC_SPACING`` when the wire radius is zero; rounded up to a multiple of 64.
    """
    h = float(wire_radius) if wire_radius > 0.0 else DEFAULT_ARC_SPACING
    n = max(MIN_N_PHI, int(np.ceil(2.0 * np.pi * float(r_max) / h)))
    return int(-(-n // 64) * 64)


def _flux_unit(z_mext) -> float:
    """Phi_0 = 4 pi, or the flux 4 pi Z_Mext of an external dipole's monopole."""
    if z_mext is None:
        return PHI_0
    z_mext = float(z_mext)
    if not np.isfinite(z_mext) or z_mext == 0.0:
        raise ValueError(f"z_mext must be finite and nonzero, got {z_mext}")
    return PHI_0 * abs(z_mext)


# --------------------------------------------------------------------------- density
def rod_centres(position) -> np.ndarray:
    """Rod centres ``(x_a + x_b) / 2``.

    Parameters
    ----------
    position : (n_tips, 3) float64
        Tip positions, rod ``i`` at rows ``2 i`` and ``2 i + 1``.

    Returns
    -------
    (n_rods, 3) float64
    """
    position = _positions(position)
    return 0.5 * (position[0::2] + position[1::2])


def radial_density(centre, r_max, n_bins, z_range, mask=None):
    """Rods per unit volume in cylindrical shells around the z axis (docs/model.md 'Figure diagnostics').

    A rod counts in the shell ``r_k <= rho < r_{k+1}`` (``rho`` the distance of its
    centre to the z axis) when its centre has ``z_lo <= z <= z_hi``; the count is
    divided by the shell's volume ``pi (r_{k+1}^2 - r_k^2) (z_hi - z_lo)``. This is
    the density averaged over z in ``z_range`` and over azimuth (paper Figs. 3, 7, 9).

    Parameters
    ----------
    centre : (n, 3) float64
        Rod centres (:func:`rod_centres`).
    r_max : float
        Outer radius of the last shell, > 0.
    n_bins : int
        Number of shells of equal width ``r_max / n_bins``.
    z_range : (float, float)
        ``(z_lo, z_hi)`` with ``z_hi > z_lo``: the slab averaged over.
    mask : (n,) bool, optional
        Count only these rods (e.g. ``role == FILAMENT``, or the largest structure).

    Returns
    -------
    r_edges : (n_bins + 1,) float64
        Shell edges, ``0 .. r_max``.
    density : (n_bins,) float64
        Rods per unit volume (units L^-3) in each shell.
    """
    centre = np.asarray(centre, dtype=np.float64)
    if centre.ndim != 2 or centre.shape[1] != 3:
        raise ValueError(f"centre must have shape (n, 3), got {centre.shape}")
    r_max = float(r_max)
    if not np.isfinite(r_max) or r_max <= 0.0:
        raise ValueError(f"r_max must be finite and > 0, got {r_max}")
    n_bins = _positive_int(n_bins, "n_bins")
    z_lo, z_hi = (float(z) for z in z_range)
    if not (np.isfinite(z_lo) and np.isfinite(z_hi) and z_hi > z_lo):
        raise ValueError(f"z_range must be (z_lo, z_hi) with z_hi > z_lo, got {tuple(z_range)}")
    keep = (centre[:, 2] >= z_lo) & (centre[:, 2] <= z_hi)
    if mask is not None:
        mask = np.asarray(mask, dtype=bool)
        if mask.shape != (centre.shape[0],):
            raise ValueError(f"mask must have shape ({centre.shape[0]},), got {mask.shape}")
        keep &= mask
    rho = np.hypot(centre[keep, 0], centre[keep, 1])
    r_edges = np.linspace(0.0, r_max, n_bins + 1)
    # np.histogram closes the last bin on the right; keep shells half-open instead
    count = np.bincount(
        np.floor(rho[rho < r_max] / r_max * n_bins).astype(np.int64).clip(0, n_bins - 1), minlength=n_bins
    )
    volume = np.pi * (r_edges[1:] ** 2 - r_edges[:-1] ** 2) * (z_hi - z_lo)
    return r_edges, count / volume


# --------------------------------------------------------------------------- fields
def bz_profile(points_r, z_plane, position, active_rod, current, wire_radius, n_phi=None):
    """B_z of the rod currents on the plane ``z = z_plane``, averaged over azimuth.

    ``Bz(r) = (1 / n_phi) sum_k B_z(r cos phi_k, r sin phi_k, z_plane)`` with
    ``phi_k = 2 pi (k + 1/2) / n_phi``: the trapezoid rule for the azimuthal mean
    (see the module docstring for its accuracy). The field is the regularised
    Biot-Savart field of the rod currents only (docs/model.md 'Term 9', wire radius w),
    from :func:`~selfas_graph.kernels.currents.rod_current_field`; no external field,
    plasma filament or external object is included (paper Figs. 4, 10).

    Parameters
    ----------
    points_r : (m,) float64
        Radii >= 0 (units L); ``r = 0`` is the axis.
    z_plane : float
        Height of the plane.
    position : (n_tips, 3) float64
        Tip positions.
    active_rod : (n_active,) int64 or None
        Distinct rods that carry current; ``None``: the rods with ``current != 0``.
    current : (n_rods,) float64
        Rod currents J (units J0), positive from tip a to tip b.
    wire_radius : float
        w = D / 2 (docs/model.md 'Term 9'); 0 gives the bare line-current field.
    n_phi : int, optional
        Number of azimuthal samples; default :func:`auto_n_phi` of the largest radius
        (samples at most one wire radius apart, see the module docstring).

    Returns
    -------
    (m,) float64
        Azimuthally averaged B_z (units B0).
    """
    points_r = _radii(points_r, "points_r")
    if n_phi is not None:
        n_phi = _positive_int(n_phi, "n_phi")
    z_plane = float(z_plane)
    if not np.isfinite(z_plane):
        raise ValueError(f"z_plane must be finite, got {z_plane}")
    position, active_rod, current, wire_radius = _sources(position, active_rod, current, wire_radius)
    m = points_r.shape[0]
    if m == 0 or active_rod.size == 0:
        return np.zeros(m)
    if n_phi is None:
        n_phi = auto_n_phi(points_r.max(), wire_radius)
    phi = 2.0 * np.pi * (np.arange(n_phi) + 0.5) / n_phi
    cos_phi, sin_phi = np.cos(phi), np.sin(phi)
    bz = np.empty(m)
    block = max(1, _POINTS_PER_CALL // n_phi)
    for start in range(0, m, block):
        r = points_r[start : start + block]
        point = np.empty((r.shape[0], n_phi, 3))
        point[:, :, 0] = r[:, None] * cos_phi[None, :]
        point[:, :, 1] = r[:, None] * sin_phi[None, :]
        point[:, :, 2] = z_plane
        point = point.reshape(-1, 3)
        out = np.empty_like(point)
        exclude = np.full(point.shape[0], -1, dtype=np.int64)
        rod_current_field(point, exclude, position, active_rod, current, wire_radius, out)
        bz[start : start + block] = out[:, 2].reshape(r.shape[0], n_phi).mean(axis=1)
    return bz


def disc_flux(r_values, bz_of_r, n_r=8, dr_max=0.25):
    """Flux ``int_0^R 2 pi r Bz(r) dr`` of an axisymmetric B_z through discs of radius R.

    Composite Gauss-Legendre quadrature: the interval ``[0, max R]`` is cut at every
    requested radius and into panels no wider than ``dr_max``, each with ``n_r``
    nodes, and the panel integrals are summed outward, so every radius costs only
    its own panels. Exact when ``r Bz(r)`` is a polynomial of degree
    ``<= 2 n_r - 1`` on each panel (a uniform field gives ``pi R^2 B``).

    Parameters
    ----------
    r_values : (m,) float64
        Disc radii >= 0, any order (repeats allowed).
    bz_of_r : callable
        ``bz_of_r(r)`` maps a (k,) array of radii to the (k,) azimuthally averaged
        B_z there; called once with all quadrature nodes.
    n_r : int
        Gauss-Legendre nodes per panel.
    dr_max : float
        Largest panel width (units L), > 0.

    Returns
    -------
    (m,) float64
        Flux through each disc (units B0 L^2, not divided by Phi_0).
    """
    r_values = _radii(r_values, "r_values")
    n_r = _positive_int(n_r, "n_r")
    dr_max = float(dr_max)
    if not np.isfinite(dr_max) or dr_max <= 0.0:
        raise ValueError(f"dr_max must be finite and > 0, got {dr_max}")
    if r_values.size == 0:
        return np.zeros(0)
    breaks = np.unique(np.concatenate([[0.0], r_values]))
    # panel edges: each interval between requested radii split into equal panels <= dr_max
    edges = [breaks[:1]]
    for lo, hi in zip(breaks[:-1], breaks[1:]):
        k = max(1, int(np.ceil((hi - lo) / dr_max)))
        edges.append(np.linspace(lo, hi, k + 1)[1:])
    edges = np.concatenate(edges)
    if edges.size == 1:  # all radii are zero
        return np.zeros(r_values.shape[0])
    t, w = gauss_legendre_01(n_r)
    lo, width = edges[:-1], np.diff(edges)
    nodes = lo[:, None] + width[:, None] * t[None, :]
    bz = np.asarray(bz_of_r(nodes.ravel()), dtype=np.float64)
    if bz.shape != (nodes.size,):
        raise ValueError(f"bz_of_r returned shape {bz.shape} for {nodes.size} radii")
    panel = width * ((2.0 * np.pi * nodes * bz.reshape(nodes.shape)) @ w)
    cumulative = np.concatenate([[0.0], np.cumsum(panel)])
    return cumulative[np.searchsorted(edges, r_values)]


def flux_through_disc(
    r_values, z_plane, position, active_rod, current, wire_radius, n_phi=None, n_r=8, dr_max=0.25, z_mext=None
):
    """Magnetic flux of the rod currents' B_z through discs on the plane ``z = z_plane``.

    ``Phi(R) = int_0^R 2 pi r Bz(r) dr`` with ``Bz`` from :func:`bz_profile` and the
    radial quadrature of :func:`disc_flux` (docs/model.md 'Figure diagnostics', paper Figs. 5, 11).
    The discs are centred on the z axis with normal +z.

    Parameters
    ----------
    r_values : (m,) float64
        Disc radii >= 0 (units L).
    z_plane : float
        Height of the plane.
    position, active_rod, current, wire_radius, n_phi
        As in :func:`bz_profile`; the automatic ``n_phi`` is chosen once, for the
        largest disc, so that every radius uses the same samples.
    n_r, dr_max
        Radial quadrature, as in :func:`disc_flux`.
    z_mext : float, optional
        Magnetic charge Z_Mext of an external dipole's monopole (case (ii), docs/model.md
        'Term 11'): the flux is then given in units of its flux ``4 pi |Z_Mext|``
        (paper Fig. 11) instead of Phi_0 = 4 pi (Fig. 5).

    Returns
    -------
    (m,) float64
        Flux through each disc in units of Phi_0 (or of ``4 pi |Z_Mext|``).
    """
    unit = _flux_unit(z_mext)
    r_values = _radii(r_values, "r_values")
    position, active_rod, current, wire_radius = _sources(position, active_rod, current, wire_radius)
    if n_phi is None and r_values.size:
        n_phi = auto_n_phi(r_values.max(), wire_radius)

    def bz_of_r(r):
        return bz_profile(r, z_plane, position, active_rod, current, wire_radius, n_phi=n_phi)

    return disc_flux(r_values, bz_of_r, n_r=n_r, dr_max=dr_max) / unit


def flux_through_rim(radius, z_plane, position, active_rod, current, wire_radius, n_phi=None, z_mext=None) -> float:
    """Flux of the rod currents' B through the disc of ``radius`` on ``z = z_plane`` (normal +z),
    by Stokes' theorem: the loop integral of their vector potential along the disc's rim.

    A straight segment A -> B of length L carrying J has ``A(x) = J s_hat ln((|a| + |b| + L) /
    (|a| + |b| - L))`` (a = x - A, b = x - B; Gaussian units with c absorbed in J0, so that an
    infinite wire gives B = 2 J / rho as term 9's law does), and ``Phi = oint A . dl``, summed
    with the periodic trapezoid rule over ``n_phi`` points of the rim (default :func:`auto_n_phi`:
    at most one wire radius apart). This is the bare line current's flux: it differs from
    :func:`flux_through_disc`, the area integral of term 9's regularised field, by terms of order
    (w / rho)^2 from the wires near the plane, 1e-4 of the flux late in Fig. 2
    (``tests/unit/test_diagnostics.py``), and costs one loop over the rim instead of the disc's area
    (0.1-0.8 s against 4-6 s for 600-1000 current-carrying rods). Where a rod crosses the rim, the
    logarithm's denominator is kept at least ``w^2 (1/|a| + 1/|b|) / 2`` (the distance to the
    wire's line held at w), so that the result stays finite.

    Parameters
    ----------
    radius : float
        Disc radius R > 0 (units L).
    z_plane : float
    position, active_rod, current, wire_radius
        As in :func:`bz_profile`.
    n_phi : int, optional
    z_mext : float, optional
        As in :func:`flux_through_disc`.

    Returns
    -------
    float
        Flux in units of Phi_0 (or of ``4 pi |Z_Mext|``).
    """
    unit = _flux_unit(z_mext)
    radius = float(radius)
    if not (np.isfinite(radius) and radius > 0.0):
        raise ValueError(f"radius must be a positive length, got {radius}")
    position, active_rod, current, wire_radius = _sources(position, active_rod, current, wire_radius)
    if active_rod.size == 0:
        return 0.0
    n_phi = auto_n_phi(radius, wire_radius) if n_phi is None else _positive_int(n_phi, "n_phi")
    phi = 2.0 * np.pi * (np.arange(n_phi) + 0.5) / n_phi
    rim = np.stack([radius * np.cos(phi), radius * np.sin(phi), np.full(n_phi, float(z_plane))], axis=1)
    dl = np.stack([-np.sin(phi), np.cos(phi), np.zeros(n_phi)], axis=1) * (2.0 * np.pi * radius / n_phi)
    a_end, b_end = position[2 * active_rod], position[2 * active_rod + 1]
    j = current[active_rod]
    seg = b_end - a_end
    length = np.linalg.norm(seg, axis=1)
    keep = length > 0.0
    total = 0.0
    w2 = float(wire_radius) ** 2
    for k in range(0, active_rod.size, 256):
        sl = slice(k, k + 256)
        ra = np.linalg.norm(rim[None] - a_end[sl, None], axis=2)
        rb = np.linalg.norm(rim[None] - b_end[sl, None], axis=2)
        lk = length[sl, None]
        den = np.maximum(ra + rb - lk, 0.5 * w2 * (1.0 / np.maximum(ra, 1e-300) + 1.0 / np.maximum(rb, 1e-300)))
        with np.errstate(divide="ignore", invalid="ignore"):
            log = np.where(keep[sl, None], np.log((ra + rb + lk) / den), 0.0)
            along = (seg[sl] / np.where(keep[sl], length[sl], 1.0)[:, None]) @ dl.T
        total += float(np.sum(j[sl, None] * log * along))
    return total / unit


# --------------------------------------------------------------------------- timeline
@dataclasses.dataclass(frozen=True)
class Timeline:
    """Rods in filaments and total current over time, with the short-circuit time.

    Attributes
    ----------
    time : (n,) float64
        Frame times (units t0).
    n_filament : (n,) float64
        Rods in current-carrying filaments at each frame.
    total_current : (n,) float64 or None
        Current through the circuit at each frame (units J0), None without a circuit.
    short_circuit_time : float or None
        Time of the first SHORT_CIRCUIT event, None if the circuit never closed.
    """

    time: np.ndarray
    n_filament: np.ndarray
    total_current: np.ndarray | None
    short_circuit_time: float | None


def timeline(time, n_filament, total_current=None, events=None) -> Timeline:
    """Collect a run's filament statistics over time (docs/model.md 'Figure diagnostics').

    Parameters
    ----------
    time : (n,) float64
        Frame times, e.g. the time array of the ``rods/filament`` observable.
    n_filament : (n,) float64
        Rods in filaments at each frame (observable ``rods/filament``).
    total_current : (n,) float64, optional
        Total current at each frame (observable ``total_current``).
    events : structured array with fields ``time`` and ``kind``, optional
        The run's event records (``events.EVENT_DTYPE``); the first
        ``SHORT_CIRCUIT`` gives the short-circuit time.

    Returns
    -------
    Timeline
    """
    time = np.asarray(time, dtype=np.float64)
    n_filament = np.asarray(n_filament, dtype=np.float64)
    if time.ndim != 1 or n_filament.shape != time.shape:
        raise ValueError(f"time and n_filament must be 1-D of equal length, got {time.shape}, {n_filament.shape}")
    if total_current is not None:
        total_current = np.asarray(total_current, dtype=np.float64)
        if total_current.shape != time.shape:
            raise ValueError(f"total_current must have shape {time.shape}, got {total_current.shape}")
    t_sc = None
    if events is not None and len(events):
        sc = np.asarray(events["kind"]) == SHORT_CIRCUIT
        if sc.any():
            t_sc = float(np.asarray(events["time"], dtype=np.float64)[sc].min())
    return Timeline(time=time, n_filament=n_filament, total_current=total_current, short_circuit_time=t_sc)
