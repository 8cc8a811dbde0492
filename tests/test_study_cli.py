"""The ``undulate study`` CLI through typer's CliRunner."""

from __future__ import annotations

from pathlib import Path

import pytest
import typer
from typer.testing import CliRunner

from undulate.interfaces.cli_study import study_app

app = typer.Typer()
app.add_typer(study_app, name="study")
runner = CliRunner()


@pytest.fixture(autouse=True)
def _fake_runner(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("UNDULATE_STUDY_RUNNER", "_study_fakes:fake_run")


def test_unknown_preset_is_one_clear_error(tmp_path: Path) -> None:
    res = runner.invoke(app, ["study", "run", "bogus", "--out", str(tmp_path / "x")])
    assert res.exit_code == 2
    text = res.output
    assert "unknown preset 'bogus'" in text
    for name in ("single-rod-h", "single-rod-eps0", "parallel-phase-diagram"):
        assert name in text


def test_run_status_figures_report(tmp_path: Path) -> None:
    out = tmp_path / "st"
    res = runner.invoke(app, ["study", "run", "single-rod-h", "--quick", "--out", str(out),
                              "--workers", "1", "--seeds", "2", "--no-artifacts"])
    assert res.exit_code == 0, res.output
    assert "38 runs" in res.output and "ran 38" in res.output
    assert not (out / "artifacts").exists()
    res = runner.invoke(app, ["study", "run", "single-rod-h", "--quick", "--out", str(out),
                              "--workers", "1", "--seeds", "2"])
    assert res.exit_code == 0 and "ran 0" in res.output and "skipped 36 done" in res.output

    res = runner.invoke(app, ["study", "status", str(out)])
    assert res.exit_code == 0, res.output
    assert "total" in res.output and "38" in res.output and "pending" in res.output
    assert (out / "results.parquet").is_file()

    res = runner.invoke(app, ["study", "figures", str(out)])
    assert res.exit_code == 0, res.output
    assert (out / "figures" / "single_rod_h.png").is_file()
    assert (out / "figures" / "single_rod_h.pdf").is_file()

    res = runner.invoke(app, ["study", "report", str(out)])
    assert res.exit_code == 0, res.output
    text = (out / "report.md").read_text()
    assert "eq. (1) slope" in text and "figures/single_rod_h.png" in text


def test_status_shows_failures_and_retry(tmp_path: Path) -> None:
    sweep = tmp_path / "s.toml"
    sweep.write_text('[base.rods]\nL = 60.0\n[sweep]\n"rods.h" = [0.2, 0.42, 1.3]\n')
    out = tmp_path / "o"
    res = runner.invoke(app, ["study", "run", str(sweep), "--out", str(out), "--workers", "1"])
    assert res.exit_code == 0, res.output
    assert "2 failed" in res.output
    res = runner.invoke(app, ["study", "status", str(out)])
    assert "fake divergence" in res.output and "failures" in res.output
    res = runner.invoke(app, ["study", "run", str(sweep), "--out", str(out), "--workers", "1"])
    assert "use --retry-failed" in res.output
    res = runner.invoke(app, ["study", "run", str(sweep), "--out", str(out), "--workers", "1",
                              "--retry-failed"])
    assert "ran 2" in res.output


def test_bad_sweep_and_not_a_study(tmp_path: Path) -> None:
    sweep = tmp_path / "s.toml"
    sweep.write_text('[sweep]\n"rods.h" = [0.2, 50.0]\n')
    res = runner.invoke(app, ["study", "run", str(sweep), "--out", str(tmp_path / "o")])
    assert res.exit_code == 2 and "rods.h" in res.output and "run 2/2" in res.output
    for cmd in ("status", "figures", "report"):
        res = runner.invoke(app, ["study", cmd, str(tmp_path / "nothing")])
        assert res.exit_code == 2 and "not a study directory" in res.output


def test_batch_with_dask_is_refused_in_one_line(tmp_path: Path) -> None:
    res = runner.invoke(app, ["study", "run", "single-rod-h", "--quick", "--out",
                              str(tmp_path / "s"), "--batch", "4", "--dask", "tcp://127.0.0.1:1"])
    assert res.exit_code == 2
    assert "batch: runs are batched in local workers only" in res.output


def test_a_sweep_over_L_and_eps0_makes_one_atlas_per_combination(tmp_path: Path) -> None:
    """`study atlas` on a sweep that also sweeps rods.L and release.eps0 writes one atlas per
    (L, eps0) into the --out folder, each holding its own L and eps0; a file --out is refused
    with one line."""
    from undulate.design.atlas import load_atlas

    sweep = tmp_path / "grid.toml"
    sweep.write_text('name = "grid"\n[base.rods]\nN = 1\n[sweep]\n"rods.L" = [40.0, 60.0]\n'
                     '"release.eps0" = [0.25, 0.5]\n"rods.h" = [0.2, 0.3, 0.5]\n')
    out = tmp_path / "st"
    res = runner.invoke(app, ["study", "run", str(sweep), "--out", str(out), "--workers", "1",
                              "--no-artifacts"])
    assert res.exit_code == 0, res.output
    bad = runner.invoke(app, ["study", "atlas", str(out), "--out", str(tmp_path / "a.csv")])
    assert bad.exit_code != 0 and "give a folder" in bad.output
    assert "Traceback" not in bad.output
    res = runner.invoke(app, ["study", "atlas", str(out), "--out", str(tmp_path / "atlases")])
    assert res.exit_code == 0, res.output
    files = sorted(p.name for p in (tmp_path / "atlases").glob("*.csv"))
    assert files == ["L40_eps0-0.25.csv", "L40_eps0-0.5.csv", "L60_eps0-0.25.csv",
                     "L60_eps0-0.5.csv"]
    one = load_atlas(tmp_path / "atlases" / "L60_eps0-0.25.csv")
    assert (one.meta["L"], one.meta["eps0"], one.meta["N"]) == (60.0, 0.25, 1)
    assert sorted(one.points["h"]) == [0.2, 0.3, 0.5]


def test_studies_are_pooled_into_one_atlas_of_one_set_up(tmp_path: Path) -> None:
    """`study atlas A B` pools a diagram and its refinement (their points together); studies
    run on different set-ups are refused with one line."""
    from undulate.design.atlas import load_atlas

    def sweep(name: str, hs: str, *setup: str) -> Path:
        toml = tmp_path / f"{name}.toml"
        toml.write_text(f'name = "{name}"\n[base.rods]\nN = 5\n[sweep]\n"rods.h" = [{hs}]\n'
                        '"rods.s" = [5.0, 10.0]\n')
        out = tmp_path / name
        res = runner.invoke(app, ["study", "run", str(toml), "--out", str(out), "--workers",
                                  "1", "--no-artifacts", *setup])
        assert res.exit_code == 0, res.output
        return out

    coarse, fine = sweep("coarse", "0.2, 0.4"), sweep("fine", "0.3")
    res = runner.invoke(app, ["study", "atlas", str(coarse), str(fine), "--out",
                              str(tmp_path / "a.csv")])
    assert res.exit_code == 0, res.output
    atlas = load_atlas(tmp_path / "a.csv")
    assert sorted(set(atlas.points["h"])) == [0.2, 0.3, 0.4] and atlas.meta["points"] == 6
    other = sweep("other", "0.5", "--setup", "study-2022")
    bad = runner.invoke(app, ["study", "atlas", str(coarse), str(other), "--out",
                              str(tmp_path / "b.csv")])
    assert bad.exit_code != 0 and "different set-ups" in bad.output
    assert "Traceback" not in bad.output and not (tmp_path / "b.csv").exists()
