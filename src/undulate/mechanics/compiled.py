"""Jitted kernels whose traced programs and compiled executables are kept on disk.

A new process would otherwise pay, for each kernel, tracing (run the Python function under JAX's
tracers, with ``jax.hessian``/``jax.jacfwd`` of the rod's frame: measured 1.4 s for the rod
bending kernel alone, ~8 s of a 10 s start-up in all), XLA's compilation (tens of seconds for
the rod kernels), or, with JAX's persistent compilation cache, lowering the traced program and
looking it up (the demo's 27 kernels: 0.3 s of lowering and key hashing besides the loads).
:class:`CachedJit` keeps two files per kernel and argument shapes in ``<cache dir>``:

* ``export/<name>-<key>.jaxexport``: the traced program (``jax.export``, serialized StableHLO);
* ``exe/<name>-<key>.xlaexe``: the executable XLA compiled from it
  (``jax.experimental.serialize_executable``), which a later process loads directly: no
  tracing, no lowering, no lookup, no compilation.

The key holds the kernel's name, the argument shapes, the JAX version, the backend, a digest of
undulate's own source files (any edit of the package makes new entries), ``XLA_FLAGS`` and, for
executables, the processor (model and instruction-set flags: machine code is not portable). The
program is the same either way, and it is always called through the exported form, so a run
gives the same bits whether it traced, compiled or loaded (``tests/test_determinism.py``).

An executable is written only after a copy loaded back from its bytes has given the same bits
on the call's arguments. This is why undulate does not switch on JAX's persistent compilation
cache: an executable that cache hands back cannot be serialized again (the copy fails with
"Function ... not found"). Where that happens anyway (a user's own ``JAX_COMPILATION_CACHE_DIR``)
a marker file ``<exe>.none`` records it and later processes compile through JAX's cache as
before.

``UNDULATE_JAX_CACHE=0`` turns all of this off (plain ``jax.jit``).

**Size.** Every edit of undulate, new mesh size or rod count makes new entries (~6 MB for the
demo's kernels). After each new entry the cache is pruned to ``UNDULATE_JAX_CACHE_MB``
(default :data:`DEFAULT_LIMIT_MB`), least recently used files first (a load sets an
executable's access time; the file itself is not rewritten). ``undulate cache`` shows where
it is and how large; ``undulate cache --clear`` empties it.

**Cold start.** The first run of an undulate version on a machine traces and compiles its
kernels; :func:`cold_start_notice` says so beforehand, with the time the last cold start here
took (:func:`mark_warm` records it).
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import os
import pickle
import platform
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from ..fileio import atomic_path

__all__ = ["CachedJit", "cache_root", "cache_usage", "cache_limit_mb", "clear_cache",
           "prune_cache", "cold_start_notice", "mark_warm", "DEFAULT_LIMIT_MB"]

#: the cache is pruned to this many MB unless ``UNDULATE_JAX_CACHE_MB`` says otherwise
DEFAULT_LIMIT_MB = 150
#: what a cold start is said to take when none was measured on this machine yet [s]
COLD_START_GUESS_S = 30.0
_SUBDIRS = ("export", "exe")


def cache_root() -> Path | None:
    """Directory of undulate's JAX caches, or None when caching is off."""
    if os.environ.get("UNDULATE_JAX_CACHE", "1") == "0":
        return None
    return Path(os.environ.get(
        "UNDULATE_JAX_CACHE_DIR", os.path.join(os.path.expanduser("~"), ".cache", "undulate", "jax")
    ))


def _entries(root: Path) -> list[Path]:
    return [p for d in _SUBDIRS if (root / d).is_dir() for p in (root / d).iterdir()
            if p.is_file()]


def cache_usage(root: Path | None = None) -> tuple[int, int]:
    """(number of files, bytes) of the kernel cache."""
    root = root if root is not None else cache_root()
    if root is None or not root.is_dir():
        return 0, 0
    files = _entries(root)
    return len(files), sum(p.stat().st_size for p in files)


def clear_cache(root: Path | None = None) -> tuple[int, int]:
    """Remove every cached program, executable and warm marker; (files, bytes) removed."""
    root = root if root is not None else cache_root()
    n, size = cache_usage(root)
    if root is None or not root.is_dir():
        return 0, 0
    targets = _entries(root)
    if (root / "warm").is_dir():
        targets += list((root / "warm").iterdir())
    for p in targets:
        p.unlink(missing_ok=True)
    return n, size


