"""The study's own measures (docs/model.md "Measures of the paper's claims", alignment against a null
model): the alignment |m_q| / (N mean |q|) of the largest structure, of the rods in no structure and of
all rods, the count of rods in no structure, and the rod currents' mid-plane flux over B_ext's flux
through the same disc, B_z pi R^2 in units of Phi_0 = 4 pi (B_z R^2 / 4).

The measures are taken from ``selfas_graph/studies/summary.py::STUDY_MEASURES`` by name and applied to
hand-built frames (the attributes of a saved frame they read: tip charges, positions, contacts,
parameters, flux radius; the rod currents' flux set in place of its computation). Expected values are
worked out by hand or by explicit sums here. Tolerance ROUND_OFF: sums of a few unit-size terms and one
division (about 1e-15); a wrong rod set or denominator is off by a tenth or more.
"""

import math
from types import SimpleNamespace

import numpy as np
import pytest
import scipy.integrate

from selfas_graph.studies import summary
from selfas_graph.studies.summary import STUDY_MEASURES

ROUND_OFF = 1e-12
MEASURE = {m.name: m.fn for m in STUDY_MEASURES}
UNIT = {m.name: m.unit for m in STUDY_MEASURES}


def frame(tip_a, tip_b, q, contacts, forces=None, flux=None, flux_radius=1.0):
    """A frame of rods from tip a (charge +q) to tip b (-q); ``contacts`` the tip pairs in contact (None:
    the frame has no contact data); ``flux`` the rod currents' mid-plane flux (Phi_0)."""
    tip_a, tip_b = np.asarray(tip_a, float).reshape(-1, 3), np.asarray(tip_b, float).reshape(-1, 3)
    position = np.empty((2 * len(tip_a), 3))
    position[0::2], position[1::2] = tip_a, tip_b
    charge = np.repeat(np.asarray(q, float) * np.ones(len(tip_a)), 2) * np.tile([1.0, -1.0], len(tip_a))
    graph = None if contacts is None else {"tip_contacts": np.asarray(contacts, np.int64).reshape(-1, 2)}
    f = SimpleNamespace(
        run=SimpleNamespace(tip_charge=charge),
        position=position,
        graph=graph,
        params={"forces": forces or {}},
        flux_radius=flux_radius,
    )
    if flux is not None:
        f._study_flux = flux  # the cached flux the measure reads (its computation is tested elsewhere)
    return f


def chain(n, start, direction):
    """Tips of n unit rods head to tail along ``direction`` from ``start``; contacts tip b of rod i to
    tip a of rod i + 1 (tips 2 i + 1 and 2 i + 2)."""
    d = np.asarray(direction, float) / np.linalg.norm(direction)
    points = np.asarray(start, float) + np.arange(n + 1.0)[:, None] * d
    return points[:-1], points[1:], [(2 * i + 1, 2 * i + 2) for i in range(n - 1)]


def scene(free_axes, q=1.5):
    """A head-to-tail chain of 6 rods (the largest structure), a head-to-head pair, and free rods along
    ``free_axes`` far from both; every rod of charge q. Returns (tips a, tips b, contacts)."""
    a, b, contacts = chain(6, [0.0, 0.0, 0.0], [0.3, -0.4, 1.2])
    pair_a = np.array([[10.0, 0, 0], [12.0, 0, 0]])  # tips a at the ends, tips b meeting at x = 11
    pair_b = np.array([[11.0, 0, 0], [11.0, 0, 0]])
    contacts = contacts + [(13, 15)]  # tip b of rod 6 on tip b of rod 7
    axes = np.asarray(free_axes, float).reshape(-1, 3)
    axes = axes / np.linalg.norm(axes, axis=1)[:, None]
    free_a = np.array([[-20.0 - 3 * i, 5.0, 0.0] for i in range(len(axes))]).reshape(-1, 3)
    return np.vstack([a, pair_a, free_a]), np.vstack([b, pair_b, free_a + axes]), contacts


def test_a_head_to_tail_chain_has_alignment_one():
    """The largest structure, a chain of 6 equal rods head to tail, has |m_q| = 6 q: alignment 1, beside a
    head-to-head pair and two free rods of the same charge; the count of free rods is 2."""
    a, b, contacts = scene([[1, 0, 0], [0, 1, 0]])
    f = frame(a, b, 1.5, contacts)
    assert MEASURE["largest_alignment"](f) == pytest.approx(1.0, abs=ROUND_OFF)
    assert MEASURE["free_rods"](f) == 2.0


def test_a_head_to_head_pair_as_the_largest_structure_has_alignment_zero():
    """A head-to-head pair (the only structure) has m_q = 0: alignment 0; its rods are not free."""
    f = frame(np.array([[0.0, 0, 0], [2.0, 0, 0]]), np.array([[1.0, 0, 0], [1.0, 0, 0]]), 0.8, [(1, 3)])
    assert MEASURE["largest_alignment"](f) == pytest.approx(0.0, abs=ROUND_OFF)
    assert MEASURE["free_rods"](f) == 0.0


