"""The results pipeline: the studies file, the statistics of the page, its generated blocks, and a
study run, summarised and written into a page end to end (on the quick scene)."""

import dataclasses
import json
import math
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from selfas_graph.provenance import older_version, version_key
from selfas_graph.studies import StudiesError, later_version, load_studies
from selfas_graph.studies.page import replace_blocks
from selfas_graph.studies.stats import grouped_stat, measure_text, plain_stat

ROOT = Path(__file__).resolve().parents[2]


def test_the_shipped_studies_file_loads_and_every_claim_names_its_study():
    studies = load_studies(ROOT / "docs" / "studies.toml")
    assert {"fig2", "fig6", "fig8"} <= set(studies.studies)
    assert studies.study("fig2").seeds >= 8 and studies.study("fig6").seeds >= 5 and studies.study("fig8").seeds >= 5
    for c in studies.claims:
        assert c.study in studies.studies and (not c.null or c.null in studies.studies)


@pytest.mark.parametrize(
    "text, words",
    [
        ("[study.a]\nscenario = 'x'\nseeds = 2\n", "missing key 't_end'"),
        ("[study.a]\nscenario = 'x'\nseeds = 2\nt_end = 1\nsedes = 3\n", "unknown key 'sedes'"),
        ("[study.a]\nscenario = 'x'\nseeds = 0\nt_end = 1\n", "must be finite and positive, seeds >= 1"),
        ("[study.a]\nscenario = 'x'\nseeds = 2\nt_end = 1\ntable_times = [2.0]\n", "table_times"),
        ("[[claim]]\nid='c'\nclaim='c'\npaper='p'\nstudy='nope'\nmeasure='m'\ntime=1\n", "no study named 'nope'"),
        ("[stduy.a]\n", "unknown key(s) ['stduy']"),
        # a misspelled measure gave a row of n/a and no verdict
        (
            "[study.a]\nscenario = 'x'\nseeds = 2\nt_end = 1\n[[claim]]\nid='c'\nclaim='c'\npaper='p'\nstudy='a'\n"
            "measure='filament_rods'\nalso=['largest_fracton']\ntime=1\n",
            "claim[0].also: no measure named 'largest_fracton'; valid: ",
        ),
        ("trajectories_since = 'new'\n", "trajectories_since"),
        ("trajectories_since = 4\n", "trajectories_since"),
        (
            "trajectories_since = '0.4.0'\n[study.a]\nscenario = 'x'\nseeds = 2\nt_end = 1\ntrajectories_since = '0.3.0'\n",
            "study.a.trajectories_since",
        ),
        ("[study.a]\nscenario = 'x'\nseeds = 2\nt_end = 1\ntrajectories_since = 'soon'\n", "got 'soon'"),
        ("[study.a\n", "not a valid TOML file"),
        # entries that are no numbers, and names and times that point nowhere, were taken without a word
        # or ended `study` with a bare ValueError
        ("[study.a]\nscenario = 'x'\nseeds = 2\nt_end = 1\ntable_times = ['x']\n", "a.table_times: a list of numbers"),
        (
            "[study.a]\nscenario = 'x'\nseeds = 2\nt_end = 1\nkind = 'percolation'\ncounts = [10, 'a']\n",
            "a.counts: a list of numbers",
        ),
        ("[study.a]\nscenario = 'x'\nseeds = 2\nt_end = 1\ncounts = [10.5]\n", "a.counts: a list of whole numbers"),
        ("[study.a]\nscenario = 'x'\nseeds = 2\nt_end = 1\nnull_of = 'nosuch'\n", "a.null_of: no study named 'nosuch'"),
        (
            "[study.a]\nscenario = 'x'\nseeds = 2\nt_end = 10\n[[claim]]\nid='c'\nclaim='c'\npaper='p'\nstudy='a'\n"
            "measure='filament_rods'\ntime=99\n",
            "claim[0]: time 99 and window [] must lie in [0, t_end = 10] of study 'a'",
        ),
        (
            "[study.a]\nscenario = 'x'\nseeds = 2\nt_end = 10\n[[claim]]\nid='c'\nclaim='c'\npaper='p'\nstudy='a'\n"
            "measure='filament_rods'\ntime=9\nwindow=[true, 5]\n",
            "claim[0].window: a list of numbers",
        ),
        # times that no summary holds gave n/a rows and "the null model has no value"
        (
            "[study.a]\nscenario = 'x'\nseeds = 2\nt_end = 10\nevery = 5\n[[claim]]\nid='c'\nclaim='c'\npaper='p'\n"
            "study='a'\nmeasure='filament_rods'\ntime=7\n",
            "claim[0].time 7 is no summarised time of study 'a' (study)",
        ),
        (
            "[study.a]\nscenario = 'x'\nseeds = 2\nt_end = 10\nevery = 5\n[[claim]]\nid='c'\nclaim='c'\npaper='p'\n"
            "study='a'\nmeasure='filament_rods'\ntime=10\nwindow=[6, 8]\n",
            "claim[0].window [6.0, 8.0] holds no summarised time of study 'a'",
        ),
        (
            "[study.a]\nscenario = 'x'\nseeds = 2\nt_end = 10\n[sweep.s]\ntitle='t'\nparameter='p'\nbase='a'\n"
            "base_value=1\ntime=50\n",
            "sweep.s.time 50 is no summarised time of study a",
        ),
        (
            "[study.a]\nscenario = 'x'\nseeds = 2\nt_end = 10\n[[claim]]\nid='c'\nclaim='c'\npaper='p'\nstudy='a'\n"
            "null='a'\nmeasure='filament_rods'\ntime=10\n",
            "claim[0].null: 'a' is the claim's own study",
        ),
        (
            "[study.a]\nscenario = 'x'\nseeds = 2\nt_end = 10\n[[claim]]\nid='c'\nclaim='c'\npaper='p'\nstudy='a'\n"
            "measure='filament_rods'\ntime=10\n[[claim]]\nid='c'\nclaim='d'\npaper='p'\nstudy='a'\n"
            "measure='cycle_rank'\ntime=10\n",
            "claim id 'c' is given to more than one claim",
        ),
        # tables that are not tables, an infinite end time: tracebacks before
        ("claim = 'x'\n", "claim: [[claim]] tables, got 'x'"),
        ("study = 5\n", "study: tables [study.NAME], got 5"),
        ("claim = ['x']\n", "claim[0]: must be a table"),
        ("[study.a]\nscenario = 'x'\nseeds = 2\nt_end = inf\n", "must be finite and positive"),
        ("[study.a]\nscenario = 'x'\nseeds = 2\nt_end = 1\nfirst_seed = -3\n", "first_seed >= 0"),
        ("[study.a]\nscenario = 'x'\nseeds = 2\nt_end = 1\noverrides = [60]\n", "a.overrides: a list of strings"),
        ("[study.a]\nscenario = 'x'\nseeds = 2\nt_end = 1\nsweep_value = 2\n", "given without the sweep"),
        (
            "[study.a]\nscenario = 'x'\nseeds = 2\nt_end = 1\nsweep = 's'\nsweep_value = 1\n[sweep.s]\ntitle='t'\n"
            "parameter='p'\nbase='a'\nbase_value=1\ntime=1\n",
            "sweep.s.base: a is the sweep's base at base_value; it names the sweep itself too",
        ),
    ],
)
def test_a_bad_studies_file_is_refused_naming_the_key(tmp_path, text, words):
    path = tmp_path / "studies.toml"
    path.write_text(text)
    with pytest.raises(StudiesError, match="studies.toml") as err:
        load_studies(path)
    assert words in str(err.value)


def test_versions_are_ordered_by_their_release_numbers():
    assert version_key("0.4.0+source") == version_key("0.4") == version_key("0.4.0")
    assert version_key("0.10.1") > version_key("0.9.9") > version_key("0.9.9rc1")
    assert version_key("0.4.0.dev1") < version_key("0.4.0") and version_key("0.4.0a2") < version_key("0.4.0")
    assert version_key("") is None and version_key("unknown") is None
    assert older_version("0.3.0", "0.4.0") and older_version(None, "0.4.0") and older_version("unknown", "0.4.0")
    assert not older_version("0.4.0+source", "0.4.0") and not older_version("0.3.0", "")


def _shipped_with_runs_of_version(folder, version):
    """The shipped studies file, with the committed summaries copied into ``folder``, every run's
    version set to ``version`` (runs of known version)."""
    for path in (ROOT / "docs" / "results").glob("*.json"):
        summary = json.loads(path.read_text())
        for entry in [summary] if summary.get("kind") == "percolation" else summary["seeds"]:
            entry["version"] = version
        (folder / path.name).write_text(json.dumps(summary))
    return load_studies(ROOT / "docs" / "studies.toml")


def test_studies_of_runs_older_than_the_trajectories_are_marked_where_they_are_used(tmp_path):
    """With ``trajectories_since`` newer than a study's runs, its provenance, the status paragraph,
    each claim and convergence row that uses it and its sweep rows say it is to be run again; with
    the runs' own version nothing is marked. The committed summaries, their versions set to 1.0.0,
    serve as runs of known version."""
    import dataclasses

    from selfas_graph.studies.page import page_blocks
    from selfas_graph.studies.stats import older_runs

    shipped = _shipped_with_runs_of_version(tmp_path, "1.0.0")
    same = page_blocks(dataclasses.replace(shipped, trajectories_since="1.0.0"), tmp_path)
    assert "to be run again" not in "".join(same.values()) and "1.0.0 or later" in same["status"]
    blocks = page_blocks(dataclasses.replace(shipped, trajectories_since="1.1"), tmp_path)
    assert older_runs(json.loads((tmp_path / "fig2.json").read_text()), "1.1") == ["1.0.0"]
    assert (
        "fig2 (runs of 1.0.0; trajectories since 1.1)" in blocks["status"]
        and "Runs to be made again" in blocks["status"]
    )
    assert "Runs of version 1.0.0, made before the trajectory change of version 1.1" in blocks["runs fig2"]
    assert "`selfas-graph study run fig2 --force`" in blocks["runs fig2"]
    claims = blocks["claims"].splitlines()[2:]
    assert claims and all("fig2: 1.0.0" in r and "to be run again" in r for r in claims)
    assert "to be run again" in blocks["convergence"] and "to be run again" in blocks["sensitivity fig2_rods"]