def cache_limit_mb() -> float:
    """The cache's size limit in MB: ``UNDULATE_JAX_CACHE_MB`` (a number from 10 to 1e6),
    else :data:`DEFAULT_LIMIT_MB`; anything else raises ValueError naming the variable."""
    raw = os.environ.get("UNDULATE_JAX_CACHE_MB", "").strip()
    if not raw:
        return float(DEFAULT_LIMIT_MB)
    try:
        mb = float(raw)
    except ValueError:
        mb = float("nan")
    if not 10.0 <= mb <= 1e6:  # also NaN
        raise ValueError(f"UNDULATE_JAX_CACHE_MB: must be a number of MB from 10 to 1000000 "
                         f"(got {raw!r})")
    return mb


def _limit_bytes() -> int:
    return int(cache_limit_mb() * 2**20)


def prune_cache(root: Path | None = None, limit: int | None = None) -> int:
    """Remove the least recently used entries until the cache holds at most ``limit`` bytes
    (default: ``UNDULATE_JAX_CACHE_MB``, else :data:`DEFAULT_LIMIT_MB`); bytes removed."""
    root = root if root is not None else cache_root()
    if root is None or not root.is_dir():
        return 0
    limit = _limit_bytes() if limit is None else limit
    stats = []
    for p in _entries(root):
        try:
            st = p.stat()
        except OSError:
            continue
        stats.append((max(st.st_atime, st.st_mtime), st.st_size, p))
    total = sum(size for _, size, _ in stats)
    removed = 0
    for _, size, p in sorted(stats, key=lambda t: t[0]):
        if total - removed <= limit:
            break
        try:
            p.unlink()
            removed += size
        except OSError:
            pass
    return removed


def _warm_marker(root: Path) -> Path:
    return root / "warm" / f"{_source_digest()[:24]}-{_machine_digest()[:12]}"


def cold_start_notice() -> str | None:
    """A line to show before a run that will trace and compile the kernels (the first run of
    this undulate version on this machine), or None when it will load them from the cache."""
    root = cache_root()
    if root is None:
        return None
    if _warm_marker(root).is_file():
        return None
    guess = COLD_START_GUESS_S
    last = sorted((root / "warm").glob("*"), key=lambda p: p.stat().st_mtime) \
        if (root / "warm").is_dir() else []
    for p in reversed(last):
        try:
            guess = float(p.read_text().strip())
            break
        except (OSError, ValueError):
            continue
    return (f"compiling kernels once for this version of undulate, about {guess:.0f} s "
            f"(kept in {root}; later runs load them)")


def mark_warm(seconds: float) -> None:
    """Record that this version's kernels are in the cache; ``seconds``: what it took."""
    root = cache_root()
    if root is None:
        return
    try:
        with atomic_path(_warm_marker(root)) as tmp:
            Path(tmp).write_text(f"{seconds:.1f}\n")
    except OSError:
        pass


@functools.cache
def _source_digest(parts: tuple[str, ...] | None = None) -> str:
    """Digest of undulate's source files (all of them, or those below the sub-packages
    ``parts``) and of the JAX installation (part of every key)."""
    import jaxlib

    root = Path(__file__).resolve().parents[1]
    h = hashlib.sha256()
    files = (sorted(root.rglob("*.py")) if parts is None
             else [p for part in parts for p in sorted((root / part).rglob("*.py"))])
    for p in files:
        h.update(p.relative_to(root).as_posix().encode())
        h.update(p.read_bytes())
    h.update(f"jax {jax.__version__} jaxlib {jaxlib.__version__}".encode())
    return h.hexdigest()


@functools.cache
def _machine_digest() -> str:
    """The processor, as far as machine code cares: model name and instruction-set flags (Linux
    ``/proc/cpuinfo``), else what :mod:`platform` says."""
    text = ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            key = line.split(":", 1)[0].strip()
            if key in ("model name", "flags", "Features", "CPU implementer", "CPU part"):
                text += line + "\n"
            elif not line.strip() and text:
                break  # the first processor is enough
    except OSError:
        pass
    text += f"{platform.machine()}|{platform.processor()}|{platform.system()}"
    return hashlib.sha256(text.encode()).hexdigest()


def _same_bits(a: Any, b: Any) -> bool:
    la, lb = jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b)
    return len(la) == len(lb) and all(
        np.array_equal(np.asarray(x), np.asarray(y), equal_nan=True)
        for x, y in zip(la, lb, strict=True))


def _aval_key(args: tuple) -> tuple:
    return tuple((tuple(np.shape(a)), str(jnp.result_type(a))) for a in args)


