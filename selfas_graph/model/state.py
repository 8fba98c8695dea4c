"""The state of the rods (struct of arrays); its random initial placement is :mod:`.placement`."""

from __future__ import annotations

import numbers
from dataclasses import dataclass
from typing import Optional

import numpy as np


class StateError(ValueError):
    """A state that is not a valid set of rods (shapes, non-finite values, tip charges, rod lengths)."""


#: largest |rod length - 1| a given state may have: states made by :meth:`State.from_rods` or
#: :func:`random_state` are exact to round-off, and positions that passed through float32 (an
#: export) are off by about 1e-6; a visibly wrong length (1.01) is refused instead of snapped
BOND_TOLERANCE = 1e-4


@dataclass
class State:
    """Positions and velocities of all tips, and the per-rod constants.

    Rod ``i`` has tip a at row ``2 i`` (magnetic charge ``+q_i``) and tip b at row
    ``2 i + 1`` (``-q_i``); unit tip masses and, unless ``rod_length`` is given,
    unit rod length (docs/model.md 'Rods').

    Attributes
    ----------
    position, velocity : (n_tips, 3) float64
    tip_charge : (n_tips,) float64
        Magnetic charge of each tip.
    rod_charge : (n_rods,) float64
        Electric charge Z_i of each rod.
    step : int
    time : float
    rod_length : (n_rods,) float64 or None
        Length l_i of each rod (units L, the mean length); None: every rod has length 1.
    rod_resistance : (n_rods,) float64 or None
        Resistance R_i of each rod (units R0); None: every rod has R0 = 1.
    """

    position: np.ndarray
    velocity: np.ndarray
    tip_charge: np.ndarray
    rod_charge: np.ndarray
    step: int = 0
    time: float = 0.0
    rod_length: Optional[np.ndarray] = None
    rod_resistance: Optional[np.ndarray] = None

    @property
    def n_tips(self) -> int:
        return self.position.shape[0]

    @property
    def n_rods(self) -> int:
        return self.position.shape[0] // 2

    def centre(self) -> np.ndarray:
        """Rod centres, (n_rods, 3)."""
        return 0.5 * (self.position[0::2] + self.position[1::2])

    def copy(self) -> "State":
        return State(
            self.position.copy(),
            self.velocity.copy(),
            self.tip_charge.copy(),
            self.rod_charge.copy(),
            self.step,
            self.time,
            None if self.rod_length is None else self.rod_length.copy(),
            None if self.rod_resistance is None else self.rod_resistance.copy(),
        )

    def state_dict(self) -> dict:
        """The state as a flat dict of copies (the checkpoint's keys): positions, velocities, charges,
        step and time, and the rod lengths and resistances when given."""
        d = {
            "position": self.position.copy(),
            "velocity": self.velocity.copy(),
            "tip_charge": self.tip_charge.copy(),
            "rod_charge": self.rod_charge.copy(),
            "step": self.step,
            "time": self.time,
        }
        for name in ("rod_length", "rod_resistance"):
            if getattr(self, name) is not None:
                d[name] = getattr(self, name).copy()
        return d

    @classmethod
    def from_state_dict(cls, d: dict) -> "State":
        """The state :meth:`state_dict` returned (``d`` may hold other keys too), in copies of its arrays."""
        return cls(
            np.array(d["position"]),
            np.array(d["velocity"]),
            np.array(d["tip_charge"]),
            np.array(d["rod_charge"]),
            int(d["step"]),
            float(d["time"]),
            *(np.array(d[k]) if k in d else None for k in ("rod_length", "rod_resistance")),
        )

    def bond_length(self) -> np.ndarray:
        """The length each bond should have: ``rod_length``, or an empty array for unit rods.

        The form the rigid-bond kernels take (``selfas_graph/kernels/rigid.py``).
        """
        return _UNIT_LENGTH if self.rod_length is None else self.rod_length

    def checked(self) -> "State":
        """A validated copy in float64 arrays (the caller's arrays are never written to).

        Raises
        ------
        StateError
            Wrong shapes, non-finite values, a rod whose tips do not carry +q and -q
            (docs/model.md 'Rods'), a rod length off 1 by more than ``BOND_TOLERANCE``, or a rod
            given twice (its tips on another's).
        """

        def arr(name, value, shape):
            try:
                a = np.array(value, dtype=np.float64)
            except (TypeError, ValueError):
                raise StateError(f"State.{name}: expected an array of numbers of shape {shape}") from None
            if a.shape != shape:
                raise StateError(f"State.{name}: shape {a.shape}, expected {shape} (rod i has tips 2i and 2i+1)")
            if not np.isfinite(a).all():
                raise StateError(
                    f"State.{name}: non-finite values (NaN or inf) at rows "
                    f"{np.flatnonzero(~np.isfinite(a.reshape(len(a), -1)).all(axis=1))[:5].tolist()}"
                )
            return a

        x = np.asarray(self.position)
        if x.ndim != 2 or x.shape[1:] != (3,) or x.shape[0] < 2 or x.shape[0] % 2:
            raise StateError(
                f"State.position: shape {x.shape}, expected (2 n_rods, 3) with n_rods >= 1 (rod i has tips 2i and 2i+1)"
            )
        n = x.shape[0] // 2
        position = arr("position", self.position, (2 * n, 3))
        velocity = arr("velocity", self.velocity, (2 * n, 3))
        tip_charge = arr("tip_charge", self.tip_charge, (2 * n,))
        rod_charge = arr("rod_charge", self.rod_charge, (n,))
        qa, qb = tip_charge[0::2], tip_charge[1::2]
        bad = np.flatnonzero(qa != -qb)
        if len(bad):
            i = int(bad[0])
            raise StateError(
                f"State.tip_charge: rod {i} has tip charges {qa[i]:g} and {qb[i]:g}; rod i carries +q_i "
                f"on tip 2i and -q_i on tip 2i+1 (docs/model.md 'Rods'; State.from_rods builds "
                f"them)" + (f", {len(bad) - 1} more rods too" if len(bad) > 1 else "")
            )
        extra = {}
        for name in ("rod_length", "rod_resistance"):
            value = getattr(self, name)
            if value is not None:
                extra[name] = arr(name, value, (n,))
                if (extra[name] <= 0).any():
                    i = int(np.flatnonzero(extra[name] <= 0)[0])
                    raise StateError(f"State.{name}: rod {i} has {extra[name][i]:g}; every value must be > 0")
        target = extra.get("rod_length", np.ones(n))
        length = np.linalg.norm(position[1::2] - position[0::2], axis=1)
        off = np.flatnonzero(np.abs(length - target) > BOND_TOLERANCE * target)
        if len(off):
            i = int(off[np.argmax(np.abs(length[off] - target[off]))])
            raise StateError(
                f"State.position: rod {i} has length {length[i]:.6g}, not its "
                f"{'rod_length ' if 'rod_length' in extra else 'length '}{target[i]:.6g} (to "
                f"{BOND_TOLERANCE:g} relative), {len(off)} rods are off; build the state with "
                f"State.from_rods (centres and axes)"
            )
        _refuse_twice_given(position)
        step = self.step
        whole = isinstance(step, numbers.Integral) or (isinstance(step, numbers.Real) and float(step).is_integer())
        if isinstance(step, (bool, np.bool_)) or not whole:
            raise StateError(f"State.step: a whole number of steps >= 0, got {step!r}")
        step, t = int(step), float(self.time)
        if step < 0 or not np.isfinite(t):
            raise StateError(f"State: step {step} and time {t} must be a step >= 0 and a finite time")
        return State(position, velocity, tip_charge, rod_charge, step, t, **extra)

    @classmethod
    def from_rods(cls, centre, axis, magnetic_charge, electric_charge, velocity=None, length=None, resistance=None):
        """Build a state from rod centres and axes ``s = x_b - x_a`` (normalised here).

        Parameters
        ----------
        centre, axis : (n_rods, 3) float64
        magnetic_charge, electric_charge : (n_rods,) float64, or one value for every rod
        velocity : (n_tips, 3) float64, optional (default zero)
        length : (n_rods,) float64 or one value, optional
            Rod lengths (default: every rod has length 1, ``rod_length`` None).
        resistance : (n_rods,) float64 or one value, optional
            Rod resistances (default: R0 = 1, ``rod_resistance`` None).
        """
        centre = np.asarray(centre, dtype=np.float64).reshape(-1, 3)
        n = centre.shape[0]
        axis = np.asarray(axis, dtype=np.float64)
        if axis.size != 3 * n:
            raise ValueError(f"axis must hold one 3-vector per rod ({n}), got shape {axis.shape}")
        axis = axis.reshape(n, 3)
        norm = np.linalg.norm(axis, axis=1)
        if not (np.isfinite(norm).all() and (norm > 0).all()):
            raise ValueError(
                f"axis of rod {int(np.flatnonzero(~(norm > 0) | ~np.isfinite(norm))[0])}: zero or not finite"
            )
        axis = axis / norm[:, None]
        position = np.empty((2 * n, 3))
        if length is None:
            half = 0.5 * axis
        else:
            length = _per_rod(length, n, "length")
            if not (np.isfinite(length).all() and (length > 0).all()):
                raise ValueError("rod lengths must be finite and > 0")
            half = (0.5 * length)[:, None] * axis
        position[0::2] = centre - half
        position[1::2] = centre + half
        if resistance is not None:
            resistance = _per_rod(resistance, n, "resistance")
            if not (np.isfinite(resistance).all() and (resistance > 0).all()):
                raise ValueError("rod resistances must be finite and > 0")
        q = _per_rod(magnetic_charge, n, "magnetic_charge")
        tip_charge = np.empty(2 * n)
        tip_charge[0::2] = q
        tip_charge[1::2] = -q
        v = np.zeros_like(position) if velocity is None else np.array(velocity, dtype=np.float64)
        if v.size != 6 * n:
            raise ValueError(f"velocity must hold one 3-vector per tip ({2 * n}), got shape {v.shape}")
        v = v.reshape(2 * n, 3)
        apart = np.einsum("ij,ij->i", v[1::2] - v[0::2], axis)
        if (np.abs(apart) > 1e-9 * max(1.0, float(np.abs(v).max(initial=0.0)))).any():
            i = int(np.argmax(np.abs(apart)))
            raise ValueError(
                f"velocity: the tips of rod {i} move apart along its axis at {apart[i]:.3g}; a rigid rod's may not "
                f"(give both tips v, or v -+ w x s/2 for a spin w): the first step would take it away unaccounted"
            )
        return cls(
            position,
            v,
            tip_charge,
            _per_rod(electric_charge, n, "electric_charge"),
            rod_length=length,
            rod_resistance=resistance,
        )


