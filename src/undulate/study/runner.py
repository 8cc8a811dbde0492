"""Run a study: skip finished runs, execute the rest locally or on dask, write records atomically.

The run function is injectable: ``run_fn(case, out, artifacts=...) -> dict`` with the signature
of :func:`undulate.api.run_case` (the default, imported lazily inside the worker). It may also be
given as a ``"module:function"`` string, resolved in the worker; the environment variable
``UNDULATE_STUDY_RUNNER`` sets that string when no run function is passed.

Records are written by the driver process only (dask workers need no shared filesystem for
results) via :func:`undulate.study.storage.write_record`, atomically. Killing the driver loses at
most the runs that were in flight; re-running the same command resumes.
"""

from __future__ import annotations

import functools
import importlib
import json
import multiprocessing
import os
import shutil
import socket
import sys
import time
import traceback
from collections.abc import Callable, Iterable
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from .. import __version__
from .named_setups import describe_setup
from .spec import RunSpec, Study, StudyError, coarse_first
from .storage import (
    RECORD_SCHEMA,
    jsonable,
    read_study,
    remove_stale_tmp,
    scan_runs,
    write_record,
    write_study,
    write_table,
)

__all__ = ["RunFn", "RunSummary", "run_study", "execute_run", "execute_batch", "batch_runs",
           "resolve_runner", "RUNNER_ENV"]

RunFn = Callable[..., dict]
RUNNER_ENV = "UNDULATE_STUDY_RUNNER"
_MAX_CRASHES = 2  # a run that kills its worker this many times, alone, is recorded as failed
#: runs a pool worker makes before it is replaced by a fresh process: JAX keeps every program
#: compiled for every mesh a process has seen, and one study process that had made 16
#: phase-diagram runs (sheets of different sizes) died in LLVM ("Cannot allocate memory",
#: then a segfault; 2026-12-03). A fresh worker loads its kernels from the disk cache.
RUNS_PER_WORKER = 8


def resolve_runner(runner: RunFn | str | None) -> RunFn:
    """The run function: a callable, a ``"module:function"`` string, or None for run_case."""
    if runner is None:
        try:
            from undulate.api import run_case  # lazy: the engine is heavy and optional here
        except ImportError as err:
            raise StudyError(f"runner: cannot import undulate.api.run_case: {err}") from None
        return run_case
    if callable(runner):
        return runner
    mod_name, sep, attr = str(runner).partition(":")
    if not sep or not mod_name or not attr:
        raise StudyError(f"runner: expected 'module:function', got {runner!r}")
    try:
        obj: Any = importlib.import_module(mod_name)
        for part in attr.split("."):
            obj = getattr(obj, part)
    except (ImportError, AttributeError) as err:
        raise StudyError(f"runner: cannot import {runner!r}: {err}") from None
    if not callable(obj):
        raise StudyError(f"runner: {runner!r} is not callable")
    return obj


def _now() -> str:
    return datetime.now(UTC).isoformat(timespec="milliseconds")


def _tb_summary(err: BaseException, limit: int = 12) -> str:
    lines = traceback.format_exception(type(err), err, err.__traceback__)
    text = "".join(lines).rstrip().splitlines()
    return "\n".join(text[-limit:])


