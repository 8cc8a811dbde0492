"""The atlases carried to other L and eps0 by one scaling variable (undulate.design.scaling):
the fit finds a known exponent, the shipped one is what the committed tables give, and a
case that differs from the atlas only in L or eps0 is answered from it, scaled."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from undulate.design.predict import predict_case
from undulate.design.scaling import equivalent, fit_exponent, load_scaling
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


def test_the_shipped_exponent_is_the_committed_tables_fit() -> None:
    p, hits, runs = fit_exponent(pd.read_csv(STUDIES / "single-rod-h" / "table.csv"),
                                 pd.read_csv(STUDIES / "single-rod-eps0" / "table.csv"))
    shipped = load_scaling()
    assert (shipped.p, shipped.hits, shipped.runs) == (p, hits, runs)


def test_equivalent_is_the_identity_at_the_reference() -> None:
    assert equivalent(0.3, 100.0, 0.5, L_ref=100.0, eps0_ref=0.5, p=0.25) == (0.3, 1.0)
    h_eq, k = equivalent(0.3, 50.0, 0.5, L_ref=100.0, eps0_ref=0.5, p=0.25)
    assert h_eq == pytest.approx(0.6) and k == pytest.approx(0.5)


def test_another_eps0_is_answered_from_the_atlas_scaled() -> None:
    sweep = pd.read_csv(STUDIES / "single-rod-eps0" / "table.csv")
    row = sweep[(sweep["h"] == 0.3) & (sweep["eps0"] == 0.8)].iloc[0]
    res = predict_case(case_from_dict({"rods": {"h": 0.3, "E_B": 1000.0},
                                       "release": {"eps0": 0.8}}))
    assert res["source"] == "simulation" and res["confidence"] == "scaled"
    assert res["scaled"]["h"] == pytest.approx(0.3 * 1.6 ** -0.25 * 1.0, rel=1e-6)
    assert res["rods"][0]["n"] == row["n"]
    assert "scaled from the simulated L = 100 mm" in res["summary"]
    # a shorter rod: lengths scale with L
    short = predict_case(case_from_dict({"rods": {"h": 0.1, "L": 50.0, "E_B": 1000.0}}))
    same = predict_case(case_from_dict({"rods": {"h": 0.2, "E_B": 1000.0}}))
    assert short["confidence"] in ("scaled", "near a transition")
    assert short["rods"][0]["n"] == same["rods"][0]["n"]
    assert short["rods"][0]["l"] == pytest.approx(0.5 * same["rods"][0]["l"])
