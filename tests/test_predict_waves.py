"""n of rods with many half-waves from one fit over all simulated rods (undulate.design.waves):
the fit finds a known power law, the shipped one is what its committed tables give, and
predict answers a thin rod between two simulated thicknesses with it."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from undulate.design.predict import predict_case
from undulate.design.waves import GROUP_GAP, N_MIN, fit_waves, load_waves, waves_n
from undulate.model import case_from_dict

ROOT = Path(__file__).parents[1]


def _table(k: tuple[float, ...], rng: np.random.Generator, size: int = 400) -> pd.DataFrame:
    """Made-up runs whose n is the odd number nearest a known power law."""
    h = np.exp(rng.uniform(np.log(0.08), np.log(0.4), size))
    L = rng.choice([50.0, 75.0, 100.0, 135.0], size)
    eps0 = rng.choice([0.25, 0.5, 0.85], size)
    group = rng.integers(0, 2, size)
    n = np.exp(k[0] + k[1] * np.log(L) + k[2] * np.log(eps0) + k[3] * np.log(2.0 + 40.0 * h)
               + k[4] * group)
    return pd.DataFrame({"status": "ok", "h": h, "L": L, "eps0": eps0, "b": 1.0,
                         "N": np.where(group == 1, 5, 1), "s": np.where(group == 1, 10.0, 0.0),
                         "n_mode": 2 * np.round((n - 1) / 2) + 1})


def test_the_fit_finds_a_known_power_law() -> None:
    k = (0.4, 1.0, 0.25, -1.1, 0.05)
    tab = _table(k, np.random.default_rng(0))
    fit = fit_waves([tab], c0=2.0, c1=40.0)
    assert fit.coef == pytest.approx(k, abs=0.06)
    kept = tab[tab["n_mode"] >= N_MIN]
    assert sum(fit.runs) == len(kept)
    hits = sum(waves_n(fit, r.h, r.L, r.eps0, r.N > 1) == r.n_mode for r in kept.itertuples())
    assert hits >= 0.9 * len(kept)
    with pytest.raises(ValueError, match="both lone rods and groups"):
        fit_waves([tab[tab["N"] == 1]], c0=2.0, c1=40.0)


def test_close_groups_and_few_waves_stay_out_of_the_fit() -> None:
    tab = _table((0.4, 1.0, 0.25, -1.1, 0.05), np.random.default_rng(1))
    close = tab[tab["N"] > 1].assign(s=GROUP_GAP / 2)
    fit = fit_waves([tab, close], c0=2.0, c1=40.0)  # the close copies add nothing
    assert fit.runs == fit_waves([tab], c0=2.0, c1=40.0).runs
    assert waves_n(fit, 2.0, 40.0, 0.5, False) == N_MIN  # never below what it knows


def test_the_shipped_fit_is_its_committed_tables_fit() -> None:
    shipped = load_waves()
    again = fit_waves([pd.read_csv(ROOT / p) for p in shipped.fitted_on], shipped.c0,
                      shipped.c1)
    assert again.coef == pytest.approx(shipped.coef, abs=1e-4)
    assert again.runs == shipped.runs
    on_disk = json.loads((ROOT / "src/undulate/design/data/waves.json").read_text())
    assert on_disk["fitted_on"] == list(shipped.fitted_on)


def test_a_thin_rod_between_simulated_thicknesses_takes_the_fits_n() -> None:
    """h = 0.09 mm, L = 145 mm, eps0 = 0.2 (case 28 of the first benchmark draw: simulated
    n = 21): the nearest grid point says 19, the fit 21."""
    case = case_from_dict({"rods": {"h": 0.09, "L": 145.0, "E_B": 1000.0},
                           "release": {"eps0": 0.2}})
    res = predict_case(case)
    rod = res["rods"][0]
    assert res["confidence"] == "fitted" and rod["n"] == 21
    assert rod["n"] == waves_n(load_waves(), 0.09, 145.0, 0.2, False)
    before = {"family": "waves", "n": 19}
    assert before in res["alternatives"] and "the atlas" in res["summary"]
    # the same half-waves' arc length, shared among more of them
    near = predict_case(case, waves=load_waves().__class__(
        coef=(np.log(19.0), 0.0, 0.0, 0.0, 0.0), c0=2.0, c1=40.0, b=1.0, runs=(1, 1),
        fitted_on=()))
    assert near["confidence"] != "fitted" and near["rods"][0]["n"] == 19
    assert rod["l"] * 21 == pytest.approx(near["rods"][0]["l"] * 19)


def test_thick_rods_and_close_groups_keep_the_atlas() -> None:
    thick = predict_case(case_from_dict({"rods": {"h": 0.6, "E_B": 1000.0}}))
    assert thick["confidence"] != "fitted" and thick["rods"][0]["n"] < N_MIN
    close = predict_case(case_from_dict({"rods": {"h": 0.1, "N": 5, "s": 2.5, "E_B": 1000.0}}))
    assert close["confidence"] != "fitted"
