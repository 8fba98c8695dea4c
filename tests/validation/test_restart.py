"""Checkpoints and exact restart: an interrupted and resumed run equals the uninterrupted one bit for bit."""

import json
import signal
import subprocess
import sys
import time

import h5py
import numpy as np
import pytest
from runfiles import datasets

from conftest import SMALL_CIRCUIT_SCENE
from hostile import non_finite_datasets
from selfas_graph.cli.main import main
from selfas_graph.io.checkpoint import Checkpointer, CheckpointError, checkpoint_path, read_checkpoint
from selfas_graph.io.h5md import RunFile, RunWriter
from selfas_graph.io.scenario import scenario_from_text
from selfas_graph.model import events as ev
from selfas_graph.model.simulation import RunInterrupted, Simulation

SCENE = SMALL_CIRCUIT_SCENE


def _same(a, b):
    """Bitwise equality (NaN equal to NaN for float data, which holds floating tips' potentials)."""
    if a.dtype.kind == "f":
        return a.shape == b.shape and np.array_equal(a, b, equal_nan=True)
    return a.shape == b.shape and np.array_equal(a, b)


def _run(path, stop_at=None, resume_from=None):
    sc = scenario_from_text(SCENE)
    ckpt = checkpoint_path(path)
    meta = {"scenario_text": sc.text, "overrides": "[]", "run_file": str(path), "version": "test"}
    if resume_from is None:
        sim = Simulation.from_scenario(sc)
        writer = RunWriter(
            path,
            sim.state.n_tips,
            sim.state.tip_charge,
            sim.state.rod_charge,
            {"parameters_json": json.dumps(sc.params.to_dict()), "scenario_text": sc.text},
        )
    else:
        snap, meta = read_checkpoint(resume_from)
        sim = Simulation.from_snapshot(sc.params, snap)
        writer = RunWriter.reopen(path, int(snap["step"]), drop_later=True)
    cp = Checkpointer(ckpt, 0, meta)
    try:
        sim.run(writer=writer, checkpointer=cp, stop=(lambda: sim.state.step >= stop_at) if stop_at else None)
    except RunInterrupted:
        writer.close("interrupted")
        return sim, False
    writer.close()
    return sim, True


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    path = tmp_path_factory.mktemp("ref") / "ref.h5"
    sim, finished = _run(path)
    assert finished
    contact_steps = sorted({r[0] for r in sim.events if r[2] == ev.TIP_CONTACT and r[0] > 0})
    short = [r[0] for r in sim.events if r[2] == ev.SHORT_CIRCUIT]
    return path, contact_steps, short


def test_reference_run_has_events(reference):
    _, contact_steps, short = reference
    assert len(contact_steps) > 5 and short, "the scene must include contacts and a short circuit"


def test_reference_run_file_holds_the_circuit_log(reference):
    """/circuit_log holds one row per SHORT_CIRCUIT and OPEN_CIRCUIT event, at its step and time,
    written whether or not a frame fell on that step: a closing carries a positive current, its
    filament rods (the event's a) and at most that many rods in series; an opening carries zeros.
    The file holds no NaN or inf."""
    ref_path, _, short = reference
    with RunFile(ref_path) as run:
        log, events = run.circuit_log(), run.events()
        frame_steps = set(run.f["observables/total_current/step"][:].tolist())
    closing = events[(events["kind"] == ev.SHORT_CIRCUIT) | (events["kind"] == ev.OPEN_CIRCUIT)]
    assert len(log) == len(closing) >= 1
    for name in ("step", "time", "kind"):
        np.testing.assert_array_equal(log[name], closing[name])
    sc = log["kind"] == ev.SHORT_CIRCUIT
    np.testing.assert_array_equal(log["filament_rods"][sc], closing["a"][sc])
    assert (log["total_current"][sc] > 0).all()
    assert ((log["rods_in_series"][sc] >= 0) & (log["rods_in_series"][sc] <= log["filament_rods"][sc])).all()
    assert not log["total_current"][~sc].any() and not log["rods_in_series"][~sc].any()
    assert not log["filament_rods"][~sc].any()
    assert short[0] not in frame_steps  # the first closing falls between frames: only the log has its current
    assert non_finite_datasets(ref_path) == []


