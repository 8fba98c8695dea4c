"""The MPI edge: ``world`` is the MPI communicator under ``mpiexec`` and a one-rank stub otherwise.

mpi4py is imported here and nowhere else, and only when the process was started
by an MPI launcher (so a serial run needs no MPI at all). Rank 0 writes files.

Ensembles (independent runs, one per seed) use :class:`task_pool` instead: on one
machine a pool of spawned processes, under an MPI launcher the ranks of
``mpi4py.futures`` (rank 0 hands out the runs, every other rank runs them, each alone).

Decomposition (replicated data, split force targets): every rank holds every
position and velocity. The expensive force terms compute only the rows of a
contiguous block of rods (:class:`RowBlocks`: the rods' centres, their tips, the
quadrature points of their currents); :meth:`RowBlocks.gather_rows` then
copies every other rank's rows in, so that all ranks hold the same force arrays,
bit for bit. Integration, contacts, events, graph and circuit run identically on
every rank. Energies are gathered the same way as one value per row and summed
on every rank over all rows, so they do not depend on the number of ranks either.
"""

from __future__ import annotations

import os
import sys
import threading
import time

import numpy as np

_LAUNCHER_VARS = ("PMI_SIZE", "PMI_RANK", "OMPI_COMM_WORLD_SIZE", "MPI_LOCALNRANKS", "HYDRA_CONTROL_FD")


class _SerialWorld:
    """The one-rank stand-in for an MPI communicator (the lowercase, pickle-based calls used here)."""

    rank = 0
    size = 1

    def bcast(self, obj, root=0):
        return obj

    def allgather(self, value):
        return [value]

    def Barrier(self):
        pass

    def Abort(self, code=1):  # pragma: no cover - only reached on fatal errors
        raise SystemExit(code)


SERIAL = _SerialWorld()


def _make_world():
    if not any(v in os.environ for v in _LAUNCHER_VARS):
        return SERIAL
    from mpi4py import MPI

    comm = MPI.COMM_WORLD
    return comm if comm.Get_size() > 1 else SERIAL


world = _make_world()


# How long a rank that ends the job waits after its last words: MPICH's launcher forwards a rank's
# stdout and stderr through pipes it reads in its own loop, and MPI_Abort ends the job at once, so a
# line printed just before the abort was lost now and then (an empty stderr, exit code right)
_ABORT_GRACE = 1.0


def abort_job(code: int, world=world) -> None:
    """End every rank of the job with exit ``code``, after this rank's printed lines have left it.

    Flushes stdout and stderr, gives the launcher :data:`_ABORT_GRACE` seconds to forward them, then
    calls MPI_Abort; MPICH's MPI_Abort may return to its caller while the launcher ends the job, so the
    process then ends itself (``os._exit``) rather than go on and print a second time. With one rank
    it raises ``SystemExit(code)``.
    """
    if world.size == 1:
        raise SystemExit(code)
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a closed or broken stream has nothing left to forward
            pass
    time.sleep(_ABORT_GRACE)
    world.Abort(code)
    os._exit(code)  # pragma: no cover - MPI_Abort normally does not return


def _numba():
    """numba, with ``OMP_WAIT_POLICY=PASSIVE`` in the environment unless the user set it.

    The OpenMP runtime reads the policy once, when numba starts its threads, and
    ``numba.set_num_threads`` starts them: here that may come before any kernel module, which sets
    the same default (``kernels/_jit.py`` says why: spinning idle workers take a core), is imported,
    as in an ``mpi4py.futures`` worker rank.
    """
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
    import numba

    return numba


