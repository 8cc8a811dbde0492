"""Where a study's runs execute: a pool of local worker processes (replaced every few runs,
a run that kills its worker retried alone) or a dask cluster; results come back to the
driver, which alone writes records."""

from __future__ import annotations

import multiprocessing
import os
import sys
import time
from collections.abc import Callable, Iterable
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from typing import TYPE_CHECKING, Any

from .execute import RunFn, _now, engine_id, execute_batch, execute_run, usable_cpus

if TYPE_CHECKING:
    from .runner import _Progress
from .spec import RunSpec

__all__ = ["RUNS_PER_WORKER", "worker_pardiso_threads"]

_MAX_CRASHES = 2  # a run that kills its worker this many times, alone, is recorded as failed
#: runs a pool worker makes before it is replaced by a fresh process: JAX keeps every program
#: compiled for every mesh a process has seen, and one study process that had made 16
#: phase-diagram runs (sheets of different sizes) died in LLVM ("Cannot allocate memory",
#: then a segfault; 2026-12-03). A fresh worker loads its kernels from the disk cache.
RUNS_PER_WORKER = 8


def worker_pardiso_threads(workers: int, cpus: int | None = None) -> int:
    """PARDISO threads for each of ``workers`` processes sharing ``cpus`` cores (default: the
    usable cores): ``max(1, cpus // workers)``, so that the workers' threads never outnumber
    the cores. PARDISO's threads wait for each other at every step of a factorization; with
    more threads than cores they wait for threads that are not running. Measured: two
    five-rod runs (h = 0.3, s = 15 and 20) at once on 2 cores took 72.7 and 76.7 s with two
    PARDISO threads each, 56.6 and 62.1 s with one (docs/benchmarks.md)."""
    n = cpus if cpus is not None else (usable_cpus() or 1)
    return max(1, n // max(1, workers))


def _init_worker(path: list[str], pardiso_threads: int | None = None) -> None:
    """Give spawned workers the driver's import path (so 'module:function' runners resolve)
    and, unless the user chose one (``UNDULATE_PARDISO_THREADS``), their share of the cores
    as PARDISO's thread count (set before the engine loads MKL); JAX does not preallocate a
    GPU's memory in them."""
    for p in reversed(path):
        if p not in sys.path:
            sys.path.insert(0, p)
    if pardiso_threads is not None:
        os.environ.setdefault("UNDULATE_PARDISO_THREADS", str(pardiso_threads))
    # on a GPU, JAX takes 75 % of its memory up front per process: workers sharing one GPU
    # take what they use instead (no effect on a CPU)
    os.environ.setdefault("XLA_PYTHON_CLIENT_PREALLOCATE", "false")
    _die_with_parent()


def _die_with_parent() -> None:
    """On Linux, end this worker when the driver process ends, however it ends (a SIGKILL, a
    closed terminal): otherwise workers of a killed study ran on, orphaned, to the end of
    their runs (measured: two five-rod runs still computing 20 min after their driver was
    killed). Elsewhere the pool's own shutdown is all there is."""
    if not sys.platform.startswith("linux"):
        return
    import ctypes
    import signal

    parent = os.getppid()
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, int(signal.SIGKILL), 0, 0, 0)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        return
    if os.getppid() != parent:  # the driver died before the call above: go now
        os._exit(1)


