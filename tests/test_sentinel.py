"""The sentinel preset: its cases, the set-up laid over them, and the judgement table."""

from __future__ import annotations

import pandas as pd
import pytest

from undulate.study import StudyError, get_preset, sentinel
from undulate.study.presets import parse_setting, setup_from


def test_sentinel_has_at_most_16_valid_runs_in_each_region() -> None:
    study = get_preset("sentinel")
    assert 8 <= len(study.runs) <= 16
    assert len({r.id for r in study.runs}) == len(study.runs)
    singles = [r for r in study.runs if r.case["rods"]["N"] == 1]
    five = [r for r in study.runs if r.case["rods"]["N"] == 5]
    assert min(r.case["rods"]["h"] for r in singles) <= 0.1
    assert max(r.case["rods"]["h"] for r in singles) >= 1.0
    corners = {(r.case["rods"]["h"] <= 0.5, r.case["rods"]["s"] >= 25) for r in five}
    assert corners == {(True, True), (True, False), (False, True), (False, False)}


def test_setup_is_laid_under_every_run_and_changes_ids() -> None:
    plain = get_preset("sentinel")
    stiff = get_preset("sentinel", setup={"rods": {"E_B": 10000.0}})
    assert all(r.case["rods"]["E_B"] == 10000.0 for r in stiff.runs)
    assert all(r.case["rods"]["E_B"] == 1000.0 for r in plain.runs)  # the reference set-up
    assert not {r.id for r in plain.runs} & {r.id for r in stiff.runs}
    assert stiff.definition["setup"] == {"rods": {"E_B": 10000.0}}
    # the case's own h wins over a set-up's
    h = get_preset("sentinel", setup={"rods": {"h": 0.7}})
    assert sorted({r.case["rods"]["h"] for r in h.runs}) == sorted({c.h for c in
                                                                    sentinel.SENTINEL_CASES})
    pp = get_preset("parallel-phase-diagram", setup={"fabric": {"E": 0.9}})
    assert all(r.case["fabric"]["E"] == 0.9 for r in pp.runs)


def test_parse_setting() -> None:
    assert parse_setting("rods.E_B=10000") == ("rods.E_B", 10000)
    assert parse_setting("mode=inertial") == ("mode", "inertial")
    assert parse_setting('release.clamps=["left","right","top"]') == (
        "release.clamps", ["left", "right", "top"])
    assert setup_from(["rods.E_B=1e4", "mode=inertial"]) == {"rods": {"E_B": 1e4},
                                                             "mode": "inertial"}
    for bad in ("rods.E_B", "=3", "rods..h=1", "rods.h=1 2"):
        with pytest.raises(StudyError, match="--set"):
            parse_setting(bad)
    with pytest.raises(StudyError, match="E_B"):  # a bad value is refused by the case check
        get_preset("sentinel", setup={"rods": {"E_B": -1.0}})


def _row(c: sentinel.SentinelCase, **kw: object) -> dict[str, object]:
    base = {"status": "ok", "h": c.h, "N": c.N, "s": c.s if c.N > 1 else 10.0, "L": 100.0,
            "eps0": 0.5, "b": 1.0, "E_B": 3000.0, "E": 0.45, "t": 0.4,
            "onset_release_strain": 0.05, "l_mean": 20.0, "elapsed_s": 1.0}
    base.update(kw)
    return base


def test_judge_marks_matches_and_mismatches() -> None:
    rows = []
    for c in sentinel.SENTINEL_CASES:
        lo, hi = sentinel.expected_n(c, L=100.0, eps0=0.5, b=1.0, E_B=3000.0, E=0.45, t=0.4)
        rows.append(_row(c, family=c.families[0], n_mode=lo, R_up_mean=0.9, R_down_mean=1.0))
    df = pd.DataFrame(rows)
    judged = sentinel.judge(df)
    s = sentinel.summary(judged)
    assert s["family_match"] == s["n_match"] == s["ok"] == len(sentinel.SENTINEL_CASES)
    assert s["onset_ok"] is True and s["updown_match"] == s["updown_judged"] > 0
    # one case wrong in family and n, onset spread and up flatter: each is caught
    bad = df.copy()
    k = [c.label for c in sentinel.SENTINEL_CASES].index("five-1.6-50")
    bad.loc[k, ["family", "n_mode"]] = ["coherent", 3]
    bad.loc[0, "onset_release_strain"] = 0.2
    bad["R_up_mean"] = 1.2
    judged = sentinel.judge(bad)
    s = sentinel.summary(judged)
    assert s["family_match"] == s["ok"] - 1 and s["n_match"] == s["ok"] - 1
    assert s["onset_ok"] is False and s["updown_match"] == 0
    text = sentinel.markdown(judged, {"rods": {"E_B": 3000.0}})
    assert "five-1.6-50" in text and "MISMATCH" in text and "E_B" in text
    # a missing run is reported, not judged
    assert sentinel.judge(df.drop(index=k))[k]["status"] == "missing"
    # candidates side by side: scores per row, the wrong case starred
    table = sentinel.compare_markdown([("good", None, sentinel.judge(df)),
                                       ("bad", {"rods": {"E_B": 1e4}}, judged)])
    good_row = next(ln for ln in table.splitlines() if ln.startswith("| good"))
    bad_row = next(ln for ln in table.splitlines() if ln.startswith("| bad"))
    n_cases = len(sentinel.SENTINEL_CASES)
    assert f"{n_cases}/{n_cases}" in good_row and "*" not in good_row
    assert f"{n_cases - 1}/{n_cases}" in bad_row and bad_row.endswith("c3* |")


def test_expected_n_from_eq1() -> None:
    single = {c.label: c for c in sentinel.SENTINEL_CASES}
    mat = {"L": 100.0, "eps0": 0.5, "b": 1.0, "E_B": 3000.0, "E": 0.45, "t": 0.4}
    assert sentinel.expected_n(single["single-0.5"], **mat) == (1, 5)  # eq. (1): n = 3
    assert sentinel.expected_n(single["single-2"], **mat) == (1, 1)
    assert sentinel.expected_n(single["five-1.6-2.5"], **mat) == (1, 1)


def test_other_setup_in_same_dir_refused(tmp_path) -> None:
    """A study directory holds one set-up: resuming it on another is refused, not mixed."""
    import _study_fakes as fakes

    from undulate.study import run_study

    plain = get_preset("single-rod-eps0", quick=True)
    run_study(plain, tmp_path, run_fn=fakes.fake_run, workers=1, progress=False)
    other = get_preset("single-rod-eps0", quick=True, setup={"rods": {"E_B": 10000.0}})
    with pytest.raises(StudyError, match="on the set-up study-2022"):
        run_study(other, tmp_path, run_fn=fakes.fake_run, workers=1, progress=False)
    run_study(plain, tmp_path, run_fn=fakes.fake_run, workers=1, progress=False)  # same: ok