@pytest.mark.parametrize(
    "axes, expected",
    [
        ([[1, 0, 0], [1, 0, 0], [1, 0, 0]], 1.0),  # lined up: |m_q| = 3 q
        ([[0, 0, 1], [0, 0, -1]], 0.0),  # antiparallel: they cancel
        ([[1, 0, 0], [0, 1, 0]], math.sqrt(2) / 2),  # at right angles: |m_q| = sqrt(2) q over 2 q
    ],
)
def test_free_rods_alignment_by_hand(axes, expected, monkeypatch):
    """The rods in no structure (no tip contact) have alignment |sum q (x_a - x_b)| / (n q): worked out by
    hand for rods lined up, antiparallel and at right angles; the chain and the pair are left out. The
    page's minimum count of such rods (MIN_FREE_RODS, tested in tests/cli/test_studies.py) set to 1."""
    monkeypatch.setattr(summary, "MIN_FREE_RODS", 1)
    a, b, contacts = scene(axes)
    f = frame(a, b, 1.5, contacts)
    assert MEASURE["free_rods"](f) == len(axes)
    assert MEASURE["free_alignment"](f) == pytest.approx(expected, abs=ROUND_OFF)


def test_all_rods_alignment_is_the_explicit_sum():
    """The alignment of all rods is |sum_i q_i (x_a,i - x_b,i)| / (N mean |q_i|), also for unequal charges
    and random axes: against that sum, rod by rod."""
    rng = np.random.default_rng(21)
    a, b, contacts = scene(rng.normal(size=(5, 3)))
    q = rng.uniform(2 / 3, 2, len(a))
    f = frame(a, b, q, contacts)
    m = sum(qi * (ai - bi) for qi, ai, bi in zip(q, a, b))
    assert MEASURE["all_alignment"](f) == pytest.approx(np.linalg.norm(m) / (len(a) * np.abs(q).mean()), abs=ROUND_OFF)
    # the chain's rods now differ in charge: its alignment is sum q_i over 6 mean |q| of all rods
    assert MEASURE["largest_alignment"](f) == pytest.approx(q[:6].sum() / (6 * q.mean()), abs=ROUND_OFF)


def test_no_free_rods_or_no_contact_data_give_nan(monkeypatch):
    """With every rod in a structure the free rods' alignment is NaN (no rods to average over) and their
    count 0; a frame without contact data gives NaN for the structure measures and the free rods, while
    the alignment of all rods needs no contacts (the minimum count of free rods set to 1, as above)."""
    monkeypatch.setattr(summary, "MIN_FREE_RODS", 1)
    a, b, contacts = chain(4, [0, 0, 0], [0, 0, 1])
    f = frame(a, b, 1.0, contacts)
    assert math.isnan(MEASURE["free_alignment"](f)) and MEASURE["free_rods"](f) == 0.0
    assert MEASURE["largest_alignment"](f) == pytest.approx(1.0, abs=ROUND_OFF)
    f = frame(a, b, 1.0, None)
    for name in ("largest_alignment", "free_alignment", "free_rods"):
        assert math.isnan(MEASURE[name](f)), name
    assert MEASURE["all_alignment"](f) == pytest.approx(1.0, abs=ROUND_OFF)
    # no contacts at all: no structure (NaN for the largest), every rod free
    f = frame(a, b, 1.0, [])
    assert math.isnan(MEASURE["largest_alignment"](f)) and MEASURE["free_rods"](f) == 4.0
    assert MEASURE["free_alignment"](f) == pytest.approx(1.0, abs=ROUND_OFF)


def uniform_field_flux(b_z, radius):
    """Flux of a uniform B_z through the disc of ``radius`` about the axis in units of Phi_0 = 4 pi
    (docs/model.md 'Reduced units'), by a numerical integral of B_z over the disc in polar coordinates."""
    flux, _ = scipy.integrate.dblquad(lambda r, phi: b_z * r, 0.0, 2 * math.pi, 0.0, radius, epsabs=0, epsrel=1e-13)
    return flux / (4 * math.pi)


@pytest.mark.parametrize("b_z, radius", [(1.0, 1.0), (0.35, 7.5), (-2.0, 3.2)])
def test_flux_over_external_is_one_for_the_flux_of_the_field_itself(b_z, radius):
    """Rod currents whose mid-plane flux equals that of the uniform B_z through the same disc give a
    ratio of 1, the flux worked out by integrating B_z over the disc (B_z pi R^2 / (4 pi) = B_z R^2 / 4):
    the field's flux is the one over the disc of the frame's flux radius, in Phi_0. Tolerance: the
    integral of a linear integrand, exact to round-off (1e-13 asked of it), and a few roundings."""
    forces = {"uniform_field": {"B": [0.2, -0.1, b_z]}}
    f = frame(
        [[0, 0, 0]], [[0, 0, 1]], 1.0, [], forces=forces, flux=uniform_field_flux(b_z, radius), flux_radius=radius
    )
    assert MEASURE["flux_over_external"](f) == pytest.approx(1.0, abs=ROUND_OFF)


