"""Checks of the arrays the topology and the circuit take: counts, index arrays, potentials and
resistances, with errors that name the argument and what it should hold."""

from __future__ import annotations

import math
import numbers
import operator

import numpy as np

#: the largest ratio of the circuit's largest resistance to its smallest: the currents of the
#: quick scene's first short circuit (12 rods in series) came out right to 1e-8 with contacts of
#: 1e-12 to 1e8 R0, 0.5 % off at 1e12 and wrong by orders of magnitude at 1e16 and 1e-16 (direct
#: and CG solves alike); at 1e8 the count of rods in series (a 1e-9 relative test) already failed
MAX_RESISTANCE_SPREAD = 1e6


def is_whole_number(value) -> bool:
    """Whether ``value`` is an integer (Python's or numpy's), a boolean not counting as one."""
    return isinstance(value, numbers.Integral) and not isinstance(value, (bool, np.bool_))


def as_decimal(value) -> float:
    """A real number as a float: a float32 (or narrower) number stands for the decimal it prints as, not
    its binary value widened (np.float32(1e-3) is 0.001, not 0.0010000000474974513), and an integer too
    large for a float is inf. TypeError for anything but a real number (a bool, a string, a list)."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):  # numpy's bool is not Real
        raise TypeError(f"expected a number, got {value!r}")
    try:
        return float(str(value)) if isinstance(value, np.floating) and value.itemsize < 8 else float(value)
    except OverflowError:
        return math.inf


def _as_count(value, name: str) -> int:
    """Coerce a non-negative integer count, or raise ValueError naming ``name``."""
    try:
        n = int(np.asarray(value).item()) if not isinstance(value, int) else value
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a non-negative integer, got {value!r}") from None
    if isinstance(value, (float, np.floating)) and float(value) != n:
        raise ValueError(f"{name} must be an integer, got {value!r}")
    if n < 0:
        raise ValueError(f"{name} must be non-negative, got {n}")
    return n


def _as_index_array(value, name: str, ndim: int, n_max: int | None) -> np.ndarray:
    """Coerce an integer index array of rank ``ndim`` (``(m,)`` or ``(m, 2)``).

    Raises ValueError naming ``name`` for a wrong shape, non-integer values or an
    index outside ``[0, n_max)`` (when ``n_max`` is given).
    """
    arr = np.asarray(value)
    if arr.size == 0:
        return np.zeros((0,) if ndim == 1 else (0, 2), dtype=np.int64)
    if arr.dtype.kind not in "iu":
        if arr.dtype.kind == "f" and np.all(np.isfinite(arr)) and np.all(arr == np.round(arr)):
            arr = arr.astype(np.int64)
        else:
            raise ValueError(f"{name} must hold integers, got dtype {arr.dtype}")
    arr = arr.astype(np.int64, copy=False)
    if ndim == 1 and arr.ndim != 1:
        raise ValueError(f"{name} must have shape (k,), got {arr.shape}")
    if ndim == 2 and (arr.ndim != 2 or arr.shape[1] != 2):
        raise ValueError(f"{name} must have shape (m, 2), got {arr.shape}")
    if n_max is not None:
        bad = (arr < 0) | (arr >= n_max)
        if bad.any():
            raise ValueError(f"{name} holds tip index {int(arr[bad].flat[0])} outside [0, {n_max})")
    return np.ascontiguousarray(arr)


def _as_potentials(potential, index, name, index_name, what, target) -> np.ndarray:
    """Finite float64 potentials, one per entry of ``index`` (ValueError naming both arrays)."""
    potential = np.asarray(potential, dtype=np.float64).reshape(-1)
    if potential.shape != index.shape:
        raise ValueError(
            f"{name} has shape {potential.shape}, {index_name} has shape {index.shape}: one potential per {what}"
        )
    if not np.all(np.isfinite(potential)):
        bad = np.flatnonzero(~np.isfinite(potential))[0]
        raise ValueError(f"{name} must be finite; {what} {bad} ({target} {index[bad]}) has {potential[bad]}")
    return potential


def _validate(n_tips, tip_contacts, conductor_tip, conductor_potential):
    n_tips = _as_count(n_tips, "n_tips")
    if n_tips % 2:
        raise ValueError(f"n_tips must be even (two tips per rod), got {n_tips}")
    tip_contacts = _as_index_array(tip_contacts, "tip_contacts", 2, n_tips)
    conductor_tip = _as_index_array(conductor_tip, "conductor_tip", 1, n_tips)
    conductor_potential = _as_potentials(
        conductor_potential, conductor_tip, "conductor_potential", "conductor_tip", "conductor contact", "tip"
    )
    return n_tips, tip_contacts, conductor_tip, conductor_potential


#: the range of a nonzero resistance (units R0): its conductance, and J^2 R at currents of order one,
#: stay finite in float64 (1e-310 gave an infinite conductance and NaN potentials without a word)
RESISTANCE_RANGE = (1e-100, 1e100)


def _as_resistance(value, name: str, m: int, allow_zero: bool) -> np.ndarray:
    """Coerce per-edge resistances: a scalar or an ``(m,)`` array of finite values >= 0 (or > 0), each
    nonzero one in :data:`RESISTANCE_RANGE`."""
    arr = np.asarray(value, dtype=np.float64)
    if arr.ndim == 0:
        arr = np.full(m, float(arr))
    if arr.shape != (m,):
        raise ValueError(f"{name} must be a number or have shape ({m},), got shape {arr.shape}")
    bad = ~np.isfinite(arr) | (arr < 0.0) | ((arr == 0.0) if not allow_zero else False)
    if np.any(bad):
        i = int(np.flatnonzero(bad)[0])
        want = ">= 0" if allow_zero else "> 0"
        raise ValueError(f"{name} must be finite and {want}; entry {i} is {arr[i]}")
    lo, hi = RESISTANCE_RANGE
    off = (arr != 0.0) & ((arr < lo) | (arr > hi))
    if np.any(off):
        i = int(np.flatnonzero(off)[0])
        raise ValueError(f"{name} must lie within [{lo:g}, {hi:g}] (units R0); entry {i} is {arr[i]}")
    return np.ascontiguousarray(arr)


def _as_contact_resistance(value) -> float:
    """The one resistance of every contact: 0 (ideal contacts) or a finite number in
    :data:`RESISTANCE_RANGE`."""
    r = float(value)
    if not (math.isfinite(r) and r >= 0.0):
        raise ValueError(f"contact_resistance must be finite and >= 0, got {value!r}")
    lo, hi = RESISTANCE_RANGE
    if r != 0.0 and not lo <= r <= hi:
        raise ValueError(f"contact_resistance must be 0 or lie within [{lo:g}, {hi:g}] (units R0), got {value!r}")
    return r


def _frozen(arr: np.ndarray) -> np.ndarray:
    arr.setflags(write=False)
    return arr


def conductor_id(c) -> int:
    """A conductor id as an int (ValueError if it is not an integer)."""
    try:
        return operator.index(c)
    except TypeError:
        raise ValueError(f"conductor id must be an integer, got {c!r}") from None


def tip_index(k, n_tips: int, name: str = "tip") -> int:
    """A tip index as an int in ``[0, n_tips)`` (ValueError naming ``name`` otherwise)."""
    try:
        k = operator.index(k)
    except TypeError:
        raise ValueError(f"{name} must be an integer, got {k!r}") from None
    if not 0 <= k < n_tips:
        raise ValueError(f"{name} {k} out of range [0, {n_tips})")
    return k


def tip_pair(k, l, n_tips: int) -> tuple[int, int]:
    """Two tips of different rods as ``(lower, higher)`` (ValueError for the two tips of one rod)."""
    k, l = tip_index(k, n_tips), tip_index(l, n_tips)
    if k // 2 == l // 2:
        raise ValueError(f"tips {k} and {l} are the two tips of rod {k // 2}: a rod cannot touch itself")
    return (k, l) if k < l else (l, k)


def finite_potential(potential, k, c) -> float:
    """The potential of tip ``k``'s contact with conductor ``c`` as a finite float (ValueError otherwise)."""
    pot = float(potential)
    if not np.isfinite(pot):
        raise ValueError(f"potential of tip {k} on conductor {c} must be finite, got {pot}")
    return pot
