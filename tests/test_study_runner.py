"""The study runner: records, failures, resume, retry, atomicity, workers, storage table."""

from __future__ import annotations

import json
from pathlib import Path

import _study_fakes as fakes
import pandas as pd
import pytest

from undulate.study import StudyError, build_study, collect, get_preset, run_study, scan_runs
from undulate.study.runner import execute_run
from undulate.study.storage import atomic_write_json, read_record


def _small_study(hs: list[float], name: str = "t"):
    base = {"rods": {"N": 1, "L": 60.0}, "mesh": {"dx_rod": 2.0, "dx_far": 6.0}}
    return build_study(name, base, {"rods.h": hs}, kind="sweep")


def _records(d: Path) -> dict[str, dict]:
    return scan_runs(d).records


def test_progress_is_reported_when_not_a_terminal(tmp_path: Path, capsys) -> None:
    """In a log file or a batch job (stderr not a terminal) every finished run prints a line
    with the count, the failures and an ETA; a resumed study counts the runs done before."""
    study = _small_study([0.2, 0.42, 0.6])
    run_study(study, tmp_path, run_fn=fakes.fake_run, workers=1)
    lines = [ln for ln in capsys.readouterr().err.splitlines() if ln.startswith("study: ")]
    assert len(lines) == 3
    assert lines[-1].startswith("study: 3/3 done (this sitting: ok 2, failed 1)")
    assert "ETA" in lines[0]
    run_study(study, tmp_path, run_fn=fakes.fake_run, workers=1, retry_failed=True)
    lines = [ln for ln in capsys.readouterr().err.splitlines() if ln.startswith("study: ")]
    assert lines == [lines[0]] and lines[0].startswith("study: 3/3 done (this sitting: ok 0, "
                                                       "failed 1)")


def test_run_in_process_records_ok_and_failed(tmp_path: Path) -> None:
    study = _small_study([0.2, 0.42, 0.6])
    s = run_study(study, tmp_path, run_fn=fakes.fake_run, workers=1, progress=False)
    assert (s.ran, s.ok, s.failed) == (3, 2, 1)
    recs = _records(tmp_path)
    assert len(recs) == 3 and {p.name for p in (tmp_path / "runs").iterdir()} == {
        f"{r.id}.json" for r in study.runs
    }
    bad = next(r for r in recs.values() if r["status"] == "failed")
    assert bad["params"] == {"rods.h": 0.42}
    assert bad["error"].startswith("RuntimeError: fake divergence")
    assert "fake_run" in bad["traceback"] and bad["record"] is None
    good = next(r for r in recs.values() if r["status"] == "ok")
    assert good["record"]["n_mode"] >= 1 and good["seed"] == 0 and good["attempt"] == 1
    assert good["elapsed_s"] >= 0 and good["case"]["rods"]["h"] in (0.2, 0.6)
    # CPU time of the run's process: recorded, and not more than its threads could spend
    assert 0 <= good["cpu_s"] <= good["elapsed_s"] * 64 + 1.0
    # which engine ran it (digest of the source) and on how many cores
    from undulate.study.runner import engine_id

    assert good["engine"] == engine_id() and len(good["engine"]) == 12
    assert bad["engine"] == good["engine"] and good["cpus"] >= 1
    # a failure of the label itself never fails a run (execute_run never raises)
    import undulate.study.execute as R

    R.engine_id.cache_clear()
    real = R.ENGINE_PARTS
    R.ENGINE_PARTS = None  # iterating it raises inside engine_id
    try:
        assert R.engine_id() is None
    finally:
        R.ENGINE_PARTS = real
        R.engine_id.cache_clear()
    assert R.engine_id() == good["engine"]
    # artifacts directory passed as `out`
    assert (tmp_path / "artifacts" / good["id"] / "shape.txt").is_file()
    meta = json.loads((tmp_path / "study.json").read_text())
    assert meta["name"] == "t" and meta["n_runs"] == 3 and len(meta["runs"]) == 3
    assert (tmp_path / "results.parquet").is_file()