def test_a_study_of_its_own_later_trajectories_is_marked_alone(tmp_path):
    """A study's own ``trajectories_since`` (a change that moved only its scenes) marks its runs of
    an older version, and the claims and sweep rows that use them, while the other studies of that
    version stay unmarked; ``Studies.since`` falls back on the file's value."""
    import dataclasses

    from selfas_graph.studies.page import page_blocks

    shipped = _shipped_with_runs_of_version(tmp_path, "1.0.0")
    own = {
        n: dataclasses.replace(s, trajectories_since="1.1" if n == "fig6" else "1.0.0")
        for n, s in shipped.studies.items()
    }
    studies = dataclasses.replace(shipped, trajectories_since="1.0.0", studies=own)
    assert studies.since("fig6") == "1.1" and studies.since("fig2") == "1.0.0" and studies.since("nope") == "1.0.0"
    blocks = page_blocks(studies, tmp_path)
    assert "fig6 (runs of 1.0.0; trajectories since 1.1)" in blocks["status"] and "fig2 (" not in blocks["status"]
    assert "made before the trajectory change of version 1.1" in blocks["runs fig6"]
    assert "to be run again" not in blocks["runs fig2"]
    assert "to be run again" in blocks["sensitivity fig6_delta_J0"]
    assert "to be run again" not in blocks["sensitivity fig2_rods"]
    rows = blocks["claims"].splitlines()[2:]  # no claim uses the Fig. 6 scene
    assert rows and not any("to be run again" in r for r in rows)
    # a claim whose study and null model changed in two versions names both, in version order
    own["fig2"] = dataclasses.replace(own["fig2"], trajectories_since="1.10")
    own["fig2_free"] = dataclasses.replace(own["fig2_free"], trajectories_since="1.9")
    rows = page_blocks(dataclasses.replace(studies, studies=own), tmp_path)["claims"].splitlines()[2:]
    assert any("made before the trajectory change of 1.9 and 1.10 (fig2: 1.0.0, fig2_free: 1.0.0)" in r for r in rows)
    fresh = page_blocks(dataclasses.replace(shipped, trajectories_since="", studies=own), tmp_path)["status"]
    assert "Runs to be made again" in fresh
    assert later_version("0.4.1", "0.4.0") == later_version("0.4.0", "0.4.1") == "0.4.1" == later_version("", "0.4.1")
    with pytest.raises(ValueError, match="'garbage'"):
        later_version("0.4.1", "garbage")
    text = "trajectories_since = '0.4.0'\n[study.a]\nscenario = 'x'\nseeds = 2\nt_end = 1\n[study.b]\nscenario = 'x'\n"
    (tmp_path / "s.toml").write_text(text + "seeds = 2\nt_end = 1\ntrajectories_since = '0.4.1'\n")
    loaded = load_studies(tmp_path / "s.toml")
    assert (loaded.since("a"), loaded.since("b"), loaded.study("a").trajectories_since) == ("0.4.0", "0.4.1", "")
    from selfas_graph.studies import study_ensemble

    b = dataclasses.replace(loaded.study("b"), scenario=str(ROOT / "scenarios" / "quick.toml"))
    assert study_ensemble(b, tmp_path, older_than="0.4.0").older_than == "0.4.1"  # its seed files: from 0.4.1 on
    assert study_ensemble(b, tmp_path, older_than="0.5").older_than == "0.5"


def test_plain_stat_by_hand():
    s = plain_stat([1.0, 2.0, 3.0, np.nan])
    assert s["n"] == 3 and s["mean"] == 2.0
    assert math.isclose(s["sem"], 1.0 / math.sqrt(3), rel_tol=1e-15)  # s = 1, n = 3
    # each value's own uncertainty adds mean(err^2) / n to SE^2: 1/3 + (0.3^2 + 0.4^2 + 0.5^2) / 3 / 3
    s = plain_stat([1.0, 2.0, 3.0], errors=[0.3, 0.4, 0.5])
    assert math.isclose(s["sem"] ** 2, 1 / 3 + 0.5 / 9, rel_tol=1e-14)
    assert plain_stat([1.0, 2.0, 3.0], errors=[0.3, 0.4, np.nan])["n"] == 2  # no uncertainty: left out
    assert plain_stat([np.nan])["n"] == 0
    assert math.isnan(plain_stat([5.0])["sem"])  # one seed: no spread


def test_a_dimension_at_a_time_no_seed_reached_is_no_data_not_untestable():
    """An unfinished study (seeds stopped at t = 4 and 16.5, the table asks t = 30): the dimension there is
    n/a, as every other measure; 'not testable at this size' is for seeds that reached t with no fit."""
    values = {"values": [[2.0, None, None], [2.2, None, None]]}
    errors = {"values": [[0.1, None, None], [0.1, None, None]]}
    summary = {
        "times": [4.0, 16.0, 30.0],
        "seeds": [{"t_end": 4.0}, {"t_end": 16.5}],
        "measures": {"rg_dimension": values, "rg_dimension_err": errors},
    }
    assert measure_text(summary, "rg_dimension", 30.0) == "n/a"
    assert measure_text(summary, "rg_dimension", 16.0).startswith("not testable at this size")  # seed 2 reached it
    assert measure_text(summary, "rg_dimension", 4.0).startswith("2.1 ± ")


def test_grouped_stat_reports_the_group_it_describes():
    """Three seeds carry current, two do not: k = 3 of n = 5, the median and mean of the three only."""
    g = grouped_stat([4.0, 0.0, 6.0, 0.0, 5.0], [True, False, True, False, True])
    assert (g["k"], g["n"]) == (3, 5)
    assert (g["median"], g["min"], g["max"], g["mean"]) == (5.0, 4.0, 6.0, 5.0)
    g = grouped_stat([0.0, 0.0], [False, False])
    assert (g["k"], g["n"]) == (0, 2) and math.isnan(g["mean"])


def test_grouped_measures_follow_the_summarys_current_flag_and_say_when_there_is_no_circuit():
    """The seeds a grouped measure describes are those the summary flags as carrying current (rods in
    gap-spanning filaments, or a nonzero current): without a circuit the total current is None in
    every seed, yet the rods span the gap, and the page says so instead of "0 of n carry current"."""
    rods = {"values": [[700.0], [0.0], [650.0]]}
    no_circuit = {
        "times": [600.0],
        "seeds": [{"seed": k} for k in (1, 2, 3)],
        "current": [[1.0], [0.0], [1.0]],
        "measures": {"filament_rods": rods, "total_current": {"values": [[None], [None], [None]]}},
    }
    text = measure_text(no_circuit, "filament_rods", 600.0)
    assert text.startswith("2 of 3 seeds span the gap (no circuit): median 675 [650 to 700]"), text
    with_circuit = no_circuit | {
        "measures": {"filament_rods": rods, "total_current": {"values": [[4.0], [0.0], [3.0]]}}
    }
    assert measure_text(with_circuit, "filament_rods", 600.0).startswith("2 of 3 seeds carry current: median 675")
    older = {k: v for k, v in with_circuit.items() if k != "current"}  # no flag: a nonzero current decides
    assert measure_text(older, "filament_rods", 600.0).startswith("2 of 3 seeds carry current")


def test_a_sweep_point_of_a_grouped_measure_is_the_mean_of_the_seeds_that_carry_current():
    """The sweep's figure plots what its table prints: for a grouped measure the mean of the k seeds
    with current (and k of n), not a mean with the others as 0; beside it, apart, the mean over every
    seed that the step and trend rows test."""
    from types import SimpleNamespace

    from selfas_graph.studies.sweeps import sweep_points

    summary = {
        "times": [300.0],
        "seeds": [{"seed": k} for k in (1, 2, 3)],
        "current": [[1.0], [0.0], [1.0]],
        "measures": {
            "filament_rods": {"values": [[680.0], [0.0], [700.0]]},
            "total_current": {"values": [[4.0], [0.0], [3.0]]},
            "inside_R_plas": {"values": [[0.5], [0.2], [0.3]]},
        },
    }
    studies = SimpleNamespace(sweeps={"s": SimpleNamespace(time=300.0)}, sweep_points=lambda name: [(0.0, "p0")])
    ((_, rods),) = sweep_points(studies, {"p0": summary}, "s", "filament_rods")
    assert (rods["n"], rods["of"], rods["mean"]) == (2, 3, 690.0)
    ((_, every),) = sweep_points(studies, {"p0": summary}, "s", "filament_rods", every_seed=True)
    assert (every["n"], every["mean"]) == (3, 460.0)  # what the tests use, drawn beside it
    ((_, frac),) = sweep_points(studies, {"p0": summary}, "s", "inside_R_plas")
    assert frac["n"] == 3 and frac["mean"] == pytest.approx(1.0 / 3.0)


def test_a_sweeps_trend_ranks_every_seed_and_adjusts_over_the_measures():
    """Two points: the fraction within R_plas 0.1, 0.2, 0.3 at value 0 and 0.4, 0.5, 0.6 at value 1 is
    concordant in all 9 pairs across the points: tau-b = 9 / sqrt(15 * 9) = 0.775 (ties in the value:
    15 pairs of the 6 seeds less the 3 + 3 tied), scipy's p. The rods in current-carrying filaments
    rank every seed, 0 where it carries none (1 of 3 carries current at value 0): ranking only those
    that do picked the seeds by the outcome. Holm over the measures with a trend; a fitted dimension's
    steps are given with and without each seed's fit error."""
    from scipy.stats import kendalltau

    from selfas_graph.studies.sweeps import _step_p, _trend_text, sweep_trends

    def point(frac, rods, flags, dims, errs):
        return {
            "times": [300.0],
            "seeds": [{"seed": k + 1} for k in range(3)],
            "current": [[f] for f in flags],
            "measures": {
                "inside_R_plas": {"values": [[v] for v in frac]},
                "filament_rods": {"values": [[v] for v in rods]},
                "total_current": {"values": [[float(f)] for f in flags]},
                "fractal_dimension": {"values": [[v] for v in dims]},
                "fractal_dimension_err": {"values": [[v] for v in errs]},
            },
        }

    a = point([0.1, 0.2, 0.3], [0.0, 500.0, 0.0], [0, 1, 0], [2.0, 2.1, 2.2], [0.5] * 3)
    b = point([0.4, 0.5, 0.6], [600.0, 700.0, 800.0], [1, 1, 1], [2.3, 2.4, 2.5], [0.5] * 3)
    rows = {r["measure"]: r for r in sweep_trends([(0.0, a), (1.0, b)], 300.0)}
    frac = rows["inside_R_plas"]
    assert frac["n"] == 6 and frac["tau"] == pytest.approx(9.0 / math.sqrt(15.0 * 9.0))
    assert frac["p"] == pytest.approx(kendalltau([0, 0, 0, 1, 1, 1], [0.1, 0.2, 0.3, 0.4, 0.5, 0.6]).pvalue)
    assert rows["filament_rods"]["n"] == 6
    from selfas_graph.studies.sweeps import _cell

    assert _cell(a, "filament_rods", 300.0).endswith("; every seed, 0 without current: 167 ± 167 (3)")
    assert "every seed" not in _cell(b, "filament_rods", 300.0)  # all carry current: the one mean
    want = kendalltau([0, 0, 0, 1, 1, 1], [0, 500, 0, 600, 700, 800])
    assert (rows["filament_rods"]["tau"], rows["filament_rods"]["p"]) == pytest.approx((want.statistic, want.pvalue))
    assert math.isnan(rows["midplane_flux"]["p"]) and math.isnan(rows["midplane_flux"]["holm"])
    tested = [r for r in rows.values() if math.isfinite(r["p"])]
    smallest = min(tested, key=lambda r: r["p"])
    assert smallest["holm"] == pytest.approx(min(1.0, len(tested) * smallest["p"]))
    assert _trend_text(frac).startswith("rises: τ = +0.77, p = ") or _trend_text(frac).startswith("none shown")
    assert _trend_text({"tau": -0.5, "p": 0.01, "holm": 0.02}) == "falls: τ = −0.50, p = 0.01 (0.02 after Holm)"
    assert _trend_text({"tau": 0.1, "p": 0.5, "holm": 1.0}).startswith("none shown")
    # fit errors of 0.5 swamp the steps of 0.3; the seeds alone resolve them
    step = _step_p([(0.0, a), (1.0, b)], "fractal_dimension", 300.0)
    assert step.startswith("0.") and "(seeds alone: 0.0" in step, step


