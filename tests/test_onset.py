"""Onset of buckling from a release history: by deflection (interpolated) and by stability,
per rod."""

import json
from types import SimpleNamespace

import numpy as np
import pytest

from undulate.api import ONSET_DEFLECTION, onset


def _result(history, h=0.3, n_rods=2):
    return SimpleNamespace(history=history, sections=[SimpleNamespace(h=h)] * n_rods,
                           centerlines=[np.zeros((3, 3))] * n_rods)


def _step(release, neg, rods):
    return dict(release_strain=release, negative_steps=neg, max_deflection=max(rods),
                rod_max_deflection=rods)


def test_onset_by_deflection_interpolated_per_rod_and_by_stability():
    thr = ONSET_DEFLECTION * 0.3
    hist = [_step(0.0, 0, [0.001, 0.001]), _step(0.1, 0, [0.1, 0.2]),
            _step(0.2, 2, [0.2, thr + 0.2]), _step(0.3, 0, [thr + 0.1, 1.2])]
    out = onset(_result(hist))
    # rod 1 crosses h between 0.1 (0.2 mm) and 0.2 (h + 0.2 mm): at 0.1 + 0.1 * 0.1 / 0.3
    assert out["onset_release_strain"] == pytest.approx(0.1 + 0.1 * (thr - 0.2) / (thr))
    rods = json.loads(out["rods_onset_release_strain"])
    assert rods[0] == pytest.approx(0.2 + 0.1 * (thr - 0.2) / (thr + 0.1 - 0.2))
    assert rods[1] == pytest.approx(out["onset_release_strain"])
    assert rods[1] < rods[0]  # which rod went first
    assert out["onset_negative_curvature_release_strain"] == 0.2


def test_smooth_curl_below_the_thickness_is_not_an_onset():
    # 10 x a 1 um imperfection is passed at once by the bilayer's curl: not buckling
    hist = [_step(0.0, 0, [0.001]), _step(0.25, 0, [0.05]), _step(0.5, 0, [0.29])]
    out = onset(_result(hist, n_rods=1))
    assert out["onset_release_strain"] is None
    assert out["onset_negative_curvature_release_strain"] is None
    assert json.loads(out["rods_onset_release_strain"]) == [None]
