"""The simulated phase diagram as an atlas: one row per (h, s), majority over seeds, what was
held fixed, and where a design sits on it (simulated here, between agreeing points, near a
transition, outside)."""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from undulate.design.atlas import ATLAS_FILE, build_atlas, load_atlas, locate, write_atlas


def _table() -> pd.DataFrame:
    rows = []
    for h in (0.5, 1.0):
        for s in (0.0, 10.0, 20.0):
            fam, n = ("coherent", 3) if h == 0.5 else ("bends", 1)
            if s == 0.0:
                fam = "waves" if h == 0.5 else "bends"
            for seed in (0, 1, 2):
                f, k = fam, n
                if h == 1.0 and s == 20.0 and seed == 0:
                    f, k = "coherent", 3  # one seed of three disagrees: the majority wins
                rows.append({"status": "ok", "seed": seed, "h": h, "s": s, "family": f,
                             "n_mode": k, "l_mean": 100.0 / k, "lam_mean": 80.0 / k,
                             "a_mean": 10.0, "N": 1 if s == 0 else 5, "b": 5.0 if s == 0
                             else 1.0, "L": 100.0, "eps0": 0.5, "E_B": 1000.0, "E": 0.45,
                             "t": 0.4})
    rows.append(dict(rows[-1], status="failed", family="flat"))
    return pd.DataFrame(rows)


def test_build_write_load(tmp_path: Path) -> None:
    atlas = build_atlas(_table(), setup={"rods": {"E_B": 1000.0}})
    p = atlas.points.set_index(["h", "s"])
    assert len(p) == 6 and int(p.loc[(1.0, 20.0), "runs"]) == 3
    assert p.loc[(1.0, 20.0), "family"] == "bends" and p.loc[(1.0, 20.0), "n"] == 1
    assert p.loc[(0.5, 0.0), "family"] == "waves"
    m = atlas.meta
    assert m["N"] == 5 and m["b"] == 1.0 and m["L"] == 100.0 and m["E_B"] == 1000.0
    assert m["h_step"] == 0.5 and m["s_step"] == 10.0 and m["runs"] == 18
    back = load_atlas(write_atlas(atlas, tmp_path / "a.csv"))
    assert back.meta == atlas.meta
    pd.testing.assert_frame_equal(back.points, atlas.points, check_dtype=False)


def test_locate() -> None:
    atlas = build_atlas(_table())
    case = {"N": 5, "L": 100.0, "eps0": 0.5, "E_B": 1000.0, "E": 0.45, "t": 0.4, "b": 1.0}
    here = locate(atlas, h=0.5, s=10.0, **case)
    assert here.inside and here.confidence == "simulated" and here.distance == 0
    assert here.summary().startswith("simulated here: coherent n = 3")
    between = locate(atlas, h=0.5, s=15.0, **case)
    assert between.confidence == "simulated" and "agree" in between.summary()
    edge = locate(atlas, h=0.75, s=15.0, **case)
    assert edge.confidence == "near a transition"
    assert {(edge.family, edge.n), *edge.alternatives} == {("coherent", 3), ("bends", 1)}
    out = locate(atlas, h=0.5, s=10.0, **(case | {"L": 60.0, "E_B": 3000.0}))
    assert not out.inside and out.confidence == "outside"
    assert "L = 60, the diagram's L = 100" in out.reason and "E_B = 3000" in out.reason
    far = locate(atlas, h=3.0, s=10.0, **case)
    assert not far.inside and "h = 3 mm, simulated 0.5..1 mm" in far.reason
    # s = 0 is one rod N times as wide: any N and b are that
    assert locate(atlas, h=0.5, s=0.0, **(case | {"N": 3, "b": 1.0})).inside


def test_the_shipped_atlas_loads() -> None:
    atlas = load_atlas(ATLAS_FILE)
    assert atlas.meta["N"] == 5 and atlas.meta["points"] == len(atlas.points) > 0
    assert set(atlas.points["family"]) <= {"coherent", "independent", "rolls", "bends",
                                           "waves", "flat"}


def test_a_sweep_over_h_and_s_makes_an_atlas_and_others_are_refused(tmp_path: Path) -> None:
    """`undulate study atlas` takes a SWEEP.toml study that sweeps rods.h / rods.s (and the
    seed) only, e.g. the diagram at another rod length, and refuses one that sweeps anything
    else, naming it."""
    from typer.testing import CliRunner

    from undulate.interfaces.cli import app

    studies = Path(__file__).resolve().parents[1] / "docs" / "studies" / "rare-modes"
    runner = CliRunner()
    ok = runner.invoke(app, ["study", "atlas", str(studies / "study-five"),
                             "--out", str(tmp_path / "five.csv")])
    assert ok.exit_code == 0, ok.output
    atlas = load_atlas(tmp_path / "five.csv")
    assert atlas.meta["N"] == 5 and sorted(atlas.points["s"]) == [17.5, 20.0]
    bad = runner.invoke(app, ["study", "atlas", str(studies / "study-printed-reference"),
                              "--out", str(tmp_path / "printed.csv")])
    assert bad.exit_code != 0
    assert "imperfection.amplitude" in bad.output and "Traceback" not in bad.output
    assert not (tmp_path / "printed.csv").exists()


def test_a_refined_row_answers_a_design_at_its_thickness() -> None:
    """A diagram refined at the thin end (a row with few gaps between full rows): a design
    is read off the simulated thickness nearest its h, even where another row has its gap;
    the slack past the ends is half the step at that end, and at the thin end at most the
    thickness over which the half-wave length l0 shrinks by 5 %."""
    rows = []
    for h, n in ((0.1, 15), (0.2, 9)):
        rows += [{"h": h, "s": s, "n": n} for s in (0.0, 10.0, 20.0, 30.0, 40.0)]
    rows += [{"h": 0.15, "s": s, "n": 13} for s in (0.0, 40.0)]
    table = pd.DataFrame([{"status": "ok", "seed": 0, "family": "coherent", "n_mode": r["n"],
                           "l_mean": 100.0 / r["n"], "lam_mean": 1.0, "a_mean": 1.0, "N": 5,
                           "b": 1.0, "L": 100.0, "eps0": 0.5, "E_B": 1000.0, "E": 0.45,
                           "t": 0.4, **r} for r in rows])
    atlas = build_atlas(table)
    assert atlas.meta["h_step"] == 0.05
    here = locate(atlas, h=0.14, s=28.0, N=5, L=100.0, eps0=0.5)
    assert (here.h, here.s, here.n) == (0.15, 40.0, 13)  # not (0.1, 30): h decides n
    # thin end: half the step would be 0.025 mm, but l0 = 1.89 + 41.4 h is 5 % shorter at
    # h = 0.0927 mm already (n goes as 1 / l0)
    assert locate(atlas, h=0.095, s=10.0).inside
    assert not locate(atlas, h=0.09, s=10.0).inside
    assert locate(atlas, h=0.22, s=10.0).inside  # thick end: half the step, 0.025 mm
    assert not locate(atlas, h=0.23, s=10.0).inside
    assert locate(atlas, h=0.2, s=44.0).inside and not locate(atlas, h=0.2, s=46.0).inside