def test_a_sweeps_steps_are_paired_where_its_points_start_from_the_same_rods():
    """Three points: the first two agree at t = 0 seed by seed (a force's strength changed), the third
    does not (other rods). The first step is the paired t-test over the seeds both have (differences
    0.3, 0.2, 0.4: p = 2 t_2.sf(0.3 / (0.1 / sqrt 3))), the second Welch's; the label says which."""
    from selfas_graph.studies.pairing import paired_stat
    from selfas_graph.studies.stats import plain_stat
    from selfas_graph.studies.sweeps import _step_label, _step_p
    from selfas_graph.studies.verdicts import welch_p

    def point(start, late):
        return {
            "times": [0.0, 300.0],
            "seeds": [{"seed": k + 1} for k in range(3)],
            "measures": {"inside_R_plas": {"values": [[x, y] for x, y in zip(start, late)]}},
        }

    a, b = point([0.1, 0.2, 0.3], [0.1, 0.2, 0.3]), point([0.1, 0.2, 0.3], [0.4, 0.4, 0.7])
    c = point([0.5, 0.6, 0.7], [0.9, 0.8, 1.0])
    paired = paired_stat([0.4, 0.4, 0.7], [0.1, 0.2, 0.3])["p"]
    welch = welch_p(plain_stat([0.9, 0.8, 1.0]), plain_stat([0.4, 0.4, 0.7]))
    assert paired != pytest.approx(welch_p(plain_stat([0.4, 0.4, 0.7]), plain_stat([0.1, 0.2, 0.3])))
    assert _step_p([(0, a), (1, b), (2, c)], "inside_R_plas", 300.0) == f"{paired:.2g} (3); {welch:.2g} (3, 3)"
    assert _step_label([(0, a), (1, b), (2, c)]).startswith("p (paired; Welch) from each value")
    assert _step_label([(0, a), (1, b)]).startswith("paired p, seed by seed,")
    assert _step_label([(1, b), (2, c)]).startswith("Welch p")


def test_the_alignment_of_the_rods_in_no_structure_needs_30_of_them():
    """Committed summaries: the rule applies on loading, from the kept counts; a frame: NaN below 30
    such rods, the value from 30 on."""
    from types import SimpleNamespace

    from selfas_graph.studies.stats import MIN_FREE_RODS, with_minimum_counts
    from selfas_graph.studies.summary import _alignment

    s = {"measures": {"free_alignment": {"values": [[0.9, 0.3]]}, "free_rods": {"values": [[2.0, 40.0]]}}}
    assert with_minimum_counts(s)["measures"]["free_alignment"]["values"] == [[None, 0.3]]
    assert MIN_FREE_RODS == 30

    def frame(n_rods):  # rods along z, all free (no contacts), tips +q at the top
        q = np.tile([1.0, -1.0], n_rods)
        pos = np.zeros((2 * n_rods, 3))
        pos[0::2, 2], pos[1::2, 2] = 0.5, -0.5
        pos[:, 0] = np.repeat(3.0 * np.arange(n_rods), 2)
        return SimpleNamespace(
            run=SimpleNamespace(tip_charge=q), position=pos, graph={"tip_contacts": np.zeros((0, 2))}
        )

    from selfas_graph.studies.stats import measure_text

    cell = {"times": [1.0], "seeds": [{}, {}, {}], "measures": {}}
    cell["measures"]["free_rods"] = {"values": [[40.0], [10.0], [50.0]]}
    cell["measures"]["free_alignment"] = {"values": [[0.3], [None], [0.5]]}
    assert measure_text(cell, "free_alignment", 1.0) == "0.4 ± 0.1 (2); 1 seed with fewer than 30 such rods left out"
    cell["measures"]["free_rods"] = {"values": [[4.0], [10.0], [5.0]]}
    cell["measures"]["free_alignment"] = {"values": [[None], [None], [None]]}
    assert measure_text(cell, "free_alignment", 1.0) == "n/a (fewer than 30 such rods in every seed)"
    assert math.isnan(_alignment(frame(29), "free"))
    assert _alignment(frame(30), "free") == pytest.approx(1.0)
    assert _alignment(frame(3), "all") == pytest.approx(1.0)  # the rule is the free rods' alone


def test_the_sweep_figure_draws_a_point_of_one_seed_hollow(tmp_path, monkeypatch):
    """A point whose measure one seed gives has no spread: hollow, not a bar of zero length that reads
    as a certain value; points of several seeds are filled."""
    from types import SimpleNamespace

    from selfas_graph.studies import figures

    def point(rods, flags):
        return {
            "times": [300.0],
            "seeds": [{"seed": k + 1} for k in range(len(rods))],
            "current": [[f] for f in flags],
            "measures": {"filament_rods": {"values": [[v] for v in rods]}},
        }

    summaries = {"a": point([500.0, 0.0, 0.0], [1, 0, 0]), "b": point([600.0, 650.0, 700.0], [1, 1, 1])}
    sweep = SimpleNamespace(title="t", parameter="x", base="b", base_value=1.0, time=300.0)
    studies = SimpleNamespace(sweeps={"s": sweep}, sweep_points=lambda name: [(0.0, "a"), (1.0, "b")])
    drawn = {}
    monkeypatch.setattr(figures, "_save", lambda fig, out: drawn.setdefault("fig", fig))
    figures.plot_sweep(studies, summaries, "s", tmp_path / "s.png")
    ax = drawn["fig"].axes[0]
    hollow = [ln for ln in ax.get_lines() if ln.get_markerfacecolor() == "white"]
    assert len(hollow) == 1 and hollow[0].get_xdata().tolist() == [0.0]


def test_replace_blocks_changes_only_the_generated_blocks():
    text = "a\n<!-- begin generated: x -->\nold\n<!-- end generated: x -->\nb\n<!-- begin generated: y -->\n<!-- end generated: y -->\n"
    new, missing = replace_blocks(text, {"x": "new\nlines"})
    assert new == text.replace("old", "new\nlines") and missing == ["y"]
    again, _ = replace_blocks(new, {"x": "new\nlines"})
    assert again == new


def _study_cli(folder):
    """``selfas-graph study ARGS --studies studies.toml`` run in ``folder``: asserts exit 0, returns stdout."""

    def cli(*args):
        res = subprocess.run(
            [sys.executable, "-m", "selfas_graph.cli.main", "study", *args, "--studies", "studies.toml"],
            cwd=folder,
            capture_output=True,
            text=True,
            timeout=600,
        )
        assert res.returncode == 0, res.stdout + res.stderr
        return res.stdout

    return cli


def test_a_study_is_run_summarised_and_written_into_a_page(tmp_path, monkeypatch):
    """`study run`, `study summarise`, `study page`: the summary holds the per-seed values, the
    episodes and the provenance; the page's block is what the summary gives; --check agrees. A seed's
    episodes join its values by file: where the frames of seed 1 cannot be read, seed 2's row is still
    seed 2's; a file read for its frames but not its events stops the summary, naming it."""
    (tmp_path / "studies.toml").write_text(
        f"""
[study.q]
title = "Quick scene"
scenario = "{(ROOT / "scenarios" / "quick.toml").as_posix()}"
overrides = ["rods.count=60", "output.interval=0.25"]
seeds = 2
t_end = 0.5
every = 0.25
table_times = [0.5]
"""
    )
    (tmp_path / "page.md").write_text(
        "# R\n<!-- begin generated: table q -->\n<!-- end generated: table q -->\n"
        "<!-- begin generated: runs q -->\n<!-- end generated: runs q -->\n"
    )

    cli = _study_cli(tmp_path)
    started = time.monotonic()
    cli("run", "q", "--runs", "runs", "--jobs", "1")
    elapsed = time.monotonic() - started
    cli("summarise", "q", "--runs", "runs", "--summaries", "res", "--figures", "figs")
    summary = json.loads((tmp_path / "res" / "q.json").read_text())
    assert summary["n_seeds"] == 2 and summary["times"] == [0.0, 0.25, 0.5]
    assert len(summary["measures"]["largest_alignment"]["values"]) == 2
    seed = summary["seeds"][0]
    assert seed["commit"] is not None and seed["cpu_model"] and seed["wall_seconds"] > 0
    # the seeds ran one after the other inside the command: their wall times add up to less than its own
    assert sum(x["wall_seconds"] for x in summary["seeds"]) <= elapsed
    assert {"start", "end", "filament_rods", "opened_by"} <= set(seed["episodes"])
    for key in ("total_current", "rods_in_series"):  # the circuit log's row at each closing
        assert len(seed["episodes"].get(key, seed["episodes"]["start"])) == len(seed["episodes"]["start"])
    assert (tmp_path / "figs" / "q_series.png").exists() and (tmp_path / "figs" / "q_snapshot.png").exists()

    import selfas_graph.studies.summary as study_summary
    from selfas_graph.studies import StudiesError, load_studies

    spec = load_studies(tmp_path / "studies.toml")
    real = study_summary.summarise
    monkeypatch.setattr(study_summary, "summarise", lambda paths, *a, **k: real(paths[1:], *a, **k))
    one = study_summary.summarise_study(spec.study("q"), tmp_path / "runs", spec)
    assert [(x["seed"], x["path"]) for x in one["seeds"]] == [(2, "seed_0002.h5")]
    assert one["seeds"][0]["episodes"] == summary["seeds"][1]["episodes"]
    monkeypatch.setattr(study_summary, "summarise", real)
    monkeypatch.setattr(study_summary, "_seed_record", lambda path: None)
    with pytest.raises(StudiesError, match="seed_0001.h5, seed_0002.h5 in .*not for its events"):
        study_summary.summarise_study(spec.study("q"), tmp_path / "runs", spec)
    monkeypatch.undo()
    out = cli("page", "--summaries", "res", "--page", "page.md")  # the figures beside the page, each named
    assert f"wrote {Path('figures') / 'q_series.png'}" in out and (tmp_path / "figures" / "q_series.png").exists()
    page = (tmp_path / "page.md").read_text()
    assert "| fraction of rods within R_plas |" in page
    assert "is up to date" in cli("page", "--summaries", "res", "--page", "page.md", "--check")

    def failing(*args):
        cmd = [sys.executable, "-m", "selfas_graph.cli.main", "study", *args, "--studies", "studies.toml"]
        res = subprocess.run(cmd, cwd=tmp_path, capture_output=True, text=True, timeout=600)
        return res.returncode, res.stdout + res.stderr

    # the studies file now defines the study otherwise than its summary was made: --check fails, the page says so
    studies = (tmp_path / "studies.toml").read_text()
    (tmp_path / "studies.toml").write_text(studies.replace("rods.count=60", "rods.count=80").replace("= 2\n", "= 3\n"))
    code, out = failing("page", "--summaries", "res", "--page", "page.md", "--check", "--no-figures")
    assert code == 1, out
    cli("page", "--summaries", "res", "--page", "page.md", "--no-figures")
    assert "Summarised from another definition of this study" in (tmp_path / "page.md").read_text()
    assert "(its overrides, seeds differ)" in (tmp_path / "page.md").read_text()
    # a study named but with nothing to summarise is not a success; a damaged summary is named in one line
    code, out = failing("summarise", "q", "--runs", "nowhere", "--summaries", "res2")
    assert code == 1 and "nothing to summarise for q" in out
    (tmp_path / "res" / "q.json").write_text('{"version": ')
    code, out = failing("page", "--summaries", "res", "--page", "page.md", "--check", "--no-figures")
    assert code == 2 and "q.json: not a readable study summary" in out and "Traceback" not in out


