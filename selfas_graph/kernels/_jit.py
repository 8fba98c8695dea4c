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
vector with AVX2, 8 with AVX-512. ``selfas-graph bench kernels --targets host haswell``
times the hot kernels for both; docs/performance.md has the figures.

Compiled kernels are cached on disk, keyed also by the digest of all kernel sources
(:class:`SourcesKeyedCache`, docs/model.md 'Assumptions and project choices', B27): a kernel
compiled before a law it inlines changed is never loaded. Importing the package deletes nothing.

Variants of one law or loop (float64 and float32, a multipole order) are written once, as a
factory: a Python function that takes the variant as a value, defines the kernel inside it,
closing over that value (numba freezes closed-over values and globals as constants when it
compiles), and returns it; each variant is built once, at import (``multipole.make_fields``,
``treewalk._make_cell_on_targets``). Their cache keys tell them apart by what they close over
(:class:`SourcesKeyedCache`).
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
# setting wins. The runtime reads it once, when numba starts its threads (the first
# parallel kernel, or numba.set_num_threads): started before this import, the workers
# spin (see _warn_if_spinning).
_USER_WAIT_POLICY = "OMP_WAIT_POLICY" in os.environ
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import numba  # noqa: E402
from numba.core.caching import FunctionCache  # noqa: E402
from numba.core.dispatcher import Dispatcher  # noqa: E402
from numba.core.serialize import dumps  # noqa: E402


def _warn_if_spinning():
    """Warn when numba's OpenMP threads were started before this module set ``OMP_WAIT_POLICY``.

    Then the runtime runs with its default policy: after every parallel kernel the idle workers
    spin for some milliseconds, on a core the serial part of the step (or another job) needs.
    Measured in the Fig. 2 scene late in the run on 2 threads (the late-state checkpoint of
    docs/performance.md): 6.1 ms of CPU and 6.6 ms of wall clock per step with the workers
    started first, 3.1 and 3.2 ms with them started after this import.
    """
    from numba.np.ufunc import parallel

    if _USER_WAIT_POLICY or not getattr(parallel, "_is_initialized", False):
        return
    if getattr(parallel, "_threading_layer", None) != "omp":
        return
    import warnings

    warnings.warn(
        "numba's OpenMP threads were started (numba.set_num_threads or a parallel kernel) before "
        "selfas_graph was imported, without OMP_WAIT_POLICY in the environment: its idle threads "
        "spin between parallel kernels and take a core. Import selfas_graph first, or set "
        "OMP_WAIT_POLICY=PASSIVE in the environment.",
        RuntimeWarning,
        stacklevel=2,
    )


_warn_if_spinning()

#: cache compiled kernels on disk so that a second CLI run starts in seconds
_COMMON = dict(cache=True, nogil=True, error_model="numpy")


def sources_digest(folder=None) -> str:
    """SHA-1 of every kernel module's source (names and bytes, in name order)."""
    folder = Path(__file__).resolve().parent if folder is None else Path(folder)
    h = hashlib.sha1()
    for f in sorted(folder.glob("*.py")):
        h.update(f.name.encode())
        h.update(f.read_bytes())
    return h.hexdigest()


#: digest of the kernel sources this process compiles from; part of every cached kernel's index key
SOURCES_DIGEST = sources_digest()


def _stable(value):
    """``value`` with every function in it (a kernel or a plain one) replaced by its module, its
    qualified name and the values it closes over: what a variant's cache key holds of it."""
    fn = value.py_func if isinstance(value, Dispatcher) else value
    if isinstance(fn, types.FunctionType):
        return ("function", fn.__module__, fn.__qualname__, closure_values(fn))
    return value


def closure_values(fn):
    """The values a function closes over, functions among them named (:func:`_stable`), as a tuple."""
    return tuple(_stable(cell.cell_contents) for cell in fn.__closure__ or ())


