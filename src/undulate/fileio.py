"""Small file helpers shared by every stage (no third-party imports, so the engine can use
them without loading the study stage): atomic replacement of a file, atomic JSON, JSON
conversion of numpy values, default modes, and run folders written whole (:class:`StagedDir`).

A run never leaves a half-written ``DIR``: :class:`StagedDir` makes a hidden sibling folder
``.DIR.incomplete-XXXX``, every file is written there, and only when all are complete is it
renamed to ``DIR`` (one atomic rename). A run that is interrupted (Ctrl-C, kill, power loss)
leaves ``DIR`` as it was, plus at most the hidden ``.incomplete-`` folder, which no reader
accepts. :func:`check_destination` refuses, before anything is simulated, an ``--out`` that is a
file, that cannot be created, or that already holds files (unless ``overwrite``: then the
previous run's files, and only those, are replaced)."""

from __future__ import annotations

import contextlib
import glob
import json
import math
import os
import re
import shutil
import socket
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

__all__ = [
    "INCOMPLETE_TAG",
    "OutputError",
    "StagedDir",
    "atomic_path",
    "atomic_write_json",
    "check_destination",
    "current_umask",
    "default_mode",
    "is_run_file",
    "jsonable",
]


def current_umask() -> int:
    """The process umask, read without changing it where the OS allows (Linux /proc)."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("Umask:"):
                return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    mask = os.umask(0o022)  # elsewhere: set and restore (briefly process-wide)
    os.umask(mask)
    return mask


def default_mode(directory: bool = False) -> int:
    """Mode a plain ``open()`` / ``mkdir()`` would give: 0666 / 0777 less the umask."""
    return (0o777 if directory else 0o666) & ~current_umask()


@contextlib.contextmanager
def atomic_path(path: Path) -> Iterator[str]:
    """Yield a temporary file name next to ``path``; on success it replaces ``path``.

    The temporary file lives in the same directory (so ``os.replace`` is atomic) and is removed
    if the block raises: a reader sees the old file or the complete new one, never a part.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    # mkstemp creates 0600; give the file the mode any other output gets (0644 under umask 022)
    os.chmod(tmp, default_mode())
    try:
        yield tmp
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise
    _sync_folder(path.parent)  # make the rename durable too


def _sync_folder(folder: Path) -> None:
    """fsync a folder, so that a rename into it survives a power loss (best effort: not
    supported everywhere)."""
    try:
        fd = os.open(folder, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
    except OSError:
        pass


def jsonable(obj: Any) -> Any:
    """Convert numpy scalars/arrays, paths and tuples to JSON types; NaN/inf become None."""
    if obj is None or isinstance(obj, bool | str | int):
        return obj
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple | set):
        return [jsonable(v) for v in obj]
    if isinstance(obj, os.PathLike):
        return os.fspath(obj)
    tolist = getattr(obj, "tolist", None)  # numpy scalars and arrays
    if callable(tolist):
        return jsonable(tolist())
    raise TypeError(f"value of type {type(obj).__name__} is not JSON-serialisable")


def atomic_write_json(path: Path, data: Any) -> None:
    """Write JSON to ``path`` atomically (tmp file in the same directory, fsync, os.replace)."""
    text = json.dumps(data, indent=1, sort_keys=False, allow_nan=False)
    with atomic_path(path) as tmp, open(tmp, "w") as fh:
        fh.write(text)
        fh.flush()
        os.fsync(fh.fileno())


INCOMPLETE_TAG = ".incomplete-"
"""Part of the name of a run folder still being written (see :class:`StagedDir`)."""

_RUN_FILE = re.compile(
    r"(final\.vtu|printed\.vtu|centerlines\.npz|metrics\.json|rod_\d+_(side|fits)\.png"
    r"|top_view\.png|view_3d\.png)"
)


class OutputError(Exception):
    """The output folder cannot be used; the message is one line that names it."""


def is_run_file(name: str) -> bool:
    """True for the names of files a run writes (see the module docstring)."""
    return _RUN_FILE.fullmatch(name) is not None


def _nearest_existing(p: Path) -> Path:
    while not os.path.lexists(p) and p != p.parent:
        p = p.parent
    return p