def execute_run(
    runner: RunFn | str | None,
    case_dict: dict[str, Any],
    out: str | None,
    artifacts: bool = True,
) -> dict[str, Any]:
    """Run one case in the current process; never raises for a failing run.

    Returns ``{"status", "record", "error", "traceback", "case_resolved", "started",
    "finished", "elapsed_s", "cpu_s", "host", "pid", "engine", "cpus"}``. ``cpu_s`` is the CPU
    time of this process (all its threads) during the run: unlike the wall time it does not
    grow while the machine is busy with something else or the worker is stopped. This is
    what worker processes / dask tasks execute.
    """
    started = _now()
    t0 = time.perf_counter()
    c0 = time.process_time()
    result: dict[str, Any] = {"record": None, "error": None, "traceback": None}
    try:
        from undulate.model import case_from_dict

        fn = resolve_runner(runner)
        case = case_from_dict(case_dict)
        # every field, defaults included: a record stays readable when a default changes
        result["case_resolved"] = case.model_dump(mode="json")
        out_path = Path(out) if (out is not None and artifacts) else None
        if out_path is not None:
            # artifacts of an earlier attempt of this run (its record is being replaced) go:
            # run_case writes the new ones atomically into the then empty folder
            if out_path.is_dir():
                shutil.rmtree(out_path)
            out_path.mkdir(parents=True, exist_ok=True)
        record = fn(case, out_path, artifacts=artifacts)
        if not isinstance(record, dict):
            raise TypeError(f"run function returned {type(record).__name__}, expected dict")
        result["record"] = jsonable(record)
        result["status"] = "ok"
    except Exception as err:  # a failed run is data, not a crash of the study
        result["status"] = "failed"
        result["error"] = f"{type(err).__name__}: {err}"
        result["traceback"] = _tb_summary(err)
    result.update(
        started=started,
        finished=_now(),
        elapsed_s=round(time.perf_counter() - t0, 6),
        cpu_s=round(time.process_time() - c0, 6),
        host=socket.gethostname(),
        pid=os.getpid(),
        engine=engine_id(),
        cpus=usable_cpus(),
    )
    return result


#: case fields that change no mesh, clamp or element group, only element parameters, the
#: start imperfection or a run's own solver settings: runs that differ only in these share a
#: topology and can be released as one batch (``run_study(batch=...)``)
BATCHABLE_FIELDS = (
    ("name",), ("rods", "h"), ("rods", "E_B"), ("rods", "nu_B"), ("rods", "rho_B"),
    ("fabric", "rho"), ("imperfection", "seed"), ("imperfection", "amplitude"),
    ("imperfection", "correlation"), ("solver",), ("dynamics",), ("mode",),
    ("release", "steps"), ("release", "adaptive"), ("release", "min_step_fraction"),
    ("release", "max_step_factor"), ("release", "onset_substeps"),
    ("release", "snap_iterations"), ("release", "snap_resolution"),
)


def topology_key(case_dict: dict[str, Any]) -> str:
    """A key equal for cases that share mesh, clamps and element groups (the resolved case
    without :data:`BATCHABLE_FIELDS`); a case that does not parse gets a key of its own."""
    try:
        from undulate.model import case_from_dict

        full = case_from_dict(case_dict).model_dump(mode="json")
    except Exception:  # noqa: BLE001 - the run reports its own error when it is executed
        return f"invalid:{id(case_dict)}"
    for path in BATCHABLE_FIELDS:
        node: Any = full
        for part in path[:-1]:
            node = node.get(part, {})
        node.pop(path[-1], None)
    return json.dumps(full, sort_keys=True)


def batch_runs(runs: list[RunSpec], size: int) -> list[list[RunSpec]]:
    """``runs`` cut into batches of at most ``size`` runs that share a topology (in the order
    of their first run); ``size`` 1: one run per batch."""
    if size <= 1:
        return [[r] for r in runs]
    groups: dict[str, list[RunSpec]] = {}
    for r in runs:
        groups.setdefault(topology_key(r.case), []).append(r)
    out = []
    for members in groups.values():
        out.extend(members[k : k + size] for k in range(0, len(members), size))
    return sorted(out, key=lambda b: runs.index(b[0]))


