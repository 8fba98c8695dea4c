"""``selfas-graph ensemble`` and :mod:`selfas_graph.ensemble`: seeds in their own files, nothing run twice.

One small ensemble of the shipped quick scene (4 seeds on 2 worker processes to t = 0.5,
about 30 s on 2 cores) is shared by the checks of the printed table, the summary files and
the rerun that must run nothing; the resume, refusal and summary checks use the 60-rod
circuit scene of conftest (one seed to t = 0.6 takes about 2 s).
"""

import csv
import json
import math
import os
import shutil
import signal
from pathlib import Path

import h5py
import numpy as np
import pytest
from runfiles import differing_datasets

from conftest import SMALL_CIRCUIT_SCENE
from selfas_graph import RunFile
from selfas_graph.analysis import rod_centres
from selfas_graph.cli.main import main
from selfas_graph.ensemble import Ensemble, EnsembleError, default_times, format_table, seed_path, summarise
from selfas_graph.grid import Grid
from selfas_graph.io.checkpoint import checkpoint_path
from selfas_graph.io.scenario import load_scenario, scenario_from_text
from selfas_graph.model import events as ev

ROOT = Path(__file__).resolve().parents[2]
QUICK = str(ROOT / "scenarios" / "quick.toml")
T_END = 0.5  # short: the machinery, not the physics (quick.toml short-circuits near t = 1.3)


_same_run = differing_datasets


def _kill_group(proc):
    """End an ensemble started in its own session and everything it started (a test's cleanup)."""
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass
    proc.communicate(timeout=30)


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    """4 seeds of quick.toml on 2 processes; (folder, stdout of the run)."""
    folder = tmp_path_factory.mktemp("ens") / "quick"
    capture = pytest.MonkeyPatch()
    import io
    import sys

    out = io.StringIO()
    capture.setattr(sys, "stdout", out)
    try:
        rc = main(["ensemble", QUICK, "--seeds", "4", "--jobs", "2", "--t-end", str(T_END), "-o", str(folder)])
    finally:
        capture.undo()
    assert rc == 0, out.getvalue()
    return folder, out.getvalue()


def test_quick_ensemble_prints_the_summary_table(quick):
    folder, out = quick
    assert "seeds 1..4 to t = 0.5" in out and "4 to run, 0 to resume, 0 done" in out
    assert "2 processes x 1 numba thread" in out
    assert out.count("finished at t = 0.5") == 4
    assert "short circuit: 0 of 4 seeds (4 without one, censored at their end time)" in out
    for name in ("filament_rods", "total_current", "inside_R_plas", "median_axis_distance", "midplane_flux"):
        assert f"| {name} |" in out
    # the quarters of t = 0.5 at their nearest frames (every 0.5): t = 0 and t = 0.5, each once
    assert "| t = 0 | t = 0.5 |" in out
    assert sorted(p.name for p in folder.glob("seed_*.h5")) == [
        f"seed_000{s}{x}.h5" for s in (1, 2, 3, 4) for x in (".checkpoint", "")
    ]


def test_summary_files(quick):
    folder, _ = quick
    s = json.loads((folder / "summary.json").read_text())
    assert s["n_seeds"] == 4 and s["times"] == [0.0, 0.5]
    assert [d["seed"] for d in s["seeds"]] == [1, 2, 3, 4] and {d["status"] for d in s["seeds"]} == {"finished"}
    assert s["short_circuit"]["n_censored"] == 4 and s["short_circuit"]["median"] is None
    med = s["measures"]["median_axis_distance"]
    assert med["n"] == [4, 4] and all(v is not None for v in med["sem"])
    # the measure recomputed from the files: median distance of rod centres from the plasma axis at t = 0.5
    per_seed = []
    for k in (1, 2, 3, 4):
        with RunFile(seed_path(folder, k)) as run:
            c = rod_centres(run.position(-1))
            per_seed.append(np.median(np.hypot(c[:, 0], c[:, 1])))
    assert med["values"][0][1] == per_seed[0] and med["mean"][1] == pytest.approx(np.mean(per_seed), rel=1e-14)
    assert med["sem"][1] == pytest.approx(np.std(per_seed, ddof=1) / 2, rel=1e-12)  # sem = s / sqrt(4)
    rows = list(csv.DictReader((folder / "summary.csv").read_text().splitlines()))
    row = [r for r in rows if r["measure"] == "median_axis_distance" and float(r["time"]) == 0.5][0]
    assert float(row["mean"]) == med["mean"][1] and row["n"] == "4"
    assert [r for r in rows if r["measure"] == "seeds_without_short_circuit"][0]["mean"] == "4"


def test_default_times_are_frame_times():
    """The default summary times are the quarters of the end time at their nearest frames, each once:
    frames every 0.5 to t = 1 give 0.5 and 1 (the quarter 0.25 used to be the frame at t = 0, labelled
    0.25, and 0.75 the frame at 0.5); an end time off the frame grid stays the last time."""
    assert default_times(1.0, 0.5) == [0.5, 1.0]
    assert default_times(100.0, 2.0) == [26.0, 50.0, 76.0, 100.0]
    assert default_times(600.0, 10.0) == [150.0, 300.0, 450.0, 600.0]
    assert default_times(1.1, 0.5) == [0.5, 1.0, 1.1]
    assert default_times(1.0) == [0.25, 0.5, 0.75, 1.0]


def test_default_summary_times_fall_on_frames_whose_interval_is_rounded_to_whole_steps():
    """Frames every output.interval = 0.0125 at dt = 0.002 are every 6 steps, 0.012: the default times
    were the quarters rounded to 0.0125 (the 0.025 column held the frame at 0.024, and giving 0.025 back
    was refused, no frame there). They are frame times now, each of which check_times takes back."""
    from selfas_graph.ensemble.plan import check_times, summary_times

    times = summary_times(None, 0.1, 0.0125, 0.002)
    assert times == summary_times(times, 0.1, 0.0125, 0.002)
    assert all(abs(t / 0.012 - round(t / 0.012)) < 1e-9 or t == 0.1 for t in times)
    assert check_times(times, 0.1, 0.012) == times


def test_default_times_that_collapse_are_explained():
    """Frames too far apart for four default columns get a note that says why and what to give."""
    from selfas_graph.cli.ensemble import _default_times_note

    note = _default_times_note(default_times(1.0, 0.5), 1.0, 0.5)
    assert note.startswith("the default times (a quarter, half, three quarters and all of t = 1) fall on 2 frames")
    assert "give --times" in note
    assert _default_times_note(default_times(600.0, 10.0), 600.0, 10.0) is None


def test_rerun_runs_nothing_new(quick, capsys):
    folder, _ = quick
    before = {p.name: p.read_bytes() for p in folder.glob("seed_*.h5")}
    assert (
        main(
            [
                "ensemble",
                QUICK,
                "--seeds",
                "4",
                "--jobs",
                "2",
                "--t-end",
                str(T_END),
                "-o",
                str(folder),
                "--times",
                "0.5",
            ]
        )
        == 0
    )
    out = capsys.readouterr().out
    assert "0 to run, 0 to resume, 4 done" in out and "[1/" not in out and "| t = 0.5 |" in out
    assert {p.name: p.read_bytes() for p in folder.glob("seed_*.h5")} == before


