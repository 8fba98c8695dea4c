"""The MPI contract: ``mpiexec -n P selfas-graph simulate`` gives the serial run, bit for bit.

The ranks split the rows of the expensive force terms (selfas_graph/parallel.py) and
gather them, and every row is computed by the same arithmetic whatever the split, so
positions, velocities, events, graph, currents and energies do not merely agree within
round-off: every dataset of the run file is equal bit for bit on 1, 2 and 3 ranks (the
tolerance is zero). Bad input and a numerical failure stop every rank with one message
and the serial exit code, without a hang (each launch has a timeout).

Every launch uses one numba thread per rank (3 ranks already oversubscribe the 2-core
machine); the serial run comes first and fills the numba cache, so that the ranks do
not compile the same kernels at once.
"""

import h5py
import numpy as np
import pytest
from runfiles import MPIEXEC, assert_same_run, launch

from conftest import SMALL_CIRCUIT_SCENE
from selfas_graph.model import events as ev

pytestmark = pytest.mark.mpi

if MPIEXEC is None:
    pytest.skip(
        "mpiexec not found next to the Python interpreter or on PATH (install the mpich wheel)", allow_module_level=True
    )
pytest.importorskip("mpi4py", reason="mpi4py is not installed")

SCENE = SMALL_CIRCUIT_SCENE


def _launch(ranks, args, cwd):
    """Run ``selfas-graph simulate ARGS`` serially (ranks = 0) or under ``mpiexec -n ranks``."""
    return launch(["-m", "selfas_graph.cli.main", "simulate", *args, "--progress", "none"], cwd, ranks)


_assert_same_run = assert_same_run


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    """The scene file and its serial run (which also fills the numba cache)."""
    folder = tmp_path_factory.mktemp("mpi")
    (folder / "scene.toml").write_text(SCENE)
    res = _launch(0, ["scene.toml", "-o", "serial.h5"], folder)
    assert res.returncode == 0, res.stderr
    return folder


def test_serial_scene_has_contacts_and_a_short_circuit(scene):
    """The contract below means something only if the scene has events and currents."""
    with h5py.File(scene / "serial.h5", "r") as f:
        events = f["events"][()]
        current = f["graph/current"][()]
    assert (events["kind"] == ev.TIP_CONTACT).sum() > 10
    assert (events["kind"] == ev.SHORT_CIRCUIT).any()
    assert np.count_nonzero(current[-1]) > 0


@pytest.mark.parametrize("ranks", [2, 3])
def test_ranks_give_the_serial_run_bit_for_bit(scene, ranks):
    """2 and 3 ranks: the same events in the same order, positions, graph and energies, bit for bit.

    3 ranks split the 60 rods 20/20/20 and exercise a middle block; rank 0 alone writes
    and prints (one summary, nothing on stderr).
    """
    out = f"ranks{ranks}.h5"
    res = _launch(ranks, ["scene.toml", "-o", out], scene)
    assert res.returncode == 0, res.stderr
    assert res.stdout.count("done: 1200 steps") == 1 and f"1 thread x {ranks} ranks" in res.stdout
    assert res.stderr == ""
    _assert_same_run(scene / out, scene / "serial.h5")


def test_tree_on_two_ranks_gives_the_serial_tree_run_bit_for_bit(scene):
    """With the tip-tip force by the multipole tree, 2 ranks equal 1 rank bit for bit: every
    rank builds the same tree and a target's force does not depend on the rows asked for."""
    tree = ["--set", "forces.tip_magnetic.method=tree", "--t-end", "0.3"]
    serial = _launch(0, ["scene.toml", "-o", "tree1.h5", *tree], scene)
    assert serial.returncode == 0, serial.stderr
    res = _launch(2, ["scene.toml", "-o", "tree2.h5", *tree], scene)
    assert res.returncode == 0, res.stderr
    _assert_same_run(scene / "tree2.h5", scene / "tree1.h5")


@pytest.mark.parametrize("leaf", [64, 16])
def test_tree_force_and_energy_split_over_two_ranks_give_the_serial_run(tmp_path, leaf):
    """The quick scene (300 rods: 600 tips in 32 target groups of at most 128 tips, 15 and 17 a rank, cells accepted
    as multipoles; the default groups of 1024 would hold all 600 tips in one), tip-tip
    force and energy of every frame by the tree: the two ranks each walk their own groups and gather
    the rows, and the run equals the serial one bit for bit (the 60-rod scene above has one group,
    which one rank walks alone). So with leaves of 16 tips (the ranks share the moments of the cells
    of the tree with the scene's leaf_size)."""
    from pathlib import Path

    (tmp_path / "quick.toml").write_text((Path(__file__).parents[2] / "scenarios" / "quick.toml").read_text())
    tree = ["--set", "forces.tip_magnetic.method=tree", "--set", "forces.tip_magnetic.energy_tree_above=1"]
    tree += ["--set", "forces.tip_magnetic.group_size=128", "--t-end", "0.1", "--set", "output.interval=0.05"]
    tree += ["--set", f"forces.tip_magnetic.leaf_size={leaf}"]
    serial = _launch(0, ["quick.toml", "-o", "q1.h5", *tree], tmp_path)
    assert serial.returncode == 0, serial.stderr
    res = _launch(2, ["quick.toml", "-o", "q2.h5", *tree], tmp_path)
    assert res.returncode == 0, res.stderr
    _assert_same_run(tmp_path / "q2.h5", tmp_path / "q1.h5")


