"""``selfas-graph export``: GSD and extended XYZ that gsd, MDAnalysis and ASE open, with the rods as
bonds, the roles as types and the currents; the output path rules."""

import os
import shutil
import stat
from pathlib import Path

import h5py
import numpy as np
import pytest

from selfas_graph.cli.main import main
from selfas_graph.io.export import (
    ROLE_TYPES,
    ExportError,
    ExportExistsError,
    MissingGraphWarning,
    export_run,
    parse_frames,
)
from selfas_graph.io.h5md import RunFile

#: a short circuit at frame 6: filament and dead-end rods, currents (tests/data/README.md)
RUN = Path(__file__).parent.parent / "data" / "legacy_run_58b30f8.h5"


@pytest.fixture
def run(tmp_path):
    path = tmp_path / "run.h5"
    shutil.copyfile(RUN, path)
    return path


def _expected(path):
    with RunFile(path) as r:
        return {
            "pos": r.f["particles/tips/position/value"][:],
            "vel": r.f["particles/tips/velocity/value"][:],
            "role": r.f["graph/role"][:],
            "current": r.f["graph/current"][:],
            "step": r.step,
            "time": r.time,
            "charge": r.tip_charge,
        }


def test_gsd_export_opens_in_gsd_and_mdanalysis(run, capsys):
    gsd_hoomd = pytest.importorskip("gsd.hoomd")
    assert main(["export", str(run), "--format", "gsd"]) == 0
    out = run.with_suffix(".gsd")
    assert "7 frames" in capsys.readouterr().out
    e = _expected(run)
    assert (e["role"][-1] == 3).any() and np.abs(e["current"][-1]).max() > 0  # the file tests what it should
    with gsd_hoomd.open(str(out), "r") as traj:
        assert len(traj) == 7
        for k, frame in enumerate(traj):
            assert frame.configuration.step == e["step"][k]
            np.testing.assert_array_equal(frame.particles.position, e["pos"][k].astype(np.float32))
            assert list(frame.particles.types) == ROLE_TYPES == ["free", "cluster", "dead_end", "filament"]
            np.testing.assert_array_equal(frame.particles.typeid, np.repeat(e["role"][k], 2))
            assert frame.bonds.N == 60
            np.testing.assert_array_equal(frame.bonds.group, np.arange(120).reshape(60, 2))
            np.testing.assert_array_equal(frame.bonds.typeid, e["role"][k])
            np.testing.assert_array_equal(frame.log["bonds/current"], e["current"][k])
            np.testing.assert_array_equal(frame.log["particles/current"], np.repeat(e["current"][k], 2))
            assert frame.log["time"][0] == e["time"][k]
            box = frame.configuration.box
            assert (np.abs(frame.particles.position) < box[0] / 2).all()  # nothing wrapped
    mda = pytest.importorskip("MDAnalysis")
    u = mda.Universe(str(out))
    assert len(u.atoms) == 120 and len(u.bonds) == 60 and u.trajectory.n_frames == 7
    u.trajectory[-1]
    np.testing.assert_array_equal(u.atoms.positions, e["pos"][-1].astype(np.float32))
    assert set(u.atoms.types) <= set(ROLE_TYPES)