def test_other_parameters_are_refused(quick, capsys):
    folder, _ = quick
    before = {p.name: p.read_bytes() for p in folder.glob("seed_*.h5")}
    assert (
        main(["ensemble", QUICK, "--seeds", "2", "--t-end", str(T_END), "-o", str(folder), "--set", "rods.count=200"])
        == 2
    )
    err = capsys.readouterr().err
    assert "seed_0001.h5 belongs to other parameters: rods.count = 300 (here 200)" in err and "--force" in err
    assert {p.name: p.read_bytes() for p in folder.glob("seed_*.h5")} == before


def test_a_finished_seed_of_another_version_is_kept_and_named(quick, tmp_path, capsys):
    """``selfas-graph ensemble`` keeps a finished seed file made by another version (no trajectories_since
    here) and says which version made it."""
    from selfas_graph import __version__

    folder, _ = quick
    copy = tmp_path / "copy"
    shutil.copytree(folder, copy)
    with h5py.File(seed_path(copy, 2), "r+") as f:
        f["parameters/selfas_graph"].attrs["version"] = "0.0.1"
    argv = ["ensemble", QUICK, "--seeds", "4", "--t-end", str(T_END), "-o", str(copy), "--no-run"]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert f"seed 2: finished at t = {T_END:g} by version 0.0.1, not this version {__version__}" in out
    assert "seed 1: finished" not in out


def test_no_run_without_t_end_summarises_to_the_end_of_the_seed_files(quick, tmp_path, capsys):
    """``--no-run`` without the ``--t-end`` the seeds were run with summarises them to their own end
    time, and says so, not to the scene's end (where nothing was run and every seed would count as
    unfinished); the summary is the one ``--t-end`` gives."""
    folder, _ = quick
    copy = tmp_path / "copy"
    shutil.copytree(folder, copy)
    assert main(["ensemble", QUICK, "--seeds", "4", "-o", str(copy), "--no-run"]) == 0
    out = capsys.readouterr().out
    assert f"summarising to t = {T_END:g}, the end time of the seed files" in out and "4 done" in out
    first = json.loads((copy / "summary.json").read_text())
    assert main(["ensemble", QUICK, "--seeds", "4", "--t-end", str(T_END), "-o", str(copy), "--no-run"]) == 0
    assert "summarising to" not in capsys.readouterr().out
    assert json.loads((copy / "summary.json").read_text()) == first


def test_no_run_with_force_does_not_summarise_files_of_other_parameters(quick, tmp_path, capsys):
    """``--no-run --force`` runs nothing, so it replaces nothing: seed files of other parameters stop
    it (naming the keys), with no advice to pass --force, and no summary is written for them."""
    folder, _ = quick
    copy = tmp_path / "copy"
    shutil.copytree(folder, copy)
    (copy / "summary.json").unlink()
    argv = ["ensemble", QUICK, "--seeds", "2", "--t-end", str(T_END), "-o", str(copy), "--no-run", "--force"]
    assert main([*argv, "--set", "rods.count=200"]) == 2
    err = capsys.readouterr().err
    assert "belongs to other parameters: rods.count" in err and "pass --force" not in err
    assert not (copy / "summary.json").exists()


def test_seed_files_of_a_version_before_the_trajectories_are_not_reused(quick):
    """``older_than`` (docs/studies.toml ``trajectories_since``): finished seed files made by an older
    version are refused, naming the file and both versions, and planned to be replaced with force;
    at their own version they are done. Planning writes nothing."""
    from selfas_graph import __version__

    folder, _ = quick
    before = {p.name: p.read_bytes() for p in folder.glob("seed_*.h5")}
    same = Ensemble(QUICK, 4, folder, t_end=T_END, older_than=__version__.split("+")[0])
    assert [p.action for p in same.plan()] == ["done"] * 4
    with pytest.raises(EnsembleError) as info:
        Ensemble(QUICK, 4, folder, t_end=T_END, older_than="99.0").plan()
    msg = str(info.value)
    assert "seed_0001.h5 was made by version " + __version__ in msg and "trajectories of version 99.0" in msg
    assert "trajectories_since" in msg and "--force" in msg
    plans = Ensemble(QUICK, 4, folder, t_end=T_END, older_than="99.0", force=True).plan()
    assert [p.action for p in plans] == ["run"] * 4 and all("replacing: made by version" in p.note for p in plans)
    assert {p.name: p.read_bytes() for p in folder.glob("seed_*.h5")} == before


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--seeds", "0"], "--seeds: 0 must be >= 1"),
        (["--seeds", "2", "--set", "scenario.seed=5"], "the ensemble sets scenario.seed"),
        # it was taken, ignored and written into each seed file's parameters
        (["--seeds", "2", "--set", "output.file=zz.h5"], "the ensemble sets output.file for each run; each seed's"),
        (["--seeds", "2", "--set", "rods.cont=5"], "rods.cont"),
        (["--seeds", "2", "--times", "1,x"], "give simulated times separated by commas"),
        (["--seeds", "2", "--t-end", "0.5", "--times", "0.6"], "after the end time 0.5"),
        # between two frames (every 0.5 t0): it would take one of them and be labelled 0.25
        (["--seeds", "2", "--t-end", "1", "--times", "0.25"], "no frame at t = 0.25"),
        (["--seeds", "2", "--first-seed", "-3"], "seeds must be distinct integers >= 0"),
        (["--seeds", "2", "--first-seed", str(2**70)], "seed 1180591620717411303424: "),
        (["--seeds", "2", "--flux-radius", "nan"], "--flux-radius must be a positive length"),
    ],
)
def test_bad_input(tmp_path, capsys, argv, message):
    """Exit code 2 (argparse's or the command's), the message names the problem, nothing is written."""
    try:
        rc = main(["ensemble", QUICK, "-o", str(tmp_path / "e"), *argv])
    except SystemExit as exc:
        rc = exc.code
    assert rc == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "e").exists()


def test_output_folder_that_is_a_file_is_refused(tmp_path, capsys):
    (tmp_path / "e").write_text("precious")
    assert main(["ensemble", QUICK, "--seeds", "1", "-o", str(tmp_path / "e")]) == 2
    assert "the output folder" in capsys.readouterr().err and (tmp_path / "e").read_text() == "precious"
    assert main(["ensemble", QUICK, "--seeds", "1", "-o", str(tmp_path / "e" / "sub")]) == 2
    res = capsys.readouterr()
    assert "cannot" in res.err and res.out == ""  # refused before the plan is printed
    grid = ["--grid", "integrator.dt=0.002,0.004"]
    assert main(["ensemble", QUICK, "--seeds", "1", *grid, "-o", str(tmp_path / "e" / "sub")]) == 2
    res = capsys.readouterr()
    assert "cannot" in res.err and res.out == "" and (tmp_path / "e").read_text() == "precious"


