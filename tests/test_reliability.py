"""Reliability: a run and its checkpoint know each other, nothing corrupt is accepted, no NaN is
stored, output paths are checked, I/O errors end a run cleanly, and kills at any moment leave a
run that resumes to the uninterrupted one bit for bit.

Each ``test_*`` below reproduces one way the long-run machinery used to break (written against
the code before its fix, where it failed) and pins the behaviour now.
"""
from __future__ import annotations

import json
import shutil

import h5py
import numpy as np
import pytest

from selfas_graph.cli.main import main
from selfas_graph.io.checkpoint import CheckpointError, checkpoint_path, read_checkpoint

#: 4 rods, every term of the circuit scene, 4 steps and 3 frames: a real run in well under a second
SCENE = """
[scenario]
name = "tiny"
seed = 7
[rods]
count = 4
[placement]
box = [[-1.5, 1.5], [-1.5, 1.5], [-1.0, 1.0]]
[forces.tip_magnetic]
[forces.tip_brake]
[forces.ambient_brake]
[forces.uniform_field]
[forces.yukawa]
[forces.electrodes]
gap = 2.0
[forces.current_field]
[forces.current_lorentz]
[circuit]
delta_J0 = 2.0
[integrator]
dt = 1e-3
[run]
t_end = 0.004
[output]
interval = 0.002
checkpoint_interval = 0
"""


def cli(capsys, *argv):
    capsys.readouterr()
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    assert "Traceback" not in err, err
    return code, out, err


@pytest.fixture
def scen(tmp_path):
    p = tmp_path / "s.toml"
    p.write_text(SCENE)
    return p


def simulate(capsys, *argv):
    return cli(capsys, "simulate", "--progress", "none", *argv)


def frame_times(path):
    with h5py.File(path, "r") as f:
        return f["particles/tips/position/time"][:]


# ----------------------------------------------------------------------------- run identity

def test_run_and_checkpoint_carry_the_same_run_id(scen, tmp_path, capsys):
    out = tmp_path / "run.h5"
    assert simulate(capsys, scen, "-o", out)[0] == 0
    with h5py.File(out, "r") as f:
        run_id = f["parameters/selfas_graph"].attrs["run_id"]
    _, meta = read_checkpoint(checkpoint_path(out))
    assert len(run_id) == 32 and meta["run_id"] == run_id
    # a second run gets another identity
    assert simulate(capsys, scen, "-o", tmp_path / "other.h5")[0] == 0
    assert read_checkpoint(checkpoint_path(tmp_path / "other.h5"))[1]["run_id"] != run_id


def test_resume_of_a_copied_folder_continues_the_copy(scen, tmp_path, capsys):
    """``cp -r a b; simulate --resume b/run.h5`` used to append to a/run.h5 (an absolute path in the checkpoint)."""
    a, b = tmp_path / "a", tmp_path / "b"
    a.mkdir()
    assert simulate(capsys, scen, "-o", a / "run.h5")[0] == 0
    shutil.copytree(a, b)
    before = (a / "run.h5").read_bytes(), (a / "run.checkpoint.h5").read_bytes()
    assert simulate(capsys, "--resume", b / "run.h5", "--t-end", "0.008")[0] == 0
    assert ((a / "run.h5").read_bytes(), (a / "run.checkpoint.h5").read_bytes()) == before
    assert frame_times(b / "run.h5")[-1] == pytest.approx(0.008)


def test_resume_of_a_moved_folder(scen, tmp_path, capsys):
    a = tmp_path / "a"
    a.mkdir()
    assert simulate(capsys, scen, "-o", a / "run.h5")[0] == 0
    moved = tmp_path / "elsewhere"
    a.rename(moved)
    assert simulate(capsys, "--resume", moved / "run.h5", "--t-end", "0.008")[0] == 0
    assert frame_times(moved / "run.h5")[-1] == pytest.approx(0.008)
    # and through the checkpoint's name: the run file beside it
    assert simulate(capsys, "--resume", moved / "run.checkpoint.h5", "--t-end", "0.01")[0] == 0
    assert frame_times(moved / "run.h5")[-1] == pytest.approx(0.01)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["elsewhere", "s.toml"]


