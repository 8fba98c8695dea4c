"""Scalar force laws, each written once and inlined into the loops in this package.

Every law returns the *radial* factor ``f(r) / r`` so that the force vector is
``factor * (x_k - x_l)``; this avoids a division by ``r`` in the loops and makes
``r = 0`` easy to guard. Potentials are returned alongside for the energy
kernels and the gradient tests. Sources are docs/model.md 'Force terms' (by term number).
"""

import math

import numpy as np

from ._jit import inline, inline_sum
from .expo import exp_nonpositive, exp_nonpositive_f32


@inline_sum
def tip_force_over_r(r2, p, rstar, kappa):
    """Tip-tip magnetic force with a soft core (docs/model.md 'Term 1'), divided by r.

    ``f(r) = p / r^2`` for ``r >= r*`` (Coulomb law between magnetic charges) and
    ``f(r) = p r / r*^3 + kappa (r* - r) / r*^3`` inside (a charge smeared over a
    ball of radius r* plus an elastic wall of stiffness kappa). ``p = q_k q_l``;
    a positive f pushes the tips apart. f is continuous at r*; at ``r = 0`` the
    direction is undefined and the factor is set to 0, so the force stays finite.

    Both branches are computed and one is selected, with no jump in control
    flow, so that the all-pairs loops vectorise (see ``_jit``). One square root and one
    division per pair, the least a float64 ``1/r^3`` needs: the core's ``1 / r*^3`` is a
    factor the loop hoists, not a second division per pair (division and square root
    share the divider, which bounds these loops; on one core of an AVX2 Zen 3 the direct
    sum went from 0.52-0.54e9 to 0.54-0.61e9 tip pairs/s, at the edge of the spread
    between runs, docs/performance.md). Inside r* this may round differently from
    dividing by ``r*^3``: at most 1 ulp of the inner force.

    Parameters
    ----------
    r2 : float
        Squared tip distance.
    p : float
        Product of the two magnetic charges.
    rstar, kappa : float
        Transition radius r* and core stiffness.
    """
    rs2 = rstar * rstar
    inv_rs3 = 1.0 / (rs2 * rstar)  # loop-invariant: hoisted out of the pair loops
    inv_r = 1.0 / math.sqrt(max(r2, 1e-300))
    outer = p * inv_r * inv_r * inv_r
    inner = (p + kappa * (rstar * inv_r - 1.0)) * inv_rs3
    g = outer if r2 >= rs2 else inner
    return g if r2 > 0.0 else 0.0


#: float32 constants of :func:`tip_force_over_r_f32` (a float64 literal would promote the law to float64)
_F32_ONE = np.float32(1.0)
_F32_ZERO = np.float32(0.0)
#: below this squared distance the float32 law gives 0 (:func:`tip_force_over_r_f32`)
_F32_TINY = np.float32(1e-37)


@inline_sum
def tip_force_over_r_f32(r2, p, rstar, kappa):
    """:func:`tip_force_over_r` in float32: every argument float32, every constant float32.

    The same law and branches (the core below ``r*``), for the mixed-precision near field of the
    tip tree (``treewalk.evaluate_groups``) and the mixed direct sum: AVX2 takes 8 float32 lanes per
    square root and division against 4 float64 lanes. Where float64 gives 0 at ``r2 = 0``, this
    gives 0 for every ``r2`` below ``1e-37``, the smallest round float32 power of ten that is
    normal: a tip pair closer than ``3e-19`` is not resolved in float32 anyway, and the one select
    also discards whatever the reciprocal square root made of such an ``r2`` (inf or NaN), so that
    no clamp of ``r2`` is needed before it (one instruction less per pair). The core is taken as
    ``(p / r*^3 - kappa / r*^3) + (kappa / r*^2) / r``, three loop-invariant factors where
    ``(p + kappa (r* / r - 1)) / r*^3`` held four in registers and took one operation more: with
    AVX2's 16 vector registers, 1.03 times faster tree evaluation and 1.02-1.07 times faster mixed
    direct sum (24 000 and 1200 rods, one thread, interleaved with the code before). Relative
    rounding about 1e-7 of f.
    """
    rs2 = rstar * rstar
    inv_rs3 = _F32_ONE / (rs2 * rstar)  # loop-invariant: hoisted out of the pair loops
    k1 = kappa * inv_rs3  # so is this: the core's three constants, not four, in registers
    k2 = k1 * rstar
    inv_r = _F32_ONE / math.sqrt(r2)
    outer = p * inv_r * inv_r * inv_r
    inner = (p * inv_rs3 - k1) + k2 * inv_r
    g = outer if r2 >= rs2 else inner
    return g if r2 >= _F32_TINY else _F32_ZERO


@inline
def tip_potential(r2, p, rstar, kappa):
    """Potential of :func:`tip_force_over_r` (docs/model.md 'Term 1'), zero at infinity.

    ``U = p / r`` outside, ``U = p (3 r*^2 - r^2) / (2 r*^3) + kappa (r* - r)^2 / (2 r*^3)``
    inside; U is continuous at r* and ``f = -dU/dr``.
    """
    rs2 = rstar * rstar
    r = math.sqrt(r2)
    if r2 >= rs2:
        return p / r
    rs3 = rs2 * rstar
    d = rstar - r
    return (p * (3.0 * rs2 - r2) + kappa * d * d) / (2.0 * rs3)


