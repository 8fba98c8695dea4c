"""``selfas-graph ensemble`` across MPI ranks (mpi4py.futures), in both documented launch forms.

``mpiexec -n P selfas-graph ensemble ...`` (every rank starts the command; rank 0 hands
the seeds to the other P - 1) and ``mpiexec -n P python -m mpi4py.futures -m
selfas_graph.cli.main ensemble ...`` (mpi4py's own launcher). Each seed runs alone on its
rank, so its file equals the serial ensemble's bit for bit. Each launch has a timeout: a
hang fails the test instead of blocking the suite.
"""

import pytest
from runfiles import MPIEXEC, differing_datasets, launch

from conftest import SMALL_CIRCUIT_SCENE
from selfas_graph.ensemble import seed_path

pytestmark = pytest.mark.mpi

if MPIEXEC is None:
    pytest.skip(
        "mpiexec not found next to the Python interpreter or on PATH (install the mpich wheel)", allow_module_level=True
    )
pytest.importorskip("mpi4py", reason="mpi4py is not installed")

ARGS = ["scene.toml", "--seeds", "2", "--t-end", "0.2"]


def _launch(cmd, cwd, ranks=0):
    return launch(cmd, cwd, ranks)


def _assert_same_seeds(folder, reference):
    for s in (3, 4):
        differ = differing_datasets(seed_path(folder, s), seed_path(reference, s))
        assert not differ, f"seed {s} differs from the serial ensemble in {differ}"


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    """The scene and its serial ensemble (which also fills the numba cache)."""
    folder = tmp_path_factory.mktemp("ensmpi")
    (folder / "scene.toml").write_text(SMALL_CIRCUIT_SCENE)
    res = _launch(["-m", "selfas_graph.cli.main", "ensemble", *ARGS, "-o", "serial"], folder)
    assert res.returncode == 0, res.stderr
    return folder


@pytest.mark.parametrize("form, ranks", [("plain", 3), ("futures", 2)])
def test_ranks_run_the_seeds_of_the_serial_ensemble(scene, form, ranks):
    out = f"{form}{ranks}"
    head = ["-m", "mpi4py.futures"] if form == "futures" else []
    res = _launch([*head, "-m", "selfas_graph.cli.main", "ensemble", *ARGS, "-o", out], scene, ranks)
    assert res.returncode == 0, res.stderr
    assert f"2 to run, 0 to resume, 0 done, 0 failed; on {ranks - 1} MPI worker rank{'s' * (ranks > 2)}" in res.stdout
    assert res.stdout.count("| median_axis_distance |") == 1  # one summary, from rank 0
    _assert_same_seeds(scene / out, scene / "serial")
    if form == "futures":
        return
    again = _launch([*head, "-m", "selfas_graph.cli.main", "ensemble", *ARGS, "-o", out], scene, ranks)
    assert again.returncode == 0, again.stderr
    assert "0 to run, 0 to resume, 2 done" in again.stdout and "[1/" not in again.stdout


def test_bad_input_under_mpi_stops_every_rank_with_one_message(scene):
    res = _launch(["-m", "selfas_graph.cli.main", "ensemble", *ARGS, "-o", "never", "--set", "rods.cont=3"], scene, 2)
    assert res.returncode == 2
    assert res.stderr.count("error:") == 1 and "rods.cont" in res.stderr, res.stderr
    assert not (scene / "never").exists()
