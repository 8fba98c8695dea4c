"""Every engine kernel equals its reference (tests/reference.py) on random configurations.

Tolerance: rtol 1e-12 on each component, with an absolute floor of 1e-12 times
the largest component, since sums of many terms of both signs can cancel to
well below their size (the round-off is relative to the terms, not the sum).
"""

import os

import numpy as np
import pytest

import reference as ref
from conftest import random_rods
from selfas_graph.kernels import brakes, contacts, yukawa
from selfas_graph.kernels import fields as kf
from selfas_graph.kernels import integrate as ki
from selfas_graph.kernels import rigid as kr
from selfas_graph.kernels import tips as kt
from selfas_graph.model.neighbours import NeighbourList

#: small inputs: also run with NUMBA_DISABLE_JIT=1, the kernels as Python (.ci/run)
pytestmark = pytest.mark.jit_off_ok

RSTAR, KAPPA = 0.06, 1.0


def close(actual, expected):
    scale = np.abs(expected).max(initial=0.0)
    np.testing.assert_allclose(actual, expected, rtol=1e-12, atol=1e-12 * scale)


@pytest.fixture
def state(rng):
    s = random_rods(40, rng, box=3.0)
    # force some tips into each other's cores, and one pair exactly on top of each other
    s.position[5] = s.position[40] + [0.02, 0.0, 0.01]
    s.position[7] = s.position[50] + [0.0, 0.03, 0.0]
    s.position[9] = s.position[60]
    s.velocity[:] = rng.normal(size=s.velocity.shape)
    return s


def test_tip_tip_direct(state):
    out = np.empty_like(state.position)
    x, y, z = (np.ascontiguousarray(state.position[:, d]) for d in range(3))
    kt.tip_tip_direct(x, y, z, state.tip_charge, RSTAR, KAPPA, 0, len(x), out)
    close(out, ref.tip_tip_force(state.position, state.tip_charge, RSTAR, KAPPA))


def test_tip_tip_direct_rows(state, rng):
    """The direct sum restricted to some target rows equals those rows of the full sum."""
    x, y, z = (np.ascontiguousarray(state.position[:, d]) for d in range(3))
    full = np.empty_like(state.position)
    kt.tip_tip_direct(x, y, z, state.tip_charge, RSTAR, KAPPA, 0, len(x), full)
    row = rng.choice(len(x), 17, replace=False)
    out = np.empty((len(row), 3))
    kt.tip_tip_direct_rows(x, y, z, state.tip_charge, RSTAR, KAPPA, row, out)
    np.testing.assert_array_equal(out, full[row])  # the same loop, so the same bits
    close(out, ref.tip_tip_force(state.position, state.tip_charge, RSTAR, KAPPA)[row])


def test_tip_tip_energy(state):
    x, y, z = (np.ascontiguousarray(state.position[:, d]) for d in range(3))
    rows = np.empty(len(x))
    kt.tip_tip_energy(x, y, z, state.tip_charge, RSTAR, KAPPA, 0, len(x), rows)
    e = rows.sum()
    # 3160 pair energies of both signs, by rows against by pairs: the total is 1-4 % of the sum of their
    # magnitudes here, so a random walk of round-off, sqrt(n) eps of that sum, is about 1e-12 of the total
    # at worst (measured 0.7-4e-15 over five seeds)
    assert e == pytest.approx(ref.tip_tip_energy(state.position, state.tip_charge, RSTAR, KAPPA), rel=1e-12)


def test_tip_brake(state):
    nl = NeighbourList(RSTAR, 0.2, exclude_same_rod=True)
    nl.build(state.position)
    out = np.empty_like(state.position)
    brakes.tip_brake(state.position, state.velocity, nl.start, nl.index, RSTAR, 100.0, out)
    expected = ref.tip_brake(state.position, state.velocity, RSTAR, 100.0)
    assert np.abs(expected).max() > 0  # the fixture has tips in contact
    close(out, expected)


