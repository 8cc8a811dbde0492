"""Study definitions: presets, sweep files, run ids, the s = 0 rule, validation messages."""

from __future__ import annotations

from pathlib import Path

import pytest

from undulate.model import case_from_dict
from undulate.study import StudyError, get_preset, load_sweep_toml, preset_names, run_id
from undulate.study.presets import resolve_study
from undulate.study.spec import build_study, frange, set_path


@pytest.mark.parametrize(
    ("name", "quick", "count"),
    [
        ("single-rod-h", False, 137),
        ("single-rod-eps0", False, 30),
        ("parallel-phase-diagram", False, 420),
        ("single-rod-h", True, 19),
        ("parallel-phase-diagram", True, 12),
    ],
)
def test_preset_sizes_and_valid_cases(name: str, quick: bool, count: int) -> None:
    study = get_preset(name, quick=quick)
    assert len(study.runs) == count
    assert len({r.id for r in study.runs}) == count
    for r in study.runs[:: max(1, count // 10)]:
        case_from_dict(r.case)  # every case validates


def test_single_rod_h_grid_ends_and_defaults() -> None:
    runs = get_preset("single-rod-h").runs
    hs = [r.params["rods.h"] for r in runs if r.seed == 0]
    assert hs[0] == 0.08 and hs[-1] == 2.0 and hs[1] == 0.1 and len(hs) == 97
    # the spread: seeds 1 and 2 at every 5th thickness
    spread = sorted((r.params["rods.h"], r.seed) for r in runs if r.seed > 0)
    assert len(spread) == 40 and spread[:3] == [(0.08, 1), (0.08, 2), (0.18, 1)]
    assert all(r.case["rods"]["N"] == 1 and r.case["release"]["eps0"] == 0.5 for r in runs)


def test_quick_variant_is_cheaper() -> None:
    r = get_preset("single-rod-h", quick=True).runs[0].case
    assert r["rods"]["L"] == 60.0 and r["mesh"]["dx_rod"] == 2.0 and r["release"]["steps"] == 15


def test_s0_means_one_wide_rod() -> None:
    runs = get_preset("parallel-phase-diagram").runs
    s0 = [r for r in runs if r.params["rods.s"] == 0.0]
    assert len(s0) == 20
    for r in s0:
        assert r.case["rods"]["N"] == 1 and r.case["rods"]["b"] == 5.0
    other = [r for r in runs if r.params["rods.s"] > 0]
    assert all(r.case["rods"]["N"] == 5 and r.case["rods"]["b"] == 1.0 for r in other)
    assert sorted({r.params["rods.s"] for r in runs})[:3] == [0.0, 2.5, 5.0]


def test_seeds_axis_and_ids_stable() -> None:
    a = get_preset("single-rod-eps0", seeds=3)
    assert len(a.runs) == 90
    assert sorted({r.seed for r in a.runs}) == [0, 1, 2]
    b = get_preset("single-rod-eps0", seeds=3)
    assert [r.id for r in a.runs] == [r.id for r in b.runs]
    # seed 0 runs of a seeded study are the runs of the unseeded one (same ids)
    plain = {r.id for r in get_preset("single-rod-eps0").runs}
    assert plain == {r.id for r in a.runs if r.seed == 0}


def test_run_id_canonical() -> None:
    assert run_id({"a": 1, "b": {"c": 0.1 * 3}}) == run_id({"b": {"c": 0.3}, "a": 1})
    assert run_id({"a": 1}) != run_id({"a": 2})
    assert frange(0.08, 2.0, 0.02)[-1] == 2.0 and len(frange(0.0, 50.0, 2.5)) == 21


def test_sweep_toml(tmp_path: Path) -> None:
    p = tmp_path / "SWEEP.toml"
    p.write_text(
        'name = "mine"\n[base]\nname = "x"\n[base.rods]\nh = 0.3\nN = 3\n'
        '[sweep]\n"rods.h" = [0.2, 0.4]\nrods.s = {start = 0.0, stop = 10.0, step = 5.0}\n'
        "[options]\nseeds = 2\n"
    )
    study = load_sweep_toml(p)
    assert study.name == "mine" and study.kind == "sweep"
    assert len(study.runs) == 2 * 3 * 2
    s0 = [r for r in study.runs if r.params["rods.s"] == 0.0]
    assert all(r.case["rods"]["N"] == 1 and r.case["rods"]["b"] == 3.0 for r in s0)
    assert resolve_study(str(p)).name == "mine"


def test_sweep_bad_case_names_field(tmp_path: Path) -> None:
    p = tmp_path / "bad.toml"
    p.write_text('[base]\n[sweep]\n"rods.h" = [0.2, -0.1]\n')
    with pytest.raises(StudyError) as e:
        load_sweep_toml(p)
    msg = str(e.value)
    assert "\n" not in msg and "rods.h" in msg and "run 2/2" in msg
    p.write_text('[base]\n[sweep]\n"rods.hh" = [0.2]\n')
    with pytest.raises(StudyError, match="rods.hh"):
        load_sweep_toml(p)


def test_sweep_file_errors(tmp_path: Path) -> None:
    p = tmp_path / "s.toml"
    p.write_text("[base]\n")
    with pytest.raises(StudyError, match="sweep"):
        load_sweep_toml(p)
    p.write_text('[sweep]\n"rods.h" = {start = 1, stop = 2}\n')
    with pytest.raises(StudyError, match="start, stop, step"):
        load_sweep_toml(p)
    with pytest.raises(StudyError, match="no such file"):
        load_sweep_toml(tmp_path / "missing.toml")


def test_unknown_preset_lists_valid_names() -> None:
    with pytest.raises(StudyError) as e:
        get_preset("nope")
    for name in preset_names():
        assert name in str(e.value)


def test_seed_conflict_and_set_path() -> None:
    with pytest.raises(StudyError, match="already swept"):
        build_study("x", {}, {"imperfection.seed": [1, 2]}, kind="sweep", seeds=2)
    d: dict = {"a": 1}
    with pytest.raises(StudyError):
        set_path(d, "a.b", 2)


def test_coarse_first_covers_the_grid_before_filling_it() -> None:
    from undulate.study.spec import coarse_first

    study = build_study("grid", {"rods": {"L": 100.0}},
                        {"rods.h": [0.1 * (i + 1) for i in range(9)],
                         "rods.s": [2.5 * j for j in range(5)]},
                        kind="sweep", single_rod_rule=False, validate=False)
    order = coarse_first(study.runs)
    assert sorted(r.id for r in order) == sorted(r.id for r in study.runs)

    def idx(r):
        return (round(r.params["rods.h"] / 0.1) - 1, round(r.params["rods.s"] / 2.5))

    pos = [idx(r) for r in order]
    # the first values first, then every 4th, every 2nd, then the rest: each level is a
    # whole coarser grid
    assert pos[0] == (0, 0) and pos[1] == (8, 0)  # index 8 divides by 2 three times
    assert set(pos[:6]) == {(i, j) for i in (0, 4, 8) for j in (0, 4)}
    n4 = sum(1 for i, j in pos if i % 4 == 0 and j % 4 == 0)
    assert all(i % 4 == 0 and j % 4 == 0 for i, j in pos[:n4])
    n2 = sum(1 for i, j in pos if i % 2 == 0 and j % 2 == 0)
    assert all(i % 2 == 0 and j % 2 == 0 for i, j in pos[:n2])
    # within a level the listed order is kept
    rest = pos[n2:]
    listed = [idx(r) for r in study.runs if idx(r) in set(rest)]
    assert rest == listed
