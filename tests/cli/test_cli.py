"""``selfas-graph simulate``: output layout, protection of existing files, exit codes."""

import shutil
import subprocess

import h5py
import numpy as np
import pytest

from selfas_graph import RunFile
from selfas_graph.cli.main import main

TINY = """
[scenario]
name = "tiny"
seed = 3
[rods]
count = 8
[placement]
box = [[-2, 2], [-2, 2], [-1.9, 1.9]]
[forces.tip_magnetic]
[forces.tip_brake]
[forces.ambient_brake]
[forces.uniform_field]
[forces.yukawa]
[forces.electrodes]
gap = 3.8
[integrator]
dt = 1e-3
[run]
t_end = 0.05
[output]
interval = 0.01
"""


@pytest.fixture
def scenario(tmp_path):
    path = tmp_path / "tiny.toml"
    path.write_text(TINY)
    return path


def test_simulate_writes_h5md_run(scenario, tmp_path, capsys):
    out = tmp_path / "run.h5"
    assert main(["simulate", str(scenario), "-o", str(out), "--progress", "lines"]) == 0
    text = capsys.readouterr().out
    assert "done: 50 steps" in text and "max bond-length error" in text and "energy balance" in text
    with h5py.File(out, "r") as f:
        assert tuple(f["h5md"].attrs["version"]) == (1, 1)
        assert f["h5md/creator"].attrs["name"].decode() == "selfas-graph"  # fixed-length: bytes
        assert "name" in f["h5md/author"].attrs
        pos = f["particles/tips/position"]
        assert pos["value"].shape == (6, 16, 3)  # frames at t = 0, 0.01, ..., 0.05
        np.testing.assert_array_equal(pos["step"][:], [0, 10, 20, 30, 40, 50])
        np.testing.assert_allclose(pos["time"][:], [0, 0.01, 0.02, 0.03, 0.04, 0.05], atol=1e-12)
        assert f["particles/tips/velocity/value"].shape == (6, 16, 3)
        for name in (
            "energy/kinetic",
            "energy/tip_magnetic",
            "work/tip_brake",
            "energy_balance",
            "bond_error",
            "momentum",
            "contacts",
        ):
            assert f[f"observables/{name}/value"].shape[0] == 6, name
        assert f["observables/bond_error_per_step/value"].shape == (50,)
        meta = f["parameters/selfas_graph"].attrs
        assert meta["status"] == "finished" and meta["seed"] == 3
        assert "[forces.tip_brake]" in meta["scenario_text"]
        for key in ("parameters_json", "version", "command_line", "mpi_ranks", "numba_threads"):
            assert key in meta
    with RunFile(out) as run:
        assert run.n_frames == 6 and run.parameters["rods"]["count"] == 8
        assert np.isfinite(run.position(-1)).all()


def test_existing_output_is_never_overwritten_without_force(scenario, tmp_path, capsys):
    out = tmp_path / "precious.h5"
    out.write_bytes(b"results of last week")
    assert main(["simulate", str(scenario), "-o", str(out)]) == 2
    assert "exists; pass --force" in capsys.readouterr().err
    assert out.read_bytes() == b"results of last week"
    assert main(["simulate", str(scenario), "-o", str(out), "--force", "--progress", "none"]) == 0
    with RunFile(out) as run:
        assert run.n_frames == 6


def test_a_file_another_process_is_writing_is_not_replaced_even_with_force(scenario, tmp_path, capsys):
    """A run file still open for writing (HDF5 locks it: here held by this process through another file
    description, as a running simulation holds it) is refused by name with --force too, and left as it
    was; before, it was emptied before its lock was tried, and the running simulation ended with an
    unreadable file. Once closed it may be replaced."""
    out = tmp_path / "running.h5"
    with h5py.File(out, "w") as f:
        f["x"] = np.arange(3)
        f.flush()
        for argv, words in (
            (
                ["simulate", str(scenario), "-o", str(out), "--force", "--progress", "none"],
                "is open in another process",
            ),
            # an export never replaces an HDF5 file, open or not
            (
                ["export", str(finished_run(tmp_path, scenario)), "--format", "xyz", "-o", str(out), "--force"],
                "an export never replaces one",
            ),
        ):
            assert main(argv) == 2
            assert words in capsys.readouterr().err
        np.testing.assert_array_equal(f["x"][()], np.arange(3))
    with h5py.File(out, "r") as f:
        np.testing.assert_array_equal(f["x"][()], np.arange(3))
    assert main(["simulate", str(scenario), "-o", str(out), "--force", "--progress", "none"]) == 0