@pytest.mark.parametrize("bounds", [(0, 80), (0, 37, 80), (0, 5, 6, 40, 41, 79, 80)])
def test_tip_brake_rows_in_blocks(state, bounds):
    """``brakes.tip_brake_rows`` over blocks of rows (one block; a split at tip 37, which cuts rod 18
    and the list in the middle; blocks of one row, two of them tips 5 and 40 in contact, and one at
    the end) equals the slow reference of
    docs/model.md 'Term 2' (tests/reference.py ``tip_brake``, all pairs by distance) row by row, and
    a block writes its own rows only. Tolerance: ``close`` (each row a sum of a few terms of size
    k_br |v|: round-off)."""
    nl = NeighbourList(RSTAR, 0.2, exclude_same_rod=True)
    nl.build(state.position)
    expected = ref.tip_brake(state.position, state.velocity, RSTAR, 100.0)
    assert np.count_nonzero(np.abs(expected).sum(axis=1)) >= 6  # the fixture's tips in contact
    out = np.full_like(state.position, np.nan)
    for lo, hi in zip(bounds[:-1], bounds[1:]):
        brakes.tip_brake_rows(state.position, state.velocity, nl.start, nl.index, RSTAR, 100.0, lo, hi, out)
        assert np.isnan(out[hi:]).all() and not np.isnan(out[:hi]).any()
    close(out, expected)


@pytest.mark.parametrize("cutoff", [0.7, 2.0, 100.0])
@pytest.mark.parametrize("core", [0.0, 0.3])
def test_yukawa(state, cutoff, core):
    """Term 6 neighbour kernel against the all-pairs reference, with and without the core
    (core 0.3 is large enough that several pairs of the fixture fall inside it)."""
    c = state.centre()
    if core > 0:  # the core branch is met: rod pairs closer than the core radius (3 with this fixture)
        d = np.linalg.norm(c[:, None] - c[None], axis=-1)
        assert np.triu(d < core, 1).sum() > 0
    nl = NeighbourList(cutoff, 0.3)
    nl.build(c)
    out = np.empty_like(c)
    yukawa.yukawa_centres(c, state.rod_charge, nl.start, nl.index, 0.8, core, cutoff, 0, len(c), out)
    close(out, ref.yukawa_force(c, state.rod_charge, 0.8, cutoff, core))
    rows = np.empty(len(c))
    yukawa.yukawa_energy(c, state.rod_charge, nl.start, nl.index, 0.8, core, cutoff, 0, len(c), rows)
    e = rows.sum()
    # repulsive pair energies, all of one sign but for the shift at the cut-off: no cancellation,
    # round-off of a few hundred terms (measured at most 1.2e-15 over five seeds)
    assert e == pytest.approx(ref.yukawa_energy(c, state.rod_charge, 0.8, cutoff, core), rel=1e-12)


def test_plasma(state):
    """Term 5's field and force on tips against the reference, with tips inside the channel (rho <= R,
    the linear branch) and outside it (the 1/rho branch): 33 and 47 tips with this fixture."""
    out = np.empty_like(state.position)
    args = (0.3, -0.2, 1.1, 7.5)
    rho = np.hypot(state.position[:, 0] - args[0], state.position[:, 1] - args[1])
    assert (rho <= args[2]).sum() > 0 and (rho > args[2]).sum() > 0
    kf.plasma_field(state.position, *args, out)
    close(out, ref.plasma_field(state.position, *args))
    kf.plasma_force_on_tips(state.position, state.tip_charge, *args, out)
    close(out, state.tip_charge[:, None] * ref.plasma_field(state.position, *args))


def test_electrode_walls(state):
    z_lo, z_hi = state.position[:, 2].min() + 0.03, state.position[:, 2].max() - 0.05
    push, brake = np.empty_like(state.position), np.empty_like(state.position)
    kf.electrode_walls(state.position, state.velocity, z_lo, z_hi, RSTAR, KAPPA, 100.0, push, brake)
    ep, eb = ref.electrode_walls(state.position, state.velocity, z_lo, z_hi, RSTAR, KAPPA, 100.0)
    assert np.abs(ep).max() > 0
    close(push, ep)
    close(brake, eb)


def test_electrode_energy(state):
    """The walls' energy, its constant included (zero beyond r*, continuous at r*), tips beyond a plane too."""
    z_lo, z_hi = state.position[:, 2].min() + 0.03, state.position[:, 2].max() - 0.05
    got = kf.electrode_energy(state.position, z_lo, z_hi, RSTAR, KAPPA)
    expect = ref.electrode_energy(state.position, z_lo, z_hi, RSTAR, KAPPA)
    assert expect > 0
    assert got == pytest.approx(expect, rel=1e-12)  # positive terms: round-off relative to the sum