@pytest.mark.parametrize("where", ["startup", "after_contact", "after_short_circuit", "mid_frame"])
def test_interrupted_and_resumed_run_is_bitwise_identical(reference, tmp_path, where):
    """Interrupt at a step, resume from the checkpoint into the truncated run file: every dataset equal.

    Interrupt points: step 2 (inside the RK4 start-up of AB4), the step of a contact event,
    the step of the short circuit, and a step between two frames.
    """
    ref_path, contact_steps, short = reference
    stop_at = {
        "startup": 2,
        "after_contact": contact_steps[len(contact_steps) // 2],
        "after_short_circuit": short[0],
        "mid_frame": 537,
    }[where]
    path = tmp_path / "run.h5"
    _, finished = _run(path, stop_at=stop_at)
    assert not finished
    _, finished = _run(path, resume_from=checkpoint_path(path))
    assert finished
    ref, got = datasets(ref_path), datasets(path)
    assert sorted(ref) == sorted(got)
    for name in ref:
        assert _same(ref[name], got[name]), name


@pytest.mark.parametrize("how", ["copy", "no room", "copy fails", "through a link"])
def test_resume_truncates_frames_written_after_the_checkpoint(reference, tmp_path, monkeypatch, how):
    """Frames written after the last checkpoint (a kill between checkpoint and frame) are dropped and redone.

    They are dropped in a copy that replaces the file (a new inode, the file's permissions kept, no copy
    left behind): HDF5 shrinks a file before it rewrites the superblock that states its end, and a
    kill in between left a file nothing opens. Without room for the copy, or when the copy fails (a
    quota), in place; through a symbolic link, the copy replaces the file the link points to. The same
    data every way."""
    import errno
    import os

    from selfas_graph.io import trim

    if how == "no room":
        monkeypatch.setattr(trim, "room_for_copy", lambda path: False)
    if how == "copy fails":

        def quota(*args, **kwargs):
            raise OSError(errno.EDQUOT, "Disk quota exceeded")

        monkeypatch.setattr(trim.shutil, "copy2", quota)
    ref_path, _, _ = reference
    folder = tmp_path / "store" if how == "through a link" else tmp_path
    folder.mkdir(exist_ok=True)
    real = folder / "run.h5"
    _run(real, stop_at=300)
    path = tmp_path / "run.h5"
    if how == "through a link":
        path.symlink_to(real)
        checkpoint_path(real).rename(checkpoint_path(path))
    ckpt = checkpoint_path(path)
    saved = ckpt.read_bytes()
    _run(path, resume_from=ckpt, stop_at=900)  # the file now holds frames up to step 900
    ckpt.write_bytes(saved)  # as if killed before the step-900 checkpoint replaced the step-300 one
    os.chmod(real, 0o640)
    before = os.stat(real)
    writer = RunWriter.reopen(path, 300, drop_later=True)
    after = os.stat(real)
    writer.close("interrupted")
    assert (after.st_ino != before.st_ino) == (how in ("copy", "through a link")) and after.st_mode == before.st_mode
    assert path.is_symlink() == (how == "through a link")
    assert [p.name for p in folder.iterdir() if "part" in p.name] == []
    _run(path, resume_from=ckpt)
    ref, got = datasets(ref_path), datasets(real)
    for name in ref:
        assert _same(ref[name], got[name]), name


def test_bad_checkpoint_files(tmp_path):
    with pytest.raises(CheckpointError, match="no such checkpoint"):
        read_checkpoint(tmp_path / "none.checkpoint.h5")
    junk = tmp_path / "junk.checkpoint.h5"
    junk.write_bytes(b"not hdf5")
    with pytest.raises(CheckpointError, match="not a readable HDF5 file"):
        read_checkpoint(junk)
    with h5py.File(tmp_path / "other.checkpoint.h5", "w") as f:
        f["x"] = 1
    with pytest.raises(CheckpointError, match="not a selfas-graph checkpoint"):
        read_checkpoint(tmp_path / "other.checkpoint.h5")


def test_cli_resume_errors(tmp_path, capsys):
    assert main(["simulate", "--resume", str(tmp_path / "missing.h5")]) == 2
    assert "neither the run file nor its checkpoint" in capsys.readouterr().err  # both named missing
    assert main(["simulate", "x.toml", "--resume", str(tmp_path / "missing.h5")]) == 2
    assert "give no SCENARIO" in capsys.readouterr().err


def test_continuation_is_the_one_rule_of_a_resume(tmp_path):
    """``lifecycle.continuation`` (what ``simulate --resume`` and an ensemble's plan and seeds check):
    a run's own checkpoint gives its scenario at the end time asked for and its identity, with no
    note; another run's checkpoint, or a run file that is not one, is refused by name, and nothing
    is written to either file."""
    from selfas_graph.lifecycle import ContinuationError, continuation

    (tmp_path / "s.toml").write_text(SCENE)
    for name in ("a", "b"):
        out = tmp_path / f"{name}.h5"
        assert main(["simulate", str(tmp_path / "s.toml"), "-o", str(out), "--t-end", "0.2", "--progress", "none"]) == 0
    a, b = tmp_path / "a.h5", tmp_path / "b.h5"
    before = {f: f.read_bytes() for f in (a, b, checkpoint_path(a), checkpoint_path(b))}
    cont = continuation(checkpoint_path(a), a, t_end=0.5)
    assert cont.scenario.params.run.t_end == 0.5 and cont.notes == ()
    with RunFile(a) as run:
        assert cont.run_id == run.meta["run_id"] == cont.meta["run_id"]
    assert continuation(checkpoint_path(a), a).scenario.params.run.t_end == pytest.approx(0.2)  # the run's own end
    with pytest.raises(ContinuationError, match="belongs to another run than the run file") as other:
        continuation(checkpoint_path(b), a)
    assert other.value.advice == "give the run file's own checkpoint"
    assert str(other.value) == f"{other.value.reason}; {other.value.advice}"  # simulate --resume prints both
    with pytest.raises(ContinuationError, match="cannot resume into"):
        continuation(checkpoint_path(a), tmp_path / "s.toml")
    with pytest.raises(ContinuationError, match="no such checkpoint"):
        continuation(tmp_path / "none.checkpoint.h5", a)
    assert {f: f.read_bytes() for f in before} == before


def test_sigterm_checkpoints_and_resume_completes(tmp_path):
    """A real process stopped by SIGTERM writes a checkpoint, exits 143, and --resume finishes the run
    with the same data as an uninterrupted process."""
    scen = tmp_path / "s.toml"
    scen.write_text(
        SCENE.replace("t_end = 0.6", "t_end = 3.0").replace("checkpoint_interval = 0", "checkpoint_interval = 0.3")
    )
    cmd = [sys.executable, "-m", "selfas_graph.cli.main", "simulate", str(scen), "--progress", "none"]
    full = subprocess.run(cmd + ["-o", str(tmp_path / "full.h5")], capture_output=True, text=True, timeout=300)
    assert full.returncode == 0, full.stderr
    proc = subprocess.Popen(
        cmd + ["-o", str(tmp_path / "cut.h5")], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    # wait until the run is stepping: its first periodic checkpoint appears (renamed into place
    # atomically). The run file itself cannot be opened meanwhile: HDF5 locks a file open for writing.
    deadline = time.time() + 120
    while time.time() < deadline and proc.poll() is None and not checkpoint_path(tmp_path / "cut.h5").exists():
        time.sleep(0.05)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=120)
    if proc.returncode == 0:
        pytest.skip("the run finished before the signal arrived")
    assert proc.returncode == 128 + signal.SIGTERM, err
    assert "SIGTERM received" in err and "--resume" in err
    res = subprocess.run(
        [
            sys.executable,
            "-m",
            "selfas_graph.cli.main",
            "simulate",
            "--resume",
            str(tmp_path / "cut.h5"),
            "--progress",
            "none",
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert res.returncode == 0, res.stderr
    ref, got = datasets(tmp_path / "full.h5"), datasets(tmp_path / "cut.h5")
    for name in ref:
        assert _same(ref[name], got[name]), name


def test_kill_9_keeps_the_file_readable_and_resume_completes_it(tmp_path):
    """``kill -9`` at random moments: the run file opens and reads each time, losing at most the frames
    after the last checkpoint, and resuming after each kill ends with the uninterrupted run's data.

    The run file uses HDF5's default format: the newer superblock carries a writer flag that a
    killed process leaves set, after which HDF5 refuses to open the file at all.
    """
    import random

    rng = random.Random(7)
    scen = tmp_path / "s.toml"
    scen.write_text(
        SCENE.replace("t_end = 0.6", "t_end = 3.0").replace("checkpoint_interval = 0", "checkpoint_interval = 0.2")
    )
    base = [sys.executable, "-m", "selfas_graph.cli.main", "simulate", "--progress", "none"]
    full = subprocess.run(
        base + [str(scen), "-o", str(tmp_path / "full.h5")], capture_output=True, text=True, timeout=300
    )
    assert full.returncode == 0, full.stderr
    out = tmp_path / "cut.h5"
    cmd = base + [str(scen), "-o", str(out)]
    kills = 0
    for _ in range(3):
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        deadline = time.time() + 120
        while time.time() < deadline and proc.poll() is None and not checkpoint_path(out).exists():
            time.sleep(0.05)
        time.sleep(rng.uniform(0.1, 1.5))
        if proc.poll() is not None:
            break
        proc.kill()
        proc.wait()
        kills += 1
        with h5py.File(out, "r") as f:  # readable after every kill
            n = f["particles/tips/position/value"].shape[0]
            assert n >= 1 and np.isfinite(f["particles/tips/position/value"][n - 1]).all()
        cmd = base + ["--resume", str(out)]
    assert kills >= 1
    if proc.returncode is None or proc.returncode != 0:
        res = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
        assert res.returncode == 0, res.stderr
    ref, got = datasets(tmp_path / "full.h5"), datasets(out)
    for name in ref:
        assert _same(ref[name], got[name]), name


def test_wall_time_of_a_killed_segment_counts_up_to_its_last_flush(tmp_path):
    """``wall_seconds_total`` sums the wall time of every segment of a run: a segment killed after a
    flush (a frame or a checkpoint) keeps its time up to there, and a resumed segment adds its own.
    The sleeps set lower bounds only (a busy machine makes the totals larger, never smaller)."""
    sc = scenario_from_text(SCENE)
    sim = Simulation.from_scenario(sc)
    path = tmp_path / "run.h5"
    writer = RunWriter(path, sim.state.n_tips, sim.state.tip_charge, sim.state.rod_charge, {"scenario_text": sc.text})
    sim.write_frame(writer)
    time.sleep(0.2)
    writer.flush()
    writer.f.close()  # killed: the file never closed by the writer, its status still "running"
    with h5py.File(path, "r") as f:
        attrs = f["parameters/selfas_graph"].attrs
        assert attrs["status"] == "running"
        first = float(attrs["wall_seconds_total"])
    assert first >= 0.2
    writer = RunWriter.reopen(path, 0, drop_later=True)
    time.sleep(0.1)
    writer.close()
    with h5py.File(path, "r") as f:
        assert float(f["parameters/selfas_graph"].attrs["wall_seconds_total"]) >= first + 0.1


def test_a_run_killed_before_its_first_step_can_be_resumed(tmp_path, monkeypatch):
    """The first checkpoint is written before the first step (and before the kernels compile, a
    minute on a cold cache): a run killed at any time after its file appeared resumes, to the same
    data as a run never interrupted. Before, a kill in that minute left a file without a checkpoint,
    which neither a resume nor a new run without --force would take."""
    scen = tmp_path / "s.toml"
    scen.write_text(SCENE.replace("checkpoint_interval = 0", "checkpoint_interval = 900"))
    argv = ["simulate", str(scen), "--progress", "none"]
    assert main(argv + ["-o", str(tmp_path / "full.h5")]) == 0
    out = tmp_path / "cut.h5"

    def killed(self, *args, **kwargs):
        raise KeyboardInterrupt  # as a kill would stop it: before any step

    with monkeypatch.context() as m:
        m.setattr(Simulation, "run", killed)
        assert main(argv + ["-o", str(out)]) == 130
    snap, meta = read_checkpoint(checkpoint_path(out))
    assert int(snap["step"]) == 0 and meta["step"] == 0
    assert main(["simulate", "--resume", str(out), "--progress", "none"]) == 0
    ref, got = datasets(tmp_path / "full.h5"), datasets(out)
    for name in ref:
        assert _same(ref[name], got[name]), name


def test_a_resume_from_step_0_writes_frame_0_again(reference, tmp_path):
    """A run continued from the checkpoint before its first step drops frame 0 and everything after it
    (a kill while frame 0 was written could leave it torn, with a step of 0 that looks whole), so the
    continuation writes it again."""
    import shutil

    path = tmp_path / "run.h5"
    shutil.copy(reference[0], path)
    writer = RunWriter.reopen(path, 0, drop_later=True)
    try:
        assert writer.n_frames == 0 and writer.events_written == 0 and writer.circuit_rows_written == 0
    finally:
        writer.close("interrupted")


def test_a_resume_with_a_later_end_from_an_end_off_the_grids_is_the_run_made_at_once(tmp_path):
    """A run ended off the frame grid and off the slow pattern, then resumed to a later end, against the
    same run made at once: the positions of the last frame the same bit for bit. Both broke it: the
    last frame's energies rebuilt the rod-centre list there, and, in a scene without electrodes, the
    rebuilt simulation's compiled steps ran without the uniform field until a step ran in Python."""
    (tmp_path / "s.toml").write_text(SMALL_CIRCUIT_SCENE)
    scene = [str(tmp_path / "s.toml"), "--progress", "none", "--set", "integrator.slow_every=8"]
    scene += ["--set", "neighbours.centre_skin=1e-4", "--set", "output.interval=0.01"]
    for key in ("forces.electrodes", "circuit", "forces.current_field", "forces.current_lorentz"):
        scene += ["--set", f"{key}=false"]
    at_once, resumed = tmp_path / "at_once.h5", tmp_path / "resumed.h5"
    assert main(["simulate", *scene, "-o", str(at_once), "--t-end", "0.05"]) == 0
    assert main(["simulate", *scene, "-o", str(resumed), "--t-end", "0.0215"]) == 0  # 43 steps
    assert main(["simulate", "--resume", str(resumed), "--t-end", "0.05", "--progress", "none"]) == 0
    with RunFile(at_once) as a, RunFile(resumed) as b:
        assert a.step[-1] == b.step[-1] == 100
        assert np.array_equal(a.position(-1), b.position(-1)) and np.array_equal(a.velocity(-1), b.velocity(-1))


@pytest.mark.parametrize("torn", ["step", "time", "value"])
def test_a_frame_row_torn_by_a_kill_is_no_frame_and_a_resume_continues(tmp_path, torn):
    """A kill while a frame is appended can leave its step, time or positions a row longer than the other
    two (the size flushed, the data not). That row is no frame for RunFile (``torn_frame``), the file is
    continued from its checkpoint (a resume drops the row), and the run then holds what the resume of
    the same file without the torn row holds, bit for bit."""
    import shutil

    (tmp_path / "s.toml").write_text(SMALL_CIRCUIT_SCENE)
    run, clean = tmp_path / "run.h5", tmp_path / "clean.h5"
    quiet = ["--progress", "none"]
    assert main(["simulate", str(tmp_path / "s.toml"), "-o", str(run), "--t-end", "0.01", *quiet]) == 0
    for path in (run, clean):
        if path == clean:
            shutil.copy(run, clean)
            shutil.copy(checkpoint_path(run), checkpoint_path(clean))
        with h5py.File(path, "r+") as f:
            f["parameters/selfas_graph"].attrs["status"] = "running"  # as a kill leaves it
    with RunFile(run) as f:
        frames, times = f.n_frames, f.time
    with h5py.File(run, "r+") as f:
        ds = f[f"particles/tips/position/{torn}"]
        ds.resize(ds.shape[0] + 1, axis=0)
    with RunFile(run) as f:
        assert f.torn_frame and f.n_frames == frames and np.array_equal(f.time, times) and len(f.step) == frames
    for path in (run, clean):
        assert main(["simulate", "--resume", str(path), "--t-end", "0.02", *quiet]) == 0
    with RunFile(run) as got, RunFile(clean) as ref:
        assert not got.torn_frame and got.n_frames == ref.n_frames > frames
        assert np.array_equal(got.step, ref.step) and np.array_equal(got.time, ref.time)
        assert all(np.array_equal(got.position(k), ref.position(k)) for k in range(ref.n_frames))


def test_a_frame_whose_velocities_a_kill_left_unwritten_is_no_frame_and_a_resume_keeps_them_in_step(tmp_path):
    """A frame's velocities are appended after its positions: a kill between the two left the velocities
    a row short. RunFile counted the frame (its velocity then raised IndexError, as did ``export``), and
    a resume trimmed the two apart, leaving every later velocity a frame behind its positions. The frame
    is no frame now, and after a resume each frame's velocities are those of the same step in a run
    that was never killed."""
    import shutil

    (tmp_path / "s.toml").write_text(SMALL_CIRCUIT_SCENE)
    run, clean = tmp_path / "run.h5", tmp_path / "clean.h5"
    quiet = ["--progress", "none"]
    assert main(["simulate", str(tmp_path / "s.toml"), "-o", str(run), "--t-end", "0.01", *quiet]) == 0
    shutil.copy(run, clean)
    shutil.copy(checkpoint_path(run), checkpoint_path(clean))
    with RunFile(run) as f:
        frames = f.n_frames
    with h5py.File(run, "r+") as f:
        f["parameters/selfas_graph"].attrs["status"] = "running"  # as a kill leaves it
        for name in ("step", "time", "value"):
            ds = f[f"particles/tips/velocity/{name}"]
            ds.resize(ds.shape[0] - 1, axis=0)
    with RunFile(run) as f:
        assert f.torn_frame and f.n_frames == frames - 1
        assert np.array_equal(f.velocity(-1), RunFile(clean).velocity(frames - 2))
    assert main(["export", str(run), "--format", "xyz", "-o", str(tmp_path / "run.xyz")]) == 0
    assert main(["simulate", "--resume", str(run), "--t-end", "0.02", *quiet]) == 0
    assert main(["simulate", "--resume", str(clean), "--t-end", "0.02", *quiet]) == 0
    with RunFile(run) as got, RunFile(clean) as ref, h5py.File(run, "r") as raw:
        assert not got.torn_frame and got.n_frames > frames - 1
        assert np.array_equal(raw["particles/tips/velocity/step"][:], raw["particles/tips/position/step"][:])
        at = {int(s): k for k, s in enumerate(ref.step)}
        for k, s in enumerate(got.step):
            assert np.array_equal(got.velocity(k), ref.velocity(at[int(s)]))
            assert np.array_equal(got.position(k), ref.position(at[int(s)]))


def test_a_graph_record_torn_by_a_kill_is_no_record_and_the_readers_go_on(tmp_path):
    """A kill while a frame's graph record was appended can leave its step and time without the rest
    (roles, currents, potentials, counts): that record is no record for RunFile (the frame has no graph
    data), the readers of the frame go on without it, and a resume from the checkpoint of that frame's
    step drops the torn rows and continues (that frame stays without graph data; the next have theirs)."""
    from selfas_graph.analysis.claims import claims_series
    from selfas_graph.io import layout

    (tmp_path / "s.toml").write_text(SMALL_CIRCUIT_SCENE)
    run = tmp_path / "run.h5"
    quiet = ["--progress", "none"]
    assert main(["simulate", str(tmp_path / "s.toml"), "-o", str(run), "--t-end", "0.01", *quiet]) == 0
    with RunFile(run) as f:
        steps = f.graph_steps
    with h5py.File(run, "r+") as f:
        g = f[layout.GRAPH]
        n = g["step"].shape[0] - 1
        for name in (*layout.GRAPH_PER_FRAME, layout.GRAPH_FLOATING):
            if name not in ("step", "time"):
                g[name].resize(n, axis=0)
        f["parameters/selfas_graph"].attrs["status"] = "running"  # as a kill leaves it
    with RunFile(run) as f:
        assert np.array_equal(f.graph_steps, steps[:-1]) and f.frame(-1).graph is None
        assert f.graph(frame=-1)["step"] == steps[-2]
        assert len(claims_series(f)["time"]) == f.n_frames
    assert main(["simulate", "--resume", str(run), "--t-end", "0.02", *quiet]) == 0
    with RunFile(run) as f:
        assert f.frame(-1).graph is not None and f.frame(1).graph is None
        assert np.array_equal(f.graph_steps, np.delete(f.step, 1))
        assert len(claims_series(f)["time"]) == f.n_frames