def test_current_tree_on_three_ranks_gives_the_serial_run_bit_for_bit(scene):
    """With both rod-current terms by the tree of the currents, 3 ranks equal 1 rank bit for bit
    through the short circuit: the ranks share the tree's groups of points (here one group, which
    the last rank walks while the others send nothing; tests/physics/test_current_tree.py shares many
    among threads standing in for ranks) and gather them."""
    tree = ["--set", "forces.current_field.method=tree", "--set", "forces.current_lorentz.method=tree"]
    serial = _launch(0, ["scene.toml", "-o", "ctree1.h5", *tree], scene)
    assert serial.returncode == 0, serial.stderr
    res = _launch(3, ["scene.toml", "-o", "ctree3.h5", *tree], scene)
    assert res.returncode == 0, res.stderr
    with h5py.File(scene / "ctree1.h5", "r") as f:
        assert np.count_nonzero(f["graph/current"][-1]) > 0
    _assert_same_run(scene / "ctree3.h5", scene / "ctree1.h5")


def test_multiple_time_stepping_on_two_ranks_gives_the_serial_run_bit_for_bit(scene):
    """With the slow forces held between full evaluations, 2 ranks equal 1 rank bit for bit: the
    fast part is computed whole on every rank, the slow part only on full steps and gathered."""
    mts = ["--set", "integrator.slow_every=4", "--t-end", "0.3"]
    serial = _launch(0, ["scene.toml", "-o", "mts1.h5", *mts], scene)
    assert serial.returncode == 0, serial.stderr
    res = _launch(2, ["scene.toml", "-o", "mts2.h5", *mts], scene)
    assert res.returncode == 0, res.stderr
    _assert_same_run(scene / "mts2.h5", scene / "mts1.h5")


def test_resume_on_other_rank_counts_gives_the_serial_run(scene):
    """A run to t = 0.3 on 2 ranks, resumed to t = 0.6 on 3 ranks, equals the serial run to 0.6.

    Rank 0 reads the checkpoint and reopens the run file and sends the snapshot to the others.
    """
    first = _launch(2, ["scene.toml", "-o", "resumed.h5", "--t-end", "0.3"], scene)
    assert first.returncode == 0, first.stderr
    second = _launch(3, ["--resume", "resumed.h5", "--t-end", "0.6"], scene)
    assert second.returncode == 0, second.stderr
    assert second.stdout.count("resuming at step 600") == 1
    _assert_same_run(scene / "resumed.h5", scene / "serial.h5")


@pytest.mark.parametrize("case", ["bad_key", "output_exists", "missing_folder"])
def test_bad_input_stops_every_rank_with_one_message(scene, case):
    """Bad input under 2 ranks: exit code 2 as serially, one error line, no hang, nothing written.

    The output checks are made by rank 0 alone and broadcast: a rank checking for itself
    could see the file rank 0 has just created.
    """
    args = {
        "bad_key": ["scene.toml", "-o", "never.h5", "--set", "forces.tip_magnetc=true"],
        "output_exists": ["scene.toml", "-o", "exists.h5"],
        "missing_folder": ["scene.toml", "-o", "no/such/folder/run.h5"],
    }[case]
    expected = {
        "bad_key": "did you mean 'tip_magnetic'",
        "output_exists": "output file exists.h5 exists",
        "missing_folder": "does not exist",
    }[case]
    (scene / "exists.h5").write_bytes(b"precious")
    res = _launch(2, args, scene)
    assert res.returncode == 2
    assert res.stderr.count("error:") == 1 and expected in res.stderr, res.stderr
    assert res.stdout == ""
    assert (scene / "exists.h5").read_bytes() == b"precious"
    assert not (scene / "never.h5").exists()


def test_numerical_failure_stops_every_rank_with_one_message(scene):
    """dt = 0.05 blows the scene up at step 1 on every rank at once: exit code 3, one diagnosis,
    the failed state written once by rank 0."""
    res = _launch(2, ["scene.toml", "-o", "fail.h5", "--set", "integrator.dt=0.05"], scene)
    assert res.returncode == 3, res.stderr
    assert res.stderr.count("numerical failure at step 1") == 1, res.stderr
    assert (scene / "fail.failure.h5").exists()


