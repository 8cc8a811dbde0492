"""The atlases carried to other L and eps0 by one scaling variable (undulate.design.scaling):
the fit finds a known exponent, the shipped one is what the committed tables give, and a
case that differs from the atlas only in L or eps0 is answered from it, scaled."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from undulate.design.atlas import load_atlas
from undulate.design.predict import SINGLE_ROD_FILE, predict_case
from undulate.design.scaling import equivalent, fit_exponent, fit_wavelength, load_scaling
from undulate.model import case_from_dict

STUDIES = Path(__file__).parents[1] / "docs" / "studies"


def _n_of_x(x: np.ndarray) -> np.ndarray:
    """A made-up quantization: odd n growing with x."""
    return 2 * np.floor(x / 6.0).astype(int) + 1


def test_the_fit_finds_a_known_exponent() -> None:
    p_true = 0.3
    h = np.geomspace(0.08, 2.0, 2000)  # fine enough in x for the steps of n
    h_tab = pd.DataFrame({"status": "ok", "h": h, "L": 100.0, "eps0": 0.5,
                          "n": _n_of_x(100.0 / h)})
    hh, ee = np.meshgrid([0.15, 0.2, 0.3, 0.5, 0.7], np.linspace(0.1, 1.0, 10))
    x = 100.0 / (hh * (ee / 0.5) ** (-p_true))
    e_tab = pd.DataFrame({"status": "ok", "h": hh.ravel(), "L": 100.0, "eps0": ee.ravel(),
                          "n": _n_of_x(x.ravel())})
    p, hits, runs = fit_exponent(h_tab, e_tab)
    assert p == pytest.approx(p_true, abs=0.03) and runs == 50 and hits >= 48  # steps: +-1
    wrong = e_tab.assign(n=_n_of_x(100.0 / e_tab["h"].to_numpy()))  # no eps0 effect at all
    assert fit_exponent(h_tab, wrong)[0] == pytest.approx(0.0, abs=0.03)


def test_the_wavelength_fit_takes_the_runs_with_many_waves() -> None:
    h = np.linspace(0.08, 1.0, 40)
    n = np.where(h < 0.4, 9, 3)  # few waves: l is L / n there, not the rod's own
    tab = pd.DataFrame({"status": "ok", "h": h, "L": 100.0, "eps0": 0.5, "n": n,
                        "l_mean": np.where(n >= 7, 2.0 + 40.0 * h, 100.0 / n)})
    assert fit_wavelength(tab) == pytest.approx((2.0, 40.0))
    with pytest.raises(ValueError, match="fewer than two"):
        fit_wavelength(tab[tab["n"] < 7])


def test_the_shipped_scaling_is_the_committed_tables_fit() -> None:
    h_tab = pd.read_csv(STUDIES / "single-rod-h" / "table.csv")
    c0, c1 = fit_wavelength(h_tab)
    p, hits, runs = fit_exponent(h_tab, pd.read_csv(STUDIES / "single-rod-eps0" / "table.csv"),
                                 c0=c0, c1=c1)
    shipped = load_scaling()
    assert (shipped.p, shipped.hits, shipped.runs) == (p, hits, runs)
    assert (shipped.c0, shipped.c1) == pytest.approx((c0, c1), abs=1e-3)


def test_equivalent_is_the_identity_at_the_reference() -> None:
    kw = {"L_ref": 100.0, "eps0_ref": 0.5, "p": 0.25, "c0": 2.0, "c1": 40.0}
    h_eq, k = equivalent(0.3, 100.0, 0.5, **kw)
    assert (h_eq, k) == (pytest.approx(0.3), 1.0)
    h_eq, k = equivalent(0.3, 50.0, 0.5, **kw)  # l0 doubles: 14 -> 28 mm
    assert h_eq == pytest.approx((28.0 - 2.0) / 40.0) and k == pytest.approx(0.5)
    assert np.isnan(equivalent(0.08, 500.0, 0.5, **kw)[0])  # l0 below the intercept


def test_another_eps0_is_answered_from_the_atlas_scaled() -> None:
    """The scaling itself, from the single-rod sweep alone (L = 100 mm, eps0 = 0.5)."""
    alone = [("single_rod", load_atlas(SINGLE_ROD_FILE))]
    sweep = pd.read_csv(STUDIES / "single-rod-eps0" / "table.csv")
    row = sweep[(sweep["h"] == 0.3) & (sweep["eps0"] == 0.8)].iloc[0]
    res = predict_case(case_from_dict({"rods": {"h": 0.3, "E_B": 1000.0},
                                       "release": {"eps0": 0.8}}), atlases=alone)
    assert res["source"] == "simulation" and res["confidence"] == "scaled"
    sc = load_scaling()
    l_eq = (sc.c0 + sc.c1 * 0.3) * 1.6 ** (-sc.p)
    assert res["scaled"]["h"] == pytest.approx((l_eq - sc.c0) / sc.c1, rel=1e-6)
    assert res["rods"][0]["n"] == row["n"]
    assert "scaled from the simulated L = 100 mm" in res["summary"]
    # a shorter rod: read off at the thickness of the same x, lengths scaled by L / 100
    short = predict_case(case_from_dict({"rods": {"h": 0.15, "L": 50.0, "E_B": 1000.0}}),
                         atlases=alone)
    h_eq = short["scaled"]["h"]
    assert h_eq == pytest.approx((2 * (sc.c0 + sc.c1 * 0.15) - sc.c0) / sc.c1)
    same = predict_case(case_from_dict({"rods": {"h": round(h_eq, 2), "E_B": 1000.0}}))
    assert short["rods"][0]["n"] == same["rods"][0]["n"]
    assert short["rods"][0]["l"] == pytest.approx(0.5 * same["rods"][0]["l"], rel=0.05)


def test_the_shipped_grid_answers_from_the_nearest_length_and_pre_stretch() -> None:
    """With the lone-rod grid shipped, eps0 = 0.8 is read off the atlas at eps0 = 0.85 and
    L = 60 mm off the one at L = 55 mm (the nearest in log L, p log eps0)."""
    res = predict_case(case_from_dict({"rods": {"h": 0.3, "E_B": 1000.0},
                                       "release": {"eps0": 0.8}}))
    assert res["atlas"] == "single_rod_grid/L100_eps0-0.85"
    assert res["scaled"]["L"] == 100.0 and res["scaled"]["eps0"] == 0.85
    res = predict_case(case_from_dict({"rods": {"h": 0.3, "L": 60.0, "E_B": 1000.0},
                                       "release": {"eps0": 0.55}}))
    assert res["atlas"] == "single_rod_grid/L55_eps0-0.5"
    assert res["scaled"]["length_factor"] == pytest.approx(60.0 / 55.0)
