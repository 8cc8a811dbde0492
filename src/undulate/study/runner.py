"""Run a study: skip finished runs, execute the rest locally or on dask, write records atomically.

The runs themselves: :mod:`undulate.study.execute` (one run or a batch, as a record) and
:mod:`undulate.study.workers` (the local pool and dask).

Records are written by the driver process only (dask workers need no shared filesystem for
results) via :func:`undulate.study.storage.write_record`, atomically. Killing the driver loses at
most the runs that were in flight; re-running the same command resumes.
"""

from __future__ import annotations

import os
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .. import __version__
from ..model import case_from_dict
from ..model.numerics import MeshOptions
from .execute import (  # re-exported: a study's runs by one address
    ENGINE_PARTS,
    RUNNER_ENV,
    RunFn,
    batch_runs,
    engine_id,
    execute_batch,
    execute_run,
    resolve_runner,
    usable_cpus,
)
from .named_setups import describe_setup
from .spec import RunSpec, Study, StudyError, coarse_first
from .storage import (
    RECORD_SCHEMA,
    read_study,
    remove_stale_tmp,
    scan_runs,
    write_record,
    write_study,
    write_table,
)
from .workers import _run_dask, _run_pool, worker_pardiso_threads

__all__ = ["RunFn", "RunSummary", "run_study", "execute_run", "execute_batch", "batch_runs",
           "resolve_runner", "RUNNER_ENV", "worker_pardiso_threads", "engine_id",
           "usable_cpus", "ENGINE_PARTS"]

@dataclass
class RunSummary:
    """What :func:`run_study` did."""

    total: int
    skipped_ok: int = 0
    skipped_failed: int = 0
    stale: int = 0  # finished runs run again: their rod spacing is not today's default
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


def _stale_mesh(prev: dict[str, Any], r: RunSpec) -> bool:
    """Whether a finished run was made on another rod spacing than its case gets now: the
    default ``mesh.dx_rod`` depends on the rods (finer for thin ones, since 2026-12-07), and
    a record of the old spacing is a result of another mesh. Records without a resolved
    case were made with the 1 mm default."""
    old = ((prev.get("case_resolved") or {}).get("mesh") or {}).get(
        "dx_rod", MeshOptions.model_fields["dx_rod"].default)
    try:
        now = case_from_dict(r.case).mesh.dx_rod
    except ValueError:  # an invalid case fails when it runs, with its own message
        return False
    return abs(float(old) - now) > 1e-9


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
        elif prev["status"] == "ok" and not _stale_mesh(prev, r):
            summary.skipped_ok += 1
        elif prev["status"] == "ok":
            todo.append(r)
            attempts[r.id] = int(prev.get("attempt") or 1) + 1
            summary.stale += 1
        elif retry_failed:
            todo.append(r)
            attempts[r.id] = int(prev.get("attempt") or 1) + 1
        else:
            summary.skipped_failed += 1

    def artifact_dir(r: RunSpec) -> str | None:
        return str(out / "artifacts" / r.id) if artifacts else None

    if summary.stale and progress:
        print(f"study: {summary.stale} finished runs run again: they were made on another rod "
              "spacing than their case gets now (mesh.dx_rod)", file=sys.stderr, flush=True)
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