def test_a_run_file_in_use_is_not_resumed_and_the_advice_is_to_close_it(scenario, tmp_path, capsys):
    """The refusal of a resume while the run file is open elsewhere (a notebook's RunFile) spoke of
    replacing it, --force and another name, none of which a resume has."""
    run = finished_run(tmp_path, scenario)
    with h5py.File(run, "r+"):
        assert main(["simulate", "--resume", str(run), "--t-end", "2", "--progress", "none"]) == 2
    err = capsys.readouterr().err
    assert "is open in another process" in err and "it is not continued while open" in err and "--force" not in err


def finished_run(tmp_path, scenario):
    """A finished run file of the test scene to export from (made once per test)."""
    path = tmp_path / "source.h5"
    if not path.exists():
        assert main(["simulate", str(scenario), "-o", str(path), "--progress", "none"]) == 0
    return path


def test_bad_scenario_exits_2_and_writes_nothing(scenario, tmp_path, capsys):
    out = tmp_path / "run.h5"
    code = main(["simulate", str(scenario), "-o", str(out), "--set", "integrator.dt=0"])
    assert code == 2
    assert "integrator.dt: 0.0 is out of range; valid: > 0" in capsys.readouterr().err
    assert not out.exists()
    assert main(["simulate", str(tmp_path / "missing.toml")]) == 2
    assert main(["simulate", str(scenario), "-o", str(tmp_path / "no" / "dir" / "x.h5")]) == 2
    assert "does not exist" in capsys.readouterr().err


def test_a_finished_run_is_named_so_when_simulated_again(scenario, tmp_path, capsys):
    """Run again into a finished run (its checkpoint beside it), simulate names the run as finished
    and how to extend it, not only the checkpoint: --resume alone would have nothing to continue."""
    out = tmp_path / "run.h5"
    assert main(["simulate", str(scenario), "-o", str(out), "--progress", "none"]) == 0
    capsys.readouterr()
    before = out.read_bytes()
    assert main(["simulate", str(scenario), "-o", str(out), "--progress", "none"]) == 2
    err = capsys.readouterr().err
    assert f"{out} exists and finished at t = " in err and f"--resume {out} --t-end LATER" in err
    assert out.read_bytes() == before


def test_dry_run_writes_nothing(scenario, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["simulate", str(scenario), "--dry-run", "--t-end", "2"]) == 0
    out = capsys.readouterr().out
    assert "dry run" in out and '"steps": 2000' in out
    assert not list(tmp_path.glob("*.h5"))


def test_dry_run_refuses_what_the_run_would_refuse(scenario, tmp_path, capsys):
    """A dry run is a pre-flight check: an existing output file, a missing folder or an earlier
    run's checkpoint stop it (exit 2) as they stop the run, and nothing is touched."""
    out = tmp_path / "run.h5"
    out.write_bytes(b"keep")
    assert main(["simulate", str(scenario), "-o", str(out), "--dry-run"]) == 2
    assert f"output file {out} exists; pass --force" in capsys.readouterr().err
    assert main(["simulate", str(scenario), "-o", str(out), "--dry-run", "--force"]) == 0
    assert out.read_bytes() == b"keep"
    capsys.readouterr()
    assert main(["simulate", str(scenario), "-o", str(tmp_path / "none" / "x.h5"), "--dry-run"]) == 2
    assert "the folder" in capsys.readouterr().err and not (tmp_path / "none").exists()
    out.unlink()
    (tmp_path / "run.checkpoint.h5").write_bytes(b"keep")
    assert main(["simulate", str(scenario), "-o", str(out), "--dry-run"]) == 2
    assert "checkpoint file" in capsys.readouterr().err and not out.exists()


