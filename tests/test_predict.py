"""undulate predict: simulated results where the case is inside the shipped atlases, theory
(with a warning saying why) elsewhere; JSON with a family and one entry per rod."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
from typer.testing import CliRunner

from undulate.design.atlas import load_atlas
from undulate.design.predict import SINGLE_ROD_FILE, arch_rise, predict_case
from undulate.interfaces.cli import app
from undulate.model import case_from_dict


def _case(**rods) -> object:
    return case_from_dict({"rods": {"E_B": 1000.0, **rods}})


def test_inside_the_single_rod_atlas_gives_the_simulated_point() -> None:
    atlas = load_atlas(SINGLE_ROD_FILE)
    row = atlas.points.iloc[(atlas.points["h"] - 0.2).abs().argmin()]
    res = predict_case(_case(h=0.2))
    assert res["source"] == "simulation" and res["warnings"] == []
    assert len(res["rods"]) == 1 and res["rods"][0]["n"] == row["n"]
    assert res["rods"][0]["l"] == pytest.approx(row["l"]) and res["family"] == row["family"]


def test_outside_falls_back_to_theory_and_says_why() -> None:
    res = predict_case(_case(h=0.2, E_B=3000.0))
    assert res["source"] == "theory" and "E_B = 3000" in res["warnings"][0]
    near = predict_case(_case(h=0.2, E_B=3000.0), "simulation")
    assert near["source"] == "simulation" and near["confidence"] == "outside"
    assert "the nearest point" in near["warnings"][0]
    five = predict_case(_case(h=0.3, N=5, s=10.0), "theory")
    assert five["source"] == "theory" and len(five["rods"]) == 5
    with pytest.raises(ValueError, match="source: must be one of"):
        predict_case(_case(h=0.2), "oracle")


def test_one_arch_rise_is_the_circular_arc_on_the_relaxed_chord() -> None:
    a = arch_rise(100.0, 0.5)
    # a circular arc of 100 mm on a 66.7 mm chord: check by rebuilding the chord
    x = 1.49578  # half its turning angle, sin(x) / x = 2 / 3
    assert math.sin(x) / x == pytest.approx(2 / 3, abs=1e-4)
    assert a == pytest.approx(100 / (2 * x) * (1 - math.cos(x)), rel=1e-3)
    res = predict_case(case_from_dict({"rods": {"h": 2.0, "L": 60.0}}), "theory")
    assert res["rods"][0]["n"] == 1 and res["rods"][0]["a"] == pytest.approx(arch_rise(60, 0.5))


def test_cli_json(tmp_path: Path) -> None:
    (tmp_path / "c.toml").write_text("[rods]\nh = 0.2\nE_B = 1000.0\n")
    res = CliRunner().invoke(app, ["predict", str(tmp_path / "c.toml"), "--json"])
    assert res.exit_code == 0, res.output
    out = json.loads(res.stdout)
    assert out["source"] == "simulation" and out["rods"][0]["n"] >= 3
    bad = CliRunner().invoke(app, ["predict", str(tmp_path / "c.toml"), "--source", "x"])
    assert bad.exit_code == 2 and "--source: must be one of" in bad.stderr


def test_the_atlas_at_the_nearest_rod_length_answers(tmp_path: Path,
                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    """Further atlas CSVs in the data folder (and its sub-folders) are read, a case inside one
    is answered from it directly, and a scaled case from the atlas whose (L, eps0) is nearest
    its own (in log L and log eps0)."""
    from undulate.design import predict
    from undulate.design.atlas import ATLAS_FILE

    data = tmp_path / "data"
    data.mkdir()
    first, rest = ATLAS_FILE.read_text().split("\n", 1)
    meta = json.loads(first[2:])
    meta["L"] = 50.0
    (data / "phase_diagram_L50.csv").write_text("# " + json.dumps(meta) + "\n" + rest)
    for src in (SINGLE_ROD_FILE, ATLAS_FILE):
        (data / src.name).write_text(src.read_text())
    first, rest = SINGLE_ROD_FILE.read_text().split("\n", 1)
    (data / "grid").mkdir()
    (data / "grid" / "eps0-0.25.csv").write_text(
        "# " + json.dumps(json.loads(first[2:]) | {"eps0": 0.25}) + "\n" + rest)
    monkeypatch.setattr(predict, "SINGLE_ROD_FILE", data / SINGLE_ROD_FILE.name)
    monkeypatch.setattr(predict, "ATLAS_FILE", data / ATLAS_FILE.name)
    found = {name: (a.meta["L"], a.meta["eps0"]) for name, a in predict._atlases()}
    assert found == {"single_rod": (100.0, 0.5), "phase_diagram": (100.0, 0.5),
                     "phase_diagram_L50": (50.0, 0.5), "grid/eps0-0.25": (100.0, 0.25)}
    def lone(eps0: float) -> object:
        return case_from_dict({"rods": {"E_B": 1000.0, "h": 0.3}, "release": {"eps0": eps0}})

    low = predict_case(lone(0.3))
    assert low["atlas"] == "grid/eps0-0.25" and low["scaled"]["eps0"] == 0.25
    assert predict_case(lone(0.45))["atlas"] == "single_rod"

    direct = predict_case(_case(N=5, h=0.3, s=10.0, L=50.0))
    assert direct["source"] == "simulation" and "scaled" not in direct
    assert direct["atlas"] == "phase_diagram_L50"
    near = predict_case(_case(N=5, h=0.3, s=10.0, L=45.0))
    # (this made-up L = 50 mm atlas is the L = 100 mm one: its n need not be the fit's)
    assert near["confidence"] in ("scaled", "near a transition", "fitted")
    assert near["scaled"]["L"] == 50.0
    far = predict_case(_case(N=5, h=0.3, s=10.0, L=90.0))
    assert far["scaled"]["L"] == 100.0


def test_one_rod_as_wide_as_five_is_the_diagrams_s0_column() -> None:
    """Five rods printed with no gap are one rod five times as wide (how the studies run
    s = 0): such a rod is answered from the five-rod diagram's s = 0 column, not from the
    lone rods of width 1 mm (nor from theory)."""
    from undulate.design.atlas import ATLAS_FILE

    pts = load_atlas(ATLAS_FILE).points
    row = pts[pts["s"] == 0].iloc[0]
    wide = predict_case(_case(h=float(row["h"]), b=5.0, N=1, s=0.0))
    assert wide["source"] == "simulation" and wide["atlas"] == "phase_diagram"
    assert wide["rods"][0]["n"] == row["n"] and len(wide["rods"]) == 1
    assert predict_case(_case(h=float(row["h"]), N=1))["atlas"] != "phase_diagram"


def test_five_rods_at_another_pre_stretch_are_answered_from_their_own_diagram() -> None:
    """The five-rod diagrams at L = 75 mm, eps0 = 0.25 and 0.85 ship: a design on one of
    their points is answered from it directly (rolls at eps0 = 0.85, which no eps0 = 0.5
    diagram has)."""
    from undulate.design.predict import atlas_named

    at = atlas_named("five_rods_eps0/L75_eps0-0.85")
    assert (at.meta["N"], at.meta["L"], at.meta["eps0"]) == (5, 75.0, 0.85)
    row = at.points[at.points["family"] == "rolls"].iloc[0]
    case = case_from_dict({"rods": {"E_B": 1000.0, "N": 5, "L": 75.0, "h": float(row["h"]),
                                    "s": float(row["s"])}, "release": {"eps0": 0.85}})
    res = predict_case(case)
    assert res["atlas"] == "five_rods_eps0/L75_eps0-0.85" and "scaled" not in res
    assert res["family"] == "rolls" and len(res["rods"]) == 5


def test_a_group_beyond_every_diagram_takes_its_n_from_the_lone_rods() -> None:
    """Five thin rods 145 mm long, 40 mm apart: no five-rod diagram holds them even scaled
    (they would land below the diagrams' thinnest rods), so each rod's n is a lone rod's of
    the same h, L, eps0 (rods at least 5 mm apart mostly share it) and the family is what
    most groups of the nearest diagram's thinnest rods have, with a warning; closer rods
    (2.5 mm) are left to theory."""
    from undulate.design.atlas import ATLAS_FILE
    from undulate.design.waves import WavesFit, load_waves, waves_n

    case = case_from_dict({"rods": {"E_B": 1000.0, "N": 5, "L": 145.0, "h": 0.16,
                                    "s": 40.0}, "release": {"eps0": 0.8}})
    # the many-half-waves fit off (it answers only rods of its width b): the lone-rod rule
    off = WavesFit(coef=(0.0,) * 5, c0=2.0, c1=40.0, b=1e3, runs=(0, 0), fitted_on=())
    res = predict_case(case, waves=off)
    lone = predict_case(case_from_dict({"rods": {"E_B": 1000.0, "N": 1, "L": 145.0,
                                                 "h": 0.16}, "release": {"eps0": 0.8}}),
                        waves=off)
    assert res["confidence"] == "lone rods" and res["source"] == "simulation"
    assert [r["n"] for r in res["rods"]] == [lone["rods"][0]["n"]] * 5
    assert res["rods"][0]["l"] == pytest.approx(lone["rods"][0]["l"])
    pts = load_atlas(ATLAS_FILE).points
    thin = pts[(pts["h"] == pts["h"].min()) & (pts["s"] > 0) & (pts["n"] > 1)]
    assert res["family"] == thin["family"].value_counts().index[0]
    assert "lone rod" in res["warnings"][0] and "thinnest simulated rods" in res["warnings"][0]
    shipped = predict_case(case)  # with the fit: a group's rods, many half-waves
    assert shipped["rods"][0]["n"] == waves_n(load_waves(), 0.16, 145.0, 0.8, group=True)
    assert shipped["family"] == res["family"]
    close = case_from_dict({"rods": {"E_B": 1000.0, "N": 5, "L": 145.0, "h": 0.16,
                                     "s": 2.5}, "release": {"eps0": 0.8}})
    assert predict_case(close)["source"] == "theory"
