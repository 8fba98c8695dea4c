"""Statistics over seeds (selfas_graph.analysis.ensemble_stats) on hand-made data with known answers."""

import math

import numpy as np
import pytest

from selfas_graph.analysis import ensemble_stats as es


def test_mean_sem_by_hand():
    # 1, 2, 3, 4: mean 2.5, sample variance 5/3, standard error sqrt(5/3 / 4)
    mean, sem, n = es.mean_sem([1.0, 2.0, 3.0, 4.0])
    assert mean == pytest.approx(2.5, rel=1e-15) and n == 4
    assert sem == pytest.approx(math.sqrt(5.0 / 12.0), rel=1e-15)  # rel 1e-15: a handful of roundings


def test_mean_sem_leaves_out_missing_seeds_per_column():
    # rows are seeds, columns times; NaN: that seed has no frame at that time
    values = np.array([[1.0, 10.0, np.nan], [3.0, np.nan, np.nan], [5.0, 20.0, 7.0]])
    mean, sem, n = es.mean_sem(values)
    assert n.tolist() == [3, 2, 1]
    assert mean[0] == 3.0 and mean[1] == 15.0 and mean[2] == 7.0
    assert sem[0] == pytest.approx(2.0 / math.sqrt(3.0), rel=1e-15)  # s = 2
    assert sem[1] == pytest.approx(5.0, rel=1e-15)  # s = 5 sqrt 2, / sqrt 2
    assert math.isnan(sem[2])  # one seed: no spread to estimate
    mean, sem, n = es.mean_sem(np.full((2, 1), np.nan))
    assert math.isnan(mean[0]) and math.isnan(sem[0]) and n[0] == 0


def test_kaplan_meier_without_censoring_is_the_empirical_distribution():
    t, F = es.kaplan_meier([3.0, 1.0, 2.0, 2.0], [True] * 4)
    # F = 1 - a product of ratios 1 - d / at_risk (2/3 is not a float): measured exact; rel 1e-15, about
    # 4 ulp, leaves room for their roundings
    assert t.tolist() == [1.0, 2.0, 3.0] and F == pytest.approx([0.25, 0.75, 1.0], rel=1e-15)
    assert es.km_quantile(t, F, 0.5) == 2.0 and es.km_quantile(t, F, 0.25) == 1.0


def test_kaplan_meier_with_early_censoring():
    # events at 1 and 3; one run censored at 2 (a failure), one at 4 (the end time):
    # S(1) = 3/4; at t = 3 two runs are at risk (3 and 4), S = 3/4 * 1/2
    t, F = es.kaplan_meier([1.0, 3.0, 2.0, 4.0], [True, True, False, False])
    assert t.tolist() == [1.0, 3.0] and F == pytest.approx([0.25, 1 - 0.375], rel=1e-15)
    assert es.km_quantile(t, F, 0.5) == 3.0 and math.isnan(es.km_quantile(t, F, 0.75))


def test_kaplan_meier_censored_at_an_event_time_is_still_at_risk():
    t, F = es.kaplan_meier([1.0, 1.0], [True, False])
    assert F == pytest.approx([0.5], rel=1e-15)  # 1 - (1 - 1/2): measured exact; 1e-15, about 4 ulp


def test_kaplan_meier_all_censored():
    t, F = es.kaplan_meier([4.0, 4.0], [False, False])
    assert t.size == 0 and F.size == 0 and math.isnan(es.km_quantile(t, F, 0.5))


def test_wilson_interval_known_values():
    # 0 of 4: lo 0, hi = z^2 / (n + z^2) = 3.8415 / 7.8415
    lo, hi = es.wilson_interval(0, 4)
    assert lo == 0.0 and hi == pytest.approx(es.Z95**2 / (4 + es.Z95**2), rel=1e-14)
    lo, hi = es.wilson_interval(5, 10)  # symmetric about 1/2
    assert lo + hi == pytest.approx(1.0, rel=1e-14) and 0.23 < lo < 0.24  # 0.2366 (tables)
    assert es.wilson_interval(0, 0) == (0.0, 1.0)


def test_censored_times_does_not_average_the_censored_in():
    s = es.censored_times([1.0, 3.0, 6.0, 6.0], [True, True, False, False])
    assert (s["n"], s["n_observed"], s["n_censored"]) == (4, 2, 2)
    # sem = sqrt(((-1)^2 + 1^2) / 1 / 2) = 1: measured exact; rel 1e-15, about 4 ulp, for its roundings
    assert s["mean_observed"] == 2.0 and s["sem_observed"] == pytest.approx(1.0, rel=1e-15)
    assert s["fraction"] == 0.5 and s["median"] == 3.0 and math.isnan(s["q75"])
    assert s["censored_at"].tolist() == [6.0, 6.0]


@pytest.mark.parametrize("times, observed", [([1.0, np.nan], [True, False]), ([1.0], [True, False])])
def test_kaplan_meier_rejects_bad_input(times, observed):
    with pytest.raises(ValueError):
        es.kaplan_meier(times, observed)


def test_mean_sem_fits_by_hand():
    """SE_total^2 = s^2 / n + mean(err^2) / n over the seeds that have a value and an uncertainty."""
    from selfas_graph.analysis.ensemble_stats import mean_sem_fits

    v = [2.0, 2.2, 2.4, np.nan, 9.0]
    e = [0.1, 0.2, 0.2, 0.3, np.nan]  # the 4th has no value, the 5th no uncertainty: both left out
    mean, total, between, rms, n = mean_sem_fits(v, e)
    # by hand: mean 2.2, s^2 = (0.04 + 0 + 0.04) / 2 = 0.04, mean err^2 = (0.01 + 0.04 + 0.04) / 3 = 0.03
    assert n == 3 and mean == pytest.approx(2.2, rel=1e-14)  # round-off
    assert between == pytest.approx(np.sqrt(0.04 / 3), rel=1e-12)
    assert rms == pytest.approx(np.sqrt(0.03), rel=1e-12)
    assert total == pytest.approx(np.sqrt(0.04 / 3 + 0.03 / 3), rel=1e-12)
    mean, total, between, rms, n = mean_sem_fits([[1.0, np.nan]], [[0.5, 0.1]])  # one seed: no standard error
    assert n.tolist() == [1, 0] and np.isnan(total).all() and rms[0] == 0.5 and mean[0] == 1.0


def test_grouped_summary_by_hand():
    """Current in 3 of 5 seeds (one seed without a value): the active group alone, never both."""
    from selfas_graph.analysis.ensemble_stats import grouped_summary

    values = [4.0, 0.0, 6.0, np.nan, 5.0, 0.0]
    active = [True, False, True, True, True, False]  # the NaN seed counts in neither group
    g = grouped_summary(values, active)
    assert (g["k"], g["n"]) == (3, 5)
    assert (g["median"], g["min"], g["max"]) == (5.0, 4.0, 6.0)
    # a handful of roundings: measured mean exact, sem 1.9e-16 (1 ulp); 1e-14 leaves 50x
    assert g["mean"] == pytest.approx(5.0, rel=1e-14) and g["sem"] == pytest.approx(1.0 / np.sqrt(3), rel=1e-14)
    none = grouped_summary([0.0, 0.0], [False, False])
    assert none["k"] == 0 and none["n"] == 2 and all(np.isnan(none[x]) for x in ("median", "min", "max", "mean", "sem"))
    one = grouped_summary([3.0, 0.0], [True, False])
    assert one["mean"] == 3.0 and np.isnan(one["sem"])
    with pytest.raises(ValueError):
        grouped_summary([1.0], [True, False])
