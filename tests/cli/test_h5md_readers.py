"""Run files follow H5MD 1.1 and open with the readers users have (MDAnalysis, pyh5md), and
RunFile still reads files written in the layout before the H5MD additions (tests/data)."""

import json
import warnings
from pathlib import Path

import h5py
import numpy as np
import pytest

from conftest import SMALL_CIRCUIT_SCENE
from selfas_graph.cli.main import main
from selfas_graph.io.h5md import RunFile, RunWriter

DATA = Path(__file__).parent.parent / "data"
#: written by selfas-graph at commit 58b30f8 (before units, connectivity and observables/dt), see tests/data/README.md
LEGACY = DATA / "legacy_run_58b30f8.h5"


@pytest.fixture(scope="module")
def run_file(tmp_path_factory):
    """A short run of the small circuit scene: 60 rods, 100 steps, a frame every 20 steps."""
    d = tmp_path_factory.mktemp("h5md")
    scene = d / "small.toml"
    scene.write_text(
        SMALL_CIRCUIT_SCENE.replace("t_end = 0.6", "t_end = 0.05").replace("interval = 0.05", "interval = 0.01")
    )
    out = d / "small.h5"
    assert main(["simulate", str(scene), "-o", str(out), "--progress", "none"]) == 0
    return out


def _fixed_ascii(attr_id):
    t = attr_id.get_type()
    return isinstance(t, h5py.h5t.TypeStringID) and not t.is_variable_str()


def _variable_ascii(attr_id):
    """A scalar variable-length ASCII string, as the H5MD units module asks of ``system`` and ``unit``."""
    t = attr_id.get_type()
    return (
        isinstance(t, h5py.h5t.TypeStringID)
        and t.is_variable_str()
        and t.get_cset() == h5py.h5t.CSET_ASCII
        and attr_id.shape == ()
    )


def test_layout_follows_h5md_1_1(run_file):
    with h5py.File(run_file, "r") as f:
        assert tuple(f["h5md"].attrs["version"]) == (1, 1)
        for group, names in (
            ("h5md/author", ("name",)),
            ("h5md/creator", ("name", "version")),
        ):
            for name in names:  # H5MD 1.1: fixed-length strings
                assert _fixed_ascii(f[group].attrs.get_id(name)), f"{group}@{name}"
        assert _variable_ascii(f["h5md/modules/units"].attrs.get_id("system"))  # the units module's own rule
        assert f["h5md/modules/units"].attrs["system"] == "reduced"
        assert f["h5md/creator"].attrs["name"].decode() == "selfas-graph"
        assert tuple(f["h5md/modules/units"].attrs["version"]) == (1, 0)
        # every subgroup of /particles holds a box; the first one (creation order) is the tips
        assert list(f["particles"]) == ["tips", "rods"]
        for name, g in f["particles"].items():
            assert g["box"].attrs["dimension"] == 3
            assert [b.decode() for b in g["box"].attrs["boundary"]] == ["none"] * 3
        # the rods as bonds between tips, referring to the tips' particles group
        bonds = f["connectivity/rods"]
        assert f[bonds.attrs["particles_group"]].name == "/particles/tips"
        np.testing.assert_array_equal(bonds[:], np.arange(120).reshape(60, 2))
        assert bonds.fillvalue == -1  # H5MD ignores tuples holding the fill value: HDF5's default 0 is tip 0
        # step and time: time = step dt; observables/dt is the time between frames
        pos = f["particles/tips/position"]
        dt = 5e-4
        np.testing.assert_allclose(pos["time"][:], pos["step"][:] * dt, rtol=0, atol=1e-12)  # round-off of t += dt
        np.testing.assert_array_equal(pos["step"][:], np.arange(6) * 20)
        np.testing.assert_allclose(f["observables/dt/value"][:], 20 * dt, rtol=1e-12)
        # units: variable-length ASCII strings (the units module 1.0) in the reduced units, none on what
        # MDAnalysis parses
        units = {}
        f.visititems(lambda name, obj: units.__setitem__(name, obj.attrs["unit"]) if "unit" in obj.attrs else None)
        for name in units:
            assert _variable_ascii(f[name].attrs.get_id("unit")), name
        assert units["observables/energy/kinetic/value"] == "F_M0 L"
        assert units["observables/energy/kinetic/time"] == "t_0"
        assert units["observables/dt/value"] == "t_0"
        assert units["particles/tips/charge"] == units["particles/rods/charge"] == "Z_M0e"
        # H5MD 1.1 charge: type "effective" (a charge whose meaning the model gives), and which charge it is
        for name, quantity in (("tips", "magnetic charge"), ("rods", "electric charge")):
            charge = f[f"particles/{name}/charge"]
            assert charge.attrs["type"].decode() == "effective" and _fixed_ascii(charge.attrs.get_id("type"))
            assert quantity in charge.attrs["quantity"].decode()
        assert units["graph/current"] == "J_0" and units["graph/potential"] == "R_0 J_0"
        assert not any(name.startswith(("particles/tips/position", "particles/tips/velocity")) for name in units)


