"""Only the ratio of the moduli matters: the energy is linear in E_B and E (no gravity, the
clamps' motion does not depend on them), so multiplying both by the same factor must give the
same shape, the same Newton path and energies scaled by that factor. A check that no term or
tolerance uses an absolute stiffness (measured on the default rod: E_B / E = 6,667 at three
scales gave the same onset, n and l; docs/studies/onset/)."""

from __future__ import annotations

import numpy as np
import pytest

from undulate.model import case_from_dict
from undulate.solve.release import run_release

SMALL = {"rods": {"L": 40.0, "h": 0.2}, "fabric": {"margin_x": 5.0, "margin_y": 20.0},
         "release": {"steps": 8}, "mesh": {"h_far": 6.0}}


def _run(scale: float):
    data = {k: dict(v) for k, v in SMALL.items()}
    data["rods"]["E_B"] = 3000.0 * scale
    data["fabric"]["E"] = 0.45 * scale
    return run_release(case_from_dict(data))


def test_scaling_both_moduli_changes_only_the_energies() -> None:
    a, b = _run(1.0), _run(3.0)
    assert b.stats["newton_iterations"] == a.stats["newton_iterations"]
    assert np.abs(b.x_final - a.x_final).max() < 1e-6
    assert np.abs(a.x_final[:, 2]).max() > 0.5  # it did buckle
    for name, e in a.energies.items():
        assert b.energies[name] == pytest.approx(3.0 * e, rel=1e-6, abs=1e-9)