def test_dry_run_names_a_brake_too_stiff_for_the_step(scenario, tmp_path, capsys):
    """A brake past Adams-Bashforth 4's limit (rate * dt above 0.3) stops the run, at once or at the first
    contacts: the dry run names it and exits 3 as the run would (it exited 0, and the run stopped at
    step 1); the explicit tip brake counts only in its own mode."""
    argv = ["simulate", str(scenario), "-o", str(tmp_path / "r.h5"), "--dry-run"]
    assert main([*argv, "--set", "forces.ambient_brake.coefficient=1e30"]) == 3
    assert "would stop with a numerical failure: the 'ambient_brake' term is too stiff" in capsys.readouterr().err
    tip = ["--set", "forces.tip_brake={coefficient=1000}"]
    assert main([*argv, *tip, "--set", "integrator.brake=explicit"]) == 3
    assert "the 'tip_brake' term is too stiff for the step" in capsys.readouterr().err
    assert main([*argv, *tip, "--set", "integrator.brake=split"]) == 0
    assert not list(tmp_path.glob("*.h5"))


def test_a_resumed_dry_run_says_what_it_read_and_what_is_left(scenario, tmp_path, capsys):
    """``--resume --dry-run`` places nothing: it names the checkpoint and its step, counts the steps
    and frames still to come, and writes the scenario as JSON null (a resume has no scene file)."""
    import json

    out = tmp_path / "run.h5"
    assert main(["simulate", str(scenario), "-o", str(out), "--progress", "none"]) == 0
    before = out.read_bytes()
    capsys.readouterr()
    assert main(["simulate", "--resume", str(out), "--t-end", "0.085", "--dry-run"]) == 0
    text = capsys.readouterr().out
    assert "placement" not in text
    assert f"checkpoint {tmp_path / 'run.checkpoint.h5'} read and verified against {out} (step 50, t = 0.05)" in text
    plan = json.loads(text[text.index("{") :])
    assert plan["scenario"] is None and plan["from_step"] == 50 and plan["steps"] == 35
    assert plan["frames"] == 4  # steps 60, 70, 80 and the last, 85
    assert out.read_bytes() == before


@pytest.mark.parametrize(
    "start, n, every, first, frames",
    [
        (0, 100, 10, True, 11),
        (0, 95, 10, True, 11),
        (0, 0, 10, True, 1),
        (50, 35, 10, False, 4),
        (55, 5, 10, False, 1),
        (55, 4, 10, False, 1),
        (50, 0, 10, False, 0),
    ],
)
def test_the_plan_counts_the_frames_the_writer_writes(start, n, every, first, frames):
    """A frame at each multiple of the interval, one at the end if it is not one, and the first."""
    from selfas_graph.cli.simulate import _new_frames

    assert _new_frames(start, n, every, first) == frames


def test_the_progress_of_a_resumed_run_counts_the_whole_run(scenario, tmp_path):
    """The progress line's percentage goes with its absolute t and step: a run resumed half-way starts at 50 %."""
    import io

    from selfas_graph.cli.progress import Lines
    from selfas_graph.io.scenario import load_scenario
    from selfas_graph.model.simulation import Simulation

    sim = Simulation.from_scenario(load_scenario(scenario))
    sim.run(0.025)
    stream = io.StringIO()
    Lines(stream)(sim, 0, 25)
    assert "step 25   50.0%" in stream.getvalue()


def test_an_output_interval_of_no_whole_number_of_steps_is_named_with_the_one_used(scenario, tmp_path, capsys):
    """Frames come every whole number of steps: an interval between two is rounded, and simulate
    says to what, as the plan's frame count does."""
    argv = ["simulate", str(scenario), "--dry-run", "--t-end", "1", "--set", "integrator.dt=1e-3"]
    assert main([*argv, "--set", "output.interval=0.1234"]) == 0
    out = capsys.readouterr().out
    assert "note: output.interval = 0.1234 is 123.4 steps of integrator.dt = 0.001: a frame every 123 steps" in out
    assert '"frames": 10' in out  # steps 0, 123, ..., 984 and the last, 1000
    assert main([*argv, "--set", "output.interval=0.25"]) == 0
    assert "note: output.interval" not in capsys.readouterr().out


