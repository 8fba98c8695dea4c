"""The MPI edge: ``world`` is the MPI communicator under ``mpiexec`` and a one-rank stub otherwise.

mpi4py is imported here and nowhere else, and only when the process was started
by an MPI launcher (so a serial run needs no MPI at all). Rank 0 writes files;
every rank runs the same deterministic model, so events and the graph agree.
"""
from __future__ import annotations

import os

_LAUNCHER_VARS = ("PMI_SIZE", "PMI_RANK", "OMPI_COMM_WORLD_SIZE", "MPI_LOCALNRANKS", "HYDRA_CONTROL_FD")


class _SerialWorld:
    rank = 0
    size = 1

    def bcast(self, obj, root=0):
        return obj

    def allreduce(self, value, op=None):
        return value

    def Barrier(self):
        pass

    def Abort(self, code=1):  # pragma: no cover - only reached on fatal errors
        raise SystemExit(code)


def _make_world():
    if not any(v in os.environ for v in _LAUNCHER_VARS):
        return _SerialWorld()
    from mpi4py import MPI

    comm = MPI.COMM_WORLD
    return comm if comm.Get_size() > 1 else _SerialWorld()


world = _make_world()


def fit_threads_to_cores(world=world):
    """Give each rank ``cores // ranks`` numba threads (at least 1) unless NUMBA_NUM_THREADS is set.

    Ranks times threads then fit the machine instead of oversubscribing it. Returns the count.
    """
    import numba

    if world.size > 1 and "NUMBA_NUM_THREADS" not in os.environ:
        cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
        numba.set_num_threads(max(1, min(numba.config.NUMBA_NUM_THREADS, cores // world.size)))
    return numba.get_num_threads()