def test_a_percolation_study_runs_summarises_and_tabulates(tmp_path):
    """A percolation study: `study run` calls `bench percolation` (runs that write no file), `summarise`
    keeps the statistics per rod count with the provenance, `page` tabulates them."""
    (tmp_path / "studies.toml").write_text(
        f"""
[study.p]
title = "Quick scene"
kind = "percolation"
scenario = "{(ROOT / "scenarios" / "quick.toml").as_posix()}"
counts = [20, 40]
seeds = 2
t_end = 0.2
"""
    )
    (tmp_path / "page.md").write_text("<!-- begin generated: table p -->\n<!-- end generated: table p -->\n")

    cli = _study_cli(tmp_path)
    cli("run", "p", "--runs", "runs")
    assert "exists" in cli("run", "p", "--runs", "runs")  # done: not run again
    cli("summarise", "p", "--runs", "runs", "--summaries", "res")
    summary = json.loads((tmp_path / "res" / "p.json").read_text())
    assert [d["count"] for d in summary["densities"]] == [20, 40] and summary["commit"] is not None
    assert all(d["runs"] == 2 for d in summary["densities"])
    cli("page", "--summaries", "res", "--page", "page.md")
    assert "| 20 | " in (tmp_path / "page.md").read_text()


def _fake_summary(values, t=600.0, measure="largest_alignment"):
    return {
        "times": [t],
        "seeds": [{"seed": k + 1} for k in range(len(values))],
        "n_seeds": len(values),
        "measures": {measure: {"values": [[v] for v in values]}, "all_alignment": {"values": [[v] for v in values]}},
    }


def _claim_against_null(tmp_path, lines):
    """A studies file of two 3-seed studies to t = 600, ``a`` and its null model ``b``, and one claim
    on ``a`` at t = 600 with the TOML ``lines`` (its measure, and what else it sets)."""
    (tmp_path / "s.toml").write_text(
        "[study.a]\nscenario = 'x'\nseeds = 3\nt_end = 600\n[study.b]\ntitle = 'null'\nscenario = 'x'\nseeds = 3\n"
        f"t_end = 600\n[[claim]]\nid = 'c'\nclaim = 'a claim'\npaper = 'words'\nstudy = 'a'\ntime = 600\nnull = 'b'\n{lines}\n"
    )
    return load_studies(tmp_path / "s.toml")


@pytest.mark.parametrize(
    "claim, null, words",
    [
        # d = 0.8 / sqrt(2 * (0.1/sqrt3)^2) = 9.8, and its Welch's t-test with 4 degrees of freedom
        # (scipy.stats.t.sf by hand: 2 sf(9.80, 4) = 0.00061), below 0.0027
        ([0.9, 1.0, 1.1], [0.1, 0.2, 0.3], "reproduced (+9.8 SE from the null model; Welch p = 0.00061)"),
        ([0.1, 0.2, 0.3], [0.9, 1.0, 1.1], "opposite to the claim (−9.8 SE from the null model; Welch p = 0.00061)"),
        # 4.9 SE is more than 3, but with 3 seeds a side p = 2 sf(4.90, 4) = 0.0080: no verdict
        (
            [0.5, 0.6, 0.7],
            [0.1, 0.2, 0.3],
            "not distinguished from the null model (+4.9 SE; Welch p = 0.008, not below 0.0013)",
        ),
        ([0.2, 0.3, 0.4], [0.1, 0.2, 0.3], "not distinguished from the null model (+1.2 SE; Welch p = 0.29, not below"),
    ],
)
def test_a_verdict_needs_its_test_below_the_chance_of_three_se_in_the_claimed_direction(tmp_path, claim, null, words):
    """One rule for every test: p below the level, 0.0027 (the chance of 3 SE of a normal variable)
    spent over the claim's readings, 0.0013 at a first one, counted with the seeds' degrees of
    freedom; d > 3 alone was "reproduced" at p = 0.2 with 2 pairs."""
    from selfas_graph.studies.verdicts import claim_rows

    studies = _claim_against_null(tmp_path, 'measure = "largest_alignment"\nnull_measure = "all_alignment"')
    table = claim_rows(studies, {"a": _fake_summary(claim), "b": _fake_summary(null)})
    assert words in table, table


def test_a_claim_read_before_at_other_seed_counts_is_tested_over_all_its_readings(tmp_path):
    """Seeds added until a verdict turns raise its chance of a false one: the k-th reading is tested at
    0.0027 / (k (k + 1)), whose sum over any number of readings stays below 0.0027 (a level divided by
    the readings so far sums as the harmonic series). ``looks`` lists the readings before this one, a
    count read twice twice (it dropped every earlier reading at this one's counts). Welch p = 0.00061
    (3 seeds a side, d = 9.8) passes 0.0027 / 2 at the first reading, not 0.0027 / 6 at the second."""
    from selfas_graph.studies.verdicts import VERDICT_LEVEL, claim_rows, reading_level

    assert sum(reading_level(k) for k in range(1, 10_000)) < VERDICT_LEVEL
    assert [reading_level(k) * k * (k + 1) for k in (1, 5)] == pytest.approx([VERDICT_LEVEL] * 2, rel=1e-15)
    scene, null = _fake_summary([0.9, 1.0, 1.1]), _fake_summary([0.1, 0.2, 0.3])
    for looks, words in [
        ("[]", "| reproduced (+9.8 SE from the null model; Welch p = 0.00061) |"),
        ("[[2, 2]]", "not distinguished from the null model (+9.8 SE; Welch p = 0.00061, not below 0.00045); read "
         "before at 2/2 seeds (study/null model): the 2nd reading, tested at 0.0027 / 6 |"),
        # a reading at this one's counts (runs made again) is an earlier one too
        ("[[1, 1], [3, 3], [1, 1], [3, 3]]", "read before at 1/1 (twice) and 3/3 (twice) seeds (study/null model): "
         "the 5th reading, tested at 0.0027 / 30 |"),
    ]:  # fmt: skip
        studies = _claim_against_null(
            tmp_path, f'measure = "largest_alignment"\nnull_measure = "all_alignment"\nlooks = {looks}'
        )
        table = claim_rows(studies, {"a": scene, "b": null})
        assert words in table, table
    none = _fake_summary([None, None, None])
    table = claim_rows(_claim_against_null(tmp_path, 'measure = "largest_alignment"'), {"a": scene, "b": none})
    assert "| not decided (the null model has no value of the measure) |" in table  # not "too few seeds"
    for bad in ("[[3]]", "[3, 3]", "[[0, 3]]", "[[2.5, 3]]", '[["a", 3]]'):
        with pytest.raises(StudiesError, match=r"claim\[0\]\.looks: a list of \[seeds of the study, seeds of the null"):
            _claim_against_null(tmp_path, f'measure = "largest_alignment"\nlooks = {bad}')


@pytest.mark.parametrize(
    "claim_err, words",
    [
        # fit errors of 1 a seed: SE sqrt((0.01 + 1) / 3) = 0.58 a side, d = +0.7 / 0.82 = +0.85, Welch p
        # 2 sf(0.853, 4) = 0.44; by the spread alone (0.1 / sqrt 3 = 0.058 a side) d = +8.6, p = 0.0010:
        # the verdicts differ, and the page says so
        (1.0, "depends on the fits' own errors: not distinguished from the null model (+0.9 SE; Welch p = 0.44, "
         "not below 0.0013) with each seed's fit error, opposite to the claim (+8.6 SE from the null model; "
         "Welch p = 0.001) by the spread between seeds alone"),
        # fit errors of 0.01: both ways opposite, the one with the fits first (d = 8.53, p = 0.0010)
        (0.01, "opposite to the claim (+8.5 SE from the null model; Welch p = 0.001; +8.6 SE by the spread between "
         "seeds alone; Welch p = 0.001)"),
    ],
)  # fmt: skip
def test_a_fitted_measures_verdict_is_given_with_and_without_the_fits_errors(tmp_path, claim_err, words):
    """A fitted dimension's standard error carries each seed's fit error; most of that error is the bend
    of the mass-radius curve, alike from seed to seed, so the verdict by the spread between seeds alone
    is given beside it, and a disagreement is named rather than resolved."""
    from selfas_graph.studies.verdicts import claim_rows

    studies = _claim_against_null(tmp_path, 'measure = "fractal_dimension"\nexpect = "less"')

    def fitted(values, err):
        s = _fake_summary(values, measure="fractal_dimension")
        s["measures"]["fractal_dimension_err"] = {"values": [[err] for _ in values]}
        s["seeds"] = [{"seed": k + 1, "t_end": 600.0} for k in range(len(values))]
        return s

    table = claim_rows(studies, {"a": fitted([2.6, 2.7, 2.8], claim_err), "b": fitted([1.9, 2.0, 2.1], claim_err)})
    assert words in table, table


def test_study_commands_away_from_their_files_say_which_file_and_what_to_do(tmp_path):
    """Run outside the repository's root, `study list` names --studies; `study page` of a study whose
    scenario file cannot be read from here stops, naming the file, and writes nothing (it would
    otherwise word case (ii)'s closings of the circuit as short circuits of the electrodes)."""
    from selfas_graph.cli.main import main

    res = subprocess.run(
        [sys.executable, "-m", "selfas_graph.cli.main", "study", "list"], cwd=tmp_path, capture_output=True, text=True
    )
    assert res.returncode == 2 and "--studies" in res.stderr and "Traceback" not in res.stderr
    (tmp_path / "s.toml").write_text("[study.a]\nscenario = 'no/such.toml'\nseeds = 1\nt_end = 1\n")
    (tmp_path / "res").mkdir()
    (tmp_path / "res" / "a.json").write_text(
        json.dumps(_fake_summary([0.3, 0.4], t=1.0) | {"study": {"scenario": "no/such.toml", "table_times": [1.0]}})
    )
    page = tmp_path / "page.md"
    page.write_text("<!-- begin generated: table a -->\nold\n<!-- end generated: table a -->\n")
    args = ["study", "page", "--studies", str(tmp_path / "s.toml"), "--summaries", str(tmp_path / "res")]
    assert main([*args, "--page", str(page), "--figures", str(tmp_path / "figs")]) == 2
    assert "old" in page.read_text() and not (tmp_path / "figs").exists()


def test_study_page_through_a_link_writes_the_file_it_names(tmp_path):
    """The page named through a symbolic link: the file it points to is rewritten, the link stays a
    link (nothing the user did not name changes)."""
    import os

    from selfas_graph.cli.main import main

    (tmp_path / "s.toml").write_text("[study.a]\nscenario = 'x'\nseeds = 1\nt_end = 1\n")
    real = tmp_path / "real.md"
    real.write_text("<!-- begin generated: table a -->\nold\n<!-- end generated: table a -->\n")
    os.symlink(real, tmp_path / "link.md")
    args = ["study", "page", "--studies", str(tmp_path / "s.toml"), "--summaries", str(tmp_path / "none")]
    # a summaries folder that is not there (a typo) is refused: every block would say "not run yet"
    assert main([*args, "--page", str(tmp_path / "link.md")]) == 2
    assert "old" in real.read_text()
    (tmp_path / "none").mkdir()
    assert main([*args, "--page", str(tmp_path / "link.md")]) == 0
    assert os.path.islink(tmp_path / "link.md") and "Not run at this version yet" in real.read_text()
    assert f"--studies {tmp_path / 's.toml'}" in real.read_text()  # the commands it names find this file