def test_numerical_failure_exits_3_with_diagnosis_and_no_nan_in_file(scenario, tmp_path, capsys):
    out = tmp_path / "run.h5"
    code = main(
        [
            "simulate",
            str(scenario),
            "-o",
            str(out),
            "--set",
            "integrator.dt=0.05",
            "--set",
            "output.interval=0.05",
            "--t-end",
            "100",
            "--progress",
            "none",
        ]
    )
    assert code == 3
    err = capsys.readouterr().err
    assert "numerical failure at step" in err and "integrator.dt = 0.05" in err
    with h5py.File(out, "r") as f:
        assert f["parameters/selfas_graph"].attrs["status"].startswith("failed")
        assert np.isfinite(f["particles/tips/position/value"][:]).all()
    # the last good state (here the start) and the failed one are kept aside for inspection, with the diagnosis
    from selfas_graph.io.checkpoint import read_checkpoint

    snap, meta = read_checkpoint(tmp_path / "run.failure.h5")
    assert "numerical failure" in meta["failure"] and snap["position"].shape == (16, 3)
    # a resume would take the same steps and fail again: refused, naming the failure and what to do
    assert main(["simulate", "--resume", str(out), "--progress", "none"]) == 2
    err = capsys.readouterr().err
    assert "ended in a numerical failure" in err and "run.failure.h5" in err and "--force" in err
    # --resume of the failure file itself: named as the failed state of its run, not as a run missing a checkpoint
    assert main(["simulate", "--resume", str(tmp_path / "run.failure.h5"), "--progress", "none"]) == 2
    err = capsys.readouterr().err
    assert f"the failed state of the run {out}" in err and "failure.checkpoint" not in err
    # a new run under the same name: the old failed state is not left beside it unless asked to be removed
    argv = ["simulate", str(scenario), "-o", str(out), "--progress", "none"]
    assert main(argv) == 2 and "exists" in capsys.readouterr().err
    assert main(argv + ["--force"]) == 0
    assert not (tmp_path / "run.failure.h5").exists()
    # resuming the finished run takes no step, and says so (not a speed of 1e12 ms a step)
    assert main(["simulate", "--resume", str(out), "--progress", "none"]) == 0
    assert "no step to take" in capsys.readouterr().out


def test_console_script_installed():
    exe = shutil.which("selfas-graph")
    assert exe, "the selfas-graph console script is not on PATH (pip install -e .)"
    res = subprocess.run([exe, "--version"], capture_output=True, text=True, timeout=60)
    assert res.returncode == 0 and "selfas-graph" in res.stdout


