"""The scalar force laws of docs/model.md 'Term 1', 'Term 6', 'Term 8' against their formulas."""

import math

import pytest

from selfas_graph.kernels.laws import (
    tip_force_over_r,
    tip_force_over_r_f32,
    tip_potential,
    wall_potential,
    wall_push,
    yukawa_force_over_r,
    yukawa_force_over_r_f32,
    yukawa_potential,
)

#: small inputs: also run with NUMBA_DISABLE_JIT=1, the kernels as Python (.ci/run)
pytestmark = pytest.mark.jit_off_ok

RSTAR = 0.06


@pytest.mark.parametrize("r", [0.07, 0.5, 1.0, 3.7, 25.0])
@pytest.mark.parametrize("p", [-2.0, -1.0, 0.5, 4.0])
def test_coulomb_outside_core(r, p):
    """Outside r* the tip law is Coulomb's: f = p / r^2, U = p / r (term 1)."""
    # 1e-14: one division and one sqrt of round-off
    assert tip_force_over_r(r * r, p, RSTAR, 1.0) * r == pytest.approx(p / r**2, rel=1e-14)
    assert tip_potential(r * r, p, RSTAR, 1.0) == pytest.approx(p / r, rel=1e-14)


@pytest.mark.parametrize("p", [-1.0, 1.0, -3.0])
@pytest.mark.parametrize("kappa", [0.0, 1.0, 5.0])
def test_inner_branch_continuous_at_rstar(p, kappa):
    """Force and potential are continuous at r* (the core adds 0 there)."""
    eps = 1e-9
    for law in (tip_force_over_r, tip_potential):
        inside = law((RSTAR * (1 - eps)) ** 2, p, RSTAR, kappa)
        outside = law((RSTAR * (1 + eps)) ** 2, p, RSTAR, kappa)
        # a jump would be O(1/r*^2) ~ 300; continuity leaves O(eps / r*^2)
        assert inside == pytest.approx(outside, rel=1e-7)


def test_inner_branch_bounded_at_zero():
    """At r -> 0 the force stays finite (|f| -> kappa / r*^2) and is 0 at r = 0 exactly, never NaN."""
    kappa, p = 1.0, -1.0
    for r in (1e-3, 1e-8, 1e-150):
        f = tip_force_over_r(r * r, p, RSTAR, kappa) * r
        assert math.isfinite(f)
        # f(r) = p r / r*^3 + kappa (r* - r) / r*^3, which tends to kappa / r*^2 as r -> 0; no cancellation
        # at these r, a handful of roundings: measured at most 2.0e-16 (compiled) and 4.1e-16 (the kernels
        # as Python, NUMBA_DISABLE_JIT=1), 1e-14 leaves 20x
        assert f == pytest.approx((p * r + kappa * (RSTAR - r)) / RSTAR**3, rel=1e-14)
        assert abs(f) <= kappa / RSTAR**2 * (1 + 1e-12)  # the bound, with room for the rounding of f (above)
    assert tip_force_over_r(0.0, p, RSTAR, kappa) == 0.0
    assert math.isfinite(tip_potential(0.0, p, RSTAR, kappa))


def test_opposite_tips_rest_at_half_rstar():
    """Two opposite tips with |q1 q2| = 1 and kappa = 1 rest at r = r*/2 (docs/model.md 'Term 1')."""
    r = RSTAR / 2
    # the force there is a difference of two terms of size 1/(2 r*^2) ~ 140: round-off 1e-12
    assert abs(tip_force_over_r(r * r, -1.0, RSTAR, 1.0) * r) < 1e-12
    # and it is a minimum of U: the force points back to r*/2 from both sides
    assert tip_force_over_r((0.4 * RSTAR) ** 2, -1.0, RSTAR, 1.0) > 0
    assert tip_force_over_r((0.6 * RSTAR) ** 2, -1.0, RSTAR, 1.0) < 0


def _central_difference(u, r, h):
    return -(u(r + h) - u(r - h)) / (2 * h)