class CachedJit:
    """``jax.jit(fn)`` whose traced program is exported to (and later loaded from) disk.

    Called with arrays only (no static arguments); one exported program per set of argument
    shapes and dtypes. Anything that goes wrong with the disk cache (unwritable directory,
    damaged file, a program JAX cannot export) falls back to tracing, never to an error.
    """

    def __init__(self, fn: Callable[..., Any], name: str) -> None:
        self.name = name
        self._jit = jax.jit(fn)
        self._by_avals: dict[tuple, Callable[..., Any]] = {}
        # one load per shape also when threads ask at once (the assembly evaluates element
        # groups on two threads: the first caller loads, the others wait)
        self._lock = threading.Lock()

    def __call__(self, *args: Any) -> Any:
        args = tuple(a if isinstance(a, jax.Array | np.ndarray) else jnp.asarray(a)
                     for a in args)
        key = _aval_key(args)
        f = self._by_avals.get(key)
        if f is None:
            with self._lock:
                f = self._by_avals.get(key)
                if f is None:
                    f = self._by_avals[key] = self._program(args, key)
        return f(*args)

    def _program(self, args: tuple, key: tuple) -> Callable[..., Any]:
        root = cache_root()
        if root is None:
            return self._jit
        try:
            from jax import export  # noqa: F401 - both needed, or plain jit
            from jax.experimental import serialize_executable  # noqa: F401
        except ImportError:  # pragma: no cover - old JAX
            return self._jit
        digest, exe_digest = self._digests(key)
        exe_path = root / "exe" / f"{self.name}-{exe_digest}.xlaexe"
        loaded = _load_executable(exe_path) if exe_path.is_file() else None
        if loaded is not None:
            return loaded
        exp = self._exported(root / "export" / f"{self.name}-{digest}.jaxexport", args)
        if exp is None:
            return self._jit
        program = jax.jit(exp.call)
        marker = exe_path.with_name(exe_path.name + ".none")
        if marker.is_file():
            return program
        return _compile_and_keep(program, args, exe_path, marker, root)

    def _digests(self, key: tuple) -> tuple[str, str]:
        """The keys of the exported program and of the executable (see the module doc)."""
        digest = hashlib.sha256(
            f"{_source_digest()}|{self.name}|{key}|{jax.default_backend()}|"
            f"x64={jax.config.jax_enable_x64}".encode()
        ).hexdigest()[:24]
        backend = jax.devices()[0].client
        exe_digest = hashlib.sha256(
            f"{digest}|{backend.platform}|{backend.platform_version}|"
            f"{os.environ.get('XLA_FLAGS', '')}|{_machine_digest()}".encode()
        ).hexdigest()[:24]
        return digest, exe_digest

    def _exported(self, path: Path, args: tuple) -> Any:
        """The exported program from ``path``, or traced, exported and written there; None
        when this JAX cannot export it."""
        from jax import export

        if path.is_file():
            try:
                return export.deserialize(bytearray(path.read_bytes()))
            except Exception:  # noqa: BLE001 - a damaged entry is made again
                pass
        try:
            exp = export.export(self._jit)(*args)
            data = exp.serialize()
        except Exception:  # noqa: BLE001 - e.g. flatbuffers missing: plain jit
            return None
        try:  # concurrent writers of one key write the same bytes; readers never see a part
            with atomic_path(path) as tmp:
                Path(tmp).write_bytes(bytes(data))
        except OSError:
            pass  # an unwritable cache only costs the next process a trace
        return exp


def _load_executable(exe_path: Path) -> Callable[..., Any] | None:
    """The executable kept at ``exe_path`` (its access time set: pruned last), or None."""
    from jax.experimental import serialize_executable

    try:
        payload, in_tree, out_tree = pickle.loads(exe_path.read_bytes())
        loaded = serialize_executable.deserialize_and_load(payload, in_tree, out_tree)
        with contextlib.suppress(OSError):  # recently used (access time): pruned last
            os.utime(exe_path, ns=(time.time_ns(), exe_path.stat().st_mtime_ns))
        return loaded
    except Exception:  # noqa: BLE001 - a damaged entry is made again
        return None


def _compile_and_keep(program: Callable[..., Any], args: tuple, exe_path: Path, marker: Path,
                      root: Path) -> Callable[..., Any]:
    """Compile ``program`` for ``args``; keep the executable at ``exe_path`` when a copy
    loaded back from its bytes gives the same bits (else write ``marker``)."""
    from jax.experimental import serialize_executable

    try:
        compiled = program.lower(*args).compile()
    except Exception:  # noqa: BLE001 - e.g. a backend without AOT compilation
        return program
    try:
        blob = pickle.dumps(serialize_executable.serialize(compiled))
        loaded = serialize_executable.deserialize_and_load(*pickle.loads(blob))
        keep = _same_bits(compiled(*args), loaded(*args))
    except Exception:  # noqa: BLE001 - not serializable here
        keep = False
    try:
        with atomic_path(exe_path if keep else marker) as tmp:
            Path(tmp).write_bytes(blob if keep else b"")
        prune_cache(root)
    except OSError:
        pass  # an unwritable cache only costs the next process a compilation
    return compiled