def test_python_m_runs_the_command():
    """``python -m selfas_graph`` is the console script (for a PATH without it, or under mpiexec)."""
    import sys

    res = subprocess.run(
        [sys.executable, "-m", "selfas_graph", "--version"], capture_output=True, text=True, timeout=60
    )
    assert res.returncode == 0 and "selfas-graph" in res.stdout
    res = subprocess.run(
        [sys.executable, "-m", "selfas_graph", "simulate", "no_such_scene.toml"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert res.returncode == 2 and "no_such_scene.toml" in res.stderr


def test_usage_errors_are_printed_by_rank_zero_alone(monkeypatch, capsys):
    """Under mpiexec every rank parses the same command line: a usage error is printed once (rank 0),
    and every rank exits with 2. The launcher's rank variable stands for mpiexec here."""
    for rank, printed in (("1", False), ("0", True)):
        monkeypatch.setenv("PMI_RANK", rank)
        with pytest.raises(SystemExit) as exc:
            main(["simulate", "--no-such-option"])
        assert exc.value.code == 2
        assert ("unrecognized arguments" in capsys.readouterr().err) is printed


class _TwoRanks:
    """A stand-in for the MPI world of two ranks: MPI_Abort records its code and ends with SystemExit
    (as the one-rank stub does) instead of ending the process."""

    size = 2

    def __init__(self, rank):
        self.rank, self.aborted = rank, None

    def Abort(self, code):  # noqa: N802 - mpi4py's name
        self.aborted = code
        raise SystemExit(code)


@pytest.mark.parametrize("rank", [0, 1])
def test_an_interrupt_outside_a_run_ends_every_rank(monkeypatch, capsys, rank):
    """A Ctrl-C that reaches the command line outside a run's own signal handling (while the command
    starts) leaves the other ranks waiting in a collective call, where no signal reaches Python: the
    job is ended with MPI_Abort(130), and the one line is printed by rank 0 alone."""
    import selfas_graph.cli.simulate as simulate

    world = _TwoRanks(rank)
    monkeypatch.setattr("selfas_graph.parallel.world", world)
    monkeypatch.setattr("selfas_graph.parallel._ABORT_GRACE", 0.0)

    def interrupted(args):
        raise KeyboardInterrupt

    monkeypatch.setattr(simulate, "run", interrupted)
    with pytest.raises(SystemExit) as exc:
        main(["simulate", "any.toml"])
    assert exc.value.code == world.aborted == 130
    assert ("selfas-graph simulate: interrupted" in capsys.readouterr().err) is (rank == 0)


def test_abort_job_lets_the_last_words_out_then_ends_every_rank(monkeypatch):
    """Under MPI a rank that ends the job flushes its streams and waits the grace time before MPI_Abort,
    so the launcher forwards the line printed just before (it was lost now and then); if MPICH's
    MPI_Abort returns, the process ends itself rather than go on and print a second time."""
    import selfas_graph.parallel as parallel

    calls = []

    class Streams:
        def __init__(self, name):
            self.name = name

        def flush(self):
            calls.append(("flush", self.name))

    class ReturningAbort:
        size, rank = 2, 0

        def Abort(self, code):  # noqa: N802 - mpi4py's name
            calls.append(("abort", code))

    def exit_now(code):
        calls.append(("exit", code))
        raise SystemExit(code)

    monkeypatch.setattr("sys.stdout", Streams("out"))
    monkeypatch.setattr("sys.stderr", Streams("err"))
    monkeypatch.setattr(parallel.time, "sleep", lambda s: calls.append(("sleep", s)))
    monkeypatch.setattr(parallel.os, "_exit", exit_now)
    with pytest.raises(SystemExit):
        parallel.abort_job(4, ReturningAbort())
    assert calls == [("flush", "out"), ("flush", "err"), ("sleep", parallel._ABORT_GRACE), ("abort", 4), ("exit", 4)]
    assert parallel._ABORT_GRACE > 0
    with pytest.raises(SystemExit) as exc:  # one rank: no MPI, the stub's SystemExit
        parallel.abort_job(3, parallel.SERIAL)
    assert exc.value.code == 3


def test_resume_notes_a_scenario_file_changed_since_the_run_started(tmp_path, capsys):
    """--resume continues a run as it started, from the scenario its files hold: a scenario file edited
    since is named in a note (the edit is not taken), and an unchanged one gives no note."""
    from conftest import SMALL_CIRCUIT_SCENE

    scene, out = tmp_path / "small.toml", tmp_path / "small.h5"
    scene.write_text(SMALL_CIRCUIT_SCENE)
    assert main(["simulate", str(scene), "-o", str(out), "--t-end", "0.005", "--progress", "none"]) == 0
    assert main(["simulate", "--resume", str(out), "--t-end", "0.01", "--progress", "none"]) == 0
    assert "differs from the scenario" not in capsys.readouterr().err
    scene.write_text(SMALL_CIRCUIT_SCENE.replace("dt = 5e-4", "dt = 1e-3"))
    assert main(["simulate", "--resume", str(out), "--t-end", "0.015", "--progress", "none"]) == 0
    assert f"the scenario file {scene} differs from the scenario this run started with" in capsys.readouterr().err
    with RunFile(out) as run:
        assert run.parameters["integrator"]["dt"] == 5e-4


def test_progress_lines_time_the_rate_from_the_first_line(monkeypatch):
    """The steps before the first progress line include compiling the kernels: the first line gives no
    rate (it promised hours on a fresh installation), later lines the rate since the first."""
    import io

    from conftest import SMALL_CIRCUIT_SCENE
    from selfas_graph.cli import progress
    from selfas_graph.io.scenario import scenario_from_text
    from selfas_graph.model.simulation import Simulation

    sim = Simulation.from_scenario(scenario_from_text(SMALL_CIRCUIT_SCENE))
    clock = iter([160.0, 170.0])  # the first line after a minute of compiling, the second 10 s and 1000 steps later
    monkeypatch.setattr(progress.time, "perf_counter", lambda: next(clock))
    out = io.StringIO()
    lines = progress.Lines(out, period=0.0)
    lines(sim, 10, 2010)
    lines(sim, 1010, 2010)
    first, second = out.getvalue().splitlines()
    assert "-- steps/s  ETA --" in first
    assert "100 steps/s  ETA 0m10s" in second


def test_an_ensemble_stopped_by_a_signal_exits_as_simulate_does():
    """128 + the number of the signal the first interrupted seed names (None: a seed never started);
    130 where no seed names one (under mpiexec the signal stays with rank 0)."""
    import signal

    from selfas_graph.cli.main import interrupted_code

    done = {"status": "finished", "signum": None}
    assert interrupted_code([done, None, {"status": "interrupted", "signum": signal.SIGTERM}]) == 143
    assert interrupted_code([{"status": "interrupted", "signum": signal.SIGINT}]) == 130
    assert interrupted_code([done, None]) == interrupted_code([]) == 130


def test_a_run_file_beside_one_of_the_same_name_before_its_suffix_is_refused(scenario, tmp_path, capsys):
    """c.h5 and c.hdf5 both checkpoint to c.checkpoint.h5: a second run would take, and with --force
    destroy, the first one's checkpoint; it is refused before anything is written."""
    import h5py

    with h5py.File(tmp_path / "c.h5", "w"):
        pass
    for force in ([], ["--force"]):
        assert main(["simulate", str(scenario), "-o", str(tmp_path / "c.hdf5"), "--dry-run", *force]) == 2
        assert "the same name before its suffix: the two would share the checkpoint c.checkpoint.h5" in (
            capsys.readouterr().err
        )
    assert main(["simulate", str(scenario), "-o", str(tmp_path / "d.hdf5"), "--dry-run"]) == 0


def test_an_output_name_whose_checkpoints_temporary_name_is_too_long_is_refused_before_the_run(
    scenario, tmp_path, capsys
):
    """240 characters before .h5 is a legal name, but its checkpoint is written aside as
    NAME.checkpoint.h5.tmp (258 characters): refused with a one-line error (exit 2), not found at the first
    checkpoint as an I/O error that left a run file behind."""
    out = tmp_path / ("a" * 240 + ".h5")
    assert main(["simulate", str(scenario), "-o", str(out), "--dry-run"]) == 2
    err = capsys.readouterr().err
    assert "is too long: its checkpoint's temporary file would have 258 characters" in err
    assert "at most 237 characters before the suffix" in err and not list(tmp_path.glob("a*"))


def test_an_atomic_write_of_a_name_the_folder_takes_needs_no_longer_temporary_name(tmp_path):
    """A 250-character name is legal; the temporary file beside it is named within the folder's limit."""
    from selfas_graph.io.atomic import write_text_atomic

    out = tmp_path / ("b" * 246 + ".xyz")
    write_text_atomic(out, "x\n")
    assert out.read_text() == "x\n" and [p.name for p in tmp_path.iterdir()] == [out.name]


def test_write_failed_tells_a_full_disk_from_a_wrong_target():
    """exit 4 where the system failed the write (an errno, or HDF5's wrapped one), 2 where the target is
    wrong (missing folder, permission, a folder in its place) or the failure is not the system's."""
    import errno

    from selfas_graph.cli.main import EXIT_IO, EXIT_USAGE, write_failed

    cases = [
        (OSError(errno.ENOSPC, "No space left on device"), EXIT_IO),
        (OSError(errno.EDQUOT, "Disk quota exceeded"), EXIT_IO),
        (RuntimeError("Can't write data (file write failed: ..., errno = 28, error message = 'No space')"), EXIT_IO),
        (FileNotFoundError(errno.ENOENT, "No such file or directory"), EXIT_USAGE),
        (PermissionError(errno.EACCES, "Permission denied"), EXIT_USAGE),
        (IsADirectoryError(errno.EISDIR, "Is a directory"), EXIT_USAGE),
        (NotADirectoryError(errno.ENOTDIR, "Not a directory"), EXIT_USAGE),
        (ValueError("a summary with no seeds"), EXIT_USAGE),
    ]
    for exc, code in cases:
        err = write_failed("cannot write x.h5", exc)
        assert err.code == code, exc
        assert str(err).startswith("cannot write x.h5: ") and "\n" not in str(err)
