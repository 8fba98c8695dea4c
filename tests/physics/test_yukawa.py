"""The Yukawa sum between rod centres (docs/model.md 'Term 6') at its edges, against the
all-pairs reference (tests/reference.py ``yukawa_force``), over the Verlet list the force field uses.

Tolerance: as tests/unit/test_kernels.py, rtol 1e-12 on each component with a floor of 1e-12 times the
largest: the kernel sums a row in another order (vectorised, ``njit_parallel_sum``) and its
exponential is within 2 ulp of libm's (kernels/expo.py), so rows differ from the reference by
round-off relative to the terms, which can cancel to well below their size.
"""

import numpy as np
import pytest

import reference as ref
from selfas_graph.kernels import yukawa as ky
from selfas_graph.model.neighbours import NeighbourList

#: small inputs: also run with NUMBA_DISABLE_JIT=1, the kernels as Python (.ci/run)
pytestmark = pytest.mark.jit_off_ok

SCREENING = 1.0


def close(actual, expected):
    scale = np.abs(expected).max(initial=0.0)
    np.testing.assert_allclose(actual, expected, rtol=1e-12, atol=1e-12 * scale)


def kernel(centre, charge, cutoff, core=0.0, skin=0.3, lo=0, hi=None):
    centre = np.ascontiguousarray(centre, dtype=np.float64)
    hi = len(centre) if hi is None else hi
    nl = NeighbourList(cutoff, skin)
    nl.build(centre)
    out = np.full((len(centre), 3), np.nan)
    ky.yukawa_centres(centre, charge, nl.start, nl.index, SCREENING, core, cutoff, lo, hi, out)
    return out


@pytest.mark.parametrize("core", [0.0, 0.06])
@pytest.mark.parametrize(
    "box, cutoff",
    [
        (20.0, 3.0),  # several cells per axis
        (0.5, 3.0),  # all rods in one cell, the cut-off larger than the box
        (8.0, 6.56),  # the Fig. 2 cut-off, spanning most of the box
    ],
)
def test_against_reference(rng, box, cutoff, core):
    c = rng.uniform(-box / 2, box / 2, (150, 3))
    z = rng.uniform(0.5, 1.5, 150)
    close(kernel(c, z, cutoff, core), ref.yukawa_force(c, z, SCREENING, cutoff, core))


def test_one_rod_and_none_in_range():
    """One rod feels nothing; rods farther apart than the cut-off feel nothing (exact zeros)."""
    np.testing.assert_array_equal(kernel(np.zeros((1, 3)), np.ones(1), 2.0), np.zeros((1, 3)))
    c = np.array([[0.0, 0.0, 0.0], [5.0, 0.0, 0.0], [0.0, 5.0, 0.0]])
    np.testing.assert_array_equal(kernel(c, np.ones(3), 2.0), np.zeros((3, 3)))


def test_on_the_cut_off():
    """A pair exactly at the cut-off is left out (``r < cutoff``), one a hair inside is counted."""
    c = np.array([[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 2.0 - 1e-12, 0.0]])
    out = kernel(c, np.ones(3), 2.0)
    close(out, ref.yukawa_force(c, np.ones(3), SCREENING, 2.0))
    assert out[1].tolist() == [0.0, 0.0, 0.0] and out[0, 1] < 0.0


