"""Traced kernels and their executables kept on disk (undulate.mechanics.compiled): same
bits, robust to damage, keyed by the machine."""

from pathlib import Path

import jax.numpy as jnp
import numpy as np
import pytest

import undulate.mechanics.assemble  # noqa: F401  (float64, as in every run)
from undulate.mechanics import compiled
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
    first = CachedJit(_kernel, "test.kernel")(x, w)  # traces, compiles, writes both
    files = list((cache_dir / "export").glob("test.kernel-*.jaxexport")) + \
        list((cache_dir / "exe").glob("test.kernel-*.xlaexe"))
    assert len(files) == 2 and all(f.stat().st_size > 0 for f in files)
    mtimes = [f.stat().st_mtime_ns for f in files]
    again = CachedJit(_kernel, "test.kernel")(x, w)  # a new instance loads the executable
    assert [f.stat().st_mtime_ns for f in files] == mtimes
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
    (exe,) = (cache_dir / "exe").glob("test.kernel-*.xlaexe")
    exe.write_bytes(b"not an executable")
    out = CachedJit(_kernel, "test.kernel")(x, w)
    assert np.allclose(np.asarray(out[0]), np.sum(np.sin(x) * w, axis=1))
    assert exe.stat().st_size > 100
    # a damaged program (and no executable): traced again
    (f,) = (cache_dir / "export").glob("test.kernel-*.jaxexport")
    f.write_bytes(b"not a program")
    exe.unlink()
    out = CachedJit(_kernel, "test.kernel")(x, w)
    assert np.allclose(np.asarray(out[0]), np.sum(np.sin(x) * w, axis=1))
    assert f.stat().st_size > 100 and exe.stat().st_size > 100


def test_executable_of_another_machine_is_not_loaded(cache_dir: Path,
                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    x, w = _args()
    CachedJit(_kernel, "test.kernel")(x, w)
    monkeypatch.setattr(compiled, "_machine_digest", lambda: "another processor")
    out = CachedJit(_kernel, "test.kernel")(x, w)
    assert np.allclose(np.asarray(out[0]), np.sum(np.sin(x) * w, axis=1))
    assert len(list((cache_dir / "exe").glob("test.kernel-*.xlaexe"))) == 2
    assert len(list((cache_dir / "export").glob("test.kernel-*.jaxexport"))) == 1


def test_cache_off_writes_nothing(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("UNDULATE_JAX_CACHE_DIR", str(tmp_path))
    monkeypatch.setenv("UNDULATE_JAX_CACHE", "0")
    x, w = _args()
    out = CachedJit(_kernel, "test.kernel")(x, w)
    assert np.allclose(np.asarray(out[0]), np.sum(np.sin(x) * w, axis=1))
    assert not (tmp_path / "export").exists() and not (tmp_path / "exe").exists()


def test_executable_that_does_not_load_back_is_not_written(cache_dir: Path,
                                                           monkeypatch: pytest.MonkeyPatch) -> None:
    """A copy that does not give the same bits (as an executable JAX's own cache handed back):
    a marker instead of the executable, and later processes compile as before."""
    x, w = _args()
    monkeypatch.setattr(compiled, "_same_bits", lambda a, b: False)
    out = CachedJit(_kernel, "test.kernel")(x, w)
    assert np.allclose(np.asarray(out[0]), np.sum(np.sin(x) * w, axis=1))
    assert not list((cache_dir / "exe").glob("test.kernel-*.xlaexe"))
    (marker,) = (cache_dir / "exe").glob("test.kernel-*.xlaexe.none")
    monkeypatch.undo()
    out = CachedJit(_kernel, "test.kernel")(x, w)
    assert np.allclose(np.asarray(out[0]), np.sum(np.sin(x) * w, axis=1))
    assert not list((cache_dir / "exe").glob("test.kernel-*.xlaexe")) and marker.is_file()


def test_cache_is_pruned_least_recently_used_first(tmp_path, monkeypatch) -> None:
    import os

    from undulate.mechanics import compiled

    monkeypatch.setenv("UNDULATE_JAX_CACHE_DIR", str(tmp_path))
    (tmp_path / "exe").mkdir()
    (tmp_path / "export").mkdir()
    for k in range(6):  # 6 entries of 1 MB, the older the smaller k
        p = tmp_path / ("exe" if k % 2 else "export") / f"kernel{k}"
        p.write_bytes(b"x" * 2**20)
        os.utime(p, (1000.0 + k, 1000.0 + k))
    assert compiled.cache_usage() == (6, 6 * 2**20)
    assert compiled.prune_cache(limit=int(3.5 * 2**20)) == 3 * 2**20
    left = sorted(p.name for d in ("exe", "export") for p in (tmp_path / d).iterdir())
    assert left == ["kernel3", "kernel4", "kernel5"]
    assert compiled.clear_cache() == (3, 3 * 2**20)
    assert compiled.cache_usage() == (0, 0)


def test_cold_start_is_announced_until_the_kernels_are_kept(tmp_path, monkeypatch) -> None:
    from typer.testing import CliRunner

    from undulate.interfaces.cli import app
    from undulate.mechanics import compiled

    monkeypatch.setenv("UNDULATE_JAX_CACHE_DIR", str(tmp_path))
    first = compiled.cold_start_notice()
    assert first is not None and "compiling kernels once" in first
    assert f"about {compiled.COLD_START_GUESS_S:.0f} s" in first
    compiled.mark_warm(12.3)
    assert compiled.cold_start_notice() is None
    # another version (another source digest): announced with the time measured here
    compiled._source_digest.cache_clear()
    monkeypatch.setattr(compiled, "_source_digest", lambda parts=None: "f" * 64)
    assert "about 12 s" in (compiled.cold_start_notice() or "")
    res = CliRunner().invoke(app, ["cache"])
    assert res.exit_code == 0 and str(tmp_path) in res.stdout and "0 files" in res.stdout
    res = CliRunner().invoke(app, ["cache", "--clear"])
    assert res.exit_code == 0 and "removed" in res.stdout
    assert not list((tmp_path / "warm").iterdir())


def test_a_cold_run_says_so_once_its_output_folder_is_accepted(tmp_path, monkeypatch) -> None:
    from error_cases import TINY
    from typer.testing import CliRunner

    import undulate.pipeline.run
    from undulate.interfaces.cli import app
    from undulate.solve import ConvergenceError

    def stop(*a, **k):
        raise ConvergenceError("stopped by the test", step=0, residual=1.0)

    monkeypatch.setattr(undulate.pipeline.run, "simulate", stop)
    monkeypatch.setenv("UNDULATE_JAX_CACHE_DIR", str(tmp_path / "cache"))
    (tmp_path / "tiny.toml").write_text(TINY)
    run = ["run", str(tmp_path / "tiny.toml"), "--out"]
    res = CliRunner().invoke(app, [*run, str(tmp_path / "r1")])
    assert res.exit_code == 3 and "compiling kernels once" in res.stdout, res.output
    (tmp_path / "file").write_text("x")  # a refused folder: its error is the only output
    res = CliRunner().invoke(app, [*run, str(tmp_path / "file")])
    assert res.exit_code == 2 and "compiling" not in res.output