def make_yukawa_force_over_r(ft, exp):
    """The Yukawa law :func:`yukawa_force_over_r` in the float type ``ft`` with the exponential
    ``exp`` (:func:`.expo.exp_nonpositive` for float64, :func:`.expo.exp_nonpositive_f32` for
    float32): one definition of the law, every constant of type ``ft``, built once per type below."""
    one = ft(1.0)
    zero = ft(0.0)

    @inline
    def law(r2, zz, inv_s, core2):
        """``f(r) / r`` of the Yukawa force (:data:`yukawa_force_over_r`)."""
        rr = max(r2, core2)
        coincident = rr == zero  # NaN is not zero: it propagates
        rs = one if coincident else rr
        r = math.sqrt(rs)
        inv_r = one / r
        f = zz * exp(-r * inv_s) * (inv_r * inv_r + inv_s * inv_r) * inv_r
        return zero if coincident else f

    return law


#: Screened electric repulsion between rod centres (docs/model.md 'Term 6'), divided by r:
#: ``yukawa_force_over_r(r2, zz, inv_s, core2)`` with ``r2`` the squared distance, ``zz = Z_i Z_j``,
#: ``inv_s = 1 / R_D`` and ``core2 = a^2`` (the last two loop-invariant, taken once by the caller).
#:
#: ``f(r) = Z_i Z_j exp(-r/R_D) (1/r^2 + 1/(R_D r))``, the negative derivative of
#: ``U = Z_i Z_j exp(-r/R_D) / r``, for ``r >= a``. Inside the core radius ``a``
#: (``forces.yukawa.core_radius``; 0 means no core) the force falls linearly to zero,
#: ``f(r) = f(a) r / a``, as for a point charge inside a uniformly charged ball of radius a
#: (the same softening as the tip law, term 1): two rods of diameter
#: D cannot bring their centres closer than about D, and without the core two crossing
#: rods feel an unbounded 1/r^2 force. Clamping r^2 to a^2 gives exactly this,
#: because the returned factor is f/r. ``r = 0`` without a core gives 0.
#:
#: The exponential is :func:`.expo.exp_nonpositive` (within 2 ulp of ``math.exp``) and
#: ``r = 0`` is a select, not a branch, so that the neighbour loop vectorises: measured
#: at 24 000 rods (5.0e6 directed pairs) on one core of the 2-core machine, the pair loop
#: of ``yukawa.yukawa_centres`` went from 9.0 to 7.5 ns per pair (the same loop with the
#: exponential left out takes 4.1: the rest is the gathers of the neighbours' centres).
#: Results differ from those with ``math.exp`` by at most 2e-16 of the largest force.
#: One square root and one division per pair (``1 / R_D`` is loop-invariant),
#: where the earlier form had four divisions: on one core of an AVX2 Zen 3, with the
#: exponential's vector conversion (``expo.py``), 9.4-9.8 against 11.0-11.6 ns per
#: listed pair at 1200 rods, within the spread between runs at 6000 and 24 000
#: (docs/performance.md). The two forms round differently: a few ulp of f.
yukawa_force_over_r = make_yukawa_force_over_r(np.float64, exp_nonpositive)

#: :func:`yukawa_force_over_r` in float32: every argument float32 (``inv_s`` and ``core2`` rounded
#: once to float32 by the caller), every constant float32, the exponential
#: :func:`.expo.exp_nonpositive_f32`; for the mixed-precision Yukawa sum
#: (``yukawa.yukawa_centres_sorted_mixed``): AVX2 takes 8 float32 lanes per square root and
#: division against 4 float64 lanes. Relative rounding about 1e-7 of f; the caller keeps
#: its inputs where no product here leaves the normal float32 range (``yukawa.py``
#: ``_yukawa_mixed_ok``), except for ``r`` near 0 without a core: ``1/r^3`` overflows float32
#: below ``r = 1e-13 |Z_i Z_j|^(1/3)`` (the caller then sums the row in float64), and a pair
#: closer than about 3e-23, whose ``r^2`` underflows to 0, counts as coincident (0, where
#: float64 gives more than 1e45).
yukawa_force_over_r_f32 = make_yukawa_force_over_r(np.float32, exp_nonpositive_f32)


@inline
def yukawa_potential(r2, zz, screening, core):
    """Potential of :func:`yukawa_force_over_r`: ``U = Z_i Z_j exp(-r/R_D) / r`` for ``r >= a``.

    Inside the core ``U = U(a) + f(a) (a^2 - r^2) / (2 a)``, continuous at a.
    """
    if r2 >= core * core:
        r = math.sqrt(r2)
        return zz * exp_nonpositive(-r / screening) / r
    ec = exp_nonpositive(-core / screening)
    g = zz * ec * (1.0 / (core * core) + 1.0 / (screening * core)) / core  # f(a) / a
    return zz * ec / core + 0.5 * g * (core * core - r2)


@inline
def wall_push(h, rstar, kappa):
    """Elastic push of an electrode plane on a tip at height h above it (docs/model.md 'Term 8').

    ``kappa (r* - h) / r*^3`` for ``h < r*`` (any h, also below the plane), else 0.
    """
    if h >= rstar:
        return 0.0
    return kappa * (rstar - h) / (rstar * rstar * rstar)


@inline
def wall_potential(h, rstar, kappa):
    """``kappa (r* - h)^2 / (2 r*^3)`` for ``h < r*``, the potential of :func:`wall_push`."""
    if h >= rstar:
        return 0.0
    d = rstar - h
    return kappa * d * d / (2.0 * rstar * rstar * rstar)