# ----------------------------------------------------------------------------- the small circuit scene
@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    folder = tmp_path_factory.mktemp("small")
    (folder / "scene.toml").write_text(SMALL_CIRCUIT_SCENE)
    return folder / "scene.toml"


def test_an_earlier_end_is_continued_from_the_checkpoint_bit_for_bit(scene, tmp_path):
    """Seed 3 to t = 0.3, then the ensemble to 0.6 resumes it: the file equals a direct run to 0.6."""
    short = Ensemble(scene, [3], tmp_path / "e", t_end=0.3)
    (r,) = short.run()
    assert r["status"] == "finished" and r["t"] == pytest.approx(0.3)
    full = Ensemble(scene, [3], tmp_path / "e")
    (plan,) = full.plan()
    assert plan.action == "resume"
    (r,) = full.run()
    assert r["status"] == "finished" and r["action"] == "resume"
    direct = Ensemble(scene, [3], tmp_path / "direct")
    direct.run()
    assert _same_run(seed_path(tmp_path / "e", 3), seed_path(tmp_path / "direct", 3)) == []
    assert [p.action for p in full.plan()] == ["done"]


def test_an_earlier_end_off_the_frame_grid_stays_a_summary_time(scene, tmp_path):
    """Seeds run to t = 0.32 (frames every 0.05 and at 0.32), then continued to 0.6: every seed holds the
    frame at 0.32, which the first summary gave; it was refused afterwards as "no frame at t = 0.32".
    A seed run at once to 0.6 has none there, and then the time is refused again."""
    Ensemble(scene, [3, 4], tmp_path / "e", t_end=0.32).run()
    full = Ensemble(scene, [3, 4], tmp_path / "e")
    full.run()
    assert full.shared_frame_times() == [pytest.approx(0.32)]
    s = full.summarise(times=[0.3, 0.32, 0.6])
    assert s["times"] == [0.3, 0.32, 0.6] and s["measures"]["cycle_rank"]["n"] == [2, 2, 2]
    Ensemble(scene, [5], tmp_path / "e").run()  # seed 5 at once: no frame at 0.32
    with pytest.raises(EnsembleError, match="no frame at t = 0.32"):
        Ensemble(scene, [3, 4, 5], tmp_path / "e").summarise(times=[0.32])


def test_jobs_below_one_are_refused_before_anything_is_made(scene, tmp_path):
    """``run(jobs=0)`` or ``jobs=-1`` ran the seeds serially without a word."""
    for jobs in (0, -1, 1.5, "2"):
        with pytest.raises(EnsembleError, match="jobs: the number of worker processes"):
            Ensemble(scene, [3], tmp_path / "e").run(jobs=jobs)
        with pytest.raises(EnsembleError, match="jobs: the number of worker processes"):
            Grid(scene, {"integrator.dt": ["2.5e-4"]}, seeds=[3], folder=tmp_path / "g").run(jobs=jobs)
    assert not (tmp_path / "e").exists() and not (tmp_path / "g").exists()


def test_an_ensemble_of_parameters_names_what_it_takes(tmp_path):
    """``Ensemble(Parameters(...))`` failed in pathlib: the message names the scenario file or a
    loaded Scenario, and the overrides for the changes."""
    import selfas_graph as sg

    with pytest.raises(EnsembleError, match=r"scenario: a scenario file's path, or a Scenario .* got Parameters"):
        Ensemble(sg.Parameters(), 2, tmp_path / "e")
    assert not (tmp_path / "e").exists()


def test_summary_times_are_checked(scene, tmp_path):
    """``summarise(times=0.3)`` failed with a TypeError, and a time after the end gave columns of n/a
    without a word (the command line refuses it)."""
    ens = Ensemble(scene, [3], tmp_path / "e")
    assert ens.summarise(times=0.3)["times"] == [0.3]
    # frames every 0.05: a time between two would take one of them under its own label
    with pytest.raises(EnsembleError, match="no frame at t = 0.325; the frames are every 0.05"):
        ens.summarise(times=[0.3, 0.325])
    for bad in ([5.0], [-1.0], ["x"], [float("nan")]):
        with pytest.raises(EnsembleError, match="is not a simulated time between 0 and the end time 0.6"):
            ens.summarise(times=bad)
    # a time twice was a column twice
    with pytest.raises(EnsembleError, match="times: 0.3 and 0.3 are one time; give each time once"):
        ens.summarise(times=[0.3, 0.1, 0.3])
        with pytest.raises(EnsembleError, match="is not a simulated time"):
            Grid(scene, {"integrator.dt": ["2.5e-4"]}, seeds=[3], folder=tmp_path / "g").summarise(times=bad)


def test_a_loaded_scenario_runs_as_its_file_with_its_overrides_and_end_time(scene, tmp_path):
    """``Ensemble(load_scenario(path, ...), ...)`` and ``Grid`` of it used to fail with a TypeError (a
    path was expected): a loaded scenario is its file, its overrides and its end time; one built from
    text alone has no file for the seeds and is refused by name."""
    loaded = load_scenario(scene, overrides=["circuit.delta_J0=3"], t_end=0.3)
    a = Ensemble(loaded, [3], tmp_path / "a")
    b = Ensemble(scene, [3], tmp_path / "b", overrides=["circuit.delta_J0=3"], t_end=0.3)
    assert (
        (a.scenario_path, a.overrides, a.t_end)
        == (b.scenario_path, b.overrides, b.t_end)
        == (
            Path(scene),
            ["circuit.delta_J0=3"],
            0.3,
        )
    )
    (point,) = Grid(loaded, {"integrator.dt": ["2.5e-4"]}, seeds=[3], folder=tmp_path / "g").ensembles
    assert point.overrides == ["circuit.delta_J0=3", "integrator.dt=2.5e-4"] and point.t_end == 0.3
    with pytest.raises(EnsembleError, match="built from text"):
        Ensemble(scenario_from_text(Path(scene).read_text()), [3], tmp_path / "c")


def test_killed_seed_resumes_and_one_without_checkpoint_is_refused(scene, tmp_path):
    ens = Ensemble(scene, [3, 4], tmp_path, t_end=0.2)
    ens.run()
    for s in (3, 4):  # as after kill -9 at t = 0.2: status still "running"
        with h5py.File(seed_path(tmp_path, s), "r+") as f:
            f["parameters/selfas_graph"].attrs["status"] = "running"
    checkpoint_path(seed_path(tmp_path, 4)).unlink()
    ens = Ensemble(scene, [3, 4], tmp_path, t_end=0.3)
    with pytest.raises(EnsembleError, match=r"seed_0004.h5 is running at t = 0.2 .* no usable checkpoint"):
        ens.plan()
    # summarising only, a file still being written (or killed) is read up to its last frame, with its
    # checkpoint or without: nothing resumes it
    assert [(p.seed, p.action) for p in ens.plan(summary_only=True)] == [(3, "partial"), (4, "partial")]
    forced = Ensemble(scene, [3, 4], tmp_path, t_end=0.3, force=True)
    assert [(p.seed, p.action) for p in forced.plan()] == [(3, "resume"), (4, "run")]
    assert [r["status"] for r in forced.run()] == ["finished", "finished"]