def test_a_windowed_claim_and_a_null_without_spread():
    """A claim's `window` averages each seed over the summarised times in it; a null model whose seeds
    all give the same value, against seeds that all give another, differs by infinitely many SE. Its
    verdict rests on the exact rank test, 2 / C(n_a + n_b, n_a), against the 0.0027 of 3 SE: 2 against
    3 seeds (p = 0.2) or 5 against 5 (0.0079) are no verdict, 6 against 6 (0.0022) is; as the sign
    test of pairs alike: 5 pairs (0.0625) are none, 10 (0.00195) are."""
    from scipy.stats import norm

    from selfas_graph.studies.stats import plain_stat, window_values
    from selfas_graph.studies.verdicts import VERDICT_LEVEL, _claim_difference, _verdict, separation_p

    assert VERDICT_LEVEL == pytest.approx(2.0 * norm.sf(3.0), rel=1e-12)
    s = {"times": [0.0, 10.0, 20.0], "seeds": [{}, {}], "measures": {"m": {"values": [[9, 1, 3], [9, None, 5]]}}}
    assert list(window_values(s, "m", 5.0, 20.0)) == [2.0, 5.0]  # (1 + 3) / 2 and 5 alone
    a, b = plain_stat([4.0, 4.0]), plain_stat([0.0, 0.0, 0.0])
    d = _claim_difference(a, b)
    assert d == math.inf and separation_p(a, b) == pytest.approx(0.2)
    assert _verdict(d, "greater", separation_p(a, b)).startswith("not distinguished from the null model (every seed")
    assert _verdict(d, "greater").startswith("not distinguished")  # no p-value: no verdict
    five, six = (plain_stat([4.0] * n) for n in (5, 6))
    assert separation_p(five, plain_stat([0.0] * 5)) == pytest.approx(2.0 / 252.0)
    assert _verdict(d, "greater", separation_p(five, plain_stat([0.0] * 5))).startswith("not distinguished")
    assert _verdict(d, "greater", separation_p(six, plain_stat([0.0] * 6))).startswith("reproduced (every seed")
    assert _verdict(d, "less", separation_p(six, plain_stat([0.0] * 6))).startswith("opposite to the claim")
    assert _verdict(d, "greater", 0.0625, paired=5).startswith("not distinguished")
    assert _verdict(d, "greater", 2.0 / 2**10, paired=10).startswith("reproduced (every seed differs from the same")
    assert math.isnan(_claim_difference(plain_stat([4.0]), plain_stat([0.0, 0.0])))  # one seed: no spread


def test_a_fitted_verdict_without_seeds_or_spread_reads_plainly():
    """One seed a side: "not decided (too few seeds)" alone, not with "+nan SE"; no spread between the
    seeds alone: their verdict in words, not "+inf SE"."""
    from selfas_graph.studies.verdicts import _fit_verdict

    assert _fit_verdict(math.nan, math.nan, "less", math.nan, 1) == "not decided (too few seeds)"
    text = _fit_verdict(-0.5, -math.inf, "less", math.nan, 0.0625, 5)
    assert "inf" not in text and "nan" not in text
    assert (
        text.startswith("not distinguished from the null model (−0.5 SE")
        and "sign test over 5 seeds, p = 0.062" in text
    )


def test_a_paired_verdict_says_which_seeds_it_leaves_out():
    """Seeds 1-5 of the study against seeds 1-3 of its null model pair 3; the verdict says that 2 of the
    study's 5 have no pair (the row's values are over all 5). Equal seed sets say nothing."""
    from selfas_graph.studies.pairing import common_rows
    from selfas_graph.studies.verdicts import _unpaired_note

    five = {"seeds": [{"seed": k} for k in range(1, 6)]}
    three = {"seeds": [{"seed": k} for k in (3, 1, 2)]}
    ia, ib = common_rows(five, three)
    assert list(ia) == [0, 1, 2] and list(ib) == [1, 2, 0]
    assert _unpaired_note(five, three, len(ia)) == "; 2 of the study's 5 seeds have no pair and are left out"
    assert _unpaired_note(three, five, 3) == "; 2 of the null model's 5 seeds have no pair and are left out"
    assert _unpaired_note(five, five, 5) == ""
    # a pair without a value on either side is left out too, and counted
    assert (
        _unpaired_note(five, five, 4)
        == "; 1 of the study's 5 seeds and 1 of the null model's 5 seeds have no pair and are left out"
    )


def test_a_seed_that_stopped_early_has_no_value_past_its_end_in_any_statistic():
    """Seed 2 stopped at t = 18 (its last frame within half an interval of t = 20 is in the summary):
    it has no value at t = 20, in a fitted cell as in a plain one, and no mean over a window that ends
    after it stopped; before t = 18 it counts as the others."""
    from selfas_graph.studies.stats import measure_text, reached, values_at, window_values

    s = {
        "times": [0.0, 10.0, 20.0],
        "seeds": [{"seed": 1, "t_end": 20.0}, {"seed": 2, "t_end": 18.0}, {"seed": 3}],
        "measures": {
            "m": {"values": [[1.0, 2.0, 3.0], [1.0, 4.0, 9.0], [1.0, 6.0, 5.0]]},
            "fractal_dimension": {"values": [[None, 2.0, 2.0], [None, 2.0, 9.0], [None, 2.0, 2.2]]},
            "fractal_dimension_err": {"values": [[None, 0.1, 0.1], [None, 0.1, 0.1], [None, 0.1, 0.1]]},
        },
    }
    assert list(reached(s, 20.0)) == [True, False, True] and reached(s, 10.0).all()
    assert np.isnan(values_at(s, "m", 20.0)[1]) and list(values_at(s, "m", 10.0)) == [2.0, 4.0, 6.0]
    assert list(window_values(s, "m", 10.0, 20.0))[::2] == [2.5, 5.5] and np.isnan(window_values(s, "m", 10.0, 20.0)[1])
    assert window_values(s, "m", 0.0, 10.0)[1] == 2.5
    assert measure_text(s, "fractal_dimension", 20.0).endswith("(2)")


def test_the_flux_is_summarised_where_other_studies_are_set_against_a_study():
    """The rod currents' flux, costly, is summarised at a few times only; those include the times a
    convergence setting, a sweep or a claim compares with the study (t = 150 for the Fig. 2
    convergence settings), or their tables read n/a for the default."""
    from types import SimpleNamespace

    from selfas_graph.studies.summary import study_measures

    studies = load_studies(ROOT / "docs" / "studies.toml")
    fig2 = studies.study("fig2")
    compared = studies.compared_times("fig2")
    assert 150.0 in compared and 300.0 in compared
    flux = {m.name: m for m in study_measures(fig2, compared)}["midplane_flux"]
    frame = SimpleNamespace(time=150.0, _study_flux=1.25)  # the flux cached on the frame
    assert flux.fn(frame) == 1.25
    assert 130.0 not in compared  # neither compared with, nor a table time, nor on the 20 t0 grid
    assert math.isnan(flux.fn(SimpleNamespace(time=130.0, _study_flux=1.25)))
    assert 150.0 not in {t for t in studies.compared_times("fig6")}
    # a null model that is also a sweep's point (fig2_no_plasma, I_plas = 0) is compared at the sweep's time
    assert studies.study("fig2_no_plasma").sweep == "fig2_I_plas" and 300.0 in studies.compared_times("fig2_no_plasma")


def test_a_study_table_words_its_circuit_by_the_scene_and_leaves_out_measures_it_lacks():
    """Case (i) closes between the electrodes; case (ii) (Fig. 8) through the external filament, with
    no gap and no R_plas: the table says so, and a measure that is n/a at every time has no row."""
    from selfas_graph.studies.figures import series_panels
    from selfas_graph.studies.page import has_electrodes, provenance_text, study_table

    def summary(scenario):
        s = _fake_summary([0.3, 0.4], t=10.0, measure="largest_alignment")
        s["measures"]["inside_R_plas"] = {"values": [[None], [None]]}
        s["measures"]["total_current"] = {"values": [[2.0], [1.0]]}
        s["study"] = {"scenario": str(ROOT / "scenarios" / scenario), "overrides": [], "table_times": [10.0]}
        s["short_circuit"] = {"n_observed": 2, "median": 3.0}
        for k, seed in enumerate(s["seeds"]):
            seed["episodes"] = {"start": [3.0], "end": [None], "total_current": [1.0], "rods_in_series": [1]}
            seed["t_end"], seed["wall_seconds"] = 10.0, 60.0 * (k + 1)
        return s

    fig2, fig8 = summary("fig2.toml"), summary("fig8.toml")
    assert has_electrodes(fig2) and not has_electrodes(fig8)
    with pytest.raises(StudiesError, match="no/such/file.toml: cannot read the study's scenario file"):
        has_electrodes({"study": {"scenario": "no/such/file.toml"}})  # no guess at the circuit: it words the table
    two = study_table(fig2)
    assert "short circuit of the electrodes" in two and "current through the gap" in two
    assert "through median 1 rod in series" in two
    eight = study_table(fig8)
    assert "circuit closed through the external filament" in eight and "closings of the circuit" in eight
    assert "current through the network" in eight and "gap" not in eight
    assert "R_plas" not in eight  # n/a at every table time: no row
    fig8["measures"]["median_axis_distance"] = {"values": [[3.0], [4.0]]}
    assert series_panels(fig8) == ["total_current", "median_axis_distance", "largest_alignment"]
    fig8["measures"]["inside_R_plas"] = {"values": [[0.5], [None]]}
    assert series_panels(fig8) == ["total_current", "inside_R_plas", "largest_alignment"]
    fig8["measures"]["largest_alignment"] = {"values": [[None], [None]]}  # no structure: free rods only
    fig8["measures"]["free_alignment"] = {"values": [[0.3], [0.4]]}
    assert "largest_alignment" in series_panels(fig8)
    assert "wall time a seed 1-2 min" in provenance_text(fig8)
    for s in fig8["seeds"]:
        s["wall_seconds"] = 120.0
    assert "wall time a seed 2 min" in provenance_text(fig8)


def test_case_ii_flux_is_also_given_over_the_external_dipoles_flux():
    """The paper's Fig. 11 gives the rod currents' flux in units of Phi_ext = 4 pi |Z_Mext|; with
    Phi_0 = 4 pi (docs/model.md 'Reduced units') that is the flux in Phi_0 over |Z_Mext|."""
    from types import SimpleNamespace

    from selfas_graph.studies.summary import STUDY_MEASURES

    fn = {m.name: m for m in STUDY_MEASURES}["flux_over_dipole"].fn
    dipole = {"forces": {"external_dipole": {"magnetic_charge": -10.0}}}
    assert fn(SimpleNamespace(params=dipole, _study_flux=2.5)) == 0.25
    assert math.isnan(fn(SimpleNamespace(params={"forces": {}}, _study_flux=2.5)))


