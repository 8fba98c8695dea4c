"""The one place where numba compilation flags are set.

Every kernel module imports its decorators from here, so that caching,
parallelism and fastmath are decided once for the package.

Full ``fastmath`` is off everywhere: the run loop checks forces for NaN and the
tests check conservation laws to round-off, both of which need IEEE handling
of NaN and inf. The all-pairs kernels use only the ``reassoc`` and ``contract``
flags (``njit_parallel_sum``): they let LLVM vectorise the force reductions
and keep NaN/inf semantics. Measured on the 2-core machine for the tip-tip
direct sum at 1200 rods: 9.8 ms strict IEEE, 1.7 ms with these two flags and
structure-of-arrays input (3.4e9 tip pairs/s); the result differs from the
strict one by at most 4e-15 relative (tests hold it to 1e-12).
"""
import functools
import os
import types

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
_SUM_FLAGS = {"reassoc", "contract"}

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
