"""The one place where numba compilation flags are set.

Every kernel module imports its decorators from here, so that caching,
parallelism and fastmath are decided once for the package.

Full ``fastmath`` is off everywhere: the run loop checks forces for NaN and the
tests check conservation laws to round-off, both of which need IEEE handling
of NaN and inf. The all-pairs kernels use only the ``reassoc``, ``contract`` and
``arcp`` flags (``njit_parallel_sum``): the first two let LLVM vectorise the force
reductions, the third lets it keep a loop-invariant reciprocal (``1 / r*^3``,
``1 / R_D``) hoisted out of a pair loop instead of folding ``x * (1 / a)`` back into
a division per pair (``reassoc`` alone does that fold); none of them touches NaN/inf
semantics. Results differ from strict IEEE evaluation by round-off only (tests hold
the direct sum to 1e-12 relative of a strict reference).

No code path depends on the CPU: the kernels are plain loops that LLVM vectorises for
whatever numba compiles for (``NUMBA_CPU_NAME``; the host CPU by default), 4 doubles a
vector with AVX2, 8 with AVX-512. ``tools/bench_kernels.py --targets host haswell``
times the hot kernels for both; docs/performance.md has the figures.
"""
import functools
import hashlib
import os
import types
from pathlib import Path

# numba's OpenMP threading layer lets idle workers spin; with as many threads as
# cores the spinning workers compete with the Python thread that launches the
# next kernel. Measured on the 2-core machine: 7.8 ms per launch of a trivial
# parallel kernel with the default policy, 10 us with PASSIVE (56 us with
# numba's workqueue layer). Set before the OpenMP runtime starts; a user's own
# setting wins.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import numba  # noqa: E402

#: cache compiled kernels on disk so that a second CLI run starts in seconds
_COMMON = dict(cache=True, nogil=True, error_model="numpy")

#: name of the file, beside the cached kernels, that holds the digest of the sources they came from
DIGEST_FILE = "selfas_graph_kernel_sources.sha1"


def sources_digest(folder=None) -> str:
    """SHA-1 of every kernel module's source (names and bytes, in name order)."""
    folder = Path(__file__).resolve().parent if folder is None else Path(folder)
    h = hashlib.sha1()
    for f in sorted(folder.glob("*.py")):
        h.update(f.name.encode())
        h.update(f.read_bytes())
    return h.hexdigest()


def drop_stale_cache(cache_dir, digest) -> int:
    """Delete the cached kernels in ``cache_dir`` unless they were compiled from sources with ``digest``.

    numba checks a cached kernel only against the file that defines it, not against the laws it
    inlines from other modules (``laws.py``, ``expo.py``): after an update of those alone, the
    old machine code would be loaded silently. A digest of all kernel sources, kept beside the
    cache, catches that; on a mismatch every cached kernel of this package is dropped and
    compiled again. Returns the number of files deleted. Errors (a read-only or vanished
    folder, another process deleting at the same time) are ignored: numba then compiles afresh
    or caches elsewhere.
    """
    cache_dir = Path(cache_dir)
    stamp = cache_dir / DIGEST_FILE
    try:
        if stamp.read_text().strip() == digest:
            return 0
    except OSError:
        pass
    dropped = 0
    for f in list(cache_dir.glob("*.nbi")) + list(cache_dir.glob("*.nbc")):
        try:
            f.unlink()
            dropped += 1
        except OSError:
            pass
    try:
        cache_dir.mkdir(parents=True, exist_ok=True)
        stamp.write_text(digest + "\n")
    except OSError:
        pass
    return dropped


def _kernel_cache_dir():
    """The folder numba caches this package's kernels in (in the source tree, or user-wide if that
    is read-only, or under NUMBA_CACHE_DIR), as numba itself locates it for a kernel here."""
    probe = numba.njit(cache=True)(lambda: 0)
    return Path(probe._cache._cache_path)


try:
    drop_stale_cache(_kernel_cache_dir(), sources_digest())
except Exception:  # noqa: BLE001 - numba internals differ between versions; the check is a safeguard
    pass
_SUM_FLAGS = {"reassoc", "contract", "arcp"}

njit = numba.njit(fastmath=False, **_COMMON)
njit_parallel = numba.njit(parallel=True, fastmath=False, **_COMMON)
#: all-pairs reductions: vectorisable sums, NaN/inf kept (see module docstring)
njit_parallel_sum = numba.njit(parallel=True, fastmath=_SUM_FLAGS, **_COMMON)
#: scalar laws: always inlined into the loops that call them
inline = numba.njit(inline="always", fastmath=False, **_COMMON)
inline_sum = numba.njit(inline="always", fastmath=_SUM_FLAGS, **_COMMON)
prange = numba.prange

#: rows from which an O(n) kernel (:func:`njit_rows`) runs on all numba threads. Below it one
#: thread is faster: these kernels are memory-bound, and waking the passive OpenMP workers
#: costs more than the loop. Measured on the 2-core machine, in the run loop of the Fig. 2
#: scene (2400 tips), 78-85 us per call of ``bond_length_error`` on 2 threads against 3 us on
#: one; in a tight loop (workers awake) the two threads first win at about 50 000 rows, and
#: only compute-heavy loops (``electrode_walls``) gain much even at 2e5 rows.
PARALLEL_ROWS = 50_000


class _RowsKernel:
    """One O(n) kernel compiled twice, serial and parallel; the length of its first array picks."""

    def __init__(self, fn):
        self.py_func = fn
        self.parallel = numba.njit(parallel=True, fastmath=False, **_COMMON)(fn)
        # a renamed copy, so that the on-disk cache keeps the serial build apart from the parallel one
        twin = types.FunctionType(fn.__code__, fn.__globals__, fn.__name__ + "_serial", fn.__defaults__,
                                  fn.__closure__)
        twin.__qualname__ = fn.__qualname__ + "_serial"
        twin.__module__ = fn.__module__
        self.serial = numba.njit(parallel=False, fastmath=False, **_COMMON)(twin)
        functools.update_wrapper(self, fn)

    def __call__(self, first, *args):
        kernel = self.parallel if first.shape[0] >= PARALLEL_ROWS else self.serial
        return kernel(first, *args)


def njit_rows(fn):
    """Decorator for O(n) kernels called from Python: serial below :data:`PARALLEL_ROWS` rows of
    the first argument, parallel (``prange``) from there on. Both builds give the same numbers
    bit for bit, since no loop in these kernels reduces across rows except by max."""
    return _RowsKernel(fn)
#: iterations handed to a thread at a time in the next prange loop (0: equal static
#: blocks, numba's default); callable inside kernels, returns the previous value
set_parallel_chunksize = numba.set_parallel_chunksize