def _run_pool(
    todo: list[list[RunSpec]],
    workers: int,
    run_fn: RunFn | str | None,
    artifacts: bool,
    artifact_dir: Callable[[RunSpec], str | None],
    finish: Callable[[RunSpec, dict[str, Any]], None],
    bar: _Progress,
    threads: int | None = None,
) -> None:
    """Bounded submission to a process pool: at most ``workers`` tasks in flight, a task being
    one run or a batch of runs (:func:`execute_batch`).

    Every ``RUNS_PER_WORKER x workers`` tasks the pool is drained and replaced by fresh
    processes. A worker that dies (a crash of the interpreter, not an exception: those are results)
    breaks the whole pool, and every task in flight then fails with it, so the culprit is not
    known. Those tasks are retried one at a time in a fresh pool (a *suspect* never shares the
    pool with another task); a task that kills its worker alone ``_MAX_CRASHES`` times is
    recorded as failed, and an innocent neighbour is never blamed. ``threads``: PARDISO
    threads per worker (default: the worker's share of the cores).
    """
    queue = list(reversed(todo))
    crashes: dict[str, int] = {}
    suspects: set[str] = set()

    def key(task: list[RunSpec]) -> str:
        return task[0].id

    while queue:
        # spawn, not fork: the engine uses JAX, which is multithreaded (fork can deadlock)
        pool = ProcessPoolExecutor(
            max_workers=workers, initializer=_init_worker,
            initargs=(list(sys.path), threads or worker_pardiso_threads(workers)),
            mp_context=multiprocessing.get_context("spawn"))
        inflight: dict[Future, list[RunSpec]] = {}
        broken = False
        # the pool is replaced after RUNS_PER_WORKER tasks per worker (drained first; not
        # max_tasks_per_child, which can deadlock on Python 3.11-3.13: cpython gh-115634)
        budget = RUNS_PER_WORKER * workers
        try:
            while queue or inflight:
                while queue and len(inflight) < workers and not broken and budget > 0:
                    alone = any(key(t) in suspects for t in inflight.values())
                    if alone or (inflight and key(queue[-1]) in suspects):
                        break  # a suspect runs alone
                    task = queue.pop()
                    try:
                        fut = pool.submit(execute_batch, run_fn, [r.case for r in task],
                                          [artifact_dir(r) for r in task], artifacts)
                    except BrokenProcessPool:
                        queue.append(task)
                        broken = True
                        break
                    inflight[fut] = task
                    budget -= 1
                bar.running = sum(len(t) for t in inflight.values())
                bar.update()
                if not inflight:
                    break
                done, _ = wait(inflight, return_when=FIRST_COMPLETED)
                for fut in done:
                    task = inflight.pop(fut)
                    k = key(task)
                    try:
                        results = fut.result()
                    except BrokenProcessPool:
                        broken = True
                        if k in suspects and not inflight and len(done) == 1:
                            crashes[k] = crashes.get(k, 0) + 1  # it died alone
                        suspects.add(k)
                        if crashes.get(k, 0) >= _MAX_CRASHES:
                            for r in task:
                                finish(r, _crash_result("worker process died "
                                                        "(BrokenProcessPool)"))
                        else:
                            queue.append(task)
                        continue
                    except Exception as err:  # e.g. unpicklable result
                        results = [_crash_result(f"{type(err).__name__}: {err}")] * len(task)
                    suspects.discard(k)
                    for r, res in zip(task, results, strict=True):
                        finish(r, res)
                if broken and not inflight:
                    break
        except BaseException:
            # Ctrl-C (or any error here): the runs in flight are lost either way; stop their
            # workers now, or the interpreter would wait for them at exit
            for proc in list(getattr(pool, "_processes", {}).values()):
                proc.terminate()
            pool.shutdown(wait=False, cancel_futures=True)
            raise
        pool.shutdown(wait=True)
        if not broken and budget > 0:
            break  # every task done (a spent budget goes round again with a fresh pool)


def _crash_result(error: str, local: bool = True) -> dict[str, Any]:
    now = _now()
    # a local worker that died ran this process's code: its engine and cores are ours (a
    # remote, dask, worker's are unknown)
    return {"status": "failed", "record": None, "error": error, "traceback": None,
            "started": None, "finished": now, "elapsed_s": None, "cpu_s": None, "host": None,
            "pid": None,
            "engine": engine_id() if local else None, "cpus": usable_cpus() if local else None}


def _run_dask(
    todo: Iterable[RunSpec],
    address: Any,
    run_fn: RunFn | str | None,
    artifacts: bool,
    artifact_dir: Callable[[RunSpec], str | None],
    finish: Callable[[RunSpec, dict[str, Any]], None],
    bar: _Progress,
) -> None:
    """Submit every run to a dask.distributed scheduler; write results as they complete."""
    from distributed import Client, as_completed

    todo = list(todo)
    if not todo:
        return
    own = not isinstance(address, Client)
    client = Client(address) if own else address
    try:
        futs = {}
        for r in todo:
            fut = client.submit(execute_run, run_fn, r.case, artifact_dir(r), artifacts,
                                key=f"undulate-run-{r.id}-{time.time_ns()}", pure=False)
            futs[fut] = r
        bar.running = len(futs)
        bar.update()
        try:
            for fut in as_completed(list(futs)):
                r = futs[fut]
                try:
                    res = fut.result()
                except Exception as err:  # KilledWorker, lost worker, ...
                    res = _crash_result(f"{type(err).__name__}: {err}", local=False)
                bar.running -= 1
                finish(r, res)
        except BaseException:
            client.cancel(list(futs))
            raise
    finally:
        if own:
            client.close()
