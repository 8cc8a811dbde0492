"""Jitted kernels whose traced programs are kept on disk, so that a new process skips tracing.

JAX's persistent compilation cache (set up in :mod:`undulate.mechanics.assemble`) stores the
*compiled* executables, but every new process still has to *trace* each kernel (run the Python
function under JAX's tracers, with ``jax.hessian``/``jax.jacfwd`` of the rod's frame) to find
the cache entry: measured 1.4 s for the rod bending kernel alone, ~8 s of a 10 s start-up in
all. :class:`CachedJit` keeps the traced program itself (``jax.export``, serialized StableHLO)
in ``<cache dir>/export``, keyed by the kernel's name, the argument shapes, the JAX version,
the backend and a digest of undulate's own source files (any edit of the package makes new
entries); a later process deserializes it (milliseconds) and compiles it from the persistent
cache. The program is the same either way, and it is always called through the exported
form, so a run gives the same bits whether it traced or loaded (``tests/test_determinism.py``).

``UNDULATE_JAX_CACHE=0`` turns this off with the compilation cache (plain ``jax.jit``).
"""

from __future__ import annotations

import functools
import hashlib
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from ..fileio import atomic_path

__all__ = ["CachedJit", "cache_root"]


def cache_root() -> Path | None:
    """Directory of undulate's JAX caches, or None when caching is off."""
    if os.environ.get("UNDULATE_JAX_CACHE", "1") == "0":
        return None
    return Path(os.environ.get(
        "UNDULATE_JAX_CACHE_DIR", os.path.join(os.path.expanduser("~"), ".cache", "undulate", "jax")
    ))


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

    def __call__(self, *args: Any) -> Any:
        args = tuple(a if isinstance(a, jax.Array | np.ndarray) else jnp.asarray(a)
                     for a in args)
        key = _aval_key(args)
        f = self._by_avals.get(key)
        if f is None:
            f = self._by_avals[key] = self._program(args, key)
        return f(*args)

    def _program(self, args: tuple, key: tuple) -> Callable[..., Any]:
        root = cache_root()
        if root is None:
            return self._jit
        try:
            from jax import export
        except ImportError:  # pragma: no cover - old JAX
            return self._jit
        digest = hashlib.sha256(
            f"{_source_digest()}|{self.name}|{key}|{jax.default_backend()}|"
            f"x64={jax.config.jax_enable_x64}".encode()
        ).hexdigest()[:24]
        path = root / "export" / f"{self.name}-{digest}.jaxexport"
        exp = None
        if path.is_file():
            try:
                exp = export.deserialize(bytearray(path.read_bytes()))
            except Exception:  # noqa: BLE001 - a damaged entry is made again
                exp = None
        if exp is None:
            try:
                exp = export.export(self._jit)(*args)
                data = exp.serialize()
            except Exception:  # noqa: BLE001 - e.g. flatbuffers missing: plain jit
                return self._jit
            try:  # concurrent writers of one key write the same bytes; readers never see a part
                with atomic_path(path) as tmp:
                    Path(tmp).write_bytes(bytes(data))
            except OSError:
                pass  # an unwritable cache only costs the next process a trace
        return jax.jit(exp.call)