def test_an_io_error_under_mpi_aborts_every_rank_with_exit_4(scene):
    """A file-size limit (RLIMIT_FSIZE, as a quota) stops rank 0's writing at its second frame: rank 0
    prints the I/O error once and calls MPI_Abort(4), which ends every rank (none is left waiting in a
    collective call) and gives mpiexec's exit code 4; the run file keeps its flushed frame, readable and
    finite. 9 MB: above the first frame's reservation for this scene (5.3 MiB), below two of them; a
    limit that lets a checkpoint be written first takes 30 s and more on 2 loaded cores. (MPICH's
    MPI_Abort returned to its caller, which then printed the message a second time; and without the
    grace time before the abort, the launcher now and then ended the job before it had forwarded the
    message: an empty stderr with exit code 4.)"""
    import os
    import resource
    import subprocess
    import sys

    from runfiles import TIMEOUT

    def limit():
        resource.setrlimit(resource.RLIMIT_FSIZE, (9_000_000, 9_000_000))

    env = {k: v for k, v in os.environ.items() if not k.startswith(("PMI_", "HYDRA_", "OMPI_", "MPI_"))}
    env["NUMBA_NUM_THREADS"] = "1"
    args = ["-m", "selfas_graph.cli.main", "simulate", "scene.toml", "-o", "quota.h5", "--progress", "none"]
    args += ["--set", "output.interval=0.0005", "--t-end", "20"]
    res = subprocess.run(
        [MPIEXEC, "-n", "2", sys.executable, *args],
        cwd=scene,
        env=env,
        preexec_fn=limit,
        capture_output=True,
        text=True,
        timeout=TIMEOUT,
    )
    assert res.returncode == 4, res.stderr
    # exit code 4 within the timeout is the abort of every rank; MPICH's own "MPI_Abort" line is not
    # asserted: on 2 loaded cores it was once missing from stderr while the exit code and message held
    assert res.stderr.count("error: I/O error at step") == 1, res.stderr
    assert "Traceback" not in res.stderr and "--resume quota.h5" in res.stderr
    with h5py.File(scene / "quota.h5", "r") as f:
        assert f["particles/tips/position/value"].shape[0] >= 1
        assert np.isfinite(f["particles/tips/position/value"][()]).all()


def test_bench_current_tree_times_the_walks_the_ranks_share(tmp_path):
    """``mpiexec -n 2 selfas-graph bench current_tree`` times the tree as a run shares it over the
    ranks (rank 0 alone prints and writes), with the error of the whole walk: the gathered field is
    the one-rank field."""
    import json

    args = ["bench", "current_tree", "--rods", "400", "--theta", "0.5", "--precision", "mixed"]
    res = launch(["-m", "selfas_graph.cli.main", *args, "--reps", "1", "--json", "ct.json"], tmp_path, 2)
    assert res.returncode == 0, res.stderr
    assert (
        res.stdout.count("2 ranks sharing the tree, mixed, opening angle 0.5, leaf / group / order 64 / 128 / 3:") == 1
    )
    assert "x 2 MPI ranks" in res.stdout
    rows = {r["method"]: r for r in json.loads((tmp_path / "ct.json").read_text())["scenes"][0]["rows"]}
    shared, whole = rows["tree, shared by the ranks"], rows["tree"]
    assert shared["median_error"] == whole["median_error"] and shared["p99_error"] == whole["p99_error"]


@pytest.mark.slow
def test_fig2_with_the_current_tree_on_two_and_three_ranks_gives_the_serial_run(tmp_path):
    """The Fig. 2 scene to t = 30 (through its first short circuit, 229 rods carrying current at the
    end) with both rod-current terms by the tree: the ranks share 19 groups of tips and up to 4 groups
    of term 10's points, and 2 and 3 ranks give the serial run file bit for bit. About a minute."""
    from pathlib import Path

    (tmp_path / "fig2.toml").write_text((Path(__file__).parents[2] / "scenarios" / "fig2.toml").read_text())
    tree = ["--set", "forces.current_field.method=tree", "--set", "forces.current_lorentz.method=tree"]
    args = ["fig2.toml", "--t-end", "30", *tree]
    serial = _launch(0, [*args, "-o", "f1.h5"], tmp_path)
    assert serial.returncode == 0, serial.stderr
    with h5py.File(tmp_path / "f1.h5", "r") as f:
        assert np.count_nonzero(f["graph/current"][-1]) > 128  # more than one group of term 10's points
    for ranks in (2, 3):
        res = _launch(ranks, [*args, "-o", f"f{ranks}.h5"], tmp_path)
        assert res.returncode == 0, res.stderr
        _assert_same_run(tmp_path / f"f{ranks}.h5", tmp_path / "f1.h5")


def test_commands_that_read_run_files_refuse_mpiexec(scene):
    """``mpiexec -n 2 selfas-graph export/plot/...`` would run the whole command on every rank (lines
    printed twice, two ranks writing one file): refused, once, and nothing is written."""
    res = launch(["-m", "selfas_graph.cli.main", "export", "serial.h5", "--format", "gsd", "-o", "twice.gsd"], scene, 2)
    assert res.returncode == 2
    assert res.stderr.count("without mpiexec") == 1, res.stderr
    assert not (scene / "twice.gsd").exists()
