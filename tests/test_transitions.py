"""Transitions by bisection: brackets that close to +-tol on either side of the change of n,
shared runs per gap, resumption without new runs, and clear errors."""

from __future__ import annotations

import json

import _study_fakes as fakes
import pandas as pd
import pytest
from typer.testing import CliRunner

from undulate.interfaces.cli import app
from undulate.study import StudyError, run_study
from undulate.study import transitions as tr


def _rounds(out):
    calls: list[int] = []

    def run_round(study):
        calls.append(len(study.runs))
        run_study(study, out, run_fn=fakes.fake_run, workers=1, progress=False,
                  artifacts=False)

    return run_round, calls


def _n_at(out, s, h):
    for p in (out / "runs").glob("*.json"):
        rec = json.loads(p.read_text())
        if rec["params"] == {"rods.h": h, "rods.s": s} and rec["status"] == "ok":
            return rec["record"]["n_mode"]
    raise AssertionError(f"no run at s={s}, h={h}")


def test_bisection_brackets_the_change_and_resumes(tmp_path) -> None:
    run_round, calls = _rounds(tmp_path)
    table = tr.find_transitions(tmp_path, run_round, s_values=[0.0, 50.0], tol=0.01,
                                quick=True)
    assert list(table["transition"]) == ["3->1", "5->3", "7->5"] * 2
    ok = table[table["status"] == "ok"]
    assert len(ok) >= 4, table
    for r in ok.itertuples():
        assert r.h_hi - r.h_lo <= 0.02 + 1e-9 and r.h_lo < r.h_star < r.h_hi
        target = tr.TRANSITIONS[r.transition]
        assert _n_at(tmp_path, r.s, r.h_lo) > target >= _n_at(tmp_path, r.s, r.h_hi)
        assert r.n_lo > target >= r.n_hi
    # each round runs more, and all transitions at a gap share the coarse grid
    assert calls == sorted(calls) and calls[0] == 2 * len(tr.COARSE_H)
    assert set(table["runs"]) == {table[table.s == s]["runs"].iloc[0] for s in (0.0, 50.0)}
    # bundling: at s = 0 the five rods act as one rod 5 b wide, stiffer, so each transition
    # comes at a smaller h than for far-apart rods
    for name in ("3->1", "5->3"):
        g = ok[ok.transition == name].set_index("s")["h_star"]
        if {0.0, 50.0} <= set(g.index):
            assert g[0.0] < g[50.0]
    again, calls2 = _rounds(tmp_path)
    table2 = tr.find_transitions(tmp_path, again, s_values=[0.0, 50.0], tol=0.01, quick=True)
    pd.testing.assert_frame_equal(table, table2)
    n_files = len(list((tmp_path / "runs").glob("*.json")))
    assert n_files == max(calls2)  # resumed: nothing new was simulated


def test_known_table_points_replace_the_coarse_grid(tmp_path) -> None:
    run_round, calls = _rounds(tmp_path)
    hs = [0.1 * k for k in range(1, 21)]
    known = pd.DataFrame({"status": "ok", "s": 50.0, "h": hs,
                          "n_mode": [9 if h < 0.45 else 5 if h < 0.85 else 3 if h < 1.35 else 1
                                     for h in hs]})
    table = tr.find_transitions(tmp_path, run_round, s_values=[50.0], tol=0.01, quick=True,
                                known=known)
    assert calls[0] < len(tr.COARSE_H)  # the first round bisects at once
    row = table.set_index("transition").loc["3->1"]
    assert row["n_lo"] > 1 >= row["n_hi"] and row["h_hi"] - row["h_lo"] <= 0.02 + 1e-9


def test_bad_input_is_one_line() -> None:
    for bad in ("3-1", "3->2", "4->2", "5->1", "x->y"):
        with pytest.raises(StudyError, match="--transition"):
            tr.parse_transition(bad)
    assert tr.parse_transition(" 5 -> 3 ") == ("5->3", 3)
    with pytest.raises(StudyError, match="--tol"):
        tr.find_transitions(".", lambda s: None, tol=0.0)
    with pytest.raises(StudyError, match="--s"):
        tr.find_transitions(".", lambda s: None, s_values=[-1.0])


def test_cli_writes_table_and_figure(tmp_path, monkeypatch) -> None:
    monkeypatch.setenv("UNDULATE_STUDY_RUNNER", "_study_fakes:fake_run")
    out = tmp_path / "tr"
    res = CliRunner().invoke(app, ["study", "transitions", "--out", str(out), "--quick",
                                   "--s", "10", "--transition", "3->1", "-j", "1"])
    assert res.exit_code == 0, res.output
    t = pd.read_csv(out / "table.csv")
    assert list(t.columns[:6]) == ["transition", "s", "h_star", "h_lo", "h_hi", "n_lo"]
    assert "runs" in t and (out / "transitions.png").stat().st_size > 1000
    res = CliRunner().invoke(app, ["study", "transitions", "--out", str(out), "--transition",
                                   "4->2"])
    assert res.exit_code == 2 and "two odd numbers" in res.output
