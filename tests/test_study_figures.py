"""Figures and report from fake (theory-shaped) data."""

from __future__ import annotations

import math
from pathlib import Path

import _study_fakes as fakes
import pandas as pd
import pytest

from undulate.study import collect, get_preset, run_study
from undulate.study.derived import (
    arcs_beat_sines,
    fit_eps0_exponents,
    fit_l_slope,
    hstar,
    hstar_ratios,
    ok_rows,
    onset_summary,
    outer_rod_first,
    theory,
)
from undulate.study.figures import make_figures
from undulate.study.report import write_report


def _run(tmp_path_factory: pytest.TempPathFactory, name: str, quick: bool) -> Path:
    d = tmp_path_factory.mktemp(name)
    run_study(get_preset(name, quick=quick), d, run_fn=fakes.fake_run, workers=1,
              progress=False, artifacts=False)
    return d


@pytest.fixture(scope="module")
def single_h(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _run(tmp_path_factory, "single-rod-h", False)


@pytest.fixture(scope="module")
def parallel(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _run(tmp_path_factory, "parallel-phase-diagram", True)


def test_theory_functions_match_spec() -> None:
    th = theory()
    ib = 0.3**3 * 1.0 / 12
    l_ref = (24 * math.sqrt(6) * 3000 * ib / (0.45 * 0.4)) ** (1 / 3) * 0.5**-0.5
    assert float(th["l"](0.3, 0.5, b=1.0, E_B=3000.0, E=0.45, t=0.4)) == pytest.approx(l_ref)
    a_ref = 1 / (2 * 0.5) * (3000 / (3 * 0.45 * 0.4)) ** (1 / 3) * 0.3
    assert float(th["a"](0.3, 0.5)) == pytest.approx(a_ref)
    assert float(th["s_hat"](0.3, 0.5)) == pytest.approx(2 * a_ref * 1.5)


def test_single_rod_figures_and_fits(single_h: Path) -> None:
    text = write_report(single_h).read_text()  # makes the figures too
    made = sorted(p.name for p in (single_h / "figures").iterdir())
    assert made == [f"{n}.{e}" for n in ("onset", "quantized_flattening", "single_rod_h")
                    for e in ("pdf", "png")]
    assert all(p.stat().st_size > 1000 for p in (single_h / "figures").iterdir())
    assert "eq. (1) slope" in text and "Arcs vs sines" in text and "Bundling" not in text
    assert "fake divergence" in text and "![single_rod_h](figures/single_rod_h.png)" in text
    df = collect(single_h)
    fit = fit_l_slope(df)
    assert fit is not None and fit["n_min"] == 7
    assert fit["slope_origin"] == pytest.approx(fit["slope_eq1"], rel=0.1)
    arcs = arcs_beat_sines(df)
    assert arcs is not None and arcs["n"] == 135 and 0 < arcs["fraction"] <= 1
    assert fit_eps0_exponents(df) == []  # eps0 not swept
    assert "## Cost" in text and "sum of run times" in text


def test_fit_quality_from_per_rod_lists() -> None:
    """Tables that only hold the per-rod R^2 lists still give the mean columns."""
    df = pd.DataFrame({"status": ["ok", "ok", "failed"],
                       "rods_r2_arcs": ["[0.99, 0.97]", "[0.9]", None],
                       "rods_r2_sine": ["[0.9, 0.8]", "[0.95]", None]})
    d = ok_rows(df)
    assert d["r2_arcs_mean"].tolist() == pytest.approx([0.98, 0.9])
    # mixed tables (old records without the column, new ones with it)
    mixed = df.assign(r2_arcs_mean=[None, 0.5, None])
    assert ok_rows(mixed)["r2_arcs_mean"].tolist() == pytest.approx([0.98, 0.5])
    arcs = arcs_beat_sines(df)
    assert arcs == {"fraction": 0.5, "wins": 1, "n": 2}


def test_eps0_figure_and_exponent(tmp_path_factory: pytest.TempPathFactory) -> None:
    d = _run(tmp_path_factory, "single-rod-eps0", False)
    made = make_figures(d)
    assert set(made) == {"l_vs_eps0"}
    exps = fit_eps0_exponents(collect(d))
    assert [e["h"] for e in exps] == [0.2, 0.3, 0.5]  # one fit per thickness
    assert all(-0.8 < e["exponent"] < -0.2 and e["n_points"] == 10 for e in exps)
    assert "exponent" in write_report(d).read_text()


def test_parallel_figures_hstar_and_bundling(parallel: Path) -> None:
    df = collect(parallel)
    hs = hstar(df, 1)
    assert list(hs.index) == [0.0, 10.0, 50.0]
    assert hs[0.0] <= hs[50.0]  # bundled rods reach n = 1 at smaller h
    ratios = hstar_ratios(df)
    assert [r["transition"] for r in ratios] == ["3->1", "5->3", "7->5"]
    assert ratios[0]["bundling"] == pytest.approx(5 ** (1 / 3))
    assert ratios[0]["N"] == 5
    text = write_report(parallel).read_text()
    for name in ("phase_diagram", "master_curve", "quantized_flattening", "transitions",
                 "onset_map"):
        assert (parallel / "figures" / f"{name}.png").is_file()
        assert f"figures/{name}.png" in text
    ons = onset_summary(df)
    assert ons["n_multi"] == 8 and ons["outer_first"] == 8  # s > 0: five rods, outer first
    assert "Onset of buckling" in text and "in 8 of 8 runs" in text
    assert not (parallel / "figures" / "single_rod_h.png").exists()
    assert "| 3->1 |" in text and "N^(1/3)" in text and "figures/phase_diagram.png" in text
    assert "h*(s_max) / h*(s_min)" in text and "N^(-1/3) = 0.585" in text


def test_outer_rod_first_reads_lists_and_table_text() -> None:
    assert outer_rod_first([0.10, 0.12, 0.13, 0.12, 0.11]) is True
    assert outer_rod_first("[0.12, 0.10, 0.13, 0.12, 0.12]") is False
    assert outer_rod_first([0.1, 0.2]) is None  # fewer than three rods
    assert outer_rod_first([0.1, None, 0.2]) is None
    assert outer_rod_first("not a list") is None


def test_linear_regime_stops_at_first_single_arch() -> None:
    """Thick rods that come back to n = 3 (l ~ L/2) are not part of the linear regime."""
    h = [0.1, 0.15, 0.2, 0.25, 0.5, 1.0, 1.8, 2.0]
    n = [7, 7, 5, 5, 1, 1, 3, 3]
    lv = [6.1, 9.2, 12.3, 15.3, 100.0, 100.0, 51.0, 50.8]
    df = pd.DataFrame({"status": "ok", "h": h, "n_mode": n, "l_mean": lv, "eps0": 0.5})
    fit = fit_l_slope(df)
    assert fit is not None and fit["h_below"] == 0.5 and fit["n_points"] == 4
    assert fit["n_min"] == 5
    assert fit["slope"] == pytest.approx(61.0, rel=0.02)


def test_up_down_radii_on_the_centre_line_and_on_the_fabric() -> None:
    from undulate.study.derived import up_down_radii

    d = 0.35  # (t + h) / 2 for h = 0.3, t = 0.4
    df = pd.DataFrame({
        "status": ["ok", "ok", "ok", "ok"],
        "n_mode": [7, 5, 3, 9],
        "h": [0.3, 0.3, 0.3, 0.3], "t": [0.4] * 4,
        # even bond-line arcs (R = 5 at the fabric), a run with crests more curved there,
        # n = 3 (end arcs only on one side: left out), unresolved arcs (left out)
        "R_up_mean": [5.0 + d, 4.5 + d, 9.0, 1.0], "R_down_mean": [5.0 - d, 5.0 - d, 5.0, 0.5],
        "r2_arcs_mean": [0.99, 0.99, 0.99, 0.4],
    })
    r = up_down_radii(df)
    assert r is not None and r["n"] == 2
    assert r["centre_max"] == pytest.approx(5.35 / 4.65)  # the offset's geometry alone
    assert r["fabric_max"] == pytest.approx(1.0)
    assert r["fabric_min"] == pytest.approx(0.9) and r["fabric_below_1"] == 1
    assert r["centre_below_1"] == 0