def _refuse_twice_given(position: np.ndarray) -> None:
    """Refuse a rod given twice (its two tips on another rod's two tips, either way round): the
    regularised laws give a pair at zero distance no force (docs/model.md 'Term 1', 'Term 6'), and
    every other force on the two is the same, so they would move as one for the whole run. Tips of
    two rods at one point, or rods crossing, are taken: the rods' other forces part them."""
    a, b = position[0::2], position[1::2]
    _, point = np.unique(position, axis=0, return_inverse=True)  # one number per distinct point
    ends = np.sort(point.reshape(-1, 2), axis=1)  # a rod's two points, either way round
    _, first, count = np.unique(ends, axis=0, return_index=True, return_counts=True)
    if (count > 1).any():
        k = int(first[np.flatnonzero(count > 1)[0]])
        same = np.flatnonzero((ends == ends[k]).all(axis=1))
        raise StateError(
            f"State.position: rods {int(same[0])} and {int(same[1])} have their tips at the same two points "
            f"{a[k].tolist()} and {b[k].tolist()}; at zero distance the forces between them have no direction, "
            f"so the two would move as one: a rod given twice?"
        )


def _per_rod(value, n: int, name: str) -> np.ndarray:
    """A fresh (n,) float64 array of one value per rod; a single value is given to every rod."""
    value = np.asarray(value, dtype=np.float64)
    if value.ndim == 0:
        return np.full(n, float(value))
    if value.size != n:
        raise ValueError(f"{name} must hold one value per rod ({n}) or one for all, got shape {value.shape}")
    return value.reshape(n).copy()


#: the rigid-bond kernels' sign for "every rod has length 1"
_UNIT_LENGTH = np.zeros(0)
_UNIT_LENGTH.setflags(write=False)