def test_axpy(rng):
    """``out = y + h d``, one product and one sum per element: bit for bit numpy's, also in place."""
    y, d = rng.normal(size=(50, 3)), rng.normal(size=(50, 3))
    out = np.empty_like(y)
    ki.axpy(y, d, 0.01, out)
    assert np.array_equal(out, y + 0.01 * d)
    ki.axpy(y, d, 0.01, y)
    assert np.array_equal(y, out)


@pytest.mark.parametrize("exact", [True, False])
def test_bond_acceleration(state, rng, exact):
    force = rng.normal(size=state.position.shape)
    out = np.empty_like(force)
    kr.bond_acceleration(force, state.velocity, state.position, exact, out)
    close(out, ref.bond_acceleration(force, state.velocity, state.position, exact))


@pytest.mark.parametrize("project", [True, False])
@pytest.mark.parametrize("correct", [True, False])
def test_constrain_bonds(state, rng, project, correct):
    x = state.position + 1e-3 * rng.normal(size=state.position.shape)
    v = state.velocity.copy()
    ex, ev = ref.constrain_bonds(x, v, project, correct)
    kr.constrain_bonds(x, v, project, correct, np.zeros(0))
    close(x, ex)
    close(v, ev)


@pytest.mark.parametrize("project", [True, False])
@pytest.mark.parametrize("correct", [True, False])
def test_constrain_bonds_per_rod_length(state, rng, project, correct):
    """Bonds of rods with lengths l_i are restored to l_i about the rod centre (docs/model.md 'Corrections after each step')."""
    ell = rng.uniform(0.5, 1.5, state.n_rods)
    x = state.position + 1e-3 * rng.normal(size=state.position.shape)
    v = state.velocity.copy()
    ex, ev = ref.constrain_bonds(x, v, project, correct, ell)
    kr.constrain_bonds(x, v, project, correct, ell)
    close(x, ex)
    close(v, ev)
    if project:
        # after the projection each bond is l_i to round-off of a sqrt and a scaling (a few ulp of l_i ~ 1)
        np.testing.assert_allclose(np.linalg.norm(x[0::2] - x[1::2], axis=1), ell, rtol=0, atol=1e-14)
        assert kr.bond_length_error(x, ell) < 1e-14


def test_unit_length_array_is_bit_for_bit_the_empty_one(state, rng):
    """An array of ones and the empty array (every rod of length 1) give the same bits."""
    x0 = state.position + 1e-3 * rng.normal(size=state.position.shape)
    v0 = rng.normal(size=state.position.shape)
    x1, v1, x2, v2 = x0.copy(), v0.copy(), x0.copy(), v0.copy()
    kr.constrain_bonds(x1, v1, True, True, np.zeros(0))
    kr.constrain_bonds(x2, v2, True, True, np.ones(state.n_rods))
    assert np.array_equal(x1, x2) and np.array_equal(v1, v2)
    assert kr.bond_length_error(x0, np.zeros(0)) == kr.bond_length_error(x0, np.ones(state.n_rods))


def test_ab4_update(rng):
    y, d0, d1, d2, d3 = (rng.normal(size=(50, 3)) for _ in range(5))
    out = np.empty_like(y)
    ki.ab4_update(y, d0, d1, d2, d3, 0.01, out)
    close(out, y + 0.01 / 24 * (55 * d0 - 59 * d1 + 37 * d2 - 9 * d3))


def test_close_pair_count(state):
    nl = NeighbourList(RSTAR, 0.3, exclude_same_rod=True)
    nl.build(state.position)
    n = contacts.close_pair_count(state.position, nl.start, nl.index, RSTAR)
    d = np.linalg.norm(state.position[:, None] - state.position[None], axis=-1)
    rod = np.arange(len(d)) // 2
    brute = np.triu((d < RSTAR) & (rod[:, None] != rod[None, :]), 1).sum()
    assert n == brute >= 3


