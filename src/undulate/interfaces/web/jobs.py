"""Background simulations for the web page: a queue, a few worker processes, files on disk.

Each job is a folder ``JOBS/<id>/`` holding ``case.json`` (what was asked), ``state.json``
(status, progress, error; rewritten atomically by the worker) and, once done, ``result/``
(the same files as ``undulate run``). A job runs in its own spawned process, so a crash or a
cancel never takes the server down and JAX starts clean; at most ``workers`` run at once, the
others wait in order. A server restart marks jobs that were running as ``interrupted``: their
``result/`` is never left looking complete (``api.run_case`` writes it atomically).
"""

from __future__ import annotations

import json
import multiprocessing as mp
import os
import shutil
import threading
import time
import uuid
from collections.abc import Callable
from pathlib import Path
from typing import Any

__all__ = ["JobManager", "JobError", "run_job"]

STATES = ("queued", "running", "done", "failed", "cancelled", "interrupted")


class JobError(ValueError):
    """A job request cannot be served (unknown id, queue full, ...)."""


def _write_state(folder: Path, state: dict[str, Any]) -> None:
    tmp = folder / f".state.{os.getpid()}.tmp"
    tmp.write_text(json.dumps(state, indent=1))
    os.replace(tmp, folder / "state.json")


def read_state(folder: Path) -> dict[str, Any]:
    try:
        return json.loads((folder / "state.json").read_text())
    except (OSError, json.JSONDecodeError):
        return {"status": "interrupted", "error": "state file missing or unreadable"}


def run_job(folder: str) -> None:
    """Worker process body: simulate ``case.json`` into ``result/``, reporting progress."""
    from undulate import api

    f = Path(folder)
    case = json.loads((f / "case.json").read_text())
    state = read_state(f)
    state.update(status="running", started=time.time(), progress=0.0, stage="set-up")
    _write_state(f, state)
    last = [0.0]

    def progress(frac: float, rec: dict[str, Any]) -> None:
        state["progress"] = float(frac)
        state["stage"] = (f"release step {rec.get('step', '?')}: release strain "
                          f"{rec.get('release_strain', 0.0):.3f}")
        now = time.time()
        if now - last[0] > 0.2 or frac >= 1.0:
            last[0] = now
            _write_state(f, state)

    def stage(text: str) -> None:
        state["stage"] = text
        _write_state(f, state)

    try:
        rec = api.run_case(case, out=f / "result", progress=progress, stage=stage)
    except api.ConvergenceError as err:
        state.update(status="failed", error=f"no equilibrium found: {err}", finished=time.time())
    except Exception as err:  # noqa: BLE001 - reported to the page, the server lives on
        state.update(status="failed", error=f"{type(err).__name__}: {err}",
                     finished=time.time())
    else:
        state.update(status="done", progress=1.0, stage="done", finished=time.time(),
                     metrics=rec)
    _write_state(f, state)


