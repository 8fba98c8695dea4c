"""Threads that share the work of one compiled call, phase after phase (docs/performance.md 'Fast steps
on both cores').

numba's ``prange`` forks the threads and joins them at every parallel loop: with passive waiting a fork
costs tens of microseconds, more than most loops of a fast step take. Here the threads are forked once
per call: one ``prange`` iteration per thread, each running :func:`join`. The first to arrive leads: it
runs the call's serial control flow and hands out the work in phases, a phase being a number of tasks
(a block of rods, a group of channels); every thread, the leader too, claims the tasks of the current
phase one at a time and runs them, and the leader waits until all are done before it reads their
results and opens the next phase. The others spin between phases, and leave when the leader closes
the call.

No thread waits for another to arrive, only for tasks claimed to be finished: a call runs alike on one
thread (numba without threads, or ``NUMBA_DISABLE_JIT=1``, where ``prange`` is ``range`` and the later
iterations find the call closed). Which thread runs a task changes nothing of what it computes, so the
numbers do not depend on the thread count.

The control block ``ctl`` (int64, zeroed by the caller): :data:`JOINED`, :data:`OPENED` (the number of
the phase open now, 0 before the first), :data:`CLOSED`; from :data:`ROW` on one row of :data:`WIDTH`
per phase (phase ``p``, from 1, at ``ROW + WIDTH p``): tasks claimed, tasks done, the number of tasks, then
the phase's own words (what the caller's task function reads). Claims and the phase counter are
atomic read-modify-writes (sequentially consistent); a task reads its phase's words after its claim
succeeded, when they can no longer change.
"""

import time

import numba
from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

from ._jit import njit

JOINED, OPENED, CLOSED = 0, 1, 2
#: the first row of the phases, and the words of a row (64 bytes)
ROW, WIDTH = 8, 8
#: the words of a row before the phase's own: claimed, done, tasks
CLAIMED, DONE, TASKS, WORDS = 0, 1, 2, 3


@njit
def control_size(phases):
    """Length of a control block for ``phases`` phases."""
    return ROW + WIDTH * (phases + 1)


def _element_pointer(context, builder, arrty, arr, i):
    a = context.make_array(arrty)(context, builder, arr)
    return cgutils.get_item_pointer(context, builder, arrty, a, [i], wraparound=False)


@intrinsic
def _fetch_add(typingctx, arr, i, value):
    """``old = arr[i]; arr[i] += value; return old`` as one atomic operation (sequentially consistent)."""
    if not (isinstance(arr, types.Array) and arr.dtype == types.int64 and arr.ndim == 1):
        return None
    sig = types.int64(arr, types.intp, types.int64)

    def codegen(context, builder, signature, args):
        ptr = _element_pointer(context, builder, signature.args[0], args[0], args[1])
        return builder.atomic_rmw("add", ptr, args[2], "seq_cst")

    return sig, codegen


@intrinsic
def _load(typingctx, arr, i):
    """``arr[i]`` read atomically (acquire): a spin loop on it sees another thread's writes."""
    if not (isinstance(arr, types.Array) and arr.dtype == types.int64 and arr.ndim == 1):
        return None
    sig = types.int64(arr, types.intp)

    def codegen(context, builder, signature, args):
        ptr = _element_pointer(context, builder, signature.args[0], args[0], args[1])
        return builder.load_atomic(ptr, "acquire", 8)

    return sig, codegen


@intrinsic
def _ticks(typingctx):
    """The CPU's cycle counter (``llvm.readcyclecounter``: ``rdtsc`` on x86-64), for timing the phases of
    a call (``steps.py``, docs/performance.md 'Fast steps on both cores'); only x86-64 is known to give it
    to user code (``bench profile --team --phases`` checks)."""
    sig = types.int64()

    def codegen(context, builder, signature, args):
        fn = builder.module.declare_intrinsic("llvm.readcyclecounter", fnty=ir.FunctionType(ir.IntType(64), []))
        return builder.call(fn, [])

    return sig, codegen


if numba.config.DISABLE_JIT:  # plain Python: one thread, nothing to make atomic

    def fetch_add(arr, i, value):
        old = arr[i]
        arr[i] += value
        return old

    def load(arr, i):
        return arr[i]

    def ticks():
        return time.perf_counter_ns()

else:
    fetch_add = _fetch_add
    load = _load
    ticks = _ticks


@njit
def read_ticks():
    """:func:`ticks` from Python (to measure the counter's rate)."""
    return ticks()


@njit
def open_phase(ctl, p, tasks, w0, w1, w2, w3):
    """Open phase ``p`` (the one after the phase open now) with ``tasks`` tasks and its four words."""
    r = ROW + WIDTH * p
    ctl[r + TASKS] = tasks
    ctl[r + WORDS] = w0
    ctl[r + WORDS + 1] = w1
    ctl[r + WORDS + 2] = w2
    ctl[r + WORDS + 3] = w3
    fetch_add(ctl, OPENED, 1)  # after the words: a thread that sees the phase open sees them


@njit
def claim(ctl, p):
    """A task of phase ``p`` not yet claimed (its number), or -1 when all are."""
    r = ROW + WIDTH * p
    j = fetch_add(ctl, r + CLAIMED, 1)
    return j if j < ctl[r + TASKS] else -1


@njit
def finish(ctl, p):
    """Count a task of phase ``p`` done (after its results are written)."""
    fetch_add(ctl, ROW + WIDTH * p + DONE, 1)


@njit
def wait(ctl, p):
    """Spin until every task of phase ``p`` is done."""
    r = ROW + WIDTH * p
    tasks = ctl[r + TASKS]
    while load(ctl, r + DONE) < tasks:
        pass


@njit
def close(ctl):
    """Close the call: the threads that wait for a phase leave."""
    fetch_add(ctl, CLOSED, 1)