def test_several_studies_run_in_one_pool_and_again_run_nothing(tmp_path):
    """`study run a b --jobs 2`: the seeds of both studies share the two workers (no worker waits for
    the end of a study), each folder gets its seed files and ensemble summary; run again, nothing
    is left to run."""
    quick = (ROOT / "scenarios" / "quick.toml").as_posix()
    (tmp_path / "studies.toml").write_text(
        "".join(
            f"""
[study.{name}]
title = "Quick scene {name}"
scenario = "{quick}"
overrides = ["rods.count=40"{extra}]
seeds = {seeds}
t_end = 0.2
every = 0.1
table_times = [0.2]
"""
            for name, extra, seeds in (("a", "", 3), ("b", ', "circuit.delta_J0=1.5"', 1))
        )
    )
    cli = _study_cli(tmp_path)
    out = cli("run", "a", "b", "--runs", "runs", "--jobs", "2")
    assert "4 seeds of 2 studies on 2 processes" in out, out
    assert "[4/4]" in out and "a seed 3: finished" in out and "b seed 1: finished" in out
    for name, seeds in (("a", 3), ("b", 1)):
        folder = tmp_path / "runs" / name
        assert sorted(p.name for p in folder.glob("seed_*[0-9].h5")) == [
            f"seed_{k:04d}.h5" for k in range(1, seeds + 1)
        ]
        assert (folder / "summary.json").exists() and not (folder / ".ensemble.lock").exists()
    again = cli("run", "a", "b", "--runs", "runs", "--jobs", "2")
    assert "0 seeds of 2 studies" in again and "3 done" in again