@pytest.mark.parametrize("r", [0.01, 0.03, 0.059, 0.061, 0.2, 1.0, 4.0])
def test_tip_force_is_minus_gradient(r):
    """f = -dU/dr for term 1 on both branches (central differences)."""
    p, kappa = -1.3, 2.0
    h = 1e-6 * max(r, RSTAR)
    numeric = _central_difference(lambda s: tip_potential(s * s, p, RSTAR, kappa), r, h)
    # central difference error O(h^2 U''') plus round-off U/h * 1e-16: both below 1e-9 relative here
    # (measured at most 3.9e-10 over these r)
    assert tip_force_over_r(r * r, p, RSTAR, kappa) * r == pytest.approx(numeric, rel=1e-8)


@pytest.mark.parametrize("r", [0.1, 0.5, 1.0, 2.5, 7.0])
@pytest.mark.parametrize("screening", [0.6, 1.0, 2.4])
def test_yukawa_force_is_minus_gradient(r, screening):
    """Term 6: f = Z Z exp(-r/R_D)(1/r^2 + 1/(R_D r)) = -dU/dr with U = Z Z exp(-r/R_D)/r."""
    zz = 1.7
    numeric = _central_difference(lambda s: yukawa_potential(s * s, zz, screening, 0.0), r, 1e-6 * r)
    analytic = zz * math.exp(-r / screening) * (1 / r**2 + 1 / (screening * r))
    # the same law written another way: a few ulp apart
    assert yukawa_force_over_r(r * r, zz, 1.0 / screening, 0.0) * r == pytest.approx(analytic, rel=1e-14)
    # central-difference truncation ~1e-10 and round-off U/h * 1e-16 ~1e-10 (measured at most 6.9e-11)
    assert analytic == pytest.approx(numeric, rel=1e-9)


@pytest.mark.parametrize("r", [0.0, 0.01, 0.03, 0.0599, 0.0601, 0.2])
def test_yukawa_core_is_bounded_continuous_and_minus_gradient(r):
    """Term 6 with core radius a = 0.06: f = f(a) r / a inside (bounded, zero at r = 0),
    the bare law outside, f = -dU/dr on both sides, and f and U continuous at a."""
    zz, screening, core = 4.0, 1.0, 0.06
    f_core = zz * math.exp(-core / screening) * (1 / core**2 + 1 / (screening * core))
    f = yukawa_force_over_r(r * r, zz, 1.0 / screening, core * core) * r
    expected = f_core * r / core if r < core else zz * math.exp(-r / screening) * (1 / r**2 + 1 / (screening * r))
    assert f == pytest.approx(expected, rel=1e-14, abs=1e-300)  # the same formulas in another order: round-off
    assert abs(f) <= f_core * (1 + 1e-14)  # at r = a the two branches meet: f_core up to the rounding of f
    if r > 0.0:
        h = 1e-6 * r
        numeric = _central_difference(lambda s: yukawa_potential(s * s, zz, screening, core), r, h)
        # truncation O(h^2 f'') and round-off U/h * 1e-16, below 1e-8 (measured at most 4.1e-9, next to a)
        assert f == pytest.approx(numeric, rel=1e-7)
    # continuity at the core radius: the two sides are 2e-12 of a apart, over which f and U change by
    # about 1e-12 of themselves (measured 1.0e-12 and 2.1e-12); a jump would be of order 1
    for rc in (core,):
        below, above = rc * (1 - 1e-12), rc * (1 + 1e-12)
        assert yukawa_force_over_r(below**2, zz, 1.0 / screening, core * core) * below == pytest.approx(
            yukawa_force_over_r(above**2, zz, 1.0 / screening, core * core) * above, rel=1e-10
        )
        assert yukawa_potential(below**2, zz, screening, core) == pytest.approx(
            yukawa_potential(above**2, zz, screening, core), rel=1e-10
        )