def test_a_seed_with_another_runs_checkpoint_is_refused_when_planned(scene, tmp_path):
    """The plan takes the checks of ``simulate --resume`` (lifecycle.continuation): a seed file beside
    another run's checkpoint (here seed 3's copied over seed 4's) was planned "resume" and failed only
    in its task; it is now refused when planned, naming the run identities, and replaced with force.
    The refusal gives the ensemble's advice (--force), not simulate's (give the run file's own checkpoint)."""
    ens = Ensemble(scene, [3, 4], tmp_path, t_end=0.2)
    ens.run()
    for s in (3, 4):  # as after kill -9 at t = 0.2: status still "running"
        with h5py.File(seed_path(tmp_path, s), "r+") as f:
            f["parameters/selfas_graph"].attrs["status"] = "running"
    shutil.copyfile(checkpoint_path(seed_path(tmp_path, 3)), checkpoint_path(seed_path(tmp_path, 4)))
    with pytest.raises(
        EnsembleError, match=r"seed_0004.h5 is running at t = 0.2 .* no usable checkpoint .*belongs to another run"
    ) as refused:
        Ensemble(scene, [3, 4], tmp_path, t_end=0.3).plan()
    assert "own checkpoint" not in str(refused.value)
    forced = Ensemble(scene, [3, 4], tmp_path, t_end=0.3, force=True)
    assert [(p.seed, p.action) for p in forced.plan()] == [(3, "resume"), (4, "run")]


def test_failed_seed_is_kept_and_reported(scene, tmp_path, capsys):
    Ensemble(scene, [3], tmp_path, t_end=0.1).run()
    with h5py.File(seed_path(tmp_path, 3), "r+") as f:
        f["parameters/selfas_graph"].attrs["status"] = "failed: a test"
    before = seed_path(tmp_path, 3).read_bytes()
    assert main(["ensemble", str(scene), "--seeds", "1", "--t-end", "0.2", "-o", str(tmp_path)]) == 3
    out = capsys.readouterr().out
    assert "1 failed" in out and "seed 3: failed: a test (kept; --force reruns it)" in out
    assert seed_path(tmp_path, 3).read_bytes() == before


def test_summary_counts_censored_short_circuits_apart(scene, tmp_path):
    """Seeds 3 and 4 of the circuit scene: the short-circuit times from the event records,
    censored ones (none by t_end) counted and not averaged in."""
    ens = Ensemble(scene, [3, 4, 5], tmp_path)
    ens.run(jobs=1)
    s = ens.summarise(times=[0.3, 0.6])
    sc_times = []
    for k in (3, 4, 5):
        with RunFile(seed_path(tmp_path, k)) as run:
            e = run.events()
            t = e["time"][e["kind"] == ev.SHORT_CIRCUIT] if len(e) else []
            sc_times.append(float(t.min()) if len(t) else None)
    seen = [t for t in sc_times if t is not None]
    assert seen, "the circuit scene must short-circuit in at least one seed"
    sc = s["short_circuit"]
    assert sc["n"] == 3 and sc["n_observed"] == len(seen) and sc["n_censored"] == 3 - len(seen)
    assert sc["mean_observed"] == pytest.approx(np.mean(seen), rel=1e-14)
    assert [d["short_circuit_time"] for d in s["seeds"]] == sc_times
    # no plasma filament in this scene: the R_plas measure does not apply
    assert s["measures"]["inside_R_plas"]["mean"] == [None, None] and s["measures"]["inside_R_plas"]["n"] == [0, 0]
    fil = s["measures"]["filament_rods"]
    with RunFile(seed_path(tmp_path, 3)) as run:
        t, v = run.observable("rods/filament")
    assert fil["values"][0][1] == v[np.argmin(np.abs(t - 0.6))]
    flux = s["measures"]["midplane_flux"]
    assert all(math.isfinite(x) for x in flux["values"][0] if x is not None)
    table = format_table(s)
    assert f"short circuit: {len(seen)} of 3 seeds" in table and "| inside_R_plas | fraction | n/a | n/a |" in table


def test_summary_leaves_out_seeds_that_ended_early(scene, tmp_path):
    Ensemble(scene, [3], tmp_path, t_end=0.2).run()
    Ensemble(scene, [4], tmp_path, t_end=0.4).run()
    s = summarise([seed_path(tmp_path, 3), seed_path(tmp_path, 4)], [0.2, 0.4])
    assert s["measures"]["median_axis_distance"]["n"] == [2, 1]
    assert s["short_circuit"]["censored_at"] == sorted(
        [d["t_end"] for d in s["seeds"] if d["short_circuit_time"] is None]
    )


def test_seed_file_is_what_simulate_writes(scene, tmp_path):
    """A seed's file is the run of ``simulate --set scenario.seed=S``, bit for bit, but for its provenance."""
    ens = Ensemble(scene, [4], tmp_path / "e", t_end=0.2)
    ens.run()
    assert (
        main(
            [
                "simulate",
                str(scene),
                "--set",
                "scenario.seed=4",
                "--t-end",
                "0.2",
                "-o",
                str(tmp_path / "direct.h5"),
                "--progress",
                "none",
            ]
        )
        == 0
    )
    differ = _same_run(seed_path(tmp_path / "e", 4), tmp_path / "direct.h5")
    assert differ == []
    with RunFile(seed_path(tmp_path / "e", 4)) as run:
        assert run.meta["command_line"] == ens.command_for(4) and run.parameters["scenario"]["seed"] == 4
    shutil.rmtree(tmp_path / "e")


@pytest.mark.parametrize("sig", ["SIGTERM", "SIGINT"])
def test_a_signal_stops_the_seeds_with_checkpoints_and_a_rerun_continues(scene, tmp_path, sig):
    """SIGTERM or SIGINT to the launching process: the running seeds stop after a step with a checkpoint
    (exit code 128 + the signal's number, as simulate gives: 143 and 130; no further seed started), no
    process of the ensemble is left, and the same command again resumes them. The signal comes twice, to the launcher and then to its whole group, as GNU timeout
    sends it: the second, while the seeds wound down, cut off the report."""
    import os
    import signal
    import time

    folder = tmp_path / "e"
    proc = _ensemble_process(scene, folder, "--seeds", "3")
    try:
        first = [seed_path(folder, s) for s in (3, 4)]
        _wait_for_seed_files(folder, (3, 4))
        time.sleep(1.0)
        proc.send_signal(getattr(signal, sig))
        os.killpg(proc.pid, getattr(signal, sig))
        out, err = proc.communicate(timeout=90)  # a step and a checkpoint; 90 s: a loaded machine
        assert proc.returncode == 128 + getattr(signal, sig), err
        if Path("/proc/self/stat").exists():
            assert _group_gone(proc.pid, 10) == [], "processes of the stopped ensemble still run"
    finally:
        _kill_group(proc)
    assert "rerun the same command to continue" in err and out.count("interrupted at t = ") == 2
    assert "partial: 2 seeds stopped before t = 20 and 1 never started" in out  # the table is of part runs
    assert not seed_path(folder, 5).exists()
    for p in first:
        assert checkpoint_path(p).exists()
        with RunFile(p) as run:
            assert run.meta["status"].startswith("interrupted at step")
    plans = Ensemble(scene, 3, folder, t_end=20).plan()
    assert [p.action for p in plans] == ["resume", "resume", "run"]


