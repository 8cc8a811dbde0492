"""Analytical model (docs/theory.md): hand-computed values, scaling laws, phase map."""

from __future__ import annotations

import math

import numpy as np
import pytest

from undulate import theory as T


def test_values_by_hand_defaults():
    h, eps0, b, E_B, E, t = 0.5, 0.5, 1.0, 3000.0, 0.45, 0.4
    ib = h**3 * b / 12
    l_hand = (24 * math.sqrt(6) * E_B * ib / (E * t)) ** (1 / 3) / math.sqrt(eps0)
    a_hand = 1 / (2 * eps0) * (E_B * b / (3 * E * t)) ** (1 / 3) * h
    R_hand = l_hand / math.sqrt(24 * eps0)
    theta = l_hand / R_hand
    assert T.I_B(h, b) == pytest.approx(ib)
    assert T.l(h, eps0) == pytest.approx(l_hand, rel=1e-12)
    assert T.l(h, eps0) == pytest.approx(30.6763, abs=1e-3)  # the number itself
    assert T.a(h, eps0) == pytest.approx(a_hand, rel=1e-12)
    assert T.R(h, eps0) == pytest.approx(R_hand, rel=1e-12)
    assert T.a(h, eps0) == pytest.approx(T.R(h, eps0), rel=1e-12)  # formula a == R
    assert T.sagitta(h, eps0) == pytest.approx(R_hand * (1 - math.cos(theta / 2)), rel=1e-12)
    assert T.s_hat(h, eps0) == pytest.approx(2 * a_hand * 1.5, rel=1e-12)
    assert T.n(h, eps0, 100.0) == 3  # 100 / 30.68 = 3.26
    assert T.l_n(100.0, 3) == pytest.approx(100 / 3)
    assert T.h_bundled(h, 5) == pytest.approx(0.5 * 5 ** (1 / 3))
    assert T.h_star_ratio(5) == pytest.approx(1.70998, abs=1e-4)


def test_scaling_laws():
    h = np.array([0.1, 0.2, 0.4, 0.8])
    lv = T.l(h, 0.5)
    assert np.allclose(lv / h, lv[0] / h[0])  # linear in h
    assert T.l(0.5, 0.125) / T.l(0.5, 0.5) == pytest.approx(2.0)  # eps0^(-1/2)
    # (E_B b)^(1/3): multiplying E_B by 8 doubles l; so does b * 8; E t * 8 halves it
    assert T.l(0.5, 0.5, E_B=24000.0) / T.l(0.5, 0.5) == pytest.approx(2.0)
    assert T.l(0.5, 0.5, b=8.0) / T.l(0.5, 0.5) == pytest.approx(2.0)
    assert T.l(0.5, 0.5, E=3.6) / T.l(0.5, 0.5) == pytest.approx(0.5)


@pytest.mark.parametrize("k", [0.1, 2.0, 25.4])
def test_unit_consistency_lengths_scale(k):
    """Scaling every length (h, b, t, L) by k with moduli fixed scales l, a, R, s_hat by k."""
    base = dict(b=1.0, t=0.4)
    sc = dict(b=k * 1.0, t=k * 0.4)
    for f in (T.l, T.a, T.R, T.sagitta, T.s_hat):
        assert f(k * 0.5, 0.5, **sc) == pytest.approx(k * f(0.5, 0.5, **base), rel=1e-12)
    assert T.n(k * 0.5, 0.5, k * 100.0, **sc) == T.n(0.5, 0.5, 100.0, **base)


def test_vectorised_and_n_odd():
    h = np.linspace(0.05, 3.0, 300)
    nn = T.n(h, 0.5, 100.0)
    assert nn.dtype.kind == "i" and nn.shape == h.shape
    assert np.all(nn % 2 == 1) and np.all(nn >= 1)
    assert np.all(np.diff(nn) <= 0)  # thicker -> fewer half-waves
    ratio = 100.0 / T.l(h, 0.5)
    assert np.all((np.abs(nn - ratio) <= 1.0 + 1e-9) | (nn == 1))  # nearest odd integer


def test_single_arc_semicircle_boundary():
    lam, rise = T.single_arc(math.pi * 10, 10.0)  # exact semicircle
    assert lam == pytest.approx(20.0) and rise == pytest.approx(10.0)
    lam, rise = T.single_arc(40.0, 10.0)  # more than a semicircle -> roll
    assert lam < 2 * rise


def test_phase_map_families():
    # chosen points (N = 5, eps0 = 0.5, L = 100, defaults); s_hat(h) = 53.1 h
    h = np.array([0.15, 0.4, 0.4, 1.0, 0.6, 1.9])
    s = np.array([45.0, 10.0, 40.0, 10.0, 0.0, 40.0])
    pm = T.phase_map(h, s)
    assert list(pm["family"]) == [
        "independent", "coherent", "independent", "rolls", "rolls", "bends"
    ]
    assert set(pm) >= {"h", "s", "family", "code", "n", "h_eff", "s_hat", "lam", "a"}
    assert np.array_equal(np.asarray(T.FAMILIES)[pm["code"]], pm["family"])
    # bundling: at s = 0 the effective thickness is h N^(1/3); beyond s_hat it is h
    assert pm["h_eff"][4] == pytest.approx(0.6 * 5 ** (1 / 3))
    assert pm["h_eff"][2] == pytest.approx(0.4)


def test_phase_map_grid_and_bundling_threshold():
    H, S = np.meshgrid(np.linspace(0.1, 2.0, 20), np.linspace(0, 50, 21))
    pm = T.phase_map(H, S)
    assert pm["family"].shape == H.shape
    # n = 1 first appears at smaller h for s = 0 (bundled) than for large s, ratio ~ N^(1/3)
    h1 = np.linspace(0.05, 2.0, 2000)
    first0 = h1[np.argmax(T.phase_map(h1, 0.0)["n"] == 1)]
    firstL = h1[np.argmax(T.phase_map(h1, 200.0)["n"] == 1)]
    assert firstL / first0 == pytest.approx(5 ** (1 / 3), rel=0.01)
    with pytest.raises(ValueError, match="h must be > 0"):
        T.phase_map(-1.0, 1.0)


def test_predictions_dict():
    p = T.predictions(0.5, 0.5, s=10.0)
    assert p["n"] == 3 and p["family"] == "coherent"
    assert p["a_formula"] == pytest.approx(p["R"]) and p["sagitta"] > p["R"]
