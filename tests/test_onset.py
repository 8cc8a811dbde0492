"""Onset of buckling from a release history: by stability and by height, per rod."""

import json
from types import SimpleNamespace

import numpy as np

from undulate.api import onset


def _result(history, amplitude=1e-3, n_rods=2):
    case = SimpleNamespace(imperfection=SimpleNamespace(amplitude=amplitude))
    return SimpleNamespace(history=history, case=case, centerlines=[np.zeros((3, 3))] * n_rods)


def _step(release, neg, rods):
    return dict(release_strain=release, negative_steps=neg, max_deflection=max(rods),
                rod_max_deflection=rods)


def test_onset_by_stability_height_and_rod():
    hist = [_step(0.0, 0, [0.001, 0.001]), _step(0.1, 0, [0.005, 0.02]),
            _step(0.2, 2, [0.3, 0.5]), _step(0.3, 0, [1.0, 1.2])]
    out = onset(_result(hist))
    assert out["onset_release_strain"] == 0.2  # first step with a negative-curvature step
    assert out["onset_height_release_strain"] == 0.1  # rod 1 above 10 x 1e-3 mm
    assert json.loads(out["rods_onset_release_strain"]) == [0.2, 0.1]


def test_no_onset_is_none_not_a_number():
    hist = [_step(0.0, 0, [0.001]), _step(0.5, 0, [0.002])]
    out = onset(_result(hist, n_rods=1))
    assert out["onset_release_strain"] is None
    assert out["onset_height_release_strain"] is None
    assert json.loads(out["rods_onset_release_strain"]) == [None]