def execute_batch(
    runner: RunFn | str | None,
    case_dicts: list[dict[str, Any]],
    outs: list[str | None],
    artifacts: bool = True,
) -> list[dict[str, Any]]:
    """Run cases that share a topology together (:func:`undulate.api.run_cases`, the engine's
    batched release) in the current process; one result per case, as :func:`execute_run`
    gives (``elapsed_s``, ``cpu_s``: the batch's wall and CPU time shared equally; ``batch``:
    its size). A
    custom runner, a single case, or cases that turn out not to share a mesh run one by one.
    """
    if runner is not None or len(case_dicts) <= 1:
        return [execute_run(runner, c, o, artifacts) for c, o in zip(case_dicts, outs,
                                                                    strict=True)]
    started = _now()
    t0 = time.perf_counter()
    c0 = time.process_time()
    from undulate.api import run_cases
    from undulate.model import case_from_dict

    results: list[dict[str, Any]] = [{"record": None, "error": None, "traceback": None}
                                     for _ in case_dicts]
    todo: list[int] = []
    cases, paths = [], []
    for k, (cd, o) in enumerate(zip(case_dicts, outs, strict=True)):
        try:
            case = case_from_dict(cd)
        except Exception as err:  # noqa: BLE001 - reported for this run
            results[k].update(status="failed", error=f"{type(err).__name__}: {err}",
                              traceback=_tb_summary(err))
            continue
        results[k]["case_resolved"] = case.model_dump(mode="json")
        out_path = Path(o) if (o is not None and artifacts) else None
        if out_path is not None:
            if out_path.is_dir():
                shutil.rmtree(out_path)
            out_path.mkdir(parents=True, exist_ok=True)
        todo.append(k)
        cases.append(case)
        paths.append(out_path)
    recs = run_cases(cases, paths, artifacts) if cases else []
    if recs and all(isinstance(r, ValueError) and str(r).startswith("batch of runs:")
                    for r in recs):
        # not one topology after all (a field outside BATCHABLE_FIELDS that changes nothing
        # of the mesh would only cost the batching): run them one by one
        return [execute_run(runner, c, o, artifacts) for c, o in zip(case_dicts, outs,
                                                                    strict=True)]
    for k, rec in zip(todo, recs, strict=True):
        if isinstance(rec, Exception):
            results[k].update(status="failed", error=f"{type(rec).__name__}: {rec}",
                              traceback=_tb_summary(rec))
        else:
            results[k].update(status="ok", record=jsonable(rec))
    wall = time.perf_counter() - t0
    cpu = time.process_time() - c0
    for res in results:
        res.update(started=started, finished=_now(), elapsed_s=round(wall / len(results), 6),
                   cpu_s=round(cpu / len(results), 6),
                   batch=len(results), host=socket.gethostname(), pid=os.getpid(),
                   engine=engine_id(), cpus=usable_cpus())
    return results


#: the packages whose code decides a run's numbers (not the interfaces, studies, figures)
ENGINE_PARTS = ("mechanics", "mesh", "model", "solve", "analysis")


@functools.cache
def engine_id() -> str | None:
    """A short digest of what decides a run's numbers: the source of undulate's engine
    (:data:`ENGINE_PARTS`), the JAX version, which sparse solvers are installed and PARDISO's
    thread count (``UNDULATE_PARDISO_THREADS``). The same for every clone of one commit on the
    same installation; an edit of the web page or the CLI does not change it. Stored in each
    run's record, so a table that grew over several sittings says which runs came from the
    same engine. None if it cannot be computed (never raises)."""
    try:
        import hashlib

        from ..mechanics.compiled import _source_digest
        from ..solve.linear import _qdldl_available, pardiso_available, pardiso_threads

        solvers = (f"pardiso {pardiso_available()} threads {pardiso_threads()} qdldl "
                   f"{_qdldl_available()}")
        both = f"{_source_digest(tuple(ENGINE_PARTS))} {solvers}"
        return hashlib.sha256(both.encode()).hexdigest()[:12]
    except Exception:  # noqa: BLE001 (a run's record must not fail for its label)
        return None