def test_no_run_summarises_the_files_present(quick, capsys):
    folder, _ = quick
    assert (
        main(
            [
                "ensemble",
                QUICK,
                "--seeds",
                "5",
                "--t-end",
                str(T_END),
                "-o",
                str(folder),
                "--no-run",
                "--times",
                "0.5",
                "--plot",
            ]
        )
        == 0
    )
    out = capsys.readouterr().out
    assert "1 missing, 4 done" in out and "to run" not in out and "[1/" not in out  # --no-run runs nothing
    png = (folder / "summary.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 1000
    assert not seed_path(folder, 5).exists()
    assert json.loads((folder / "summary.json").read_text())["missing"] == [str(seed_path(folder, 5))]


def test_a_measure_is_one_more_entry(scene, tmp_path):
    """The summary takes any list of named per-frame measures (the claim measures join this way)."""
    from selfas_graph.ensemble import FRAME_MEASURES, Measure

    Ensemble(scene, [3, 4], tmp_path, t_end=0.1).run()
    extra = Measure("frame_time", "t0", "the frame's time", lambda f: f.time)
    s = summarise([seed_path(tmp_path, 3), seed_path(tmp_path, 4)], [0.05, 0.1], measures=[*FRAME_MEASURES, extra])
    m = s["measures"]["frame_time"]
    assert m["mean"] == pytest.approx([0.05, 0.1], rel=1e-12) and m["sem"] == [0.0, 0.0] and m["n"] == [2, 2]
    assert list(s["measures"])[-1] == "frame_time" and "| frame_time | t0 |" in format_table(s)


def test_summary_leaves_out_an_unreadable_file_by_name(scene, tmp_path):
    Ensemble(scene, [3], tmp_path, t_end=0.1).run()
    seed_path(tmp_path, 4).write_bytes(b"not hdf5")
    s = summarise([seed_path(tmp_path, 3), seed_path(tmp_path, 4)], [0.1])
    assert s["n_seeds"] == 1 and s["measures"]["median_axis_distance"]["n"] == [1]
    assert s["unreadable"][0]["path"] == str(seed_path(tmp_path, 4))
    assert "left out: " in format_table(s) and "not a readable HDF5 file" in format_table(s)


def test_a_file_of_an_earlier_version_matches_where_it_lacks_only_later_keys_at_their_default():
    """Keys added after a run file was written (contacts.resistance, rods.length, ...) count as
    equal when the wanted value is their default; not otherwise, and never for a force term
    that the file has off."""
    from selfas_graph.ensemble import parameter_differences
    from selfas_graph.model.params import Parameters

    wanted = Parameters().replace({"forces.yukawa": {}}).to_dict()
    stored = json.loads(json.dumps(wanted))
    del stored["contacts"]
    assert parameter_differences(stored, wanted) == []
    changed = Parameters().replace({"forces.yukawa": {}, "contacts.resistance": 2.0}).to_dict()
    assert parameter_differences(stored, changed) == ["contacts.resistance"]
    stored["forces"]["yukawa"] = None  # the term off in the file: its keys are real differences
    assert "forces.yukawa.screening_length" in parameter_differences(stored, wanted)


def test_a_later_key_of_an_optional_table_at_its_default_matches_a_file_that_lacks_it():
    """A key added later to a table that is off by default (forces.tip_magnetic.precision)
    has a default too: a file written before it, with the table on, used that default."""
    from selfas_graph.ensemble import parameter_differences
    from selfas_graph.model.params import Parameters

    wanted = Parameters().replace({"forces.tip_magnetic": {}}).to_dict()
    stored = json.loads(json.dumps(wanted))
    del stored["forces"]["tip_magnetic"]["precision"]
    assert parameter_differences(stored, wanted) == []
    mixed = Parameters().replace({"forces.tip_magnetic": {"precision": "mixed"}}).to_dict()
    assert parameter_differences(stored, mixed) == ["forces.tip_magnetic.precision"]


def test_fit_errors_and_current_groups_in_the_summary(scene, tmp_path, monkeypatch):
    """A fitted measure's standard error adds each seed's fit uncertainty; a grouped measure is
    summarised over the seeds carrying a current alone (k of n, median, range, mean, sem), in
    summary.json, summary.csv and the table. Hand-set values per seed; which seed carries a
    current is set by hand too (seed 3 does, seed 4 does not)."""
    import selfas_graph.ensemble.summary as ens  # where summarise looks carries_current up
    from selfas_graph.ensemble import FRAME_MEASURES, Measure, write_summary

    Ensemble(scene, [3, 4], tmp_path, t_end=0.1).run()
    seed = lambda f: f.params["scenario"]["seed"]  # noqa: E731
    monkeypatch.setattr(ens, "carries_current", lambda f: float(seed(f) == 3))
    fit = Measure(
        "fake_fit", "1", "a fitted value", lambda f: 2.0 + 0.2 * (seed(f) - 3), err=lambda f: 0.1 * (seed(f) - 2)
    )
    cur = Measure("fake_current", "J0", "a current", lambda f: 5.0 * (seed(f) == 3), grouped=True)
    s = summarise([seed_path(tmp_path, 3), seed_path(tmp_path, 4)], [0.1], measures=[*FRAME_MEASURES, fit, cur])
    m = s["measures"]["fake_fit"]
    # values 2.0, 2.2: s^2 = 0.02, between = sqrt(0.02 / 2) = 0.1; errors 0.1, 0.2: mean err^2 = 0.025
    assert m["mean"] == pytest.approx([2.1], rel=1e-14) and m["sem_between"] == pytest.approx([0.1], rel=1e-12)
    assert m["fit_err_rms"] == pytest.approx([np.sqrt(0.025)], rel=1e-12)
    assert m["sem"] == pytest.approx([np.sqrt(0.01 + 0.025 / 2)], rel=1e-12) and m["n"] == [2]
    g = s["measures"]["fake_current"]
    assert (g["k"], g["n_seeds"], g["median"], g["min"], g["max"]) == ([1], [2], [5.0], [5.0], [5.0])
    assert g["mean"] == [5.0] and g["sem"] == [None] and g["n"] == [1]  # never the mean 2.5 of both groups
    assert s["current"] == [[1.0], [0.0]]
    assert "| fake_current | J0 | 1/2: 5 [5, 5], 5 (1) |" in format_table(s)
    _, cs = write_summary(s, tmp_path)
    rows = {r["measure"]: r for r in csv.DictReader(cs.read_text().splitlines())}
    assert (
        rows["fake_current"]["k"] == "1"
        and rows["fake_current"]["n_seeds"] == "2"
        and rows["fake_current"]["mean"] == "5.0"
    )
    assert float(rows["fake_fit"]["sem_between"]) == pytest.approx(0.1, rel=1e-12) and rows["fake_fit"]["k"] == ""
    for name in ("filament_rods", "total_current", "midplane_flux", "moment_J_z"):
        assert "k" in s["measures"][name] and "median" in s["measures"][name]
    for name in ("fractal_dimension", "rg_dimension"):
        assert "fit_err_rms" in s["measures"][name]


def test_a_failed_seed_keeps_its_last_good_state_and_stores_no_nan(scene, tmp_path):
    """Charges of 1e10 blow seed 3 up at its first step: the seed is "failed", and its failure file holds
    the last state that passed the checks (verified, resumable) and the failed one without a NaN."""
    from hostile import non_finite_datasets
    from selfas_graph.io.checkpoint import read_checkpoint

    ens = Ensemble(scene, [3], tmp_path, overrides=["rods.magnetic_charge.value=1e10"], t_end=0.01)
    (r,) = ens.run()
    assert r["status"] == "failed" and "numerical failure at step 1" in r["message"]
    failure = tmp_path / "seed_0003.failure.h5"
    snap, meta = read_checkpoint(failure)
    assert int(snap["step"]) == 0 and meta["failed_step"] == 1
    for path in tmp_path.glob("*.h5"):
        assert non_finite_datasets(path) == [], path.name


# ----------------------------------------------------------------------------- processes that end with the ensemble
def _group_alive(pgid) -> list:
    """Live processes (zombies left out: they hold no memory and wait only to be reaped) of process group ``pgid``."""
    import os

    alive = []
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat") as f:
                fields = f.read().rsplit(")", 1)[1].split()
        except OSError:  # ended meanwhile
            continue
        if fields[0] != "Z" and int(fields[2]) == pgid:  # state, ppid, pgrp
            alive.append(int(entry))
    return alive


def _group_gone(pgid, timeout) -> list:
    """Wait up to ``timeout`` seconds for process group ``pgid`` to end; the processes still alive."""
    import time

    deadline = time.monotonic() + timeout
    while _group_alive(pgid) and time.monotonic() < deadline:
        time.sleep(0.2)
    return _group_alive(pgid)


def _ensemble_process(scene, folder, *extra):
    """``selfas-graph ensemble`` of seeds 3.. on 2 workers to t = 20 (minutes: it is stopped long before),
    in a session of its own, so that the test finds and, whatever happens, kills every process of it.
    SIGINT as a terminal gives it: a shell without job control starts a background job (``pytest &``,
    ``nohup``) with SIGINT ignored, which the child would inherit and Python then leaves ignored."""
    import os
    import signal
    import subprocess
    import sys

    cmd = [sys.executable, "-m", "selfas_graph.cli.main", "ensemble", str(scene), "--jobs", "2", "--t-end", "20"]
    env = {**os.environ, "NUMBA_NUM_THREADS": "1"}
    return subprocess.Popen(
        [*cmd, "-o", str(folder), *extra],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
        start_new_session=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )


def _wait_for_seed_files(folder, seeds, timeout=90):
    """Until the seeds' run files exist (start-up and kernel loading take 5-20 s on a loaded 2-core machine)."""
    import time

    deadline = time.monotonic() + timeout
    while not all(seed_path(folder, s).exists() for s in seeds) and time.monotonic() < deadline:
        time.sleep(0.2)
    assert all(seed_path(folder, s).exists() for s in seeds), "the seeds did not start"


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="lists processes through /proc")
def test_kill_9_of_the_ensemble_leaves_no_process_of_it_and_every_seed_resumes(scene, tmp_path):
    """SIGKILL of the ensemble's process (a batch system, the OOM killer): its workers and the resource
    tracker used to finish their seeds and then wait, idle, for good (SIGTERM did not end them). Now each
    worker sees its launcher gone within PARENT_POLL (0.5 s), stops its seed with a checkpoint and exits:
    10 s later (a step and a checkpoint of this 60-rod scene take milliseconds; the rest is margin for a
    loaded machine) no process of the ensemble lives, and the same command resumes both seeds."""
    import time

    folder = tmp_path / "e"
    proc = _ensemble_process(scene, folder, "--seeds", "3")
    try:
        _wait_for_seed_files(folder, (3, 4))
        time.sleep(1.0)
        proc.kill()
        proc.wait(timeout=30)
        assert _group_gone(proc.pid, 10) == [], "processes of the killed ensemble still run"
    finally:
        _kill_group(proc)
    plans = Ensemble(scene, 3, folder, t_end=20).plan()
    assert [p.action for p in plans] == ["resume", "resume", "run"]