def test_core_radius():
    """Inside the core radius the force falls linearly to zero, ``f(a) r / a`` (docs/model.md 'Term 6');
    two rods with the same centre feel no force from each other (the direction is undefined), without NaN."""
    a = 0.3
    z = np.array([1.0, 0.7, 1.2, 0.9])
    two = kernel(np.array([[0.0, 0.0, 0.0], [0.1, 0.0, 0.0]]), z[:2], 2.0, core=a)
    f_a = z[0] * z[1] * np.exp(-a / SCREENING) * (1 / a**2 + 1 / (SCREENING * a))
    assert two[1, 0] == pytest.approx(f_a * 0.1 / a, rel=1e-13)  # 2 ulp of the exponential and round-off
    assert two[0, 0] == -two[1, 0] and two[:, 1:].tolist() == [[0.0, 0.0], [0.0, 0.0]]
    c = np.array([[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [1.0, 1.0, 1.0], [1.0, 1.0, 1.0]])
    out = kernel(c, z, 2.0, core=a)
    assert np.isfinite(out).all()
    with np.errstate(invalid="ignore"):  # the reference's rows 2 and 3 divide 0 by 0
        close(out[:2], ref.yukawa_force(c, z, SCREENING, 2.0, a)[:2])
    # rows 2 and 3 feel rods 0 and 1 only (the reference has no answer for the coincident pair)
    for k in (2, 3):
        keep = [0, 1, k]
        close(out[k], ref.yukawa_force(c[keep], z[keep], SCREENING, 2.0, a)[2])


def test_rows_of_a_block(rng):
    """Rows lo:hi equal those rows of the full sum; the other rows are not touched."""
    c = rng.uniform(-2, 2, (60, 3))
    z = rng.uniform(0.5, 1.5, 60)
    full = kernel(c, z, 2.5)
    part = kernel(c, z, 2.5, lo=20, hi=45)
    np.testing.assert_array_equal(part[20:45], full[20:45])
    assert np.isnan(part[:20]).all() and np.isnan(part[45:]).all()


@pytest.mark.parametrize("lo, hi", [(0, 200), (50, 130), (0, 0)])
def test_sorted_copies_same_bit_for_bit(rng, lo, hi):
    """The sum over copies in cell order (``yukawa_centres_sorted``, what the term calls) gives the
    forces of ``yukawa_centres`` over the same list bit for bit (the same terms in the same
    sequence); rows outside lo:hi are not touched."""
    c = rng.uniform(-4, 4, (200, 3))
    c[7] = c[8]  # two rods on top of each other
    z = rng.uniform(0.5, 1.5, 200)
    nl = NeighbourList(3.0, 0.3, cell_order=True)
    nl.build(c)
    order, start, index = nl.sorted_rows
    plain = np.full((200, 3), np.nan)
    ky.yukawa_centres(c, z, nl.start, nl.index, SCREENING, 0.06, 3.0, lo, hi, plain)
    out = np.full((200, 3), np.nan)
    ky.yukawa_centres_sorted(c[order], z[order], order, start, index, SCREENING, 0.06, 3.0, lo, hi, out)
    np.testing.assert_array_equal(out, plain)  # NaN (untouched) rows compare equal too
    rows = [k for k in range(lo, hi) if k not in (7, 8)]  # the reference has no answer for the coincident pair
    with np.errstate(invalid="ignore"):
        expected = ref.yukawa_force(c, z, SCREENING, 3.0, 0.06)
    close(out[rows], expected[rows])


def test_sorted_copies_one_rod_and_no_rods():
    """One rod and no rod: empty lists, a zero force and nothing to do."""
    for n in (0, 1):
        c = np.zeros((n, 3))
        nl = NeighbourList(3.0, 0.3, cell_order=True)
        nl.build(c)
        order, start, index = nl.sorted_rows
        out = np.full((n, 3), np.nan)
        ky.yukawa_centres_sorted(c[order], np.ones(n)[order], order, start, index, SCREENING, 0.0, 3.0, 0, n, out)
        np.testing.assert_array_equal(out, np.zeros((n, 3)))


def test_the_centre_list_takes_its_own_skin():
    """``neighbours.centre_skin``: the rod-centre list of the Yukawa sum takes its own skin, the tip list keeps
    ``neighbours.skin``; the Yukawa force of a state is the same to rounding (its rows hold the same pairs
    within the cut-off, summed in another order: ``close``'s tolerance), and over a run the list is built
    less often. Without it the centre list takes ``skin``."""
    from conftest import SMALL_CIRCUIT_SCENE
    from selfas_graph.io.scenario import scenario_from_text
    from selfas_graph.model.simulation import Simulation

    # a short skin, so that the centre list of the plain run is built often in a short run
    params = scenario_from_text(SMALL_CIRCUIT_SCENE).params.replace(rods={"count": 20}, neighbours={"skin": 0.02})
    plain = Simulation(params)
    assert plain.force_field.lists.centre.skin == params.neighbours.skin == 0.02
    wide = Simulation(params.replace(neighbours={"centre_skin": 1.5}))
    assert wide.force_field.lists.centre.skin == 1.5
    forces = []
    for sim in (plain, wide):
        ff = sim.force_field
        ff.evaluate(sim.state.position, sim.state.velocity)
        assert ff.lists.tip.skin == 0.02
        forces.append(ff.out["yukawa"].copy())
    assert np.abs(forces[0]).max() > 0.0
    close(forces[1], forces[0])
    builds = []
    for sim in (plain, wide):
        sim.run(t_end=0.15)
        builds.append(sim.force_field.lists.centre.n_builds)
    assert builds[1] == 1 and builds[0] > 3