def fit_threads_to_cores(world=world):
    """Give each rank ``cores // ranks`` numba threads (at least 1) unless NUMBA_NUM_THREADS is set.

    Ranks times threads then fit the machine instead of oversubscribing it. Returns the count.
    """
    numba = _numba()

    if world.size > 1 and "NUMBA_NUM_THREADS" not in os.environ:
        cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
        numba.set_num_threads(max(1, min(numba.config.NUMBA_NUM_THREADS, cores // world.size)))
    return numba.get_num_threads()


class RowBlocks:
    """Rods split into contiguous blocks, one per rank: the force targets this rank computes.

    Rank ``r`` owns rods ``bounds[r] <= i < bounds[r + 1]`` (block sizes differ by at most
    one) and their tips ``2 bounds[r] <= k < 2 bounds[r + 1]``. With one rank the block is
    everything and no method communicates.

    Parameters
    ----------
    n_rods : int
    comm : communicator or the serial stub, optional
        Default: the one-rank stub (a serial run), not :data:`world`; the command line
        passes :data:`world` explicitly.

    Attributes
    ----------
    rods : (lo, hi) rod rows of this rank
    tips : (lo, hi) tip rows of this rank, ``(2 lo, 2 hi)``
    """

    def __init__(self, n_rods: int, comm=None):
        self.comm = SERIAL if comm is None else comm
        self.size, self.rank = self.comm.size, self.comm.rank
        self.n_rods = int(n_rods)
        self.bounds = np.array([(self.n_rods * r) // self.size for r in range(self.size + 1)], dtype=np.int64)
        lo, hi = int(self.bounds[self.rank]), int(self.bounds[self.rank + 1])
        self.rods = (lo, hi)
        self.tips = (2 * lo, 2 * hi)
        self._buffers = {}

    @property
    def serial(self) -> bool:
        return self.size == 1

    def gather_rows(self, arrays, rows_per_rod=2) -> None:
        """Copy every other rank's block of rows into each array, in place (a collective call).

        Each rank has filled its own rows of every array: ``rows_per_rod * lo`` to
        ``rows_per_rod * hi`` (2 for tip arrays, 1 for rod arrays). Afterwards every rank
        holds all rows, bit for bit the same everywhere. All arrays are float64 with equal
        shapes ``(rows_per_rod * n_rods, ...)``; one ``Allgatherv`` carries them all.
        """
        if self.size == 1 or not arrays:
            return
        k = len(arrays)
        width = int(np.prod(arrays[0].shape[1:], dtype=np.int64))
        bounds = rows_per_rod * self.bounds
        lo, hi = int(bounds[self.rank]), int(bounds[self.rank + 1])
        counts = k * width * np.diff(bounds)
        displs = np.concatenate(([0], np.cumsum(counts)[:-1]))
        send = self._buffer(("send", k, width), (k, hi - lo, width))
        for c, a in enumerate(arrays):
            send[c] = a[lo:hi].reshape(hi - lo, width)
        recv = self._buffer(("recv", k, width), (int(counts.sum()),))
        self.comm.Allgatherv(send, [recv, (counts.tolist(), displs.tolist())])
        for r in range(self.size):
            if r == self.rank:
                continue
            rlo, rhi = int(bounds[r]), int(bounds[r + 1])
            block = recv[displs[r] : displs[r] + counts[r]].reshape(k, rhi - rlo, width)
            for c, a in enumerate(arrays):
                a[rlo:rhi] = block[c].reshape(a[rlo:rhi].shape)

    def gather_runs(self, array, order, bounds) -> None:
        """Copy every other rank's rows of ``array`` in, where rank r filled rows ``order[bounds[r]:bounds[r + 1]]``
        (a collective call).

        For work split in another order than the blocks of rods (the tip-tip tree splits its target
        groups, runs of tips in Morton order ``order``). ``array`` is float64 with rows of equal
        width; afterwards every rank holds all rows, bit for bit the same everywhere. One
        ``Allgatherv``.
        """
        if self.size == 1:
            return
        if not array.flags.c_contiguous:
            raise ValueError("gather_runs needs a C-contiguous array: its rows are written in place")
        width = int(np.prod(array.shape[1:], dtype=np.int64))
        bounds = np.asarray(bounds, dtype=np.int64)
        lo, hi = int(bounds[self.rank]), int(bounds[self.rank + 1])
        counts = width * np.diff(bounds)
        displs = width * bounds[:-1]
        flat = array.reshape(array.shape[0], width)
        send = np.ascontiguousarray(flat[order[lo:hi]])
        recv = self._buffer(("runs", width), (int(counts.sum()),))
        self.comm.Allgatherv(send, [recv, (counts.tolist(), displs.tolist())])
        flat[order] = recv.reshape(-1, width)  # this rank's own run comes back as it was sent

    def gather_list(self, start, index, rows_per_rod=2):
        """The whole compressed-row list on every rank from each rank's own rows (a collective call).

        Each rank has listed only the rows of its block (``rows_per_rod * lo`` to ``rows_per_rod *
        hi``; the others empty, as ``kernels/cells.py::neighbour_rows(..., rows=...)`` leaves them).
        Two ``Allgatherv``: the row lengths, then the rows. Returns ``(start, index)``, the list
        the whole build would have made, bit for bit (int64 offsets, entries of ``index``'s type).
        """
        if self.size == 1:
            return start, index
        bounds = rows_per_rod * self.bounds
        lo, hi = int(bounds[self.rank]), int(bounds[self.rank + 1])
        n = int(bounds[-1])
        lengths = np.empty(n, dtype=np.int64)
        row_counts = np.diff(bounds)
        self.comm.Allgatherv(
            np.ascontiguousarray(np.diff(start[lo : hi + 1]), dtype=np.int64),
            [lengths, (row_counts.tolist(), bounds[:-1].tolist())],
        )
        full = np.zeros(n + 1, dtype=np.int64)
        np.cumsum(lengths, out=full[1:])
        counts = full[bounds[1:]] - full[bounds[:-1]]
        out = np.empty(int(full[-1]), dtype=index.dtype)  # the entries' type is every rank's (it follows n)
        self.comm.Allgatherv(
            np.ascontiguousarray(index[start[lo] : start[hi]]),
            [out, (counts.tolist(), full[bounds[:-1]].tolist())],
        )
        return full, out

    def _buffer(self, name, shape):
        buf = self._buffers.get(name)
        if buf is None or buf.shape != shape:
            buf = self._buffers[name] = np.empty(shape)
        return buf


# --------------------------------------------------------------------------- ensembles
def _node_cores() -> int:
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


def threads_per_job(jobs: int) -> int:
    """Numba threads of each of ``jobs`` independent runs on one machine: ``cores // jobs``, at least 1."""
    return max(1, _node_cores() // max(1, int(jobs)))


def set_job_threads(threads=None) -> int:
    """Pool-worker initializer: ``threads`` numba threads for every run of this process.

    Applied with ``numba.set_num_threads`` (numba is already imported when a worker
    unpickles its task; changing ``NUMBA_NUM_THREADS`` now would make numba's next
    configuration reload fail once its threads are running). With
    ``threads=None`` (an MPI worker rank) a user's ``NUMBA_NUM_THREADS`` wins, otherwise
    the node's cores are shared among the launcher's ranks on that node.
    """
    numba = _numba()

    if threads is None:
        if "NUMBA_NUM_THREADS" in os.environ:
            threads = int(os.environ["NUMBA_NUM_THREADS"])
        else:
            local = os.environ.get("MPI_LOCALNRANKS") or os.environ.get("OMPI_COMM_WORLD_LOCAL_SIZE") or "1"
            threads = max(1, _node_cores() // max(1, int(local)))
    threads = max(1, min(int(threads), numba.config.NUMBA_NUM_THREADS))
    numba.set_num_threads(threads)
    return threads


#: how often (seconds) a pool worker looks whether its launching process still lives
PARENT_POLL = 0.5
#: how long (seconds) a worker whose launcher died lets its running task stop (a seed stops after its
#: step and writes a checkpoint, well under a second for the shipped scenes) before it exits anyway
ORPHAN_GRACE = 30.0

_orphaned = threading.Event()  # set in a worker once its launching process has died
_job = threading.Lock()  # held while a task runs in this worker


def parent_gone() -> bool:
    """True in a pool worker whose launching process has died: a running task should stop now
    (a seed, with a checkpoint, as on SIGTERM); the worker then exits. False everywhere else."""
    return _orphaned.is_set()


def _parent_dead(parent_pid) -> bool:
    if os.getppid() != parent_pid:  # re-parented (POSIX): the launcher is gone
        return True
    import multiprocessing

    parent = multiprocessing.parent_process()  # a spawned worker's handle on its launcher (every platform)
    return parent is not None and not parent.is_alive()


def _watch_parent(parent_pid) -> None:
    """A worker's daemon thread: once the launcher is dead, mark the worker orphaned, give a running
    task up to :data:`ORPHAN_GRACE` seconds to stop, and end the process (an orphan would otherwise wait
    for tasks that never come, holding its memory, for good)."""
    while not _parent_dead(parent_pid):
        _orphaned.wait(PARENT_POLL)
    _orphaned.set()
    _job.acquire(timeout=ORPHAN_GRACE)
    os._exit(1)


def _on_death_signal(signum, frame) -> None:
    """Linux's parent-death signal: the launcher (or the thread that started this worker) ended."""
    if _parent_dead(_watched[0]):
        _orphaned.set()


_watched = [None]


def watch_parent(parent_pid=None) -> None:
    """Make this process end with ``parent_pid`` (default its parent now): a daemon thread polls for the
    parent's death every :data:`PARENT_POLL` seconds (every platform), and on Linux the kernel signals it
    at once (``prctl(PR_SET_PDEATHSIG)``, the fast path). Then :func:`parent_gone` is true, a running
    task stops and the process exits."""
    import signal

    parent_pid = os.getppid() if parent_pid is None else int(parent_pid)
    _watched[0] = parent_pid
    if sys.platform.startswith("linux"):
        try:
            import ctypes

            signal.signal(signal.SIGUSR1, _on_death_signal)
            pr_set_pdeathsig = 1
            ctypes.CDLL(None, use_errno=True).prctl(pr_set_pdeathsig, int(signal.SIGUSR1), 0, 0, 0)
        except (OSError, AttributeError, ValueError):  # no libc symbol, or not the main thread: poll only
            pass
    threading.Thread(target=_watch_parent, args=(parent_pid,), name="parent-watch", daemon=True).start()


def run_job(fn, task):
    """Run ``fn(task)`` in a pool worker (the pool's task wrapper): while it runs the worker does not
    exit on its launcher's death (the task stops first); an orphaned worker starts no task."""
    with _job:
        if _orphaned.is_set():
            os._exit(1)
        return fn(task)


def init_job_worker(threads=None, parent_pid=None) -> None:
    """Initializer of a pool worker: :func:`set_job_threads`, SIGINT and SIGTERM ignored between tasks,
    and :func:`watch_parent` (the worker ends when its launcher dies, even by SIGKILL).

    A task that can stop cleanly installs its own handlers while it runs (a seed writes a
    checkpoint); an idle worker must survive the signal, or the whole pool would break.
    """
    import signal

    set_job_threads(threads)
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, signal.SIG_IGN)
    _worker[0] = True
    watch_parent(parent_pid)


_worker = [False]


def is_pool_worker() -> bool:
    """True in a worker process (or MPI worker rank) of a :class:`task_pool`."""
    return _worker[0]


class task_pool:
    """The executor that runs independent tasks (the seeds of an ensemble), as a context manager.

    * Under an MPI launcher (``mpiexec -n P selfas-graph ensemble ...``, or
      ``mpiexec -n P python -m mpi4py.futures -m selfas_graph.cli.main ensemble ...``):
      an ``mpi4py.futures.MPICommExecutor`` on ``COMM_WORLD``. Rank 0 gets the executor
      and the other P - 1 ranks serve its tasks; on them the context gives ``None`` and
      ends when rank 0 leaves it. Each worker rank takes :func:`set_job_threads` threads.
    * Otherwise, with ``jobs > 1``: a ``concurrent.futures.ProcessPoolExecutor`` of
      ``jobs`` spawned processes, each with ``threads`` numba threads (default
      ``cores // jobs``).
    * With ``jobs == 1``: ``None`` executor and ``serial = True``: run the tasks in this
      process (the caller does), with ``threads`` numba threads if given (restored on exit).

    Attributes after entering: ``executor`` (or None), ``workers`` (count), ``mpi`` (bool),
    ``serial`` (bool: no executor, run here), ``threads`` (per local worker, None under MPI).
    """

    def __init__(self, jobs=1, threads=None):
        self.jobs = max(1, int(jobs))
        self._threads = threads
        self.executor, self.mpi, self.serial, self.threads, self.workers = None, False, False, None, 1
        self._cm = self._restore = None

    def __enter__(self):
        if world.size > 1:
            from mpi4py import MPI
            from mpi4py.futures import MPICommExecutor

            self.mpi = True
            self.workers = world.size - 1
            self._cm = MPICommExecutor(MPI.COMM_WORLD, root=0, initializer=init_job_worker)
            self.executor = self._cm.__enter__()
            return self
        if self.jobs == 1:
            self.serial = True
            if self._threads is not None:
                import numba

                self._restore = numba.get_num_threads()
                self.threads = set_job_threads(self._threads)
            return self
        import concurrent.futures
        import multiprocessing

        self.workers = self.jobs
        self.threads = threads_per_job(self.jobs) if self._threads is None else int(self._threads)
        self.executor = concurrent.futures.ProcessPoolExecutor(
            max_workers=self.jobs,
            mp_context=multiprocessing.get_context("spawn"),
            initializer=init_job_worker,
            initargs=(self.threads, os.getpid()),
        )
        return self

    def __exit__(self, *exc):
        if self._cm is not None:
            self._cm.__exit__(*exc)
            return False
        if self.executor is not None:
            self.executor.shutdown(wait=True, cancel_futures=True)
        if self._restore is not None:
            import numba

            numba.set_num_threads(self._restore)
        return False

    def submit(self, fn, task):
        """Hand ``fn(task)`` to a worker (:func:`run_job`); returns its future."""
        return self.executor.submit(run_job, fn, task)

    @property
    def is_worker(self) -> bool:
        """True on an MPI rank that served the tasks (it has nothing else to do)."""
        return self.mpi and self.executor is None
