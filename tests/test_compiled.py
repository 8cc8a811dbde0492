"""Traced kernels kept on disk (undulate.mechanics.compiled): same bits, robust to damage."""

from pathlib import Path

import jax.numpy as jnp
import numpy as np
import pytest

import undulate.mechanics.assemble  # noqa: F401  (float64, as in every run)
from undulate.mechanics.compiled import CachedJit


def _kernel(x, w):
    return jnp.sum(jnp.sin(x) * w, axis=1), jnp.outer(x[0], w[0])


@pytest.fixture
def cache_dir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    monkeypatch.setenv("UNDULATE_JAX_CACHE_DIR", str(tmp_path))
    monkeypatch.delenv("UNDULATE_JAX_CACHE", raising=False)
    return tmp_path


def _args():
    rng = np.random.default_rng(3)
    return rng.standard_normal((7, 4)), rng.standard_normal((7, 4))


def test_loaded_program_gives_the_same_bits(cache_dir: Path) -> None:
    x, w = _args()
    first = CachedJit(_kernel, "test.kernel")(x, w)  # traces and writes the program
    files = list((cache_dir / "export").glob("test.kernel-*.jaxexport"))
    assert len(files) == 1 and files[0].stat().st_size > 0
    mtime = files[0].stat().st_mtime_ns
    again = CachedJit(_kernel, "test.kernel")(x, w)  # a new instance loads it
    assert files[0].stat().st_mtime_ns == mtime
    for a, b in zip(first, again, strict=True):
        assert np.array_equal(np.asarray(a), np.asarray(b))
    ref = _kernel(jnp.asarray(x), jnp.asarray(w))
    for a, b in zip(first, ref, strict=True):
        assert np.allclose(np.asarray(a), np.asarray(b), rtol=1e-14, atol=0)
    # other shapes: another program
    CachedJit(_kernel, "test.kernel")(x[:3], w[:3])
    assert len(list((cache_dir / "export").glob("test.kernel-*.jaxexport"))) == 2


def test_damaged_entry_is_made_again(cache_dir: Path) -> None:
    x, w = _args()
    CachedJit(_kernel, "test.kernel")(x, w)
    (f,) = (cache_dir / "export").glob("test.kernel-*.jaxexport")
    f.write_bytes(b"not a program")
    out = CachedJit(_kernel, "test.kernel")(x, w)
    assert np.allclose(np.asarray(out[0]), np.sum(np.sin(x) * w, axis=1))
    assert f.stat().st_size > 100


def test_cache_off_writes_nothing(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("UNDULATE_JAX_CACHE_DIR", str(tmp_path))
    monkeypatch.setenv("UNDULATE_JAX_CACHE", "0")
    x, w = _args()
    out = CachedJit(_kernel, "test.kernel")(x, w)
    assert np.allclose(np.asarray(out[0]), np.sum(np.sin(x) * w, axis=1))
    assert not (tmp_path / "export").exists()