@pytest.mark.parametrize("radius", [RSTAR, 0.5])
@pytest.mark.parametrize("exclude_same_rod", [True, False])
def test_close_pairs_are_the_brute_force_pairs(rng, radius, exclude_same_rod):
    """``contacts.close_pairs`` lists exactly the pairs k < l closer than the radius that a search over
    all distances finds (tests/reference.py ``neighbour_pairs``), each once, row k after row k and each
    row in the order of the neighbour list (the order the exact brake meets them in; not sorted by l
    within a row): 200 random tips, with pairs placed 1e-9 of the radius inside and outside it in random
    directions (the rounding of the coordinates, below 1e-14 of the radius here, cannot move them
    across), one pair on top of each other, and the two tips of one rod closer than the radius (listed only when the list keeps
    same-rod pairs)."""
    s = random_rods(100, rng, box=4.0)
    x = s.position
    direction = rng.normal(size=(40, 3))
    direction /= np.linalg.norm(direction, axis=1)[:, None]
    for j, (k, l) in enumerate(zip(range(0, 80, 2), range(121, 200, 2))):  # tips of different rods
        x[k] = x[l] + radius * (1 - 1e-9 if j % 2 else 1 + 1e-9) * direction[j]
    x[81] = x[150]
    x[83] = x[82] + 0.5 * radius * direction[0]
    nl = NeighbourList(radius, 0.3, exclude_same_rod=exclude_same_rod)
    nl.build(x)
    got = contacts.close_pairs(x, nl.start, nl.index, radius)
    expected = ref.neighbour_pairs(x, radius, exclude_same_rod)
    in_list_order = [
        (k, l) for k in range(len(x)) for l in nl.index[nl.start[k] : nl.start[k + 1]] if (k, l) in expected
    ]
    assert got.dtype == np.int64 and got.shape == (len(expected), 2)
    assert [tuple(p) for p in got.tolist()] == in_list_order and set(in_list_order) == expected
    assert {(k, k + 121) for k in range(2, 80, 4)} <= set(expected)  # the pairs just inside
    assert not {(k, k + 121) for k in range(0, 80, 4)} & set(expected)  # and none just outside
    assert (81, 150) in expected and ((82, 83) in expected) != exclude_same_rod


# ----------------------------------------------------------------------------- row ranges
BLOCKS = [(0, 7, 8, 80), (0, 1, 79, 80), (0, 26, 53, 80)]  # tip bounds; 80 tips = 40 rods


