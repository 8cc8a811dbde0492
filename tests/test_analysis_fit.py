"""Fits and per-rod metrics on synthetic centre lines with known geometry.

Tolerances (measured margins are much smaller; see docs/analysis.md):
arc chains with turning angle theta in [1.3, 3.0] rad, n in 1..9, arc length 8-30 mm,
R_down/R_up in [0.85, 1.15], isotropic noise 1e-3 R: n exact, l within 3 %, R, R_up, R_down
within 5 %, a within 5 % of the exact sagitta. Sines with A/lam in [0.04, 0.2], 2-7 half-waves,
noise 2e-3 A: lam within 1 %, A within 3 %.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from undulate.analysis import fit_arcs, fit_sine, rod_metrics
from undulate.analysis.synthetic import add_noise, arc_chain, sine_curve, to_xyz

SETTINGS = settings(max_examples=30, deadline=None)


def _chain(n, l, theta, ratio, seed, start_up=True):
    R_up = 2 * l / (theta * (1 + ratio))  # so that theta = 2 l / (R_up + R_down)
    R_down = ratio * R_up
    xz = arc_chain(n, l, R_up, R_down, M=40 * n + 40, start_up=start_up)
    return add_noise(xz, 1e-3 * R_up, seed=seed), R_up, R_down


@SETTINGS
@given(
    n=st.integers(1, 9),
    l=st.floats(8.0, 30.0),
    theta=st.floats(1.3, 3.0),
    ratio=st.floats(0.85, 1.15),
    start_up=st.booleans(),
    seed=st.integers(0, 1000),
)
def test_arc_chain_recovery(n, l, theta, ratio, start_up, seed):
    xz, R_up, R_down = _chain(n, l, theta, ratio, seed, start_up)
    m = rod_metrics(to_xyz(xz, y=3.0))
    assert m["n"] == n
    # mean interior arc length: the interior arcs alternate up/down lengths theta R
    lens = [theta * (R_up if ((k % 2 == 0) == start_up) else R_down) for k in range(n)]
    interior = lens[1:-1] if n >= 3 else lens
    assert m["l"] == pytest.approx(np.mean(interior), rel=0.03)
    radii = [R_up if ((k % 2 == 0) == start_up) else R_down for k in range(n)]
    rin = radii[1:-1] if n >= 3 else radii
    assert m["R"] == pytest.approx(np.mean(rin), rel=0.05)
    if m["R_up"] is not None and (n >= 2 or start_up):
        assert m["R_up"] == pytest.approx(R_up, rel=0.05)
    if m["R_down"] is not None and (n >= 2 or not start_up):
        assert m["R_down"] == pytest.approx(R_down, rel=0.05)
    sag = [r * (1 - math.cos(theta / 2)) for r in rin]
    assert m["a"] == pytest.approx(np.mean(sag), rel=0.05)
    assert m["quality"] == "ok"
    assert m["r2_arcs"] > 0.999
    if n >= 2:
        # arcs beat sines on arc chains turning >= 1.3 rad per arc
        assert m["rms_arcs"] < m["rms_sine"]
        assert m["r2_arcs"] > m["r2_sine"]
    json.dumps(m, allow_nan=False)


@SETTINGS
@given(
    half_waves=st.integers(2, 7),
    lam=st.floats(10.0, 40.0),
    ratio=st.floats(0.04, 0.2),
    phi=st.floats(-math.pi, math.pi),
    c=st.floats(-2.0, 2.0),
    seed=st.integers(0, 1000),
)
def test_sine_recovery(half_waves, lam, ratio, phi, c, seed):
    A = ratio * lam
    xz = sine_curve(A, lam, half_waves * lam / 2, phi=phi, c=c, M=40 * half_waves)
    xz = add_noise(xz, 2e-3 * A, seed=seed)
    sf = fit_sine(xz)
    assert sf.lam == pytest.approx(lam, rel=0.01)
    assert sf.A == pytest.approx(A, rel=0.03)
    assert sf.r2 > 0.999


@pytest.mark.parametrize(
    ("half_waves", "ratio", "phi"), [(3, 0.15, 0.0), (5, 0.1, 0.7), (7, 0.2, -1.2), (2, 0.05, 2.0)]
)
def test_sines_beat_arcs_on_sines(half_waves, ratio, phi):
    """On a pure sine (A/lam in [0.05, 0.2], noise 2e-3 A) the sine fit has the lower RMS."""
    lam = 20.0
    xz = add_noise(sine_curve(ratio * lam, lam, half_waves * lam / 2, phi=phi,
                              M=40 * half_waves), 2e-3 * ratio * lam)
    sf, af = fit_sine(xz), fit_arcs(xz)
    assert sf.rms < 0.5 * af.rms
    assert sf.r2 > af.r2


def test_known_chain_values_and_lam():
    """5 arcs, l = 20, R = 7 (theta = 2.857 rad): lam = 2 x chord, a = sagitta."""
    m = rod_metrics(arc_chain(5, 20.0, 7.0, M=300))
    chord = 2 * 7.0 * math.sin(20.0 / 7.0 / 2)
    assert m["n"] == 5
    assert m["lam"] == pytest.approx(2 * chord, rel=1e-3)
    assert m["a"] == pytest.approx(7.0 * (1 - math.cos(20.0 / 14.0)), rel=1e-3)
    assert m["kappa_up"] == pytest.approx(1 / 7.0, rel=1e-3)
    assert m["rise"] is None and m["span"] is None
    assert m["l_segments"] == pytest.approx([20.0] * 5, rel=1e-3)


def test_single_half_wave_rise_span():
    m = rod_metrics(arc_chain(1, 40.0, 10.0, M=200))
    assert m["n"] == 1
    assert m["span"] == pytest.approx(20 * math.sin(2.0), rel=1e-3)
    assert m["rise"] == pytest.approx(10 * (1 - math.cos(2.0)), rel=1e-3)
    assert m["lam"] == m["span"] and m["a"] == m["rise"]


def test_flat_ends_detected():
    m = rod_metrics(add_noise(arc_chain(5, 20.0, 7.0, flat_ends=10.0, M=400), 0.005))
    assert m["n"] == 5
    assert m["flat_ends"] == pytest.approx([10.0, 10.0], abs=0.5)
    assert m["l"] == pytest.approx(20.0, rel=0.02)
    m = rod_metrics(arc_chain(3, 10.0, 4.0, flat_ends=30.0, M=400))
    assert m["n"] == 3 and m["quality"] == "end_dominated"


def test_flat_rod():
    rng = np.random.default_rng(1)
    x = np.linspace(0, 100, 101)
    xyz = np.column_stack([x, np.zeros_like(x), 1e-5 * rng.normal(size=x.size)])
    m = rod_metrics(xyz, L=100.0)
    assert m["n"] == 0 and m["quality"] == "flat"
    assert m["l"] is None and m["flat_ends"] == [0.0, 0.0]
    json.dumps(m, allow_nan=False)  # no NaN anywhere


def test_short_and_noisy_flags():
    m = rod_metrics(arc_chain(1, 30.0, 10.0, M=12))
    assert m["quality"] == "short" and m["n"] == 1
    xz = add_noise(arc_chain(5, 20.0, 7.0, M=150), 2.0, seed=3)
    m = rod_metrics(xz)
    assert m["quality"] == "noisy"
    json.dumps(m, allow_nan=False)


@pytest.mark.parametrize(
    ("bad", "match"),
    [
        (np.array([[0, 0, 0], [1, 0, np.nan], [2, 0, 0], [3, 0, 0], [4, 0, 0]], float), "NaN"),
        (np.zeros((10, 4)), "shape"),
        (np.zeros((3, 3)), "at least"),
        ([[0, 0, 0]] * 10, "distinct"),
    ],
)
def test_invalid_input_raises(bad, match):
    for f in (rod_metrics, fit_arcs, fit_sine):
        with pytest.raises(ValueError, match=match):
            f(bad)


def test_rod_shifted_and_tilted_in_plane():
    """A rod moved in x/y and lying along a slightly rotated direction keeps its metrics."""
    xz = arc_chain(5, 20.0, 7.0, M=300)
    ang = 0.05
    xyz = np.column_stack(
        [xz[:, 0] * math.cos(ang) + 7.0, xz[:, 0] * math.sin(ang) - 3.0, xz[:, 1] + 1.0]
    )
    m = rod_metrics(xyz)
    assert m["n"] == 5 and m["l"] == pytest.approx(20.0, rel=1e-3)
