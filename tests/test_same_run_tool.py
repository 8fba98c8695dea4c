"""Smoke test of selfas_graph/bench/same_run.py (``selfas-graph compare``): equal files agree, a one-ulp
change or a missing dataset is found."""

import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

ROOT = Path(__file__).resolve().parent.parent


def _write(path, value, extra=False):
    with h5py.File(path, "w") as f:
        f.attrs["created"] = str(path)  # wall-clock-like: ignored
        g = f.create_group("observables/current")
        g.create_dataset("value", data=value)
        g.attrs["unit"] = "J0"
        f["link"] = h5py.SoftLink("/observables")
        f.attrs["ref"] = g.ref
        if extra:
            f.create_dataset("more", data=[1])


def _run(a, b):
    return subprocess.run(
        [sys.executable, "-m", "selfas_graph.bench.same_run", str(a), str(b)], capture_output=True, text=True
    )


def test_same_run_tool(tmp_path):
    x = np.array([1.0, np.nan, 3.0])
    _write(tmp_path / "a.h5", x)
    _write(tmp_path / "b.h5", x)
    r = _run(tmp_path / "a.h5", tmp_path / "b.h5")
    assert r.returncode == 0 and "the same, bit for bit" in r.stdout, r.stdout + r.stderr
    _write(tmp_path / "c.h5", np.array([1.0, np.nan, np.nextafter(3.0, 4.0)]))
    r = _run(tmp_path / "a.h5", tmp_path / "c.h5")
    assert r.returncode == 1 and "observables/current/value: data differ (1 of 3" in r.stdout, r.stdout
    _write(tmp_path / "d.h5", x, extra=True)
    r = _run(tmp_path / "a.h5", tmp_path / "d.h5")
    assert r.returncode == 1 and "more: only in" in r.stdout, r.stdout


@pytest.mark.slow
def test_same_as_commit_tool_finds_the_working_tree_equal_to_head(tmp_path):
    """selfas_graph/bench/same_as_commit.py runs a short scene with HEAD's code and with the working tree (each
    checked to import the code meant) and compares the run files; a clean tree agrees with HEAD.
    Slow: the exported commit's kernels are compiled afresh."""
    dirty = subprocess.run(["git", "status", "--porcelain", "selfas_graph"], capture_output=True, text=True, cwd=ROOT)
    if dirty.returncode != 0 or dirty.stdout.strip():
        pytest.skip("not a git checkout, or the working tree differs from HEAD in selfas_graph/")
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "selfas_graph.bench.same_as_commit",
            "scenarios/quick.toml+run.t_end=0.02+rods.count=20",
            "--keep",
            str(tmp_path),
        ],
        capture_output=True,
        text=True,
        cwd=ROOT,
    )
    assert r.returncode == 0 and "the same, bit for bit" in r.stdout, r.stdout + r.stderr
