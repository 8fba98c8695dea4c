"""The random initial placement of the rods (docs/model.md 'Assumptions and project choices'): their
charges, lengths and resistances drawn from the scene's laws, then the rods placed one by one."""

from __future__ import annotations

import numpy as np

from .params import ChargeDistribution, Parameters
from .state import State

__all__ = ["PlacementError", "draw_charges", "high_count", "random_state"]


class PlacementError(ValueError):
    """The initial placement could not be made (too dense, or the box too small)."""


def high_count(dist, n: int) -> int:
    """How many of ``n`` rods a ``two_level`` law gives the high value: ``round(high_fraction * n)``."""
    return int(round(dist.high_fraction * n))


def draw_charges(dist: ChargeDistribution, n: int, rng, magnetic=None) -> np.ndarray:
    """Per-rod values (charges, lengths, resistances) from a distribution (docs/model.md 'Rods').

    ``two_level`` gives exactly ``round(high_fraction * n)`` rods the high value,
    at random positions in the rod list.
    """
    if dist.distribution == "constant":
        return np.full(n, dist.value)
    if dist.distribution == "uniform":
        return rng.uniform(dist.low, dist.high, n)
    if dist.distribution == "two_level":
        out = np.full(n, dist.low)
        out[rng.permutation(n)[: high_count(dist, n)]] = dist.high
        return out
    if dist.distribution == "magnetic":
        return np.array(magnetic, dtype=np.float64)
    raise ValueError(f"unknown charge distribution {dist.distribution!r}")


class _TipGrid:
    """The accepted tips on a grid of cells of ``min_tip_distance``: whether a point keeps that distance
    from all of them (the 27 cells about it)."""

    def __init__(self, dmin, n_rods):
        self.dmin, self.cell = dmin, max(dmin, 1e-9)
        self.cells: dict[tuple, list] = {}
        self.tips = np.empty((2 * n_rods, 3))

    def clear(self, p) -> bool:
        if self.dmin <= 0.0:
            return True
        c = np.floor(p / self.cell).astype(np.int64)
        for dx in (-1, 0, 1):
            for dy in (-1, 0, 1):
                for dz in (-1, 0, 1):
                    for t in self.cells.get((c[0] + dx, c[1] + dy, c[2] + dz), ()):
                        d = self.tips[t] - p
                        if d @ d < self.dmin * self.dmin:
                            return False
        return True

    def add(self, k, p):
        self.tips[k] = p
        self.cells.setdefault(tuple(np.floor(p / self.cell).astype(np.int64)), []).append(k)


def _place_rod(rng, lo, hi, attempts, length, grid, i):
    """``(centre, axis)`` of rod ``i`` (of ``length``, None: 1) drawn in batches of 64 until both its tips
    lie in the box [lo, hi] and clear of the accepted tips (then added to ``grid``), or None after
    ``attempts`` draws."""
    tries = 0
    while tries < attempts:
        m = min(64, attempts - tries)
        cs = rng.uniform(lo, hi, (m, 3))
        ax = rng.normal(size=(m, 3))
        ax /= np.linalg.norm(ax, axis=1)[:, None]
        for j in range(m):
            tries += 1
            half = 0.5 * ax[j] if length is None else (0.5 * length) * ax[j]
            ta, tb = cs[j] - half, cs[j] + half
            if (ta < lo).any() or (ta > hi).any() or (tb < lo).any() or (tb > hi).any():
                continue
            if grid.clear(ta) and grid.clear(tb):
                grid.add(2 * i, ta)
                grid.add(2 * i + 1, tb)
                return cs[j], ax[j]
    return None


def random_state(params: Parameters, rng=None) -> State:
    """Random initial state of docs/model.md 'Assumptions and project choices', all from ``params.scenario.seed``.

    Charges are drawn first, then the rods one by one: centre uniform in the box,
    axis uniform on the sphere, accepted when both tips lie in the box and no tip
    is closer than ``min_tip_distance`` to a tip of an accepted rod. Velocities zero.

    Raises
    ------
    PlacementError
        If a rod cannot be placed in ``placement.max_attempts`` draws.
    """
    rng = np.random.default_rng(params.scenario.seed) if rng is None else rng
    n = params.rods.count
    q = draw_charges(params.rods.magnetic_charge, n, rng)
    z = draw_charges(params.rods.electric_charge, n, rng, magnetic=q)
    # lengths and resistances are drawn only when the scene sets them (a constant draws
    # nothing), so scenes without them draw, and place, exactly as before
    ell = None if params.rods.length is None else draw_charges(params.rods.length, n, rng)
    res = None
    if params.rods.resistance is not None:
        res = draw_charges(params.rods.resistance, n, rng)
        if params.rods.resistance.per_length and ell is not None:
            res = res * ell
    box = np.array(params.placement.box, dtype=np.float64)
    lo, hi = box[:, 0], box[:, 1]
    dmin, attempts = params.min_tip_distance, params.placement.max_attempts
    grid = _TipGrid(dmin, n)
    centre = np.empty((n, 3))
    axis = np.empty((n, 3))
    for i in range(n):
        placed = _place_rod(rng, lo, hi, attempts, None if ell is None else ell[i], grid, i)
        if placed is None and i == 0:  # no other rod in the way: the box leaves no room for a random orientation
            raise PlacementError(
                f"placed no rod in {attempts} draws (placement.max_attempts): both tips of a "
                f"rod of length {1.0 if ell is None else ell[0]:g} in a random orientation seldom fall in the box "
                f"{params.placement.box}; "
                f"make placement.box larger"
            )
        if placed is None:
            raise PlacementError(
                f"placed only {i} of {n} rods: no free spot found in {attempts} draws "
                f"(placement.max_attempts); use fewer rods (rods.count), a larger box (placement.box) or a smaller "
                f"placement.min_tip_distance (now {dmin:g})"
            )
        centre[i], axis[i] = placed
    return State.from_rods(centre, axis, q, z, length=ell, resistance=res)