class JobManager:
    """Queue of simulations under ``root``, at most ``workers`` at once, ``max_jobs`` kept.

    ``target`` is the worker function (a module-level callable taking the job folder as a
    string; :func:`run_job` unless a test swaps it).
    """

    def __init__(self, root: Path, workers: int = 1, max_queued: int = 16,
                 target: Callable[[str], None] = run_job) -> None:
        if workers < 1:
            raise JobError("workers: must be >= 1")
        self.root = Path(root)
        self.root.mkdir(parents=True, exist_ok=True)
        self.workers = workers
        self.max_queued = max_queued
        self.target = target
        self._lock = threading.Lock()
        self._queue: list[str] = []
        self._procs: dict[str, Any] = {}
        self._wake = threading.Event()
        self._stop = False
        self._ctx = mp.get_context("spawn")
        for folder in self.root.iterdir():
            st = read_state(folder) if folder.is_dir() else None
            if st and st.get("status") in ("queued", "running"):
                st.update(status="interrupted", error="the server stopped before it finished")
                _write_state(folder, st)
        self._thread = threading.Thread(target=self._loop, daemon=True, name="undulate-jobs")
        self._thread.start()

    # ---- requests --------------------------------------------------------------------
    def submit(self, case: dict[str, Any], label: str = "", owner: str = "") -> str:
        with self._lock:
            if len(self._queue) >= self.max_queued:
                raise JobError(f"queue full: {len(self._queue)} jobs wait already (at most "
                               f"{self.max_queued}); try again when one has started")
            jid = uuid.uuid4().hex[:12]
            folder = self.root / jid
            folder.mkdir()
            (folder / "case.json").write_text(json.dumps(case, indent=1))
            _write_state(folder, {"id": jid, "status": "queued", "label": label,
                                  "owner": owner, "created": time.time(), "progress": 0.0,
                                  "stage": "queued"})
            self._queue.append(jid)
        self._wake.set()
        return jid

    def folder(self, jid: str, owner: str | None = None) -> Path:
        """The job's folder; a job of another ``owner`` (when given) is "no such job"."""
        if not (len(jid) == 12 and all(c in "0123456789abcdef" for c in jid)):
            raise JobError(f"job {jid!r}: no such job")
        f = self.root / jid
        if not (f / "state.json").is_file():
            raise JobError(f"job {jid}: no such job")
        if owner is not None and read_state(f).get("owner", "") != owner:
            raise JobError(f"job {jid}: no such job")
        return f

    def state(self, jid: str, owner: str | None = None) -> dict[str, Any]:
        f = self.folder(jid, owner)
        st = read_state(f)
        st.pop("owner", None)
        st["id"] = jid
        with self._lock:
            if jid in self._queue:
                st["queue_position"] = self._queue.index(jid) + 1
        res = f / "result"
        st["files"] = sorted(p.name for p in res.iterdir() if p.is_file()) if (
            st.get("status") == "done" and res.is_dir()) else []
        return st

    def list(self, owner: str | None = None) -> list[dict[str, Any]]:
        """Jobs, oldest first (by when they were asked for; a folder's time changes with
        every progress report); only those of ``owner`` when given."""
        out = []
        for f in self.root.iterdir():
            if (f / "state.json").is_file():
                st = read_state(f)
                if owner is not None and st.get("owner", "") != owner:
                    continue
                out.append({k: st.get(k) for k in ("status", "label", "progress", "created")}
                           | {"id": f.name})
        return sorted(out, key=lambda j: (j["created"] or 0.0, j["id"]))

    def cancel(self, jid: str, owner: str | None = None) -> dict[str, Any]:
        f = self.folder(jid, owner)
        with self._lock:
            if jid in self._queue:
                self._queue.remove(jid)
                st = read_state(f)
                st.update(status="cancelled", stage="cancelled")
                _write_state(f, st)
            proc = self._procs.get(jid)
        if proc is not None:
            proc.terminate()
            proc.join(10)
            st = read_state(f)
            st.update(status="cancelled", stage="cancelled")
            _write_state(f, st)
        return self.state(jid, owner)

    def delete(self, jid: str) -> None:
        st = self.cancel(jid)
        del st
        shutil.rmtree(self.folder(jid), ignore_errors=True)

    def shutdown(self) -> None:
        self._stop = True
        self._wake.set()
        with self._lock:
            procs = list(self._procs.items())
        for jid, p in procs:
            p.terminate()
            p.join(10)
            f = self.root / jid
            st = read_state(f)
            st.update(status="interrupted", error="the server stopped before it finished")
            _write_state(f, st)
        self._thread.join(5)

    # ---- scheduler -------------------------------------------------------------------
    def _loop(self) -> None:
        while not self._stop:
            self._wake.wait(0.25)
            self._wake.clear()
            with self._lock:
                for jid, p in list(self._procs.items()):
                    if not p.is_alive():
                        p.join()
                        del self._procs[jid]
                        st = read_state(self.root / jid)
                        if st.get("status") in ("queued", "running"):
                            st.update(status="failed", error=f"the worker process ended "
                                      f"unexpectedly (exit code {p.exitcode})")
                            _write_state(self.root / jid, st)
                while self._queue and len(self._procs) < self.workers and not self._stop:
                    jid = self._queue.pop(0)
                    p = self._ctx.Process(target=self.target, args=(str(self.root / jid),),
                                          daemon=True, name=f"undulate-job-{jid}")
                    p.start()
                    self._procs[jid] = p
