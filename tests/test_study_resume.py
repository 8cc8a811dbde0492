"""Kill-and-resume: SIGKILL a running study (driver and workers), then resume it."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from undulate.study import scan_runs
from undulate.study.storage import read_record

HERE = Path(__file__).resolve().parent
N_RUNS = 24

CLI = (
    "import sys; from undulate.interfaces.cli_study import study_app; "
    "study_app(prog_name='study')"
)


def _cmd(sweep: Path, out: Path) -> list[str]:
    return [sys.executable, "-c", CLI, "run", str(sweep), "--out", str(out), "--workers", "2",
            "--runner", "_study_fakes:slow_run"]


def _env(log: Path, tag: str) -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(HERE), env.get("PYTHONPATH", "")])
    env.update(UNDULATE_FAKE_LOG=str(log), UNDULATE_FAKE_TAG=tag, UNDULATE_FAKE_SLEEP="0.25")
    return env


def test_sigkill_then_resume(tmp_path: Path) -> None:
    sweep = tmp_path / "SWEEP.toml"
    hs = [round(0.1 + 0.05 * i, 4) for i in range(N_RUNS)]
    sweep.write_text(
        '[base]\n[base.rods]\nN = 1\nL = 60.0\n[base.mesh]\ndx_rod = 2.0\ndx_far = 6.0\n'
        f'[sweep]\n"rods.h" = {json.dumps(hs)}\n'
    )
    out = tmp_path / "study"
    log = tmp_path / "log.txt"
    proc = subprocess.Popen(_cmd(sweep, out), env=_env(log, "first"), start_new_session=True,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    deadline = time.monotonic() + 60
    try:
        while time.monotonic() < deadline:
            if len(scan_runs(out).records) >= 6:
                break
            assert proc.poll() is None, proc.stdout.read().decode()
            time.sleep(0.02)
        else:
            raise AssertionError("study did not make progress")
    finally:
        os.killpg(proc.pid, signal.SIGKILL)  # the driver and its worker processes
        proc.wait()
    time.sleep(0.3)

    # every record on disk is complete and valid; nothing half-written is read as valid
    files = [p for p in (out / "runs").iterdir() if p.suffix == ".json"]
    assert files and len(files) < N_RUNS
    for p in files:
        assert read_record(p) is not None, p
    before = {i: r["finished"] for i, r in scan_runs(out).records.items()}
    h_before = {r["params"]["rods.h"] for r in scan_runs(out).records.values()}

    res = subprocess.run(_cmd(sweep, out), env=_env(log, "second"), capture_output=True,
                         text=True, timeout=120)
    assert res.returncode == 0, res.stdout + res.stderr
    assert f"skipped {len(before)} done" in res.stderr

    scan = scan_runs(out)
    assert len(scan.records) == N_RUNS and not scan.invalid
    assert all(r["status"] == "ok" and r["attempt"] == 1 for r in scan.records.values())
    assert sorted(r["params"]["rods.h"] for r in scan.records.values()) == hs
    for i, fin in before.items():  # finished runs were not redone
        assert scan.records[i]["finished"] == fin
    lines = [ln.split() for ln in log.read_text().splitlines()]
    second = [float(h) for tag, h in lines if tag == "second"]
    assert len(second) == len(set(second)) == N_RUNS - len(before)
    assert not set(second) & h_before
    assert set(second) | h_before == set(hs)


def test_ctrl_c_stops_the_driver_and_its_workers(tmp_path: Path) -> None:
    """SIGINT to the driver alone: it exits within seconds, and its workers with it (the
    runs in flight are lost, to be made again on resume), instead of waiting for them."""
    sweep = tmp_path / "SWEEP.toml"
    sweep.write_text('[base]\n[base.rods]\nN = 1\n[sweep]\n"rods.h" = [0.2, 0.3, 0.4]\n')
    out = tmp_path / "study"
    env = _env(tmp_path / "log.txt", "int")
    starts = tmp_path / "starts.txt"
    env.update(UNDULATE_FAKE_SLEEP="300", UNDULATE_FAKE_STARTS=str(starts))
    # Ctrl-C as in a terminal, also when the tests run in a background job (which starts
    # its children with SIGINT ignored: the driver then slept through the signal, measured)
    cmd = _cmd(sweep, out)
    cmd[2] = "import signal; signal.signal(signal.SIGINT, signal.default_int_handler); " + CLI
    proc = subprocess.Popen(cmd, env=env, start_new_session=True,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:  # both workers have begun a (300 s) run
            if starts.exists() and len(starts.read_text().split()) >= 2:
                break
            assert proc.poll() is None, proc.stdout.read().decode()
            time.sleep(0.1)
        else:
            raise AssertionError("the workers did not start their runs")
        proc.send_signal(signal.SIGINT)
        proc.wait(timeout=90)  # long before the runs in flight would end
        assert proc.returncode != 0
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:  # the workers are gone too
            try:
                os.killpg(proc.pid, 0)
            except ProcessLookupError:
                break
            time.sleep(0.1)
        else:
            raise AssertionError("worker processes outlived the interrupted driver")
    finally:
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    assert not scan_runs(out).records  # nothing finished, nothing half-written