def test_frame_spacing_off_the_grid_after_a_resume_and_a_non_ascii_author(tmp_path, monkeypatch):
    """A run whose end time is off the frame grid (0.012 with frames every 0.005) ends with a closer
    frame, which a resume to 0.02 keeps inside the trajectory: observables/dt states each frame's
    time since the frame before (the first frame the interval), so MDAnalysis' Timestep.dt is right
    at every frame (exact differences of the stored times, to their round-off: 1e-12 of a step).
    An author's name that is not ASCII is a fixed-length string tagged UTF-8."""
    scene = tmp_path / "small.toml"
    scene.write_text(
        SMALL_CIRCUIT_SCENE.replace("t_end = 0.6", "t_end = 0.012").replace("interval = 0.05", "interval = 0.005")
    )
    out = tmp_path / "small.h5"
    monkeypatch.setenv("USER", "Jürgen Müller")
    assert main(["simulate", str(scene), "-o", str(out), "--progress", "none"]) == 0
    assert main(["simulate", "--resume", str(out), "--t-end", "0.02", "--progress", "none"]) == 0
    with h5py.File(out, "r") as f:
        time = f["particles/tips/position/time"][:]
        spacing = f["observables/dt/value"][:]
        author = f["h5md/author"].attrs.get_id("name").get_type()
        assert f["h5md/author"].attrs["name"].decode("utf-8") == "Jürgen Müller"
    assert not author.is_variable_str() and author.get_cset() == h5py.h5t.CSET_UTF8
    np.testing.assert_allclose(time, [0, 0.005, 0.01, 0.012, 0.015, 0.02], rtol=0, atol=1e-12)
    np.testing.assert_allclose(spacing, np.diff(time, prepend=-0.005), rtol=0, atol=1e-12)
    # a continuation on another number of MPI ranks is recorded with its version, commit, CPU and threads
    with RunFile(out) as run:
        assert json.loads(run.meta.get("resumed_with", "[]")) == []
    RunWriter.reopen(out, 40, mpi_ranks=3).close()
    with RunFile(out) as run:
        assert [r["mpi_ranks"] for r in json.loads(run.meta["resumed_with"])] == [3]
    pytest.importorskip("MDAnalysis")
    from MDAnalysis.coordinates.H5MD import H5MDReader

    reader = H5MDReader(str(out), convert_units=False)
    np.testing.assert_allclose([ts.dt for ts in reader], spacing, rtol=0, atol=1e-12)
    reader.close()


def test_mdanalysis_reads_the_run(run_file):
    mda = pytest.importorskip("MDAnalysis")
    from MDAnalysis.coordinates.H5MD import H5MDReader

    with h5py.File(run_file, "r") as f:
        pos = f["particles/tips/position/value"][:]
        vel = f["particles/tips/velocity/value"][:]
        time = f["particles/tips/position/time"][:]
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no "no dt information" warning, no other
        reader = H5MDReader(str(run_file), convert_units=False)
        assert reader.n_atoms == 120 and reader.n_frames == len(pos)
        for k, ts in enumerate(reader):
            # MDAnalysis holds coordinates in float32: equal to the stored float64 rounded once
            np.testing.assert_array_equal(ts.positions, pos[k].astype(np.float32))
            np.testing.assert_array_equal(ts.velocities, vel[k].astype(np.float32))
            assert ts.time == pytest.approx(time[k], rel=1e-12)
            assert ts.dt == pytest.approx(0.01, rel=1e-12)
            assert ts.dimensions is None  # no periodic box
        reader.close()
        # a Universe: the tips as atoms, the trajectory loaded with the reduced units kept
        u = mda.Universe.empty(120, trajectory=False)
        u.load_new(str(run_file), format="H5MD", convert_units=False)
        u.trajectory[-1]
        np.testing.assert_array_equal(u.atoms.positions, pos[-1].astype(np.float32))
    # without convert_units=False MDAnalysis asks for SI units, which reduced units are not
    with pytest.raises(ValueError, match="convert_units"):
        H5MDReader(str(run_file))


def test_pyh5md_reads_the_run(run_file):
    pyh5md = pytest.importorskip("pyh5md")
    with h5py.File(run_file, "r") as f:
        pos = f["particles/tips/position/value"][:]
        step = f["particles/tips/position/step"][:]
    with pyh5md.File(str(run_file), "r") as f:
        tips = f.particles_group("tips")
        position = pyh5md.element(tips, "position")
        np.testing.assert_array_equal(position.value[:], pos)
        np.testing.assert_array_equal(position.step[:], step)
        charge = pyh5md.element(tips, "charge")
        assert charge.shape == (120,)
        energy = pyh5md.element(f["observables"], "energy_total")
        assert energy.value.shape == (len(pos),)


def test_runfile_reads_new_and_legacy_layouts(run_file):
    for path in (run_file, LEGACY):
        with RunFile(path) as run:
            n = run.n_frames
            assert n >= 6
            x = run.position(-1)
            assert x.shape == (120, 3) and np.isfinite(x).all()
            np.testing.assert_array_equal(run.bonds, np.arange(120).reshape(60, 2))
            assert run.rod_charge.shape == (60,)
            g = run.graph(-1)
            assert g["role"].shape == (60,) and g["current"].shape == (60,)
            assert len(run.events()) > 0
            assert "energy_balance" in run.observable_names()
    with h5py.File(LEGACY, "r") as f:  # the file keeps the old layout: no connectivity, no units
        assert "connectivity" not in f and "observables/dt" not in f


@pytest.mark.parametrize("command", [["topology"], ["plot", "--kind", "timeline"]])
def test_cli_reads_legacy_file(command, tmp_path):
    args = [command[0], str(LEGACY), *command[1:]]
    if command[0] == "plot":
        pytest.importorskip("matplotlib")
        args += ["-o", str(tmp_path / "t.png"), "--dpi", "30"]
    assert main(args) == 0