def check_destination(out: str | Path, overwrite: bool = False) -> None:
    """Raise :class:`OutputError` (one line) if a run cannot be written to ``out``.

    Refused: ``out`` exists and is not a folder; a parent of it is a file; ``out`` holds files
    and ``overwrite`` is false; with ``overwrite``, ``out`` holds anything that is not a run's
    output (those files would be lost). Writability is checked by :class:`StagedDir`.
    """
    out = Path(out)
    if os.path.lexists(out):
        if not out.is_dir():
            raise OutputError(f"output folder {out}: exists and is not a folder")
        entries = sorted(e.name for e in out.iterdir())
        if entries and not overwrite:
            shown = ", ".join(entries[:3]) + (", ..." if len(entries) > 3 else "")
            raise OutputError(
                f"output folder {out} is not empty ({shown}): give a new folder, or "
                "--overwrite to replace the previous run in it"
            )
        foreign = [e for e in entries if not is_run_file(e)]
        if foreign:
            shown = ", ".join(foreign[:3]) + (", ..." if len(foreign) > 3 else "")
            raise OutputError(
                f"output folder {out}: --overwrite replaces only a previous run's files, but "
                f"it also holds {shown}; move them or give another folder"
            )
    else:
        anc = _nearest_existing(out.parent)
        if not anc.is_dir():
            raise OutputError(f"output folder {out}: {anc} is a file, not a folder")


#: a staging folder's name says who writes it: this host and the writing process's id
_HOST = re.sub(r"[^A-Za-z0-9_.]", "_", socket.gethostname())[:40] or "host"


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # someone else's process
        return True
    return True


def remove_stale_staging(parent: Path, name: str) -> list[Path]:
    """Delete the staging folders of ``name`` left in ``parent`` by killed runs: those written
    by a process of this host that no longer exists (a run killed with SIGKILL, or a machine
    that went down, cannot clean up after itself). Folders of live processes, of other hosts
    (a shared file system) or without an owner in their name are left alone."""
    removed = []
    pat = re.compile(re.escape(f".{name}{INCOMPLETE_TAG}{_HOST}-") + r"(\d+)-")
    for p in parent.glob(f".{glob.escape(name)}{INCOMPLETE_TAG}*"):
        m = pat.match(p.name)
        if m and p.is_dir() and not _alive(int(m.group(1))):
            shutil.rmtree(p, ignore_errors=True)
            removed.append(p)
    return removed


class StagedDir:
    """A run folder written in a hidden sibling and renamed into place when complete.

    ``StagedDir(out, overwrite)`` checks the destination and creates the staging folder at
    once (so a destination that cannot be written is reported before any simulation);
    :attr:`path` is where to write; :meth:`commit` moves it to ``out``; :meth:`discard` (also
    on leaving a ``with`` block by an exception) deletes it.
    """

    def __init__(self, out: str | Path, overwrite: bool = False) -> None:
        self.out = Path(out)
        self.overwrite = overwrite
        check_destination(self.out, overwrite)
        self._abs = Path(os.path.abspath(self.out))
        parent = self._abs.parent
        try:
            parent.mkdir(parents=True, exist_ok=True)
            remove_stale_staging(parent, self._abs.name)
            owner = f"{_HOST}-{os.getpid()}"
            tmp = tempfile.mkdtemp(prefix=f".{self._abs.name}{INCOMPLETE_TAG}{owner}-",
                                   dir=parent)
            os.chmod(tmp, default_mode(directory=True))  # mkdtemp makes 0700
        except OSError as err:
            raise OutputError(
                f"output folder {self.out}: cannot write there ({err.strerror or err})"
            ) from None
        self.path = Path(tmp)
        self.committed = False

    def commit(self) -> Path:
        """Move the complete run into place (replacing a previous run with ``overwrite``)."""
        dest = self._abs
        trash = None
        if os.path.lexists(dest):
            check_destination(dest, self.overwrite)  # again: something may have appeared
            if any(dest.iterdir()):
                trash = dest.parent / f".{dest.name}.previous-{os.getpid()}"
                os.rename(dest, trash)
            else:
                os.rmdir(dest)
        os.rename(self.path, dest)
        self.committed = True
        if trash is not None:
            shutil.rmtree(trash, ignore_errors=True)
        _sync_folder(dest.parent)  # make the rename durable
        return self.out

    def discard(self) -> None:
        if not self.committed:
            shutil.rmtree(self.path, ignore_errors=True)

    def __enter__(self) -> StagedDir:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is not None:
            self.discard()
