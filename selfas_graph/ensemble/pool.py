"""The runner of tasks on a :class:`~selfas_graph.parallel.task_pool`: handed out one per idle worker,
wound down alike on a stopped seed, Ctrl-C or SIGTERM."""

from __future__ import annotations

import concurrent.futures
import signal
from typing import Callable

from ..lifecycle import StopOnSignal


def run_tasks(
    fn: Callable[[dict], dict], tasks: list, pool, report=None, stop_statuses=("interrupted", "io_error")
) -> list:
    """Run ``fn(task)`` for every task on ``pool`` (a :class:`~selfas_graph.parallel.task_pool`); results in task order.

    Tasks are handed out in order, one per idle worker (none waits in a queue), and
    ``report(result)`` is called as each ends. In a serial pool they run here, one after
    the other. Once a result's ``status`` is in ``stop_statuses`` (a seed stopped by a
    signal), or on Ctrl-C or SIGTERM here, no further task starts; the local workers get
    the signal received here (SIGTERM after a seed's I/O error, so that the others stop while there is
    room; a running seed then stops after its step with a checkpoint and names the signal in its result's
    ``signum``) and the running tasks' results are collected. Tasks never started are None in the returned list.
    """
    results = [None] * len(tasks)
    report = report or (lambda r: None)
    if pool.serial:
        for i, task in enumerate(tasks):
            results[i] = fn(task)
            report(results[i])
            if results[i].get("status") in stop_statuses:
                break
        return results
    waiting, running, stopping = list(range(len(tasks)))[::-1], {}, False

    def collect(futures):
        nonlocal stopping
        for fut in futures:
            i = running.pop(fut)
            results[i] = _result(fut)
            report(results[i])
            if results[i].get("status") == "io_error" and not stopping and not pool.mpi:
                _terminate_workers()  # the other running seeds stop with a checkpoint while there is room
            stopping |= results[i].get("status") in stop_statuses

    # Ctrl-C and SIGTERM wind the pool down alike, and a repeat of either is ignored from the first on
    with StopOnSignal(signals=(signal.SIGTERM, signal.SIGINT), interrupt=True) as received:
        try:
            while waiting or running:
                while waiting and not stopping and len(running) < pool.workers:
                    i = waiting.pop()
                    running[pool.submit(fn, tasks[i])] = i
                if not running:
                    break
                done, _ = concurrent.futures.wait(list(running), return_when=concurrent.futures.FIRST_COMPLETED)
                collect(done)
        except KeyboardInterrupt:
            stopping = True
            if not pool.mpi:
                _terminate_workers(received.signum or signal.SIGINT)
            collect(list(running))
    return results


def _terminate_workers(signum=signal.SIGTERM):
    """Send ``signum`` to the local workers: a running seed stops after its step with a checkpoint."""
    import multiprocessing
    import os

    for child in multiprocessing.active_children():
        try:
            os.kill(child.pid, signum)
        except (ProcessLookupError, TypeError):  # ended meanwhile (a pid of None: never started)
            pass


def _result(fut):
    try:
        return fut.result()
    except Exception as exc:  # noqa: BLE001 - a worker process died (killed, out of memory): reported
        return {"status": "error", "message": f"{type(exc).__name__}: {exc}"}