def test_an_unusable_seed_file_in_one_study_stops_all_before_anything_runs(tmp_path):
    quick = (ROOT / "scenarios" / "quick.toml").as_posix()
    (tmp_path / "studies.toml").write_text(
        "".join(
            f'\n[study.{n}]\nscenario = "{quick}"\noverrides = ["rods.count=40"]\nseeds = 1\nt_end = 0.1\n'
            for n in ("a", "b")
        )
    )
    (tmp_path / "runs" / "b").mkdir(parents=True)
    (tmp_path / "runs" / "b" / "seed_0001.h5").write_text("not a run file")
    res = subprocess.run(
        [sys.executable, "-m", "selfas_graph.cli.main", "study", "run", "a", "b", "--runs", "runs", "--jobs", "2"]
        + ["--studies", "studies.toml"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert res.returncode == 2 and "seed_0001.h5" in res.stderr, res.stdout + res.stderr
    assert not list((tmp_path / "runs" / "a").glob("seed_*.h5"))  # nothing ran
    assert (tmp_path / "runs" / "b" / "seed_0001.h5").read_text() == "not a run file"  # nothing overwritten


def test_study_names_after_the_options_count_and_unknown_options_are_refused(capsys):
    from selfas_graph.cli.main import build_parser, parse_args

    parser = build_parser()
    args = parse_args(parser, ["study", "run", "fig2", "--jobs", "2", "fig6", "fig8", "--runs", "r"])
    assert args.names == ["fig2", "fig6", "fig8"] and args.jobs == 2 and args.runs == "r"
    with pytest.raises(SystemExit) as info:
        parse_args(parser, ["study", "run", "fig2", "--jbos", "2"])
    assert info.value.code == 2 and "unrecognized arguments: --jbos" in capsys.readouterr().err
    with pytest.raises(SystemExit):  # a command without a trailing list takes no extra names
        parse_args(parser, ["simulate", "a.toml", "b.toml"])


def _studies_file(folder, text):
    (folder / "studies.toml").write_text(text)
    return str(folder / "studies.toml")


def test_a_kept_failed_seed_makes_one_study_exit_3(tmp_path, capsys):
    """One study runs in the pool as several do, with the ensemble command's codes: a failed seed kept
    from before is listed and the run exits 3, its file untouched."""
    import h5py

    from conftest import SMALL_CIRCUIT_SCENE
    from selfas_graph.cli.main import main
    from selfas_graph.ensemble import seed_path

    (tmp_path / "scene.toml").write_text(SMALL_CIRCUIT_SCENE)
    studies = _studies_file(
        tmp_path,
        f"[study.s]\nscenario = '{(tmp_path / 'scene.toml').as_posix()}'\nseeds = 1\nfirst_seed = 3\nt_end = 0.1\n",
    )
    runs = tmp_path / "runs"
    assert main(["study", "run", "s", "--studies", studies, "--runs", str(runs)]) == 0
    with h5py.File(seed_path(runs / "s", 3), "r+") as f:
        f["parameters/selfas_graph"].attrs["status"] = "failed: a test"
    before = seed_path(runs / "s", 3).read_bytes()
    capsys.readouterr()
    assert main(["study", "run", "s", "--studies", studies, "--runs", str(runs)]) == 3
    assert "seed 3: failed: a test (kept; --force reruns it)" in capsys.readouterr().out
    assert seed_path(runs / "s", 3).read_bytes() == before


def test_an_older_percolation_result_or_installation_is_refused_before_anything_runs(tmp_path, capsys):
    """A percolation result made before trajectories_since is refused (exit 2, naming the file and both
    versions) unless --force; an installation that reports an older version than trajectories_since
    is refused, since its runs would be taken for older ones."""
    from selfas_graph.cli.main import main

    body = (
        f"[study.p]\nkind = 'percolation'\nscenario = '{(ROOT / 'scenarios' / 'quick.toml').as_posix()}'\n"
        "seeds = 1\nt_end = 0.1\ncounts = [10]\n"
    )
    runs = tmp_path / "runs"
    (runs / "p").mkdir(parents=True)
    (runs / "p" / "percolation.json").write_text(json.dumps({"version": "0.0.1"}))
    studies = _studies_file(tmp_path, 'trajectories_since = "0.4.0"\n' + body)
    assert main(["study", "run", "p", "--studies", studies, "--runs", str(runs)]) == 2
    err = capsys.readouterr().err
    assert "percolation.json was made by version 0.0.1, before the trajectories of version 0.4.0" in err
    assert "--force" in err
    studies = _studies_file(tmp_path, 'trajectories_since = "99.0"\n' + body)
    assert main(["study", "run", "p", "--studies", studies, "--runs", str(runs)]) == 2
    assert "older than trajectories_since = 99.0" in capsys.readouterr().err


def test_the_first_closing_is_left_out_where_no_seed_carries_current():
    """The study without the circuit closes the gap but carries no current: its table gives the closings,
    not a first closing of 0 J0; the Fig. 2 study's gives it."""
    from selfas_graph.studies.page import page_blocks

    blocks = page_blocks(load_studies(ROOT / "docs" / "studies.toml"), ROOT / "docs" / "results")
    assert "closings of the gap in all" in blocks["table fig2_no_circuit"]
    assert "first closing carries" not in blocks["table fig2_no_circuit"]
    assert "first closing carries" in blocks["table fig2"]


def test_study_list_names_what_a_percolation_study_runs(tmp_path, capsys):
    """`study list` gives a percolation study's rod counts and fields beside its seeds (it gave the
    scene and seeds alone, as if it were an ensemble of the scene's own rods)."""
    from selfas_graph.cli.main import main

    (tmp_path / "s.toml").write_text(
        "[study.p]\ntitle = 'P'\nkind = 'percolation'\nfields = 'off'\nscenario = 'scenarios/quick.toml'\n"
        "counts = [300, 1000]\nseeds = 8\nt_end = 20.0\n"
        "[study.e]\ntitle = 'E'\nscenario = 'scenarios/quick.toml'\nseeds = 2\nt_end = 6.0\n"
    )
    assert main(["study", "list", "--studies", str(tmp_path / "s.toml")]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out == [
        "p: P: scenarios/quick.toml, percolation over 300, 1000 rods, fields off, 8 seeds each to the short "
        "circuit or t = 20",
        "e: E: scenarios/quick.toml, 2 seeds to t = 6",
    ]


def _current_summary(rods, flags, t=150.0):
    """A summary at one time with a circuit: ``rods`` in current-carrying filaments per seed, its
    ``current`` flags (None: unknown), and the other claim measures absent."""
    return {
        "times": [t],
        "seeds": [{"seed": k + 1, "t_end": t} for k in range(len(rods))],
        "n_seeds": len(rods),
        "current": [[f] for f in flags],
        "measures": {
            "filament_rods": {"values": [[v] for v in rods]},
            "total_current": {"values": [[1.0 if f else 0.0] for f in flags]},
        },
    }


def test_a_seed_whose_current_flag_is_unknown_counts_in_neither_group():
    """A seed with a value but no flag at that time is not taken for one without current: 2 of 3, not
    2 of 4."""
    s = _current_summary([700.0, 0.0, 650.0, 600.0], [1.0, 0.0, 1.0, None])
    assert measure_text(s, "filament_rods", 150.0).startswith("2 of 3 seeds carry current: median 675")


def test_the_convergence_table_pairs_the_seeds_and_a_grouped_measure_every_seed_with_a_flag():
    """The setting runs seeds 1-3 of the default's 1-5, from the same rods: the table pairs them. The
    rods in current-carrying filaments, 0 where a seed carries none, differ by -10, -10 and +20 (seed 3
    carries current in the setting only: it was left out, a pick by the outcome): mean 0 ± 10, d = 0,
    p = 1; each side's cell is over the 3 pairs, the default's saying that 2 of them carry current.
    The loops differ by 2, 4, 6: mean 4 ± 2 / sqrt(3) = 1.155, d = +3.5, p = 2 t_2.sf(3.46) = 0.074;
    where no seed of either carries current the measure is not compared."""
    from types import SimpleNamespace

    from selfas_graph.studies.convergence import convergence_rows, paired_difference

    base = _current_summary([680.0, 700.0, 0.0, 720.0, 700.0], [1.0, 1.0, 0.0, 1.0, 1.0])
    base["measures"]["cycle_rank"] = {"values": [[100.0], [110.0], [90.0], [500.0], [500.0]]}
    setting = _current_summary([670.0, 690.0, 20.0], [1.0, 1.0, 1.0])
    setting["measures"]["cycle_rank"] = {"values": [[102.0], [114.0], [96.0]]}
    p = paired_difference(setting, base, "filament_rods", 150.0)
    assert (p["n"], p["k_a"], p["k_b"], p["of"], p["diff"], p["d"], p["p"]) == (3, 3, 2, 3, 0.0, 0.0, 1.0)
    assert p["sem"] == pytest.approx(10.0) and p["b"]["mean"] == 460.0  # the default over the same seeds
    p = paired_difference(setting, base, "cycle_rank", 150.0)
    assert (p["n"], p["diff"]) == (3, 4.0) and p["sem"] == pytest.approx(2.0 / math.sqrt(3.0))
    assert p["d"] == pytest.approx(2.0 * math.sqrt(3.0)) and p["p"] == pytest.approx(0.0742, abs=1e-4)

    st = SimpleNamespace(section="convergence", name="v", null_of="base", title="a knob", t_end=150.0)
    studies = SimpleNamespace(studies={"v": st}, since=lambda name: "")
    rows = convergence_rows(studies, {"base": base, "v": setting}).splitlines()
    loops = next(r for r in rows if "| independent loops" in r)
    assert "| 100 ± 5.8 (3) | 104 ± 5.3 (3) | 4 ± 1.2 (+3.5 SE; p = 0.074) |" in loops, loops
    rods = next(r for r in rows if "| rods in current-carrying filaments" in r)
    cell = "| 2 of 3 carry current; every seed, 0 without current: 460 ± 230 (3) | 3 of 3 carry current: 460 ± 220 (3) | 0 ± 10 (+0.0 SE; p = 1) |"
    assert cell in rods, rods
    # two measures compared: Holm multiplies the smaller p, the loops' 0.074, by 2, so nothing moves
    # the statistics
    assert (
        "no difference detected at this size (smallest: independent loops (cycle rank): p = 0.074, 0.15 after Holm over 2)"
        in rods
    )
    # five pairs alike: 2 / 32
    five = _current_summary([680.0, 700.0, 690.0, 720.0, 700.0], [1.0] * 5)
    same = _current_summary([670.0, 690.0, 680.0, 710.0, 690.0], [1.0] * 5)
    assert paired_difference(same, five, "filament_rods", 150.0)["p"] == 0.0625
    off = _current_summary([0.0, 0.0], [0.0, 0.0])
    rows = convergence_rows(studies, {"base": off, "v": off}).splitlines()
    rods = next(r for r in rows if "rods in current-carrying filaments" in r)
    assert "| 0 of 2 carry current | 0 of 2 carry current | n/a |" in rods, rods
    assert "not decided (too few seeds)" in rods  # no measure of this summary can be compared


def test_a_fitted_dimension_in_the_convergence_table_is_read_with_and_without_its_fit_errors():
    """Fit errors of 0.5 on every seed swamp a shift of 0.3 that every pair shows within 0.02: with
    them, SE = sqrt(s_d^2 / 5 + 0.5 / 5) = 0.32 and no difference; by the seeds alone +0.306 over an SE
    of 0.005, which moves the statistics, so the conclusion depends on the fits' own errors."""
    from types import SimpleNamespace

    from selfas_graph.studies.convergence import convergence_rows, paired_difference

    def summary(dims):
        return {
            "times": [100.0],
            "seeds": [{"seed": k + 1, "t_end": 100.0} for k in range(5)],
            "n_seeds": 5,
            "measures": {
                "fractal_dimension": {"values": [[v] for v in dims]},
                "fractal_dimension_err": {"values": [[0.5]] * 5},
            },
        }

    base = summary([2.0, 2.1, 2.2, 2.3, 2.4])
    setting = summary([2.31, 2.39, 2.52, 2.61, 2.70])
    with_fits = paired_difference(setting, base, "fractal_dimension", 100.0)
    alone = paired_difference(setting, base, "fractal_dimension", 100.0, fit_errors=False)
    assert with_fits["diff"] == alone["diff"] == pytest.approx(0.306)
    assert with_fits["sem"] == pytest.approx(math.sqrt(np.var([0.31, 0.29, 0.32, 0.31, 0.30], ddof=1) / 5 + 0.1))
    assert with_fits["p"] > 0.3 and alone["p"] < 1e-5
    assert alone["b"]["sem"] == pytest.approx(np.std([2.0, 2.1, 2.2, 2.3, 2.4], ddof=1) / math.sqrt(5))
    st = SimpleNamespace(section="convergence", name="v", null_of="base", title="a knob", t_end=100.0)
    studies = SimpleNamespace(studies={"v": st}, since=lambda name: "")
    rows = convergence_rows(studies, {"base": base, "v": setting})
    assert "; seeds alone: 0.306 ± " in rows and "(seeds alone: ±" in rows
    assert "depends on the fits' own errors: no difference detected at this size" in rows
    assert "moves these statistics (mass-radius dimension of the largest structure: p = " in rows


def test_an_older_summarys_current_flags_are_known_only_where_its_total_current_is():
    """A summary from before the ``current`` flags: the total current is the flag, known where it is a
    number (a bool array: ``~`` of Python's bool is an int, which made every seed known)."""
    from selfas_graph.studies.stats import current_flags

    s = {"times": [1.0], "seeds": [{"seed": k} for k in (1, 2, 3)], "measures": {}}
    s["measures"]["total_current"] = {"values": [[2.0], [None], [0.0]]}
    active, known, circuit = current_flags(s, 1.0)
    assert known.dtype == bool and known.tolist() == [True, False, True] and circuit
    assert active.tolist() == [True, False, False]
    s["measures"]["total_current"] = {"values": [[None]] * 3}  # no circuit: every seed known, none active
    active, known, circuit = current_flags(s, 1.0)
    assert known.dtype == bool and known.all() and not circuit and not active.any()


def test_holm_and_the_detectable_difference_by_hand():
    """Holm's adjustment of (0.01, 0.04, NaN, 0.03): sorted 0.01, 0.03, 0.04 times 3, 2, 1 and kept
    rising: 0.03, 0.06, 0.06. The detectable difference tends to 2 + z_0.8 = 2.84 SE at a 2-SE screen
    (level 4.55 %) with many degrees of freedom, and grows with fewer seeds and more measures."""
    from scipy.stats import norm

    from selfas_graph.studies.convergence import detectable_se, holm

    out = holm([0.01, 0.04, math.nan, 0.03])
    assert out[:2] == pytest.approx([0.03, 0.06]) and math.isnan(out[2]) and out[3] == pytest.approx(0.06)
    level = 2.0 * norm.sf(2.0)
    assert detectable_se(10**6, level=level) == pytest.approx(2.0 + norm.isf(0.2), abs=1e-3)
    assert detectable_se(4) > detectable_se(30) > detectable_se(10**6)
    assert detectable_se(4, 6) > detectable_se(4, 1)


def test_the_detectable_difference_of_two_pairs_and_several_measures_is_found_past_50_se():
    """With one degree of freedom (two pairs) and 4 measures the critical value of t alone is 50.9 SE:
    the search widens its bracket instead of failing, and the difference found has the power asked
    (the noncentral t's chance beyond the critical value is 0.8, to brentq's tolerance); a table row
    of such a setting reads "n/a" only where the difference is past 10^6 SE."""
    from scipy.stats import nct
    from scipy.stats import t as student

    from selfas_graph.studies.convergence import LEVEL, _detectable, detectable_se

    delta = detectable_se(1, 4)
    crit = student.isf(LEVEL / 8, 1)
    assert crit > 50.0 and delta > crit
    assert nct.sf(crit, 1, delta) + nct.cdf(-crit, 1, delta) == pytest.approx(0.8, abs=1e-6)
    assert detectable_se(1, 6) > delta > detectable_se(1, 3)
    assert _detectable({"n": 2, "sem": 1.0, "b": {"mean": 10.0}}, 5).endswith("%")


def test_a_percolation_table_leaves_failed_runs_out_of_the_fraction_and_names_them():
    from selfas_graph.studies.page import percolation_table

    # the interval is the page's own over the 3 runs that decide (Wilson, 2 of 3: 0.21 to 0.94), also for a
    # summary made before `decided`, whose stored interval was over all 4
    d = {"count": 40, "runs": 4, "short_circuited": 2, "censored": 1, "failed": 1}
    d |= {"fraction_ci95": [0.15, 0.85], "median": 1.5, "q25": 0.5, "q75": None}
    table = percolation_table({"study": {"t_max": 2.0}, "densities": [d]})
    assert "| 40 | 2 of 3 (0.21 to 0.94); 1 failed before t = 2 | 1.5 [0.5 to >2] |" in table, table


def test_the_convergence_conclusion_names_the_measure_of_the_smallest_p_where_holm_ties():
    """Holm gives 0.012 * 6 and 0.011 * 5 the same 0.066: the conclusion names the raw smallest, the
    fraction within R_plas (p = 0.011), not the first measure."""
    from selfas_graph.studies.convergence import _conclusion

    pairs = [{"d": 1.0, "p": p} for p in (0.012, 0.011, 0.5, 0.6, 0.7, 0.8)]
    text = _conclusion(pairs)
    assert "smallest: fraction of rods within R_plas: p = 0.011, 0.066 after Holm over 6" in text, text


def _started(values, start, t=600.0, measure="inside_R_plas"):
    """A summary of one seed a value, at t = 0 (``start``: where its rods begin) and at ``t``."""
    return {
        "times": [0.0, t],
        "seeds": [{"seed": k + 1, "t_end": t} for k in range(len(values))],
        "n_seeds": len(values),
        "measures": {measure: {"values": [[s, v] for s, v in zip(start, values, strict=True)]}},
    }


def test_a_claim_is_paired_by_seed_where_the_summaries_start_from_the_same_rods(tmp_path):
    """The same values at t = 0 seed by seed, one of them a measure of where the rods were placed: the
    null model ran the same seeds from the same rods, and the verdict pairs them. The differences 0.2, 0.3, 0.1: mean 0.2 ± 0.1 / sqrt 3 = 0.0577, d = +3.5,
    p = 2 t_2.sf(3.46) = 0.074 (no verdict with 3 pairs, though d > 3). Another start at t = 0 (seed 3's), no t = 0 in a summary, or only a
    measure one side lacks there: Welch over the two sets, d = 0.2 / sqrt(2 * 0.0577^2) = +2.4 with
    4 degrees of freedom, p = 0.07. A seed only the null model has is left out of the pairs."""
    from selfas_graph.studies.pairing import common_rows, same_start
    from selfas_graph.studies.verdicts import claim_rows

    studies = _claim_against_null(tmp_path, 'measure = "inside_R_plas"')
    scene = _started([0.5, 0.7, 0.6], [0.1, 0.2, 0.3])
    null = _started([0.3, 0.4, 0.5, 0.9], [0.1, 0.2, 0.3, 0.4])  # seed 4: the null's alone
    null["measures"]["total_current"] = {"values": [[None, None]] * 4}  # no circuit: not compared
    scene["measures"]["total_current"] = {"values": [[0.0, 1.0]] * 3}
    assert same_start(scene, null) and [list(r) for r in common_rows(scene, null)] == [[0, 1, 2], [0, 1, 2]]
    paired = "not distinguished from the null model (+3.5 SE; paired over 3 seeds, p = 0.074, not below 0.0013)"
    assert paired in claim_rows(studies, {"a": scene, "b": null})
    welch = "not distinguished from the null model (+2.4 SE; Welch p = 0.07, not below 0.0013)"
    other = _started([0.3, 0.4, 0.5], [0.1, 0.2, 0.35])
    assert not same_start(scene, other) and welch in claim_rows(studies, {"a": scene, "b": other})
    late = _started([0.3, 0.4, 0.5], [0.1, 0.2, 0.3]) | {"times": [10.0, 600.0]}  # no t = 0
    assert not same_start(scene, late) and welch in claim_rows(studies, {"a": scene, "b": late})
    blank = _started([0.3, 0.4, 0.5], [None, None, None])  # nothing finite on both sides at t = 0
    assert not same_start(scene, blank) and welch in claim_rows(studies, {"a": scene, "b": blank})
    # constants of the scene at t = 0 (as many rods, no structure) agree whatever the rods: not enough
    counts = {"times": [0.0], "seeds": [{"seed": 1}, {"seed": 2}]}
    a = counts | {"measures": {"free_rods": {"values": [[1200], [1200]]}, "structures": {"values": [[0], [0]]}}}
    b = counts | {"measures": {**a["measures"], "median_axis_distance": {"values": [[7.2], [7.4]]}}}
    assert not same_start(a, b) and not same_start(a, a) and same_start(b, b)


def test_the_paired_difference_and_a_fitted_claims_paired_verdict_by_hand(tmp_path):
    """:func:`paired_stat` is the convergence table's arithmetic; pairs alike get the sign test. A fitted
    dimension, same start: differences 0.5, 0.48, 0.52 (mean 0.5, s_d 0.02); with fit errors of 1 a seed
    SE = sqrt(0.0004 / 3 + 2 / 3) = 0.82, d = +0.6, p = 2 t_2.sf(0.612) = 0.60; by the spread alone
    0.5 / 0.01155 = +43.3, p = 2 t_2.sf(43.3) = 0.00053."""
    from selfas_graph.studies.convergence import paired_difference
    from selfas_graph.studies.pairing import paired_stat
    from selfas_graph.studies.verdicts import claim_rows

    q = paired_stat([0.5, 0.7, 0.6, np.nan], [0.3, 0.4, 0.5, 0.1])
    assert q["n"] == 3 and q["diff"] == pytest.approx(0.2) and q["sem"] == pytest.approx(0.1 / math.sqrt(3.0))
    assert q["p"] == pytest.approx(0.0742, abs=1e-4) and q["b"]["mean"] == pytest.approx(0.4)
    alike = paired_stat([5.0, 6.0, 7.0, 8.0, 9.0], [4.0, 5.0, 6.0, 7.0, 8.0])
    assert (alike["d"], alike["p"]) == (math.inf, 0.0625)
    base = _current_summary([680.0, 700.0, 690.0, 720.0], [1.0] * 4)
    base["measures"]["cycle_rank"] = {"values": [[100.0], [110.0], [90.0], [500.0]]}
    setting = _current_summary([670.0, 690.0, 20.0], [1.0] * 3)
    setting["measures"]["cycle_rank"] = {"values": [[102.0], [114.0], [96.0]]}
    want = paired_difference(setting, base, "cycle_rank", 150.0)
    got = paired_stat([102.0, 114.0, 96.0], [100.0, 110.0, 90.0])
    assert all(got[k] == pytest.approx(want[k]) for k in ("n", "diff", "sem", "d", "p"))

    studies = _claim_against_null(tmp_path, 'measure = "fractal_dimension"\nexpect = "less"')

    def fitted(values):
        s = _started(values, [1.0, 2.0, 3.0], measure="fractal_dimension")
        s["measures"]["fractal_dimension_err"] = {"values": [[None, 1.0]] * 3}
        s["measures"]["inside_R_plas"] = {"values": [[0.1 * k, 0.5] for k in (1, 2, 3)]}  # the same rods
        return s

    table = claim_rows(studies, {"a": fitted([2.4, 2.58, 2.52]), "b": fitted([1.9, 2.1, 2.0])})
    words = (
        "depends on the fits' own errors: not distinguished from the null model (+0.6 SE; paired over 3 seeds, "
        "p = 0.6, not below 0.0013) with each seed's fit error, opposite to the claim (+43.3 SE from the null "
        "model; paired over 3 seeds, p = 0.00053) by the spread between seeds alone"
    )
    assert words in table, table


def _window_summary(rods, flags, circuit=True):
    """A summary at t = 0, 300, 450 and 600 from the same rods per seed (t = 0: no filament, the
    fraction within R_plas 0.1 k for seed k): ``rods`` in current-carrying (or, without a circuit,
    gap-spanning) filaments and the ``current`` flags per seed at t = 300, 450, 600."""
    return {
        "times": [0.0, 300.0, 450.0, 600.0],
        "seeds": [{"seed": k + 1, "t_end": 600.0} for k in range(len(rods))],
        "n_seeds": len(rods),
        "current": [[0.0, *f] for f in flags],
        "measures": {
            "filament_rods": {"values": [[0.0, *r] for r in rods]},
            "total_current": {"values": [[0.0, *(1.0 * x for x in f)] if circuit else [None] * 4 for f in flags]},
            "inside_R_plas": {"values": [[0.1 * (k + 1), 0.5, 0.5, 0.5] for k in range(len(rods))]},
        },
    }


def test_a_windowed_claim_against_a_null_with_none_and_the_split_of_the_currents_row(tmp_path):
    """Seeds with 900 rods in current at 2 of 3 times, 800 at all, 1000 at 1: window means 600, 800 and
    333.3. Against a null model with none in any seed (its rods never touch): paired over 3 seeds, mean
    577.8 ± 234.1 / sqrt 3 = 135.2, d = +4.3, p = 2 t_2.sf(4.27) = 0.051: no verdict with 3 pairs, the
    null model said to be zero in every seed, and not split; with p below 0.0027 it would be worded as
    nonzero where the null model is zero by construction, not as the claim reproduced. Against a null without a
    circuit whose filaments span the gap at every time (500, 600, 400): differences 100, 200, -66.7, d =
    +1.0, p = 0.42; the row splits each side's window mean into the share of the times at which the
    seeds carry current (2/3, 1, 1/3: 0.667 ± 0.19) and the count over those times alone (900, 800, 1000:
    900 ± 58), and the null's (1 ± 0; 500 ± 58)."""
    from selfas_graph.studies.verdicts import ZERO_NULL, claim_rows

    studies = _claim_against_null(tmp_path, 'measure = "filament_rods"\nwindow = [300.0, 600.0]')
    scene = _window_summary([[0.0, 900.0, 900.0], [800.0] * 3, [0.0, 0.0, 1000.0]], [[0, 1, 1], [1, 1, 1], [0, 0, 1]])
    free = _window_summary([[0.0] * 3] * 3, [[0, 0, 0]] * 3)
    row = claim_rows(studies, {"a": scene, "b": free}).splitlines()[-1]
    words = "not distinguished from the null model (+4.3 SE; paired over 3 seeds, p = 0.051, not below 0.0013; "
    assert f"| {words}the null model's value is zero in every seed) |" in row, row
    assert "split" not in row and "reproduced" not in row
    from selfas_graph.studies.verdicts import _verdict

    assert _verdict(4.3, "greater", 0.001, 3, zero=True) == f"{ZERO_NULL}; +4.3 SE, paired over 3 seeds, p = 0.001"
    plain = _window_summary([[500.0] * 3, [600.0] * 3, [400.0] * 3], [[1, 1, 1]] * 3, circuit=False)
    row = claim_rows(studies, {"a": scene, "b": plain}).splitlines()[-1]
    cells = [c.strip() for c in row.split("|")]
    assert cells[4] == (
        "578 ± 135 (3); at t = 600: 3 of 3 seeds carry current: median 900 [800 to 1000], mean 900 ± 58 (3); "
        "split: share of the window's 3 times at which the seeds carry current: 0.667 ± 0.19 (3); the measure "
        "over those times alone: 900 ± 58 (3)"
    ), cells[4]
    assert cells[6] == (
        "500 ± 58 (3); split: share of the window's 3 times at which the seeds span the gap (no circuit): "
        "1 ± 0 (3); the measure over those times alone: 500 ± 58 (3)"
    ), cells[6]
    assert cells[7] == (
        "not distinguished from the null model (+1.0 SE; paired over 3 seeds, p = 0.42, not below 0.0013)"
    ), cells[7]


def test_the_split_of_a_window_leaves_out_a_seed_that_stopped_inside_it():
    """As the window's mean and the verdict do: seed 3 stopped at t = 2, inside the window 1-4; its
    share and size were counted from its early frames, describing other seeds than the verdict's."""
    from selfas_graph.studies.pairing import window_split
    from selfas_graph.studies.stats import plain_stat, window_values

    s = {
        "times": [0.0, 1.0, 2.0, 3.0, 4.0],
        "seeds": [{"seed": 1, "t_end": 4.0}, {"seed": 2, "t_end": 4.0}, {"seed": 3, "t_end": 2.0}],
        "measures": {
            "filament_rods": {"values": [[0, 10, 10, 10, 10], [0, 0, 10, 0, 10], [0, 50, 50, None, None]]},
            "total_current": {"values": [[0, 1, 1, 1, 1], [0, 0, 1, 0, 1], [0, 1, 1, None, None]]},
        },
        "current": [[0, 1, 1, 1, 1], [0, 0, 1, 0, 1], [0, 1, 1, None, None]],
    }
    assert plain_stat(window_values(s, "filament_rods", 1.0, 4.0))["n"] == 2
    sp = window_split(s, "filament_rods", 1.0, 4.0)
    assert sp["fraction"][:2].tolist() == [1.0, 0.5] and sp["size"][:2].tolist() == [10.0, 10.0]
    assert np.isnan(sp["fraction"][2]) and np.isnan(sp["size"][2])


def test_a_pooled_rank_test_of_seeds_that_share_their_rods_is_conservative():
    """Why a sweep's trend may pool seeds that start from the same rods at every point (docs/model.md
    "Measures of the paper's claims"): with no trend, 5, 16 and 5 seeds whose own levels spread as
    much as their noise, pooled as independent, reject at 5 % less often than 5 % (each point holds
    the same seeds' levels), and with no such spread about 5 %. 400 draws each: the binomial spread
    at 5 % is 1.1 %."""
    from scipy.stats import kendalltau

    rng = np.random.default_rng(7)
    for spread, most in ((1.0, 0.03), (0.0, 0.08)):
        rejected = 0
        for _ in range(400):
            level = rng.normal(0.0, spread, 16)
            x, y = [], []
            for j, n in enumerate((5, 16, 5)):
                x += [j] * n
                y += (level[:n] + rng.normal(0.0, 1.0, n)).tolist()
            rejected += kendalltau(x, y).pvalue < 0.05
        assert rejected / 400 < most


def test_a_study_time_that_is_no_frame_of_its_runs_stops_the_summary(tmp_path):
    """Frames every 0.05: a study summarised every 0.04 gave the nearest frame's values under the label
    0.04, 0.08, ... without a word (the ensemble command refuses such times); the summary now stops,
    naming the time and the file. Times past a file's last frame are the seeds' that stopped early."""
    import shutil

    from selfas_graph.studies.summary import _check_frames

    run = tmp_path / "seed_0001.h5"
    shutil.copyfile(Path(__file__).parent.parent / "data" / "legacy_run_58b30f8.h5", run)

    def study(lines):
        (tmp_path / "s.toml").write_text(f"[study.a]\nscenario = 'x'\nseeds = 1\nt_end = 0.3\n{lines}\n")
        return load_studies(tmp_path / "s.toml").study("a")

    _check_frames(study("every = 0.1\ntable_times = [0.25]"), [run])
    _check_frames(study("every = 0.1"), [run], also=[0.15])
    with pytest.raises(StudiesError, match=r"study a: t = 0.04 is no frame of seed_0001.h5 \(frames at 0, 0.05, 0.1"):
        _check_frames(study("every = 0.04"), [run])
    with pytest.raises(StudiesError, match="t = 0.12 is no frame"):
        _check_frames(study("every = 0.1"), [run], also=[0.12])
    short = study("every = 0.1")
    _check_frames(dataclasses.replace(short, t_end=0.5, every=0.5), [run])  # 0.5 lies past the last frame


@pytest.mark.parametrize(
    "argv, words",
    [
        (["list", "--check"], "--check is read by page, not by list: leave it out"),
        (["page", "fig2"], "study names are read by run and summarise, not by page: leave them out"),
        (["run", "fig2", "--summaries", "x"], "--summaries is read by summarise and page, not by run"),
        (["summarise", "--jobs", "2"], "--jobs is read by run, not by summarise"),
    ],
)
def test_an_option_the_action_does_not_read_is_refused(argv, words, capsys):
    """`study list --check` and `study page fig2` took what they never read without a word."""
    from selfas_graph.cli.main import main

    assert main(["study", *argv]) == 2
    assert words in capsys.readouterr().err
