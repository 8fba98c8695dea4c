"""docs/results.md holds exactly what the committed summaries give: every generated block is
regenerated from docs/studies.toml and docs/results/*.json and compared (no number on the page is
typed by hand), and every committed summary names a commit and covers its study's seeds."""

import json
import math
from pathlib import Path

from selfas_graph.studies import load_studies
from selfas_graph.studies.page import page_blocks, page_blocks_in
from selfas_graph.studies.stats import GROUPED

ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs"


def test_the_results_page_is_what_the_summaries_give():
    studies = load_studies(DOCS / "studies.toml")
    want = page_blocks(studies, DOCS / "results")
    have = page_blocks_in((DOCS / "results.md").read_text(encoding="utf-8"))
    assert set(have) <= set(want), f"blocks the generator does not make: {sorted(set(have) - set(want))}"
    needed = {"claims", "convergence", "status"} | {f"sensitivity {name}" for name in studies.sweeps}
    needed |= {
        f"table {name}" for name in studies.studies if studies.studies[name].section in ("paper", "null", "contrast")
    }
    needed |= {f"runs {name}" for name in studies.studies}  # every study says the commit, CPU and time of its runs
    assert needed <= set(have), f"blocks missing from the page: {sorted(needed - set(have))}"
    for key in have:
        assert have[key] == want[key].rstrip("\n"), f"block '{key}' differs: run `selfas-graph study page`"


def test_every_committed_summary_names_its_commits_and_is_complete():
    studies = load_studies(DOCS / "studies.toml")
    for path in sorted((DOCS / "results").glob("*.json")):
        summary = json.loads(path.read_text(encoding="utf-8"))
        study = studies.study(path.stem)
        if summary.get("kind") == "percolation":
            assert len(summary["commit"].removesuffix("+dirty")) == 40 and summary["cpu_model"], path
            assert [d["count"] for d in summary["densities"]] == list(study.counts), path
            for d in summary["densities"]:  # its statistics follow from the runs' times it keeps
                _percolation_statistics_follow_from_the_runs(d, summary["study"]["t_max"], path)
            continue
        assert summary["seeds"], path
        for m in GROUPED:  # over the seeds that carry current alone, as the page shows them
            assert m not in summary["measures"] or "group" in summary["measures"][m], (path.name, m)
        for seed in summary["seeds"]:
            assert len(seed["commit"].removesuffix("+dirty")) == 40, f"{path.name}: seed {seed['seed']} names no commit"
            assert seed["cpu_model"] and seed["wall_seconds"] > 0
        if not summary.get("missing"):
            assert summary["n_seeds"] == study.seeds
            assert min(s["t_end"] for s in summary["seeds"]) >= study.t_end - 1e-9, f"{path.name}: a seed ended early"


def _percolation_statistics_follow_from_the_runs(d, t_max, path):
    """A percolation summary's count, Wilson interval and Kaplan-Meier quartiles from its runs' times
    (a summary from before the runs' times were kept has none to check)."""
    from selfas_graph.analysis.ensemble_stats import kaplan_meier, km_quantile, wilson_interval

    if "run_times" not in d:
        return
    used = [r for r in d["run_times"] if r["status"] in ("short_circuit", "censored", "failed")]
    observed = [r["status"] == "short_circuit" for r in used]
    assert (len(used), sum(observed)) == (d["runs"], d["short_circuited"]), (path.name, d["count"])
    assert list(wilson_interval(sum(observed), len(used))) == d["fraction_ci95"]
    t, F = kaplan_meier([r["time"] for r in used], observed)
    for q, key in ((0.25, "q25"), (0.5, "median"), (0.75, "q75")):
        want = km_quantile(t, F, q)
        assert (d[key] is None and not math.isfinite(want)) or d[key] == want, (path.name, d["count"], key)


def test_the_page_links_the_movie_its_summary_was_made_with(tmp_path, monkeypatch):
    """A paper study's figures block links the movie its summary names (a GIF where no ffmpeg made an MP4),
    and none where the summary was made without one (--no-movie, or a movie that failed): an older movie
    left in the figures folder is not linked. Summaries from before the key link the MP4 of the name."""
    import shutil

    monkeypatch.chdir(ROOT)  # the studies file's scenario paths are relative to the repository's root
    studies = load_studies(DOCS / "studies.toml")
    folder = tmp_path / "results"
    shutil.copytree(DOCS / "results", folder)
    summary = json.loads((folder / "fig2.json").read_text(encoding="utf-8"))
    for movie, link in ((None, None), ("fig2_movie.gif", "figures/fig2_movie.gif")):
        (folder / "fig2.json").write_text(json.dumps(summary | {"movie": movie}), encoding="utf-8")
        block = page_blocks(studies, folder)["figures fig2"]
        assert ("A movie of seed" in block) is (link is not None)
        assert link is None or f"]({link})" in block
    assert "](figures/fig2_movie.mp4)" in page_blocks(studies, DOCS / "results")["figures fig2"]