@pytest.mark.parametrize("h", [-0.02, 0.0, 0.01, 0.05, 0.0599, 0.1])
def test_wall_push_is_minus_gradient(h):
    """Term 8: the wall push kappa (r* - h)/r*^3 is -dU/dh and vanishes for h >= r*."""
    kappa = 1.5
    numeric = _central_difference(lambda s: wall_potential(s, RSTAR, kappa), h, 1e-7)
    # a quadratic: no truncation error; round-off U eps / h with U up to 22 here, 2e-8 (measured 4.1e-8)
    assert wall_push(h, RSTAR, kappa) == pytest.approx(numeric, rel=0, abs=2e-7)
    if h >= RSTAR:
        assert wall_push(h, RSTAR, kappa) == 0.0


@pytest.mark.parametrize("r", [0.0, 1e-6, 0.01, 0.03, 0.0599, 0.06, 0.0601, 0.5, 3.7, 25.0])
@pytest.mark.parametrize("p", [-2.0, 0.5])
def test_float32_law_is_the_float64_law(r, p):
    """tip_force_over_r_f32 is the same law in float32 (the tree's mixed near field): equal to
    the float64 law to 1e-6 of the size of its terms, both branches and the r = 0 guard (float32 rounding is
    6e-8; r^2 is rounded too and a compiled 1 / sqrt may be an estimate refined by one Newton
    step, about 2e-7 of 1/r, 6e-7 of 1/r^3). Compiled, it returns a float32 (no promotion)."""
    import numba
    import numpy as np

    f32 = np.float32
    args = (f32(r * r), f32(p), f32(RSTAR), f32(2.0))
    got = tip_force_over_r_f32(*args)
    want = tip_force_over_r(float(args[0]), float(args[1]), float(args[2]), 2.0)
    # relative to the size of the terms: inside r* the law is a difference, zero at r*/2 here
    scale = 0.0 if r == 0.0 else (abs(p) + 2.0 * RSTAR / r) / RSTAR**3 if r < RSTAR else abs(p) / r**3
    assert abs(got - want) <= 1e-6 * scale
    if not numba.config.DISABLE_JIT:  # the compiled law returns float32 (Python sees a float)
        assert [sig.return_type for sig in tip_force_over_r_f32.nopython_signatures] == [numba.float32]


@pytest.mark.parametrize("r", [0.0, 0.01, 0.1, 0.2999, 0.3001, 1.0, 4.0, 12.0])
@pytest.mark.parametrize("core", [0.0, 0.3])
@pytest.mark.parametrize("screening", [0.5, 2.0])
@pytest.mark.parametrize("zz", [-2.0, 4.0])
def test_float32_yukawa_law_is_the_float64_law(r, core, screening, zz):
    """yukawa_force_over_r_f32 is the Yukawa law of docs/model.md 'Term 6' in float32 (the mixed Yukawa
    sum): on the same float32 arguments, equal to the float64 law within 1e-6 of f (1 + r / R_D), inside
    the core (r < a, the clamp to a), just outside it and far out (r / R_D up to 24), and 0 at r = 0
    without a core. The bound is the float32 one of tests/physics/test_yukawa_mixed.py: about ten
    roundings of 6e-8, the exponential within 2 float32 ulp, and the rounding of ``-r / R_D``, which
    the exponential multiplies by r / R_D (measured at most 3.2e-7 of f (1 + r / R_D) over a finer
    grid of r, a margin of 3). Compiled, it returns a float32 (no promotion)."""
    import numba
    import numpy as np

    f32 = np.float32
    args = (f32(r * r), f32(zz), f32(1.0 / screening), f32(core * core))
    got = yukawa_force_over_r_f32(*args)
    want = yukawa_force_over_r(*(float(a) for a in args))
    if r == 0.0 and core == 0.0:
        assert got == want == 0.0
    else:
        radius = math.sqrt(max(float(args[0]), float(args[3])))  # the law clamps r to the core radius
        assert want != 0.0 and abs(got - want) <= 1e-6 * abs(want) * (1 + radius / screening)
    if not numba.config.DISABLE_JIT:  # the compiled law returns float32 (Python sees a float)
        assert [sig.return_type for sig in yukawa_force_over_r_f32.nopython_signatures] == [numba.float32]