def test_flux_over_external_scales_as_flux_over_bz_r_squared():
    """The ratio is the flux over B_z R^2 / 4: linear in the flux, inverse in B_z and in R^2 (twice the
    radius, a quarter of the ratio, exactly in binary); NaN without a uniform field or with B_z = 0."""
    ratio = MEASURE["flux_over_external"]
    field = {"uniform_field": {"B": [0.0, 0.0, 0.5]}}
    assert ratio(frame([[0, 0, 0]], [[0, 0, 1]], 1.0, [], field, flux=0.3, flux_radius=2.0)) == pytest.approx(
        0.3 / (0.5 * 2.0**2 / 4), rel=ROUND_OFF
    )
    base = ratio(frame([[0, 0, 0]], [[0, 0, 1]], 1.0, [], field, flux=0.7, flux_radius=1.5))
    assert ratio(frame([[0, 0, 0]], [[0, 0, 1]], 1.0, [], field, flux=0.7, flux_radius=3.0)) == base / 4
    assert ratio(frame([[0, 0, 0]], [[0, 0, 1]], 1.0, [], field, flux=1.4, flux_radius=1.5)) == 2 * base
    double = {"uniform_field": {"B": [0.0, 0.0, 1.0]}}
    assert ratio(frame([[0, 0, 0]], [[0, 0, 1]], 1.0, [], double, flux=0.7, flux_radius=1.5)) == base / 2
    for forces in ({}, {"uniform_field": {"B": [1.0, 0.0, 0.0]}}):
        assert math.isnan(ratio(frame([[0, 0, 0]], [[0, 0, 1]], 1.0, [], forces, flux=0.7)))


def test_every_list_of_measures_names_measures_that_exist():
    """The measures are listed by hand in several places (analyze's columns and counts, the study
    table's rows, the series panels, the claim measures, the grouped and fitted measures, the words on
    the page): each must name a measure that exists, or a row or panel is left out without a word
    (studies/page.py skips a row its summary lacks: a misspelled row passed every test). A measure of
    a summary is a row of the study table or named here as not one, so that a new one is placed on
    purpose (ARCHITECTURE.md 'How to add a measure of a saved frame')."""
    from selfas_graph.analysis.claims import CLAIM_KEYS
    from selfas_graph.cli.analyze import _COUNTS, SERIES_COLUMNS
    from selfas_graph.studies.figures import SERIES_MEASURES
    from selfas_graph.studies.page import TABLE_MEASURES
    from selfas_graph.studies.stats import FIT_ERRORS, GROUPED, LABELS
    from selfas_graph.studies.verdicts import CLAIM_MEASURES

    assert set(SERIES_COLUMNS) - {"frame", "time"} <= set(CLAIM_KEYS) and set(_COUNTS) <= set(CLAIM_KEYS)
    names = set(MEASURE)
    for listed in (TABLE_MEASURES, SERIES_MEASURES, CLAIM_MEASURES, GROUPED, LABELS, FIT_ERRORS, FIT_ERRORS.values()):
        assert set(listed) <= names, sorted(set(listed) - names)
    errors = set(FIT_ERRORS.values())
    assert names - errors <= set(LABELS), f"measures without words on the page: {sorted(names - errors - set(LABELS))}"
    not_tabled = errors | {"cycle_rank_largest", "structures", "free_rods", "all_alignment", "flux_over_external"}
    not_tabled |= {"largest_moment_J_z"}
    assert names - not_tabled == set(TABLE_MEASURES), sorted(
        names.symmetric_difference(not_tabled | set(TABLE_MEASURES))
    )


def test_the_page_shows_each_measures_own_unit():
    """A unit is the measure's (``Measure.unit``); the page's words (``LABELS``) show it, or nothing
    for a count or a pure number (``UNSHOWN_UNITS``), so a unit changed in one place and not the
    other fails here."""
    from selfas_graph.studies.stats import LABELS, UNSHOWN_UNITS

    for name, (_, shown) in LABELS.items():
        unit = UNIT[name]
        assert shown == ("" if unit in UNSHOWN_UNITS else unit), (name, unit, shown)


def test_the_page_groups_and_fits_the_measures_the_summary_does():
    """A measure of the seeds that carry current is summarised over them alone (docs/model.md "Measures
    of the paper's claims": never a mean over both groups), in the summary and on the page alike: the
    flux over B_ext's, over the dipole's and the largest structure's m_J,z were grouped on the page and
    averaged over every seed in summary.json."""
    from selfas_graph.studies.stats import FIT_ERRORS, GROUPED

    assert set(GROUPED) == {m.name for m in STUDY_MEASURES if m.grouped}
    assert set(FIT_ERRORS) == {m.name for m in STUDY_MEASURES if m.err is not None}
