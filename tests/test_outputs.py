"""Outputs never lie: atomic run folders (a killed run leaves nothing complete-looking),
--overwrite replaces only the previous run, file modes, progress in logs, and analysis keeps
the measured values. Real runs, on a tiny case (L = 20 mm, 3 release steps)."""

from __future__ import annotations

import json
import os
import signal
import stat
import subprocess
import sys
import time
from pathlib import Path

import pytest
from error_cases import TINY
from typer.testing import CliRunner

from undulate.interfaces.cli import app

ROOT = Path(__file__).parents[1]

# Runs the CLI in a child process whose output writer stops after the centre lines and
# metrics.json are written, announces it, and waits to be killed.
_PAUSING_RUN = """
import faulthandler, signal, sys, time
faulthandler.register(signal.SIGUSR1, all_threads=True)
# Ctrl-C as in a terminal, also when this test runs in a background job (which starts its
# children with SIGINT ignored: the run then slept through the signal, measured)
signal.signal(signal.SIGINT, signal.default_int_handler)
import undulate.pipeline.output as o
real = o._write_vtu
def pause(*a, **k):
    print("WRITING", flush=True)
    time.sleep(120)
    return real(*a, **k)
o._write_vtu = pause
from undulate.interfaces.cli import app
app(sys.argv[1:])
"""


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT / "src") + os.pathsep + env.get("PYTHONPATH", "")
    return env


def _start_paused_run(tmp_path: Path, out: Path) -> subprocess.Popen:
    (tmp_path / "tiny.toml").write_text(TINY)
    proc = subprocess.Popen(
        [sys.executable, "-c", _PAUSING_RUN, "run", str(tmp_path / "tiny.toml"), "--out",
         str(out)],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=_env(),
    )
    t0 = time.time()
    lines = []
    assert proc.stdout is not None
    for line in proc.stdout:
        lines.append(line)
        if line.startswith("WRITING"):
            return proc
        if time.time() - t0 > 300:
            break
    proc.kill()
    raise AssertionError("the run never reached its writer:\n" + "".join(lines))


@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGINT], ids=["kill", "ctrl-c"])
def test_interrupted_run_leaves_no_complete_looking_result(tmp_path: Path, sig) -> None:
    out = tmp_path / "run1"
    proc = _start_paused_run(tmp_path, out)
    # at this moment the old writer had centerlines.npz and metrics.json ("converged": true)
    # in DIR already; now they may only be in the hidden staging folder
    staging = [p for p in tmp_path.iterdir() if p.name.startswith(".run1.incomplete-")]
    assert len(staging) == 1 and (staging[0] / "metrics.json").is_file()
    proc.send_signal(sig)
    # communicate, not wait: the run may still write to its stdout pipe while it stops
    try:
        proc.communicate(timeout=120)
    except subprocess.TimeoutExpired:
        proc.send_signal(signal.SIGUSR1)  # the child's stacks, to say where it hangs
        time.sleep(2)
        proc.kill()
        out_text, _ = proc.communicate()
        raise AssertionError("the run did not stop after the signal:\n" + out_text) from None
    assert not out.exists()
    left = [p for p in tmp_path.iterdir() if p.name.startswith(".run1.incomplete-")]
    if sig == signal.SIGINT:
        assert left == []  # Ctrl-C cleans up
    # analyse refuses both the missing folder and the hidden one
    for d in [out, *left]:
        res = CliRunner().invoke(app, ["analyse", str(d), "--no-plots"])
        assert res.exit_code == 2 and "Traceback" not in res.output