def usable_cpus() -> int | None:
    """Cores this process may run on (its affinity, where the system tells), else all."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count()


@dataclass
class RunSummary:
    """What :func:`run_study` did."""

    total: int
    skipped_ok: int = 0
    skipped_failed: int = 0
    ran: int = 0
    ok: int = 0
    failed: int = 0
    interrupted: bool = False
    invalid_files: list[str] = field(default_factory=list)
    wall_s: float = 0.0
    table: Path | None = None

    @property
    def pending(self) -> int:
        """Runs of the study still without a record (or skipped failures)."""
        return self.total - self.skipped_ok - self.skipped_failed - self.ran


class _Progress:
    """Rich progress bar (done / running / failed, ETA) on a terminal; otherwise (a log file, a
    batch job) one plain line on stderr per finished run."""

    def __init__(self, total: int, done0: int, enabled: bool, console: Any = None) -> None:
        self.ok = 0
        self.failed = 0
        self.running = 0
        self._bar = None
        self._lines = False
        self._total, self._done = total, done0
        self._t0 = time.perf_counter()
        if not enabled:
            return
        from rich.console import Console
        from rich.progress import (
            BarColumn,
            MofNCompleteColumn,
            Progress,
            TextColumn,
            TimeElapsedColumn,
            TimeRemainingColumn,
        )

        console = console or Console(stderr=True)
        if not console.is_terminal:
            self._lines = True
            return
        self._bar = Progress(
            TextColumn("[bold]study"),
            BarColumn(),
            MofNCompleteColumn(),
            TextColumn("ok [green]{task.fields[ok]}[/] failed [red]{task.fields[failed]}[/] "
                       "running [cyan]{task.fields[running]}[/]"),
            TimeElapsedColumn(),
            TextColumn("ETA"),
            TimeRemainingColumn(),
            console=console,
        )
        self._task = self._bar.add_task("study", total=total, completed=done0, ok=0, failed=0,
                                        running=0)
        self._bar.start()

    def update(self, *, advance: int = 0) -> None:
        if self._bar is not None:
            self._bar.update(self._task, advance=advance, ok=self.ok, failed=self.failed,
                             running=self.running)
        elif self._lines and advance:
            self._done += advance
            elapsed = time.perf_counter() - self._t0
            ran = self.ok + self.failed
            left = self._total - self._done
            eta = f"{elapsed / ran * left / 60:.1f} min" if ran else "?"
            print(f"study: {self._done}/{self._total} done (this sitting: ok {self.ok}, failed "
                  f"{self.failed}), {elapsed / 60:.1f} min elapsed, ETA {eta}",
                  file=sys.stderr, flush=True)

    def close(self) -> None:
        if self._bar is not None:
            self._bar.stop()


def _check_study_dir(out: Path, study: Study) -> None:
    old = read_study(out)
    if old is None:
        return
    if old.get("name") != study.name or bool(old.get("quick")) != study.quick:
        raise StudyError(
            f"{out} already holds study {old.get('name')!r} (quick={bool(old.get('quick'))}); "
            f"use another --out for {study.name!r} (quick={study.quick})"
        )
    before = (old.get("definition") or {}).get("setup") or {}
    now = study.definition.get("setup") or {}
    if before != now:
        raise StudyError(
            f"{out} already holds study {study.name!r} on the set-up {describe_setup(before)}; "
            f"use another --out for the set-up {describe_setup(now)}, or resume that one with "
            "the same --setup/--set (bare: the engine's defaults)"
        )


def run_study(
    study: Study,
    out: str | Path,
    *,
    run_fn: RunFn | str | None = None,
    workers: int | None = None,
    dask_address: str | None = None,
    retry_failed: bool = False,
    artifacts: bool = True,
    progress: bool = True,
    console: Any = None,
    write_results: bool = True,
    batch: int = 1,
) -> RunSummary:
    """Run every run of ``study`` that has no record in ``out`` yet (plus failures if asked).

    ``workers``: local worker processes (default ``os.cpu_count()``), each replaced after
    :data:`RUNS_PER_WORKER` runs. With 1, the engine (``run_fn`` None or a name) still runs
    in one worker process, so that a crash cannot end the study; a function passed as
    ``run_fn`` runs in this process.
    ``dask_address``: a dask.distributed scheduler address (or a ``Client``/``LocalCluster``
    object); runs are submitted as tasks, results come back to this process which writes them.
    ``artifacts``: pass ``DIR/artifacts/<id>`` as ``out`` to the run function, else None.
    ``batch``: with the engine's runner, release up to this many runs that share a topology
    (:func:`batch_runs`) together in one worker (:func:`execute_batch`): their evaluations
    are batched across runs, each run ends in its single-run state. Each worker then gives
    its PARDISO one thread (the batch's runs factor side by side).
    A ``KeyboardInterrupt`` stops submitting, keeps every finished record and re-raises.
    """
    if batch > 1 and dask_address is not None:
        raise StudyError("batch: runs are batched in local workers only; leave out --batch "
                         "(or --dask)")
    if batch < 1:
        raise StudyError(f"batch: must be at least 1 (got {batch})")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "runs").mkdir(exist_ok=True)
    _check_study_dir(out, study)
    if run_fn is None:
        run_fn = os.environ.get(RUNNER_ENV) or None
    if not callable(run_fn):
        resolve_runner(run_fn)  # fail fast (StudyError) rather than record every run as failed
    meta = study.meta()
    meta["runner"] = run_fn if isinstance(run_fn, str) or run_fn is None else (
        f"{getattr(run_fn, '__module__', '?')}:{getattr(run_fn, '__qualname__', '?')}"
    )
    write_study(out, meta)
    remove_stale_tmp(out)

    t_start = time.perf_counter()
    scan = scan_runs(out)
    summary = RunSummary(total=len(study.runs), invalid_files=[str(p) for p in scan.invalid])
    todo: list[RunSpec] = []
    attempts: dict[str, int] = {}
    for r in coarse_first(study.runs):
        prev = scan.records.get(r.id)
        if prev is None:
            todo.append(r)
            attempts[r.id] = 1
        elif prev["status"] == "ok":
            summary.skipped_ok += 1
        elif retry_failed:
            todo.append(r)
            attempts[r.id] = int(prev.get("attempt") or 1) + 1
        else:
            summary.skipped_failed += 1

    def artifact_dir(r: RunSpec) -> str | None:
        return str(out / "artifacts" / r.id) if artifacts else None

    bar = _Progress(len(study.runs), summary.skipped_ok + summary.skipped_failed,
                    progress, console)

    def finish(r: RunSpec, res: dict[str, Any]) -> None:
        rec = {
            "schema": RECORD_SCHEMA,
            "id": r.id,
            "study": study.name,
            "status": res["status"],
            "params": r.params,
            "seed": r.seed,
            "attempt": attempts[r.id],
            "case": r.case,
            "case_resolved": res.get("case_resolved"),
            "version": __version__,
            "record": res.get("record"),
            "error": res.get("error"),
            "traceback": res.get("traceback"),
            "started": res.get("started"),
            "finished": res.get("finished"),
            "elapsed_s": res.get("elapsed_s"),
            "cpu_s": res.get("cpu_s"),
            "host": res.get("host"),
            "pid": res.get("pid"),
            "engine": res.get("engine"),
            "cpus": res.get("cpus"),
            "batch": res.get("batch"),
            "artifacts": (f"artifacts/{r.id}" if artifacts else None),
        }
        write_record(out, rec)
        summary.ran += 1
        if res["status"] == "ok":
            summary.ok += 1
            bar.ok += 1
        else:
            summary.failed += 1
            bar.failed += 1
        bar.update(advance=1)

    try:
        if dask_address is not None:
            _run_dask(todo, dask_address, run_fn, artifacts, artifact_dir, finish, bar)
        else:
            n = workers if workers is not None else (os.cpu_count() or 1)
            # runs of the engine (a runner given by name) go to worker processes even with
            # one worker, so that a crash or a process grown large cannot end the study; a
            # function passed in (tests, notebooks) runs here
            isolate = not callable(run_fn) and len(todo) > 1
            tasks = batch_runs(todo, batch if not callable(run_fn) else 1)
            if (n <= 1 and not isolate) or len(todo) <= 1:
                for r in todo:
                    bar.running = 1
                    bar.update()
                    finish(r, execute_run(run_fn, r.case, artifact_dir(r), artifacts))
                bar.running = 0
            else:
                _run_pool(tasks, n, run_fn, artifacts, artifact_dir, finish, bar,
                          threads=1 if batch > 1 else None)
    except KeyboardInterrupt:
        summary.interrupted = True
        raise
    finally:
        bar.running = 0
        bar.update()
        bar.close()
        summary.wall_s = time.perf_counter() - t_start
        if write_results:
            try:
                summary.table = write_table(out)
            except Exception:  # pragma: no cover - the table is a convenience
                summary.table = None
    return summary


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