def test_resume_skips_and_retry_failed(tmp_path: Path) -> None:
    study = _small_study([0.2, 0.42, 0.6])
    run_study(study, tmp_path, run_fn=fakes.fake_run, workers=1, progress=False)
    before = {i: r["finished"] for i, r in _records(tmp_path).items()}
    s = run_study(study, tmp_path, run_fn=fakes.fake_run, workers=1, progress=False)
    assert (s.ran, s.skipped_ok, s.skipped_failed) == (0, 2, 1)
    assert {i: r["finished"] for i, r in _records(tmp_path).items()} == before
    s = run_study(study, tmp_path, run_fn=fakes.fake_run, workers=1, progress=False,
                  retry_failed=True)
    assert (s.ran, s.failed, s.skipped_ok) == (1, 1, 2)
    bad = [r for r in _records(tmp_path).values() if r["status"] == "failed"]
    assert len(bad) == 1 and bad[0]["attempt"] == 2
    # a run function that now succeeds turns the failure into ok
    s = run_study(study, tmp_path, run_fn=fakes.slow_run, workers=1, progress=False,
                  retry_failed=True)
    assert s.ok == 1 and all(r["status"] == "ok" for r in _records(tmp_path).values())


def test_invalid_and_tmp_files_are_ignored_and_redone(tmp_path: Path) -> None:
    study = _small_study([0.2, 0.6])
    run_study(study, tmp_path, run_fn=fakes.fake_run, workers=1, progress=False)
    a, b = study.runs
    pa = tmp_path / "runs" / f"{a.id}.json"
    text = pa.read_text()
    pa.write_text(text[: len(text) // 2])  # truncated record (e.g. a non-atomic writer)
    (tmp_path / "runs" / f".{b.id}.json.x1.tmp").write_text("{half")
    (tmp_path / "runs" / "deadbeef00000000.json").write_text('{"id": "other"}')
    scan = scan_runs(tmp_path)
    assert set(scan.records) == {b.id}
    assert len(scan.invalid) == 2 and len(scan.tmp) == 1
    assert read_record(pa) is None
    s = run_study(study, tmp_path, run_fn=fakes.fake_run, workers=1, progress=False)
    assert s.ran == 1 and len(s.invalid_files) == 2
    assert read_record(pa)["status"] == "ok"


def test_atomic_write_leaves_old_file_on_error(tmp_path: Path) -> None:
    p = tmp_path / "runs" / "x.json"
    atomic_write_json(p, {"v": 1})
    with pytest.raises(ValueError):
        atomic_write_json(p, {"v": float("nan")})  # not JSON: nothing replaced
    assert json.loads(p.read_text()) == {"v": 1}
    assert [q.name for q in p.parent.iterdir()] == ["x.json"]


def test_process_pool_matches_in_process(tmp_path: Path) -> None:
    study = _small_study([0.1, 0.2, 0.3, 0.42, 0.5, 0.6, 0.7])
    s = run_study(study, tmp_path / "pool", run_fn=fakes.fake_run, workers=2, progress=False,
                  artifacts=False)
    assert (s.ok, s.failed) == (6, 1)
    s1 = run_study(study, tmp_path / "seq", run_fn=fakes.fake_run, workers=1, progress=False,
                   artifacts=False)
    assert (s1.ok, s1.failed) == (6, 1)
    ra, rb = _records(tmp_path / "pool"), _records(tmp_path / "seq")
    assert set(ra) == set(rb)
    for i in ra:
        assert ra[i]["record"] == rb[i]["record"]
        assert ra[i]["artifacts"] is None
    assert not (tmp_path / "pool" / "artifacts").exists()


def test_workers_share_the_cores_for_pardiso(tmp_path: Path, monkeypatch) -> None:
    """Pool workers factor with their share of the cores (threads never outnumber cores),
    unless the user set UNDULATE_PARDISO_THREADS, which they then keep."""
    from undulate.study.runner import usable_cpus, worker_pardiso_threads

    assert worker_pardiso_threads(2, cpus=2) == 1
    assert worker_pardiso_threads(1, cpus=2) == 2
    assert worker_pardiso_threads(4, cpus=16) == 4
    assert worker_pardiso_threads(8, cpus=2) == 1
    study = _small_study([0.2, 0.3])
    monkeypatch.delenv("UNDULATE_PARDISO_THREADS", raising=False)
    run_study(study, tmp_path / "a", run_fn="_study_fakes:threads_run", workers=2,
              progress=False, artifacts=False)
    want = str(max(1, (usable_cpus() or 1) // 2))
    assert {r["record"]["pardiso_threads_env"] for r in _records(tmp_path / "a").values()} == {
        want}
    monkeypatch.setenv("UNDULATE_PARDISO_THREADS", "3")
    run_study(study, tmp_path / "b", run_fn="_study_fakes:threads_run", workers=2,
              progress=False, artifacts=False)
    assert {r["record"]["pardiso_threads_env"] for r in _records(tmp_path / "b").values()} == {
        "3"}


def test_string_runner_and_worker_crash(tmp_path: Path) -> None:
    study = _small_study([0.3, 0.5, 0.7])
    s = run_study(study, tmp_path, run_fn="_study_fakes:crash_run", workers=2, progress=False,
                  artifacts=False)
    recs = _records(tmp_path)
    assert len(recs) == 3 and (s.ok, s.failed) == (2, 1)
    crashed = [r for r in recs.values() if r["status"] == "failed"]
    assert crashed[0]["params"]["rods.h"] == 0.5 and "worker process died" in crashed[0]["error"]


def test_execute_run_never_raises() -> None:
    res = execute_run("no_such_module:f", {"rods": {"h": 0.3}}, None, False)
    assert res["status"] == "failed" and "cannot import" in res["error"]
    res = execute_run(fakes.fake_run, {"rods": {"h": -1.0}}, None, False)
    assert res["status"] == "failed" and "rods.h" in res["error"]


def test_other_study_in_same_dir_refused(tmp_path: Path) -> None:
    run_study(_small_study([0.2], name="a"), tmp_path, run_fn=fakes.fake_run, workers=1,
              progress=False)
    with pytest.raises(StudyError, match="already holds study 'a'"):
        run_study(_small_study([0.2], name="b"), tmp_path, run_fn=fakes.fake_run, workers=1,
                  progress=False)


def test_collect_table(tmp_path: Path) -> None:
    study = get_preset("parallel-phase-diagram", quick=True)
    run_study(study, tmp_path, run_fn=fakes.fake_run, workers=1, progress=False, artifacts=False)
    df = collect(tmp_path)
    assert len(df) == 12
    for col in ("run_id", "status", "seed", "rods.h", "rods.s", "h", "s", "N", "eps0", "l_mean",
                "family", "elapsed_s", "cpu_s", "error"):
        assert col in df, col
    s0 = df[df["rods.s"] == 0.0]
    assert (s0["N"] == 1).all() and (s0["b"] == 5.0).all()
    assert list(df["run_id"]) == [r.id for r in study.runs]  # study order
    back = pd.read_parquet(tmp_path / "results.parquet")
    assert len(back) == 12 and set(back["status"]) <= {"ok", "failed"}
    # each record keeps the validated case with every default, and the table reads it
    rec = json.loads(next((tmp_path / "runs").glob("*.json")).read_text())
    assert rec["case_resolved"]["fabric"]["margin_y"] == pytest.approx(df["margin_y"].iloc[0])
    # the sheet and the mesh of each run: the quick variant's coarser mesh
    assert (df["dx_rod"] == 2.0).all() and (df["dx_far"] == 6.0).all()
    assert (df["mesh_kind"] == "unstructured").all() and (df["margin_x"] > 0).all()
    assert rec["case_resolved"]["solver"]["max_iter"] >= 1 and rec["version"]
    assert (df["engine"] == rec["engine"]).all()


def test_csv_table_leads_with_the_documented_columns(tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from undulate.interfaces.cli import app
    from undulate.study.storage import CSV_COLUMNS

    study = _small_study([0.2, 0.42, 0.6])
    run_study(study, tmp_path, run_fn=fakes.fake_run, workers=1, progress=False)
    res = CliRunner().invoke(app, ["study", "table", str(tmp_path)])
    assert res.exit_code == 0, res.output
    df = pd.read_csv(tmp_path / "table.csv")
    assert tuple(df.columns[: len(CSV_COLUMNS)]) == CSV_COLUMNS
    assert len(df) == 3 and sorted(df["status"]) == ["failed", "ok", "ok"]
    ok = df[df["status"] == "ok"]
    assert ok["l_mean"].notna().all() and ok["h"].tolist() == [0.2, 0.6]
    # a folder as --out is one clear line, not a traceback
    res = CliRunner().invoke(app, ["study", "table", str(tmp_path), "--out", str(tmp_path)])
    assert res.exit_code == 2 and "is a folder" in res.output and "Traceback" not in res.output


def test_progress_bar_on_a_terminal(tmp_path: Path) -> None:
    import io

    from rich.console import Console

    buf = io.StringIO()
    console = Console(file=buf, force_terminal=True, width=120)
    s = run_study(_small_study([0.2, 0.42, 0.6]), tmp_path, run_fn=fakes.fake_run, workers=1,
                  progress=True, console=console)
    assert s.ran == 3
    text = buf.getvalue()
    assert "3/3" in text and "failed" in text and "running" in text


def test_unresolvable_runner_fails_fast(tmp_path: Path) -> None:
    with pytest.raises(StudyError, match="cannot import"):
        run_study(_small_study([0.2]), tmp_path, run_fn="no_such_module:f", progress=False)
    assert not list((tmp_path / "runs").glob("*.json"))


def test_report_counts_runs_per_engine_old_records_included() -> None:
    """Records written before the engine was kept show as "(not recorded)" beside the rest."""
    from undulate.study.report import _cost_lines

    df = pd.DataFrame({"status": ["ok", "ok", "ok"], "elapsed_s": [1.0, 2.0, 3.0],
                       "engine": [None, "abc123def456", "abc123def456"]})
    line = next(t for t in _cost_lines(df) if t.startswith("| engine"))
    assert "abc123def456: 2" in line and "(not recorded): 1" in line
    assert not any("CPU" in t for t in _cost_lines(df))  # none recorded: no CPU lines


def test_report_sums_cpu_times_where_recorded() -> None:
    """The cost section adds the runs' CPU times (records without one are left out of it)."""
    from undulate.study.report import _cost_lines

    df = pd.DataFrame({"status": ["ok", "ok", "ok"], "elapsed_s": [10.0, 20.0, 30.0],
                       "cpu_s": [None, 1800.0, 5400.0]})
    lines = _cost_lines(df)
    assert "| runs with CPU time recorded | 2 |" in lines
    assert "| sum of CPU times [h] | 2.00 |" in lines
    assert any(t.startswith("| median / max CPU time per run [s] | 3600.0 / 5400.0") for t in lines)


def test_report_counts_the_hours_with_runs_in_progress_once() -> None:
    """Runs in parallel count once and the gap between two sittings not at all."""
    from undulate.study.report import _busy_hours, _cost_lines

    df = pd.DataFrame({
        "status": ["ok", "ok", "ok", "failed"],
        "elapsed_s": [3600.0, 1800.0, 3600.0, 60.0],
        "started": ["2026-01-01T00:00:00+00:00", "2026-01-01T00:30:00+00:00",
                    "2026-01-02T00:00:00+00:00", None],
        "finished": ["2026-01-01T01:00:00+00:00", "2026-01-01T01:00:00+00:00",
                     "2026-01-02T01:00:00+00:00", "2026-01-02T01:00:00+00:00"],
        "cpus": [2, 2, 16, None]})
    assert _busy_hours(df) == pytest.approx(2.0)
    lines = _cost_lines(df)
    assert "| ok runs per hour of it | 1.5 |" in lines
    assert "| usable cores of the machine (cores: runs) | 2: 2, 16: 1 |" in lines


def test_workers_are_replaced_and_one_worker_still_isolates(tmp_path: Path, monkeypatch
                                                            ) -> None:
    """The engine (a runner by name) runs in worker processes even with -j 1, so a crash
    cannot end the study, and each worker is replaced after RUNS_PER_WORKER runs (a process
    that had compiled kernels for many sheets died in LLVM, out of memory)."""
    import os

    from undulate.study import workers
    from undulate.study.spec import coarse_first

    monkeypatch.setattr(workers, "RUNS_PER_WORKER", 2)
    study = _small_study([0.2, 0.3, 0.4, 0.6, 0.7])
    run_study(study, tmp_path / "a", run_fn="_study_fakes:pid_run", workers=1,
              progress=False, artifacts=False)
    recs = _records(tmp_path / "a")
    pids = [recs[r.id]["record"]["pid"] for r in coarse_first(study.runs)]  # the run order
    assert os.getpid() not in pids
    assert len(set(pids)) == 3  # 2 + 2 + 1 runs
    assert pids[0] == pids[1] != pids[2] == pids[3] != pids[4]
    s = run_study(_small_study([0.3, 0.5, 0.7]), tmp_path / "b",
                  run_fn="_study_fakes:crash_run", workers=1, progress=False, artifacts=False)
    assert (s.ok, s.failed) == (2, 1)  # the study outlived the crash


def test_workers_end_with_a_killed_driver(tmp_path: Path) -> None:
    """A study whose driver is killed (SIGKILL: no clean-up) leaves no worker running on."""
    import os
    import signal
    import subprocess
    import sys
    import textwrap
    import time

    if not sys.platform.startswith("linux"):
        pytest.skip("parent-death signal: Linux only")
    starts = tmp_path / "starts.txt"
    script = textwrap.dedent(f"""
        import sys
        sys.path.insert(0, {str(Path(__file__).parent)!r})
        from undulate.study import build_study, run_study
        study = build_study("k", {{"rods": {{"N": 1}}}}, {{"rods.h": [0.2, 0.3, 0.4, 0.5]}},
                            kind="sweep")
        run_study(study, {str(tmp_path / "out")!r}, run_fn="_study_fakes:slow_run", workers=2,
                  progress=False)
    """)
    env = {**os.environ, "UNDULATE_FAKE_SLEEP": "60", "UNDULATE_FAKE_STARTS": str(starts)}
    driver = subprocess.Popen([sys.executable, "-c", script], env=env)
    deadline = time.time() + 120
    while time.time() < deadline and (not starts.exists()
                                      or len(starts.read_text().split()) < 2):
        time.sleep(0.2)
    assert starts.exists() and len(starts.read_text().split()) == 2, "workers did not start"
    def parent_of(pid: str) -> int:
        try:
            stat = Path(f"/proc/{pid}/stat").read_text()
        except OSError:
            return -1
        return int(stat.rsplit(")", 1)[1].split()[1])

    pids = [int(p) for p in os.listdir("/proc") if p.isdigit() and parent_of(p) == driver.pid]
    assert pids
    driver.send_signal(signal.SIGKILL)
    driver.wait()
    time.sleep(3)
    alive = [p for p in pids if os.path.exists(f"/proc/{p}") and
             "zombie" not in open(f"/proc/{p}/status").read().lower()]
    for p in alive:  # clean up before failing
        os.kill(p, signal.SIGKILL)
    assert not alive, f"workers {alive} ran on after their driver was killed"


def test_a_run_made_on_another_rod_spacing_is_run_again(tmp_path: Path, capsys) -> None:
    """The default rod spacing depends on the rods (finer for thin ones): a finished run
    whose record holds another spacing than its case resolves to now is a result of another
    mesh, and resuming the study runs it again; the others stay."""
    from undulate.model import case_from_dict

    study = build_study("t", {"rods": {"N": 1, "L": 60.0, "E_B": 1000.0}},
                        {"rods.h": [0.1, 0.6]}, kind="sweep")
    assert [case_from_dict(r.case).mesh.dx_rod for r in study.runs] == [0.5, 1.0]
    run_study(study, tmp_path, run_fn=fakes.fake_run, workers=1, progress=False)
    s = run_study(study, tmp_path, run_fn=fakes.fake_run, workers=1, progress=False)
    assert (s.ran, s.stale, s.skipped_ok) == (0, 0, 2)
    thin = next(r for r in study.runs if r.case["rods"]["h"] == 0.1)
    path = tmp_path / "runs" / f"{thin.id}.json"
    rec = json.loads(path.read_text())
    rec["case_resolved"]["mesh"]["dx_rod"] = 1.0  # as made before the finer default
    atomic_write_json(path, rec)
    capsys.readouterr()
    s = run_study(study, tmp_path, run_fn=fakes.fake_run, workers=1, progress=True)
    assert (s.ran, s.stale, s.skipped_ok) == (1, 1, 1)
    assert "1 finished runs run again" in capsys.readouterr().err
    again = read_record(path)
    assert again["case_resolved"]["mesh"]["dx_rod"] == 0.5 and again["attempt"] == 2