@pytest.mark.parametrize("bounds", BLOCKS)
def test_row_ranges_do_not_change_a_row(state, bounds):
    """Forces and per-row energies computed block by block equal the one-block result bit for bit.

    This is what lets MPI ranks agree with a serial run: each row's sum runs over the same
    sources in the same order whatever ``lo, hi`` are, including in the ``reassoc``/``contract``
    tip-tip kernels, whose vectorised reduction depends on the source count only.
    """
    x, y, z = (np.ascontiguousarray(state.position[:, d]) for d in range(3))
    n = len(x)
    c = state.centre()
    m = len(c)
    nl = NeighbourList(2.0, 0.3)
    nl.build(c)
    q, zc, s, i = state.tip_charge, state.rod_charge, nl.start, nl.index

    def blockwise(kernel, shape, bounds):
        out = np.full(shape, np.nan)
        for lo, hi in zip(bounds[:-1], bounds[1:]):
            kernel(lo, hi, out)
        return out

    rod_bounds = [b // 2 for b in bounds]
    cases = [  # (kernel of (lo, hi, out), output shape, block bounds)
        (lambda lo, hi, out: kt.tip_tip_direct(x, y, z, q, RSTAR, KAPPA, lo, hi, out), (n, 3), bounds),
        (lambda lo, hi, out: kt.tip_tip_energy(x, y, z, q, RSTAR, KAPPA, lo, hi, out), (n,), bounds),
        (lambda lo, hi, out: yukawa.yukawa_centres(c, zc, s, i, 0.8, 0.3, 2.0, lo, hi, out), (m, 3), rod_bounds),
        (lambda lo, hi, out: yukawa.yukawa_energy(c, zc, s, i, 0.8, 0.3, 2.0, lo, hi, out), (m,), rod_bounds),
    ]
    for kernel, shape, blocks in cases:
        np.testing.assert_array_equal(blockwise(kernel, shape, blocks), blockwise(kernel, shape, [0, shape[0]]))


def test_centres_share_and_cell_order_copies_are_numpy_s_numbers(rng):
    """The compiled rod centres, the halving of a centre force onto the tips and the copies in cell
    order give numpy's numbers bit for bit (the runs before them used numpy's), on either build."""
    from selfas_graph.kernels.cells import take_rows

    x = rng.normal(size=(2 * 501, 3)) * 10.0 ** rng.integers(-3, 4, size=(2 * 501, 1))
    f = rng.normal(size=(501, 3))
    order = rng.permutation(501)
    want_c = 0.5 * (x[0::2] + x[1::2])
    want_t = np.empty_like(x)
    want_t[0::2] = 0.5 * f
    want_t[1::2] = 0.5 * f
    for build in ("serial", "parallel"):
        c = np.full((501, 3), np.nan)
        getattr(kr.rod_centres, build)(x, c)
        np.testing.assert_array_equal(c.view(np.int64), want_c.view(np.int64))
        t = np.full_like(x, np.nan)
        getattr(kr.share_by_mass, build)(f, t)
        np.testing.assert_array_equal(t.view(np.int64), want_t.view(np.int64))
    # a slice of the tip rows, as the Yukawa term writes its rows lo:hi
    t = np.zeros_like(x)
    kr.share_by_mass(f[100:200], t[200:400])
    np.testing.assert_array_equal(t[200:400], want_t[200:400])
    assert not t[:200].any() and not t[400:].any()
    out = np.full((501, 3), np.nan)
    take_rows(want_c, order, out)
    np.testing.assert_array_equal(out, want_c[order])


def _rows_kernel_cases(rng):
    """(kernel, arguments) for every O(n) kernel built by ``njit_rows``, on 3000 random tips."""
    from selfas_graph.kernels import external as kx
    from selfas_graph.kernels.cells import neighbour_rows
    from selfas_graph.kernels.treebuild import morton_keys

    n = 3000
    x = rng.normal(size=(n, 3))
    v = rng.normal(size=(n, 3))
    q = rng.normal(size=n)
    src = rng.normal(size=(4, 3))
    start, index = neighbour_rows(x, 0.4)  # about 30 neighbours a tip
    counts = np.zeros(n, np.int64)
    contacts._close_counts(x, start, index, 0.3, counts)
    offset = np.concatenate(([0], np.cumsum(counts)))
    return [
        (ki.ab4_update, lambda: (x, v, 2 * v, 3 * v, 4 * v, 1e-3, np.zeros((n, 3)))),
        (ki.axpy, lambda: (x, v, 0.1, np.zeros((n, 3)))),
        (ki.channel_sum, lambda: (np.zeros((n, 3)), np.stack([x, v, 2 * x]))),
        (ki.extrapolate, lambda: (np.zeros((n, 3)), v, x, 7.0)),
        (
            ki.ab4_step,
            lambda: (
                x.copy(),
                v.copy(),
                np.stack([v, x, 2 * v, 3 * x]),
                np.stack([x, v, -x, 2 * v]),
                np.array([2, 1, 0, 3]),
                1e-3,
                np.zeros(0),
            ),
        ),
        (
            ki.channel_sum_power,
            lambda: (np.zeros((n, 3)), np.stack([x, v, 2 * x]), v, np.array([0, 2]), np.zeros(2)),
        ),
        (
            ki.extrapolate_all,
            lambda: ((np.zeros((n, 3)), x.copy()), np.stack([v, x]), np.stack([x, v]), np.array([7.0, np.nan])),
        ),
        (kr.constrain_bonds_checked, lambda: (x.copy(), v.copy(), True, True, np.zeros(0))),
        (kr.bond_acceleration, lambda: (v, x, x + v, True, np.zeros((n, 3)))),
        (kr.bond_length_error, lambda: (x, np.zeros(0))),
        (kr.constrain_bonds, lambda: (x.copy(), v.copy(), True, True, np.zeros(0))),
        (kr.rod_centres, lambda: (x, np.zeros((n // 2, 3)))),
        (kr.share_by_mass, lambda: (x[: n // 2], np.zeros((n, 3)))),
        (kf.uniform_force_on_tips, lambda: (q, np.array([0.1, -0.2, 0.5]), np.zeros((n, 3)))),
        (kf.plasma_field, lambda: (x, 0.1, -0.2, 1.5, 7.5, np.zeros((n, 3)))),
        (kf.plasma_force_on_tips, lambda: (x, q, 0.1, -0.2, 1.5, 7.5, np.zeros((n, 3)))),
        (kf.electrode_walls, lambda: (x, v, -1.0, 1.0, RSTAR, KAPPA, 100.0, np.zeros((n, 3)), np.zeros((n, 3)))),
        (kx.filament_field, lambda: (x, 2.0, 0.05, np.zeros((n, 3)))),
        (kx.filament_force_on_tips, lambda: (x, q, 2.0, 0.05, np.zeros((n, 3)))),
        (
            kx.monopoles_on_tips,
            lambda: (
                x,
                v,
                q,
                src,
                np.array([1.0, -1.0, 2.0, -2.0]),
                RSTAR,
                KAPPA,
                100.0,
                np.zeros((n, 3)),
                np.zeros((n, 3)),
            ),
        ),
        (kx.monopole_field, lambda: (x, src, np.array([1.0, -1.0, 2.0, -2.0]), RSTAR, np.zeros((n, 3)))),
        (kx.line_yukawa_on_centres, lambda: (x, q, -1.0, 1.0, 0.5, 1.0, 0.05, *kc_nodes(8), np.zeros((n, 3)))),
        (kt.tip_tip_fast, lambda: (x, q, start, index, RSTAR, KAPPA, 0.2, 0.4, np.zeros((n, 3)))),
        (contacts._close_counts, lambda: (x, start, index, 0.3, np.zeros(n, np.int64))),
        (contacts._close_fill, lambda: (x, start, index, 0.3, offset, np.zeros((offset[-1], 2), np.int64))),
        (morton_keys, lambda: (*(np.ascontiguousarray(x[:, d]) for d in range(3)), np.zeros(n, np.int64))),
    ]


def kc_nodes(n):
    from selfas_graph.kernels.lorentz import gauss_legendre_01

    return gauss_legendre_01(n)


def test_rows_kernels_serial_and_parallel_builds_agree_bit_for_bit(rng):
    """The size switch of ``njit_rows`` picks a build, never a result: the serial and the
    parallel build of each O(n) kernel write identical arrays (no cross-row sums, strict IEEE)."""
    for kernel, make in _rows_kernel_cases(rng):
        a, b = make(), make()
        ra = kernel.serial(*a)
        rb = kernel.parallel(*b)
        assert ra == rb, kernel.__name__
        for u, w in zip(a, b):
            for p, q in zip(*((u, w) if isinstance(u, tuple) else ((u,), (w,)))):
                if isinstance(p, np.ndarray):
                    np.testing.assert_array_equal(p, q, err_msg=kernel.__name__)


def test_every_rows_kernel_has_its_case(rng):
    """The bit-for-bit test above covers every ``njit_rows`` kernel of the package (a new one was left
    out without a word)."""
    import importlib
    import pkgutil

    import selfas_graph.kernels as package
    from selfas_graph.kernels._jit import _RowsKernel

    found = set()
    for info in pkgutil.iter_modules(package.__path__):
        module = importlib.import_module(f"selfas_graph.kernels.{info.name}")
        found |= {f"{k.py_func.__module__}.{k.__name__}" for k in vars(module).values() if isinstance(k, _RowsKernel)}
    cased = {f"{k.py_func.__module__}.{k.__name__}" for k, _ in _rows_kernel_cases(rng)}
    assert found - cased == set(), "add these to _rows_kernel_cases"


def test_kernel_sources_digest_sees_every_kernel_module(tmp_path):
    """The digest changes when any kernel module changes, e.g. a law in laws.py that pairs.py inlines."""
    from selfas_graph.kernels._jit import sources_digest

    src = tmp_path / "src"
    src.mkdir()
    (src / "laws.py").write_text("def f(x):\n    return x\n")
    (src / "pairs.py").write_text("from .laws import f\n")
    before = sources_digest(src)
    (src / "laws.py").write_text("def f(x):\n    return 2 * x\n")
    assert sources_digest(src) != before


@pytest.mark.skipif(os.environ.get("NUMBA_DISABLE_JIT", "0") != "0", reason="no compiled kernels without the JIT")
def test_every_kernel_caches_under_the_sources_digest():
    """Every compiled kernel of the package keys its on-disk cache with the digest of all kernel sources."""
    import importlib
    import pkgutil

    from numba.core.dispatcher import Dispatcher

    import selfas_graph.kernels as package
    from selfas_graph.kernels._jit import SOURCES_DIGEST, SourcesKeyedCache, _RowsKernel

    kernels = []
    for info in pkgutil.iter_modules(package.__path__):
        module = importlib.import_module(f"selfas_graph.kernels.{info.name}")
        for obj in vars(module).values():
            if isinstance(obj, _RowsKernel):
                kernels += [obj.serial, obj.parallel]
            elif isinstance(obj, Dispatcher) and obj.py_func.__module__ == module.__name__:
                kernels.append(obj)
    assert len(kernels) > 50
    assert all(isinstance(k._cache, SourcesKeyedCache) for k in kernels)
    key = kernels[0]._cache._index_key((), kernels[0].targetctx.codegen())
    assert key[-1] == SOURCES_DIGEST


_PROBE = """
import sys
sys.path.insert(0, sys.argv[1])
from selfas_graph.kernels import _jit
_jit.SOURCES_DIGEST = sys.argv[2]   # as if the kernel sources were others
import probe_kernel
assert probe_kernel.twice(2.0) == 4.0
stats = probe_kernel.twice.stats
print(sum(stats.cache_hits.values()), sum(stats.cache_misses.values()))
"""


@pytest.mark.skipif(os.environ.get("NUMBA_DISABLE_JIT", "0") != "0", reason="no compiled kernels without the JIT")
def test_a_kernel_cached_from_other_sources_is_not_loaded(tmp_path):
    """numba checks a cached kernel only against its own file, not against the laws it inlines from
    other modules: a kernel cached under another digest of the kernel sources is compiled afresh
    (a cache miss), one cached under the same digest is loaded (a hit); nothing is deleted."""
    import subprocess
    import sys

    (tmp_path / "probe_kernel.py").write_text(
        "from selfas_graph.kernels._jit import njit\n\n\n@njit\ndef twice(x):\n    return 2.0 * x\n"
    )
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache")}

    def run(digest):
        out = subprocess.run(
            [sys.executable, "-c", _PROBE, str(tmp_path), digest], env=env, capture_output=True, text=True, check=True
        ).stdout.split()
        return tuple(int(v) for v in out)  # (cache hits, cache misses)

    assert run("A") == (0, 1)  # compiled and saved
    assert run("A") == (1, 0)  # the same sources: loaded from the cache
    assert run("B") == (0, 1)  # other sources: not loaded, compiled afresh
    assert run("A") == (1, 0)  # both entries kept side by side


_VARIANTS = """
from selfas_graph.kernels._jit import inline, njit


@inline
def law(x):
    return x + x


def make(scale, f):
    @njit
    def kernel(x):
        return f(x) * scale

    return kernel


twice, thrice = make(1.0, law), make(1.5, law)
"""

_VARIANTS_PROBE = """
import sys
sys.path.insert(0, sys.argv[1])
import probe_variants as m
assert (m.twice(2.0), m.thrice(2.0)) == (4.0, 6.0)
print(*(sum(getattr(k.stats, s).values()) for k in (m.twice, m.thrice) for s in ("cache_hits", "cache_misses")))
"""


@pytest.mark.skipif(os.environ.get("NUMBA_DISABLE_JIT", "0") != "0", reason="no compiled kernels without the JIT")
def test_the_variants_of_a_factory_are_cached_apart_and_found_again(tmp_path):
    """Kernel variants built by a factory (the pattern of ``multipole.make_fields`` and the tree's far
    loops: an inner function closing over the variant) share their bytecode and their cache index.
    Each is saved under a key of its own (the values it closes over: a wrong variant loaded would
    give the other's result), and a second process loads both, although they close over another
    kernel, which numba's own key would pickle with an identifier drawn afresh in every process."""
    import subprocess
    import sys

    (tmp_path / "probe_variants.py").write_text(_VARIANTS)
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache")}

    def run():
        out = subprocess.run(
            [sys.executable, "-c", _VARIANTS_PROBE, str(tmp_path)], env=env, capture_output=True, text=True, check=True
        ).stdout.split()
        return tuple(int(v) for v in out)  # (hits, misses) of the first variant, then of the second

    assert run() == (0, 1, 0, 1)  # each compiled and saved
    assert run() == (1, 0, 1, 0)  # each loaded, the right one