def test_a_second_ensemble_on_the_same_folder_is_refused_before_it_starts_a_seed(scene, tmp_path, capsys):
    """Two ensembles on one folder at once: the second stops with exit 2 naming the folder and the
    holder, before it reads or starts any seed; the first runs on. Its lock is released on exit, and a
    lock file left by a crash (no process holds it any more) is taken over."""
    import signal

    from selfas_graph.ensemble import LOCK_FILE

    folder = tmp_path / "e"
    proc = _ensemble_process(scene, folder, "--seeds", "2")
    try:
        _wait_for_seed_files(folder, (3, 4))
        before = {p.name: p.stat().st_mtime_ns for p in folder.iterdir() if p.name != LOCK_FILE}
        rc = main(["ensemble", str(scene), "--seeds", "3", "--t-end", "20", "-o", str(folder)])
        err = capsys.readouterr().err
        assert rc == 2 and f"the output folder {folder} is in use by another ensemble (pid {proc.pid}" in err
        assert not seed_path(folder, 5).exists()
        assert proc.poll() is None  # the first one runs on
        proc.send_signal(signal.SIGTERM)  # to the launcher alone: it hands the signal on to its workers
        proc.communicate(timeout=90)
        assert proc.returncode == 128 + signal.SIGTERM
    finally:
        _kill_group(proc)
    assert set(before) <= {p.name for p in folder.iterdir()}
    assert not (folder / LOCK_FILE).exists()  # released on exit
    (folder / LOCK_FILE).write_text("pid 999999 on a host that crashed\n")  # stale: nobody holds it
    assert (
        main(["ensemble", str(scene), "--seeds", "1", "--t-end", "0.05", "-o", str(folder), "--first-seed", "9"]) == 0
    )
    assert not (folder / LOCK_FILE).exists()