def test_study_artifacts_are_atomic(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A study run that fails while writing its artifacts leaves no partial artifacts (and the
    stale ones of an earlier attempt are gone)."""
    import tomllib

    import undulate.pipeline.output as o
    from undulate.study.runner import execute_run

    def crash(*a, **k):
        raise OSError("disk full (simulated)")

    monkeypatch.setattr(o, "_write_vtu", crash)
    art = tmp_path / "artifacts" / "r1"
    art.mkdir(parents=True)
    (art / "rod_4_side.png").write_text("from an earlier attempt")
    res = execute_run(None, tomllib.loads(TINY), str(art))
    assert res["status"] == "failed" and "disk full" in res["error"]
    assert art.is_dir() and list(art.iterdir()) == []
    assert [p.name for p in art.parent.iterdir()] == ["r1"]


def _run(d: Path, out: Path, *extra: str):
    (d / "tiny.toml").write_text(TINY)
    res = CliRunner().invoke(app, ["run", str(d / "tiny.toml"), "--out", str(out), *extra],
                             env={"COLUMNS": "200"})
    assert res.exit_code == 0, res.output
    return res


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str]:
    """A real tiny run (CliRunner: stdout is not a terminal)."""
    d = tmp_path_factory.mktemp("run")
    res = _run(d, d / "run")
    return d / "run", res.stdout


def test_overwrite_replaces_the_previous_run(tmp_path: Path) -> None:
    """--overwrite into the folder of an earlier five-rod run: no rod_3_*.png stays behind."""
    out = tmp_path / "run"
    out.mkdir()
    (out / "top_view.png").write_text("old")  # every picture of a run is its own
    for k in range(5):
        (out / f"rod_{k}_side.png").write_text("old")
        (out / f"rod_{k}_fits.png").write_text("old")
    (out / "metrics.json").write_text('{"old": true}')
    _run(tmp_path, out, "--overwrite")
    names = sorted(p.name for p in out.iterdir())
    assert names == ["centerlines.npz", "final.vtu", "metrics.json", "printed.vtu",
                     "rod_0_fits.png", "rod_0_side.png", "top_view.png", "view_3d.png"]
    assert "old" not in json.loads((out / "metrics.json").read_text())
    assert not [p for p in out.parent.iterdir() if p.name.startswith(".run.")]


def test_every_output_has_the_same_mode(tiny_run) -> None:
    out, _ = tiny_run
    umask = os.umask(0o022)
    os.umask(umask)
    for p in out.iterdir():
        assert stat.S_IMODE(p.stat().st_mode) == 0o666 & ~umask, p.name
    assert stat.S_IMODE(out.stat().st_mode) == 0o777 & ~umask


def test_progress_is_printed_when_not_a_terminal(tiny_run) -> None:
    _, stdout = tiny_run
    lines = stdout.splitlines()
    first = [line for line in lines if line.strip()][0]
    assert first.startswith("set-up: mesh, pre-stretch")
    for k in (1, 2, 3):
        assert any(line.startswith(f"release step {k}: release strain ") and " of 0.500" in line and
                   "Newton" in line for line in lines), stdout
    assert any(line.startswith("analysis") for line in lines)
    assert any(line.startswith("writing outputs") for line in lines)


def test_analyse_keeps_measured_lengths(tiny_run, tmp_path: Path) -> None:
    import shutil

    out, _ = tiny_run
    d = tmp_path / "copy"
    shutil.copytree(out, d)
    before = json.loads((d / "metrics.json").read_text())
    res = CliRunner().invoke(app, ["analyse", str(d), "--no-plots"])
    assert res.exit_code == 0, res.output
    after = json.loads((d / "metrics.json").read_text())
    for b, a in zip(before["analysis"]["rods"], after["analysis"]["rods"], strict=True):
        assert a["L_nominal"] == b["L_nominal"] == 20.0
        assert a["L_measured"] == b["L_measured"] != 20.0  # measured, not the nominal
    for b, a in zip(before["rods"], after["rods"], strict=True):
        assert a["L_measured"] == b["L_measured"] and a["L_nominal"] == b["L_nominal"]
    assert stat.S_IMODE((d / "metrics.json").stat().st_mode) & 0o044  # still readable


def test_terminal_bar_is_labelled_during_set_up(monkeypatch: pytest.MonkeyPatch) -> None:
    import io

    from rich.console import Console

    from undulate.interfaces import cli
    from undulate.model import case_from_dict

    buf = io.StringIO()
    monkeypatch.setattr(cli, "console", Console(file=buf, force_terminal=True, width=200))
    with cli._Reporter(case_from_dict({"release": {"steps": 3}})) as rep:
        assert rep.live
        rep.stage("set-up: mesh, pre-stretch, printing")
        rep._prog.refresh()
        assert "set-up: mesh, pre-stretch, printing" in buf.getvalue()
        rep.progress(1 / 3, {"step": 1, "release_strain": 0.1667, "newton_iterations": 17,
                             "max_height": 2.0})
        rep._prog.refresh()
    assert ("release step 1: release strain 0.167 of 0.500, Newton 17 iterations"
            in buf.getvalue())


def test_staging_folders_of_killed_runs_are_removed(tmp_path: Path) -> None:
    """A run killed with SIGKILL cannot remove its hidden staging folder; the next run into
    the same place removes it when its writer (this host, that process id) is gone, and
    leaves those of live processes alone."""
    from undulate.fileio import _HOST, INCOMPLETE_TAG, StagedDir

    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    stale = tmp_path / f".run{INCOMPLETE_TAG}{_HOST}-{dead.pid}-abc123"
    live = tmp_path / f".run{INCOMPLETE_TAG}{_HOST}-{os.getpid()}-def456"
    foreign = tmp_path / f".run{INCOMPLETE_TAG}otherhost-{dead.pid}-ghi789"
    for p in (stale, live, foreign):
        p.mkdir()
        (p / "metrics.json").write_text("{}")
    staged = StagedDir(tmp_path / "run")
    assert not stale.exists() and live.exists() and foreign.exists()
    staged.discard()
    assert not staged.path.exists()
