"""Helpers shared by the tests that compare whole run files or launch the command line in a
subprocess (serially or under the ``mpich`` wheel's ``mpiexec``)."""

import os
import shutil
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np

#: the mpiexec of the environment the tests run in (the mpich wheel puts it beside python)
MPIEXEC = shutil.which("mpiexec", path=str(Path(sys.executable).parent)) or shutil.which("mpiexec")

#: seconds one launched command may take before it counts as a hang: the launches of the tests
#: take 5-40 s on 2 cores; a loaded machine has been seen to need 90 s and more
TIMEOUT = 300


def datasets(path) -> dict:
    """Every dataset of an HDF5 file as {name: array} (attributes, which hold wall-clock
    provenance and the run identity, are left out)."""
    out = {}
    with h5py.File(path, "r") as f:
        f.visititems(lambda n, o: out.__setitem__(n, o[()]) if isinstance(o, h5py.Dataset) else None)
    return out


def differing_datasets(path, reference) -> list:
    """Names of the datasets that are not equal bit for bit (NaN equal to NaN in float data:
    floating tips' potentials are NaN); the two files must hold the same datasets."""
    got, want = datasets(path), datasets(reference)
    assert got.keys() == want.keys(), sorted(set(got) ^ set(want))
    return [
        k
        for k in want
        if not (got[k].shape == want[k].shape and np.array_equal(got[k], want[k], equal_nan=want[k].dtype.kind == "f"))
    ]


def assert_same_run(path, reference):
    differ = differing_datasets(path, reference)
    assert not differ, f"{Path(path).name} differs from {Path(reference).name} in {differ}"


def launch(args, cwd, ranks=0, timeout=TIMEOUT):
    """``python ARGS`` in ``cwd`` with one numba thread, under ``mpiexec -n ranks`` if ranks > 0
    (the MPI variables of an enclosing launcher removed)."""
    env = {k: v for k, v in os.environ.items() if not k.startswith(("PMI_", "HYDRA_", "OMPI_", "MPI_"))}
    env["NUMBA_NUM_THREADS"] = "1"
    cmd = [sys.executable, *args]
    if ranks:
        cmd = [MPIEXEC, "-n", str(ranks), *cmd]
    return subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)