def test_an_ensemble_that_runs_out_of_disk_stops_with_exit_4_and_resumable_seeds(scene, tmp_path):
    """Two seeds writing a frame every step onto a 32 MiB tmpfs: the disk fills within seconds. The
    ensemble used to report a generic error (exit 1) and leave files no rerun could continue; now it
    stops with exit 4, the other seed stops with a checkpoint, every seed file left is readable and
    planned "resume" (one without a checkpoint yet is removed: planned "run"), and no summary is
    attempted. Skipped where a tmpfs cannot be mounted.

    The size: a seed file starts at about 5 MiB and asks for 5.5 MiB of room before each frame (its next
    chunk). On 16 MiB both seeds could stop at their first step, before the first checkpoint (which is
    written right after the first step), when both started together; 32 MiB holds both seeds' first
    chunks."""
    import subprocess

    small = tmp_path / "tmpfs"
    small.mkdir()
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=32m", "tmpfs", str(small)], capture_output=True, text=True)
    if r.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here ({r.stderr.strip() or 'not permitted'})")
    over = ["--set", "output.interval=0.001", "--set", "output.checkpoint_interval=0.2"]
    proc = _ensemble_process(scene, small / "e", "--seeds", "2", *over)
    try:
        out, err = proc.communicate(timeout=240)  # fills in 5-30 s on 2 loaded cores; a hang fails here
        assert proc.returncode == 4, err
        assert "I/O error" in err and "run the same command again to continue" in err and "Traceback" not in err
        assert not (small / "e" / "summary.json").exists()
        moved = tmp_path / "moved"  # room again: the folder copied to a larger disk
        shutil.copytree(small / "e", moved)
    finally:
        _kill_group(proc)
        subprocess.run(["umount", "-l", str(small)], capture_output=True)
    overrides = ["output.interval=0.001", "output.checkpoint_interval=0.2"]
    plans = Ensemble(scene, 2, moved, overrides=overrides, t_end=20).plan()
    assert {p.action for p in plans} <= {"resume", "run"} and "resume" in {p.action for p in plans}
    for p in plans:
        if p.path.exists():
            with RunFile(p.path) as run:
                assert run.n_frames > 0


def test_a_null_model_without_the_plasma_filament_measures_the_same_channel(tmp_path):
    """`--set forces.plasma_filament=false` removes the force, not the region the claim is about: the
    fraction within R_plas is taken about the channel the scenario file states (R_plas = 6 L in
    quick.toml), as in the full scene."""
    root = Path(__file__).resolve().parents[2]
    out = tmp_path / "no_plasma.h5"
    args = ["simulate", str(root / "scenarios/quick.toml"), "--set", "forces.plasma_filament=false"]
    assert main([*args, "--t-end", "0.01", "-o", str(out), "--progress", "none"]) == 0
    s = summarise([out], [0.01])
    with RunFile(out) as run:
        assert run.parameters["forces"].get("plasma_filament") is None
        centres = rod_centres(run.position(-1))
    expected = float(np.mean(np.hypot(centres[:, 0], centres[:, 1]) < 6.0))
    assert s["measures"]["inside_R_plas"]["mean"] == [expected] and 0.0 < expected < 1.0


def test_the_summary_names_what_made_each_seed(quick):
    """summary.json holds each seed's provenance, as its run file states it: version, commit, CPU, numba's
    target and threads, and wall time (the grid summary and the results page take it from there)."""
    folder, _ = quick
    summary = json.loads((folder / "summary.json").read_text())
    for seed in summary["seeds"]:
        with RunFile(folder / Path(seed["path"]).name) as run:
            assert seed["commit"] == run.meta["commit"] and seed["version"] == run.meta["version"]
            assert seed["cpu_model"] == run.meta["cpu_model"] and seed["numba_threads"] >= 1
            assert seed["wall_seconds"] == float(run.meta["wall_seconds_total"]) > 0


