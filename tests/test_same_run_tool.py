"""Smoke test of tools/same_run.py: equal files agree, a one-ulp change or a missing dataset is found."""
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np

TOOL = Path(__file__).resolve().parent.parent / "tools" / "same_run.py"


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
    return subprocess.run([sys.executable, str(TOOL), str(a), str(b)], capture_output=True, text=True)


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
