"""One run (or a batch of runs that share a mesh) as a study executes it, in whichever process:
the run function resolved, the case run, its result or its error turned into a record.

The run function is injectable: ``run_fn(case, out, artifacts=...) -> dict`` with the
signature of :func:`undulate.pipeline.run_case` (the default, imported lazily inside the
worker). It may also be given as a ``"module:function"`` string, resolved in the worker; the
environment variable ``UNDULATE_STUDY_RUNNER`` sets that string when no run function is
passed.
"""

from __future__ import annotations

import functools
import importlib
import json
import os
import shutil
import socket
import time
import traceback
from collections.abc import Callable
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from .spec import RunSpec, StudyError
from .storage import (
    jsonable,
)

__all__ = ["BATCHABLE_FIELDS", "ENGINE_PARTS", "RUNNER_ENV", "RunFn", "batch_runs",
           "engine_id", "execute_batch", "execute_run", "resolve_runner", "topology_key",
           "usable_cpus"]

RunFn = Callable[..., dict]
RUNNER_ENV = "UNDULATE_STUDY_RUNNER"


def resolve_runner(runner: RunFn | str | None) -> RunFn:
    """The run function: a callable, a ``"module:function"`` string, or None for run_case."""
    if runner is None:
        try:
            from undulate.pipeline import run_case  # lazy: the engine is heavy and optional here
        except ImportError as err:
            raise StudyError(f"runner: cannot import undulate.pipeline.run_case: {err}") from None
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
    """Run cases that share a topology together (:func:`undulate.pipeline.run_cases`, the engine's
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
    from undulate.model import case_from_dict
    from undulate.pipeline import run_cases

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