def test_a_pool_started_from_a_script_without_the_main_guard_says_so(tmp_path):
    """``Ensemble.run(jobs=2)`` at a script's top level runs again in every worker that imports the script:
    the workers said the folder was locked by another ensemble (the script's own) and to use -o; they now
    say where the call must go."""
    import subprocess
    import sys

    script = tmp_path / "noguard.py"
    script.write_text(
        "from selfas_graph.ensemble import Ensemble\n"
        f"e = Ensemble({str(QUICK)!r}, seeds=2, folder='e', overrides=['rods.count=20'], t_end=0.01)\n"
        "print([r['status'] for r in e.run(jobs=2)])\n"
    )
    res = subprocess.run([sys.executable, str(script)], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert 'put the call under `if __name__ == "__main__":`' in res.stderr
    assert "in use by another ensemble" not in res.stderr


def test_a_summary_file_that_is_a_link_is_refused_before_any_seed_runs(tmp_path, capsys):
    """``summary.json`` in the folder a symbolic link to a run file elsewhere: the ensemble wrote the
    summary through it, replacing that file. It is refused (exit 2) before a seed runs, naming the link,
    and the file it points to is untouched; a link to nothing (which would create a file where no one
    named one) is refused alike, for the grid's own summaries too."""
    victim = tmp_path / "victim.h5"
    victim.write_bytes(b"\x89HDF\r\n\x1a\n run file")
    folder = tmp_path / "ens"
    folder.mkdir()
    (folder / "summary.json").symlink_to(victim)
    argv = ["ensemble", QUICK, "--seeds", "1", "--t-end", str(T_END), "-o", str(folder)]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "summary.json is a symbolic link" in err and "never through a link" in err
    assert victim.read_bytes() == b"\x89HDF\r\n\x1a\n run file" and not list(folder.glob("seed_*"))
    (folder / "summary.json").unlink()
    (folder / "summary.csv").symlink_to(tmp_path / "nowhere.csv")
    assert main(argv) == 2 and "summary.csv is a symbolic link" in capsys.readouterr().err
    assert not (tmp_path / "nowhere.csv").exists()
    grid = tmp_path / "grid"
    grid.mkdir()
    (grid / "grid_summary.json").symlink_to(tmp_path / "elsewhere.json")
    argv = ["ensemble", QUICK, "--seeds", "1", "--t-end", str(T_END), "--grid", "rods.count=20,30", "-o", str(grid)]
    assert main(argv) == 2 and "grid_summary.json is a symbolic link" in capsys.readouterr().err
    assert not (tmp_path / "elsewhere.json").exists() and not list(grid.rglob("seed_*"))


def test_a_reader_that_leaves_does_not_stop_the_summary(quick, tmp_path, monkeypatch):
    """``ensemble ... | head -3``: the table's lines met a closed pipe, and the command ended quietly with
    exit 0 before writing its summary (an older one stayed). The lines after the reader left go nowhere;
    the summary is written and the exit code is the command's."""
    import sys

    folder = tmp_path / "ens"
    folder.mkdir()
    for f in quick[0].glob("seed_*.h5"):
        shutil.copy(f, folder / f.name)

    class Head:
        """Standard output read by ``head -1``: the second write finds the pipe closed."""

        def __init__(self):
            self.lines = []

        def write(self, text):
            if self.lines:
                raise BrokenPipeError(32, "Broken pipe")
            self.lines.append(text)
            return len(text)

        def flush(self):
            pass

    head = Head()
    monkeypatch.setattr(sys, "stdout", head)
    assert main(["ensemble", QUICK, "--seeds", "4", "--t-end", str(T_END), "-o", str(folder), "--no-run"]) == 0
    monkeypatch.undo()
    assert len(head.lines) == 1 and sys.stdout is not head
    s = json.loads((folder / "summary.json").read_text())
    assert s["n_seeds"] == 4 and (folder / "summary.csv").exists()


def test_one_file_given_twice_is_refused_not_counted_as_two_seeds(quick, tmp_path):
    """``summarise([a, a])`` (or a link to ``a`` beside it) counted one run as two seeds, halving its
    spread's weight; it is refused, naming both paths."""
    a = seed_path(quick[0], 1)
    (tmp_path / "link.h5").symlink_to(a)
    for twice in ([a, a], [a, tmp_path / "link.h5"]):
        with pytest.raises(EnsembleError, match="are one file: give each seed file once"):
            summarise(twice, [0.0])


def _with_parameters(src, dst, change):
    """A copy of the run file ``src`` at ``dst`` whose stored parameters ``change`` edits (a dict in place)."""
    shutil.copyfile(src, dst)
    with h5py.File(dst, "r+") as f:
        group = f["parameters/selfas_graph"]
        params = json.loads(group.attrs["parameters_json"])
        change(params)
        group.attrs["parameters_json"] = json.dumps(params)
    return dst


def test_seed_files_of_other_parameters_or_one_seed_twice_are_refused(quick, tmp_path):
    """``summarise`` of files that differ in more than the seed and the end time averaged them as one
    ensemble without a word; the same seed in two files counted one sample twice. Both are refused,
    naming the files and the keys."""
    a, b = seed_path(quick[0], 1), seed_path(quick[0], 2)

    def other_b_ext(p):
        p["forces"]["uniform_field"] = {"B": [0.0, 0.0, 7.0]}

    def longer(p):
        p["run"]["t_end"] = 99.0

    other = _with_parameters(b, tmp_path / "other.h5", other_b_ext)
    with pytest.raises(EnsembleError, match=r"other.h5 is of other parameters than .*forces\.uniform_field"):
        summarise([a, other], [0.0])
    assert summarise([a, _with_parameters(b, tmp_path / "longer.h5", longer)], [0.0])["n_seeds"] == 2
    with pytest.raises(EnsembleError, match="are both seed 1: one sample"):
        summarise([a, shutil.copyfile(a, tmp_path / "copy.h5")], [0.0])


def test_claims_of_a_slice_of_frames(quick):
    """``claims_series(run, frames=slice(0, 2))`` takes the run's frames as a slice, as numpy would."""
    from selfas_graph.analysis.claims import claims_series

    with RunFile(seed_path(quick[0], 1)) as run:
        whole = claims_series(run, loops=False)
        part = claims_series(run, frames=slice(1, None), loops=False)
    assert all(np.array_equal(part[k], whole[k][1:], equal_nan=True) for k in whole)


def test_a_checkpoint_given_for_a_run_file_names_the_run_file(quick, tmp_path):
    """A checkpoint where a run file is wanted: the error says what it is and which file to give, not the
    seven groups a run file has and it lacks."""
    from selfas_graph.io.h5md import RunFileError

    ck = checkpoint_path(seed_path(quick[0], 2))
    with pytest.raises(
        RunFileError, match=r"a checkpoint .*, not a run file; give the run file it belongs to \(seed_0002.h5"
    ):
        RunFile(ck)
    # a run's failed state (the same format) names the run file it failed in, and is not for resuming
    failed = tmp_path / "seed_0002.failure.h5"
    shutil.copyfile(ck, failed)
    with pytest.raises(RunFileError, match=r"the failed state of a run\), not a run file; .*\(seed_0002.h5, beside"):
        RunFile(failed)


def test_the_advice_for_a_seed_run_past_the_end_is_not_force_alone(quick, tmp_path):
    """A seed interrupted after the end asked for (its checkpoint at t = 0.5, the ensemble's end 0.25):
    --force would throw away what it holds, so the message offers a later end time and --no-run first."""
    from selfas_graph.io import layout

    folder = tmp_path / "ens"
    folder.mkdir()
    for name in ("seed_0001.h5", "seed_0001.checkpoint.h5"):
        shutil.copy(quick[0] / name, folder / name)
    with h5py.File(folder / "seed_0001.h5", "r+") as f:
        f[layout.PROVENANCE].attrs["status"] = "interrupted at step 100"
    with pytest.raises(EnsembleError) as err:
        Ensemble(QUICK, 1, folder, t_end=0.25).plan()
    text = str(err.value)
    assert "after the end time" in text and "a later end time (--t-end) continues" in text
    assert "--no-run summarises the files as they are" in text and "all they hold" in text


def test_the_advice_for_a_seed_file_in_use_is_to_wait(quick, tmp_path):
    """A seed file another process holds open for writing: --force cannot replace it, and is not offered."""
    import subprocess
    import sys

    folder = tmp_path / "ens"
    folder.mkdir()
    for name in ("seed_0001.h5", "seed_0001.checkpoint.h5"):
        shutil.copy(quick[0] / name, folder / name)
    hold = "import h5py, sys, time; f = h5py.File(sys.argv[1], 'r+'); print('open', flush=True); time.sleep(60)"
    proc = subprocess.Popen(
        [sys.executable, "-c", hold, str(folder / "seed_0001.h5")], stdout=subprocess.PIPE, text=True
    )
    try:
        assert proc.stdout.readline().strip() == "open"
        try:
            Ensemble(QUICK, 1, folder, t_end=1.0).plan()
        except EnsembleError as exc:
            text = str(exc)
        else:
            pytest.skip("HDF5 file locking is off here (HDF5_USE_FILE_LOCKING=FALSE or a file system without locks)")
        with pytest.raises(EnsembleError, match="locked by another process") as forced:  # not planned to replace
            Ensemble(QUICK, 1, folder, t_end=1.0, force=True).plan()
        assert forced.value.kind == ""  # the list's error; each seed's problem had its own kind
    finally:
        proc.kill()
        proc.communicate(timeout=30)
    assert "locked by another process" in text and "wait for the processes writing them to end" in text
    assert "pass force=True" not in text


def test_measures_by_name_and_a_misspelt_one(quick):
    """``summarise(measures=["cycle_rank"])``, as a notebook names them, failed with an AttributeError; a
    name stands for its measure of FRAME_MEASURES, and one that is not there is named with the valid ones."""
    from selfas_graph.ensemble import FRAME_MEASURES

    a = seed_path(quick[0], 1)
    by_name = summarise([a], [0.0], measures=["cycle_rank"])
    by_object = summarise([a], [0.0], measures=[m for m in FRAME_MEASURES if m.name == "cycle_rank"])
    assert list(by_name["measures"]) == ["cycle_rank"] and by_name["measures"] == by_object["measures"]
    assert list(summarise([a], [0.0], measures="cycle_rank")["measures"]) == ["cycle_rank"]
    with pytest.raises(EnsembleError, match=r"measures: 'cycle_rnk' is not a measure; .*cycle_rank"):
        summarise([a], [0.0], measures=["cycle_rnk"])