def test_a_foreign_checkpoint_is_refused_naming_both_files(scen, tmp_path, capsys):
    """``cp B.checkpoint.h5 A.checkpoint.h5; simulate --resume A.h5`` used to exit 0 and change B.h5."""
    A, B = tmp_path / "A.h5", tmp_path / "B.h5"
    assert simulate(capsys, scen, "-o", A)[0] == 0
    assert simulate(capsys, scen, "-o", B)[0] == 0
    shutil.copy(checkpoint_path(B), checkpoint_path(A))
    before = {p: p.read_bytes() for p in tmp_path.iterdir()}
    code, _, err = simulate(capsys, "--resume", A, "--t-end", "0.008")
    assert code == 2
    assert "A.checkpoint.h5" in err and "A.h5" in err and "another run" in err
    assert {p: p.read_bytes() for p in tmp_path.iterdir()} == before


# ----------------------------------------------------------------------------- corrupt checkpoints

@pytest.fixture
def finished(scen, tmp_path, capsys):
    out = tmp_path / "run.h5"
    assert simulate(capsys, scen, "-o", out)[0] == 0
    return out


def _flip_bits_in_data(path):
    """Flip one bit inside the stored positions (found by their bytes in the file)."""
    with h5py.File(path, "r") as f:
        pos = f["snapshot/position"][()]
    raw = bytearray(path.read_bytes())
    k = raw.find(pos.tobytes())
    assert k >= 0
    raw[k + 3] ^= 0x10
    path.write_bytes(bytes(raw))


@pytest.mark.parametrize("damage", ["bit_flip", "nan_position", "inf_history", "event_dtype", "edited_step"])
def test_a_damaged_checkpoint_is_refused_before_anything_is_appended(finished, capsys, damage):
    """A bit-flipped checkpoint, or one with NaN positions, used to resume (and fail later blaming dt)."""
    ckpt = checkpoint_path(finished)
    if damage == "bit_flip":
        _flip_bits_in_data(ckpt)
    else:
        with h5py.File(ckpt, "r+") as f:
            g = f["snapshot"]
            if damage == "nan_position":
                g["position"][0, 0] = np.nan
            elif damage == "inf_history":
                g["hist_a"][0, 0, 0] = np.inf
            elif damage == "event_dtype":
                del g["events"]
                g["events"] = np.zeros(3)
            else:
                g.attrs["step"] = 2
    before = finished.read_bytes(), ckpt.read_bytes()
    code, _, err = simulate(capsys, "--resume", finished, "--t-end", "0.008")
    assert code == 2 and "cannot resume" in err
    assert (finished.read_bytes(), ckpt.read_bytes()) == before


def test_non_finite_state_is_refused_even_with_a_matching_checksum(finished, tmp_path):
    from selfas_graph.io.checkpoint import write_checkpoint

    snap, meta = read_checkpoint(checkpoint_path(finished))
    snap["velocity"] = snap["velocity"].copy()
    snap["velocity"][1, 2] = np.nan
    bad = tmp_path / "bad.checkpoint.h5"
    write_checkpoint(bad, snap, meta)
    with pytest.raises(CheckpointError, match="velocity holds non-finite"):
        read_checkpoint(bad)


def test_a_checkpoint_write_that_fails_leaves_no_tmp_and_keeps_the_previous(finished, monkeypatch):
    from selfas_graph.io import checkpoint as C

    ckpt = checkpoint_path(finished)
    before = ckpt.read_bytes()
    snap, meta = read_checkpoint(ckpt)

    def fail(*a):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(C.os, "fsync", fail)
    with pytest.raises(OSError):
        C.write_checkpoint(ckpt, snap, meta)
    assert ckpt.read_bytes() == before
    assert not ckpt.with_name(ckpt.name + ".tmp").exists()