class SourcesKeyedCache(FunctionCache):
    """numba's on-disk cache of one kernel, with :data:`SOURCES_DIGEST` in the index key.

    numba keys a cached kernel by its signature, the CPU and the bytecode of the function itself,
    and drops it when the file that defines it changes; it does not see the laws the kernel
    inlines from other modules (``laws.py``, ``expo.py``). With the digest of all kernel sources
    in the key, machine code compiled from other sources never matches: it is not loaded, the
    kernel is compiled afresh and saved beside it. Nothing is deleted (numba itself drops an
    index when the kernel's own file changes; ``NUMBA_CACHE_DIR`` moves the cache, and deleting
    that folder, or the ``__pycache__`` folder of the kernels, clears it).

    The variants a factory builds (one law or loop for float64 and float32, or per multipole
    order: a function defined inside the factory, closing over the variant) share their bytecode
    and their index file; the key tells them apart by the values they close over, as numba's does.
    numba pickles those values, and a pickled kernel carries an identifier drawn afresh in every
    process: a variant that closes over another kernel would never be found again, and each
    process would add an entry to its index. Here a kernel among the closed-over values counts by
    its module, its qualified name and its own closed-over values (:func:`closure_values`), which
    with :data:`SOURCES_DIGEST` name the same code in every process.
    """

    def _index_key(self, sig, codegen):
        code = hashlib.sha256(self._py_func.__code__.co_code).hexdigest()
        closure = hashlib.sha256(dumps(closure_values(self._py_func))).hexdigest()
        return (sig, codegen.magic_tuple(), (code, closure), SOURCES_DIGEST)


def _jit(**flags):
    """``numba.njit(**flags)`` with the package's common flags and a :class:`SourcesKeyedCache`."""
    decorate = numba.njit(**flags, **_COMMON)

    def wrap(fn):
        kernel = decorate(fn)
        if isinstance(kernel, Dispatcher):  # with NUMBA_DISABLE_JIT=1 the function stays Python
            kernel._cache = SourcesKeyedCache(kernel.py_func)
        return kernel

    return wrap


_SUM_FLAGS = {"reassoc", "contract", "arcp"}

njit = _jit(fastmath=False)
njit_parallel = _jit(parallel=True, fastmath=False)
#: all-pairs reductions: vectorisable sums, NaN/inf kept (see module docstring)
njit_parallel_sum = _jit(parallel=True, fastmath=_SUM_FLAGS)
#: a loop of a kernel kept as a function of its own (not inlined): the vector code LLVM makes of it
#: then does not depend on the kernel around it
njit_sum = _jit(fastmath=_SUM_FLAGS)
#: scalar laws: always inlined into the loops that call them
inline = _jit(inline="always", fastmath=False)
inline_sum = _jit(inline="always", fastmath=_SUM_FLAGS)
prange = numba.prange

#: rows from which an O(n) kernel (:func:`njit_rows`) runs on all numba threads. Below it one
#: thread is faster: these kernels are memory-bound, and waking the passive OpenMP workers
#: costs more than the loop. Measured on the 2-core machine, in the run loop of the Fig. 2
#: scene (2400 tips), 78-85 us per call of ``bond_length_error`` on 2 threads against 3 us on
#: one; in a tight loop (workers awake) the two threads first win at about 50 000 rows, and
#: only compute-heavy loops (``electrode_walls``) gain much even at 2e5 rows.
PARALLEL_ROWS = 50_000


class _RowsKernel:
    """One O(n) kernel compiled twice, serial and parallel; the length of its first array (of the
    first array of a tuple) picks."""

    def __init__(self, fn):
        self.py_func = fn
        self.parallel = _jit(parallel=True, fastmath=False)(fn)
        # a renamed copy, so that the on-disk cache keeps the serial build apart from the parallel one
        twin = types.FunctionType(fn.__code__, fn.__globals__, fn.__name__ + "_serial", fn.__defaults__, fn.__closure__)
        twin.__qualname__ = fn.__qualname__ + "_serial"
        twin.__module__ = fn.__module__
        self.serial = _jit(parallel=False, fastmath=False)(twin)
        functools.update_wrapper(self, fn)

    def __call__(self, first, *args):
        rows = (first[0] if type(first) is tuple else first).shape[0]
        kernel = self.parallel if rows >= PARALLEL_ROWS else self.serial
        return kernel(first, *args)


def njit_rows(fn):
    """Decorator for O(n) kernels called from Python: serial below :data:`PARALLEL_ROWS` rows of
    the first argument (of its first array, if a tuple), parallel (``prange``) from there on. Both
    builds give the same numbers bit for bit, since no loop in these kernels reduces across rows
    except by max (and by counting NaN)."""
    return _RowsKernel(fn)


#: iterations handed to a thread at a time in the next prange loop (0: equal static
#: blocks, numba's default); callable inside kernels, returns the previous value
set_parallel_chunksize = numba.set_parallel_chunksize