def test_xyz_export_opens_in_ase(run):
    ase_io = pytest.importorskip("ase.io")
    out = run.parent / "tail.xyz"
    assert main(["export", str(run), "--format", "xyz", "--frames=0,-2,-1", "-o", str(out)]) == 0
    e = _expected(run)
    frames = ase_io.read(str(out), index=":")
    assert len(frames) == 3
    for atoms, k in zip(frames, (0, 5, 6)):
        # written with 17 significant digits: the float64 values come back exactly
        np.testing.assert_array_equal(atoms.positions, e["pos"][k])
        np.testing.assert_array_equal(atoms.arrays["velo"], e["vel"][k])
        np.testing.assert_array_equal(atoms.arrays["role"], np.repeat(e["role"][k], 2))
        np.testing.assert_array_equal(atoms.arrays["current"], np.repeat(e["current"][k], 2))
        np.testing.assert_array_equal(atoms.arrays["rod"], np.arange(120) // 2)
        np.testing.assert_array_equal(atoms.arrays["magnetic_charge"], e["charge"])
        assert atoms.info["Time"] == e["time"][k] and atoms.info["Step"] == e["step"][k]
        assert isinstance(atoms.info["Time"], float)  # a float at t = 0 too (written "0.0", the shortest exact form)
        assert isinstance(atoms.info["total_current"], float)  # a float when 0 too, in every frame alike
        assert not atoms.pbc.any()
    first = out.read_text().splitlines()[2].split()[0]
    assert first in ROLE_TYPES  # the species column: the role name (OVITO's particle type)


def test_frames_without_a_graph_record_are_written_free_and_said_so(run, tmp_path, capsys):
    """The last of the 7 frames with its graph record torn off by a kill: the export writes it (its
    rods typed free, no current, which they were not), Python warns with the frame's number and the
    command prints a note; an export of frames that all have their records says nothing."""
    with h5py.File(run, "r+") as f:
        for name in ("conductor_contacts_count", "current", "potential", "role", "step", "time", "tip_contacts_count"):
            f["graph"][name].resize(6, axis=0)
    with pytest.warns(MissingGraphWarning, match=r"1 frame \(6\) had no graph record") as caught:
        path, n = export_run(run, "gsd", out=tmp_path / "a.gsd", frames="4:")
    assert n == 3 and caught[0].message.frames.tolist() == [6]
    with pytest.importorskip("gsd.hoomd").open(str(path)) as traj:
        assert (traj[2].particles.typeid == 0).all() and (traj[0].particles.typeid > 0).any()
    assert main(["export", str(run), "--format", "xyz", "-o", str(tmp_path / "b.xyz")]) == 0
    err = capsys.readouterr().err
    assert "note: " in err and "b.xyz: 1 frame (6) had no graph record" in err
    assert main(["export", str(run), "--format", "xyz", "--frames", ":6", "-o", str(tmp_path / "c.xyz")]) == 0
    assert capsys.readouterr().err == ""


def test_output_rules(run, capsys):
    out = run.with_suffix(".gsd")
    out.write_bytes(b"keep")
    assert main(["export", str(run), "--format", "gsd"]) == 2
    assert "--force" in capsys.readouterr().err
    assert out.read_bytes() == b"keep"
    before = run.read_bytes()
    for target in (run, run.parent / "." / run.name):
        assert main(["export", str(run), "--format", "xyz", "-o", str(target), "--force"]) == 2
        assert "run file itself" in capsys.readouterr().err
    assert run.read_bytes() == before
    checkpoint = run.with_name(run.stem + ".checkpoint.h5")
    with h5py.File(checkpoint, "w") as f:  # where the run's checkpoint would be (any HDF5 file)
        f["x"] = 1
    h5 = checkpoint.read_bytes()
    assert main(["export", str(run), "--format", "xyz", "-o", str(checkpoint), "--force"]) == 2
    assert "an export never replaces one" in capsys.readouterr().err and checkpoint.read_bytes() == h5
    checkpoint.unlink()
    assert main(["export", str(run), "--format", "gsd", "-o", str(run.parent / "x.xyz")]) == 2
    assert "names a .xyz file, but the format is gsd" in capsys.readouterr().err
    assert main(["export", str(run), "--format", "gsd", "--force", "--frames", "0"]) == 0
    assert out.read_bytes() != b"keep"
    assert main(["export", str(run), "--format", "xyz", "--frames", "99"]) == 2
    assert "out of range" in capsys.readouterr().err
    assert main(["export", str(run.parent / "missing.h5"), "--format", "xyz"]) == 2
    assert list(p.name for p in run.parent.iterdir() if p.suffix == ".part") == []


def test_an_export_replaces_only_a_file_of_its_format(run, capsys):
    """``-o`` must end in the format's suffix: a scene file (or any other) is not replaced, even with
    --force; the command line's advice names its options, Python's its arguments."""
    scene = run.parent / "scene.toml"
    scene.write_text("[rods]\ncount = 3\n")
    for name in ("scene.toml", "traj", "plot.png"):
        target = run.parent / name
        assert main(["export", str(run), "--format", "xyz", "-o", str(target), "--force"]) == 2
        assert "give a name ending in .xyz or .extxyz" in capsys.readouterr().err
        assert not target.exists() or target == scene
    assert scene.read_text() == "[rods]\ncount = 3\n"
    for name, fmt in (("a.extxyz", "xyz"), ("a.XYZ", "xyz"), ("a.gsd", "gsd")):
        assert main(["export", str(run), "--format", fmt, "--frames", "0", "-o", str(run.parent / name)]) == 0
    capsys.readouterr()
    assert main(["export", str(run), "--format", "gsd", "--frames", "0", "-o", str(run.parent / "a.gsd")]) == 2
    err = capsys.readouterr().err
    assert "pass --force to overwrite it or -o to choose another name" in err and "force=True" not in err
    with pytest.raises(ExportError, match="True or False is not a frame number"):
        export_run(run, "xyz", out=run.parent / "b.xyz", frames=True)  # it exported frame 1
    with pytest.raises(ExportExistsError, match="pass force=True to overwrite it, or another out= path") as info:
        export_run(run, "gsd", out=run.parent / "a.gsd", frames=0)
    assert info.value.path == run.parent / "a.gsd" and "--force" not in str(info.value)


def test_the_format_keyword_is_the_commands_name(run):
    """``export_run(format=...)`` as the command's ``--format``; ``fmt=``, the name of 0.4.2, still works."""
    path, n = export_run(run, format="xyz", out=run.parent / "k.xyz", frames=0)
    assert (path, n) == (run.parent / "k.xyz", 1)
    with pytest.warns(DeprecationWarning, match=r"now export_run\(format=...\)"):
        assert export_run(run, fmt="xyz", out=run.parent / "old.xyz", frames=0)[1] == 1
    assert (run.parent / "old.xyz").read_bytes() == path.read_bytes()
    with pytest.raises(TypeError, match="give format= alone"):
        export_run(run, format="xyz", fmt="gsd")
    with pytest.raises(TypeError, match=r"export_run\(run_path, format\): the format is missing; valid: gsd, xyz"):
        export_run(run)
    with RunFile(run) as open_run:  # an open run file is taken for its path
        assert export_run(open_run, format="xyz", out=run.parent / "open.xyz", frames=0)[1] == 1
    assert (run.parent / "open.xyz").read_bytes() == path.read_bytes()


def test_exports_get_the_permissions_of_a_new_file(run):
    """An export is written through a private temporary file (``mkstemp``: 0o600) and renamed: it
    used to keep those permissions, unreadable by the group where the run file beside it is not."""
    old = os.umask(0o022)
    try:
        for fmt in ("gsd", "xyz"):
            out = run.parent / f"mode.{fmt}"
            assert main(["export", str(run), "--format", fmt, "--frames", "0", "-o", str(out)]) == 0
            assert stat.S_IMODE(out.stat().st_mode) == 0o644
    finally:
        os.umask(old)


@pytest.mark.parametrize(
    "spec, frames",
    [
        ("all", [0, 1, 2, 3]),
        ("-1", [3]),
        ("1:3", [1, 2]),
        ("::2", [0, 2]),
        ("0,-1", [0, 3]),
        # from Python: integers as the command line's list (a list was refused)
        ([0, 2], [0, 2]),
        (np.array([1, -1]), [1, 3]),
        (2, [2]),
        (slice(None, None, 2), [0, 2]),  # a slice object from Python, as "::2"
        (slice(1, -1), [1, 2]),
    ],
)
def test_parse_frames(spec, frames):
    assert parse_frames(spec, 4).tolist() == frames


@pytest.mark.parametrize(
    "spec",
    [
        "x",
        "1:2:0",
        "4",
        "5:9",
        "1:2:3:4",
        "",
        "99999999999999999999999",
        [0.5],
        [4],
        [[0, 1]],
        slice(0, 2, 0),
        slice(0.5, 2),
    ],
)
def test_parse_frames_refuses(spec):
    with pytest.raises(ExportError):
        parse_frames(spec, 4)


@pytest.mark.parametrize("spec", ["1,1", "3,-1", [0, 2, -4]])
def test_a_frame_named_twice_is_refused(spec):
    """It was written twice, a trajectory stepping back in time for every reader."""
    with pytest.raises(ExportError, match=r"frame \d is named twice; give each frame once"):
        parse_frames(spec, 4)


def test_ovito_reads_the_exports(run):
    """OVITO's Python module (pip install ovito: 260 MB, so not in the test extra) reads both exports:
    the roles as particle types, the rods as bonds typed by role, the currents, time and total current."""
    ovito_io = pytest.importorskip("ovito.io")
    e = _expected(run)
    for fmt in ("gsd", "xyz"):
        assert main(["export", str(run), "--format", fmt]) == 0
        pipeline = ovito_io.import_file(
            str(run.with_suffix("." + fmt)), **({"multiple_frames": True} if fmt == "xyz" else {})
        )
        assert pipeline.source.num_frames == 7
        data = pipeline.compute(6)
        p = data.particles
        np.testing.assert_allclose(p.positions[...], e["pos"][6], rtol=0, atol=1e-5)  # GSD: float32
        types = {t.id: t.name for t in p.particle_types.types}
        names = [types[i] for i in p.particle_types[...]]
        assert names == [ROLE_TYPES[r] for r in np.repeat(e["role"][6], 2)]
        np.testing.assert_allclose(p["current"][...], np.repeat(e["current"][6], 2), rtol=1e-6)
        if fmt == "gsd":
            assert p.bonds.count == 60
            np.testing.assert_array_equal(p.bonds.topology[...], np.arange(120).reshape(60, 2))
            assert data.attributes["time"] == pytest.approx(e["time"][6])


@pytest.mark.parametrize(
    "error, code",
    [(OSError(28, "No space left on device"), 4), (PermissionError(13, "Permission denied"), 2)],
)
def test_a_failed_write_has_the_exit_code_of_every_command(run, capsys, monkeypatch, error, code):
    """One rule with plot and simulate (cli.main.write_failed): a full disk is an I/O error, exit 4; a
    target the user must change is a usage error, exit 2. Nothing is left at the output's name."""

    def fail(path, write):
        raise error

    monkeypatch.setattr("selfas_graph.io.export.atomic_write", fail)
    out = run.with_name("out.gsd")
    assert main(["export", str(run), "--format", "gsd", "-o", str(out)]) == code
    err = capsys.readouterr().err
    assert f"cannot write the export {out}: {error.strerror}" in err and not out.exists()
