"""Gravity: a stretched fabric strip sags under its own weight as a taut string does, and a
case with gravity on runs (weights from the same lumped masses as the inertial mode)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from undulate.mechanics.assemble import Assembly
from undulate.mechanics.build import fabric_groups
from undulate.mesh.grid import FabricMesh
from undulate.model import ConfigError, case_from_dict
from undulate.solve.dynamics import gravity_group
from undulate.solve.newton import NewtonOptions, minimize


def _strip(L: float, W: float, nx: int, ny: int) -> FabricMesh:
    xs, ys = np.linspace(0.0, L, nx), np.linspace(0.0, W, ny)
    X = np.array([(x, y) for y in ys for x in xs])
    tris = []
    for j in range(ny - 1):
        for i in range(nx - 1):
            a, b, c, d = j * nx + i, j * nx + i + 1, (j + 1) * nx + i + 1, (j + 1) * nx + i
            tris += [(a, b, c), (a, c, d)] if (i + j) % 2 == 0 else [(a, b, d), (b, c, d)]
    left = np.arange(ny) * nx
    return FabricMesh(X=X, tris=np.array(tris), rods=[], left=left, right=left + nx - 1,
                      hinge_factor=0.57, kind="structured")


def test_a_stretched_strip_sags_like_a_taut_string() -> None:
    """Clamped at both ends after a stretch of 5 %, long edges free, no rods: under its
    weight q per length the middle sags q L^2 / (8 P), P the clamp force (measured from the
    stretched state; bending of the thin fabric matters only next to the clamps)."""
    E, nu, t, rho, g = 0.45, 0.3, 0.4, 1.2e-9, 9810.0
    L0, W0, eps = 100.0, 20.0, 0.05
    mesh = _strip(L0, W0, 81, 11)
    groups = fabric_groups(mesh, E, nu, t)
    n = mesh.n_nodes
    clamp = np.zeros(n, bool)
    clamp[mesh.left] = clamp[mesh.right] = True
    x = np.c_[mesh.X, np.zeros(n)]
    x[:, 0] *= 1.0 + eps
    fixed = np.zeros((n, 3), bool)
    fixed[clamp] = True
    fixed[:, 2] = True
    opts = NewtonOptions(negative_curvature=False, mixed=False)
    flat = Assembly(n, groups, fixed)
    x = flat.full(minimize(flat, x, flat.free(x), opts).u, x)
    P = float(np.sum(flat.gradient_full(x)[mesh.right, 0]))  # the right clamp's force
    assert P > 0
    case = SimpleNamespace(fabric=SimpleNamespace(rho=rho, t=t), rods=SimpleNamespace(rho_B=0),
                           gravity=SimpleNamespace(on=True, g=(0.0, 0.0, -g)),
                           rod_paths=lambda: [])
    sim = SimpleNamespace(mesh=mesh, case=case, sections=[])
    fixed[:, 2] = False
    fixed[clamp] = True
    weight = gravity_group(sim, ~fixed.all(axis=1))
    assert weight.params[0][:, 2].sum() == pytest.approx(
        -rho * t * g * L0 * W0 * (1 - 1 / 80), rel=1e-9)  # the clamped columns carry none
    sag = Assembly(n, groups + [weight], fixed)
    res = minimize(sag, x, sag.free(x), opts)
    assert res.converged
    xs = sag.full(res.u, x)
    mid = np.abs(mesh.X[:, 0] - L0 / 2) < 1e-9
    w_mid = -float(np.mean(xs[mid, 2]))
    L = L0 * (1 + eps)
    q = rho * t * g * W0 * L0 / L  # weight per length of the stretched strip
    assert w_mid == pytest.approx(q * L**2 / (8 * P), rel=0.03)
    assert w_mid > 0.1  # a real sag, not a rounding error


def test_gravity_setting_is_checked_and_runs() -> None:
    with pytest.raises(ConfigError, match=r"gravity.g: each component must be within"):
        case_from_dict({"gravity": {"g": [0, 0, -2e6]}})
    with pytest.raises(ConfigError, match=r"gravity.g"):
        case_from_dict({"gravity": {"g": [0, -9810]}})
    from undulate import api

    base = {"rods": {"h": 0.3, "L": 30.0}, "fabric": {"margin_x": 8.0, "margin_y": 8.0},
            "release": {"steps": 6}, "mesh": {"dx_rod": 1.5, "h_far": 6.0}}
    up = api.simulate(case_from_dict(base))
    heavy = api.simulate(case_from_dict({**base, "gravity": {"g": [0.0, 0.0, -9810.0 * 100]}}))
    # weight pulls the whole sheet down: its lowest point goes below the one without weight
    assert heavy.x_final[:, 2].min() < up.x_final[:, 2].min() - 0.05
    assert "gravity" in heavy.energies and heavy.energies["gravity"] != 0.0


def test_edge_tension_pulls_the_free_edges_outwards() -> None:
    """fabric.edge_tension: the free edges carry T per mm of unstretched edge, outwards
    (across the stretch, turned with it), and the printed sheet is wider for it."""
    from undulate.mechanics.build import edge_tension_group

    mesh = _strip(100.0, 20.0, 21, 5)
    mesh.node_sets.update(bottom=np.arange(21), top=84 + np.arange(21))
    g = edge_tension_group(mesh, 0.01, 0.0)
    w = g.params[0]
    bottom, top = w[:21], w[21:]
    assert bottom[:, 1].sum() == pytest.approx(-0.01 * 100.0)
    assert top[:, 1].sum() == pytest.approx(0.01 * 100.0)
    assert np.allclose(w[:, [0, 2]], 0.0)
    turned = edge_tension_group(mesh, 0.01, 90.0).params[0]
    assert turned[21:, 0].sum() == pytest.approx(-1.0)  # "top" is then at -x
    assert edge_tension_group(mesh, 0.0) is None
    from undulate.solve.release import prepare, prestretch

    base = {"rods": {"h": 0.3, "L": 30.0}, "fabric": {"margin_x": 8.0, "margin_y": 8.0},
            "mesh": {"dx_rod": 1.5, "h_far": 6.0}}
    widths = []
    for T in (0.0, 0.02):
        sim = prepare(case_from_dict({**base, "fabric": {**base["fabric"], "edge_tension": T}}))
        x, _ = prestretch(sim, NewtonOptions(negative_curvature=False))
        mid = np.abs(x[:, 0]) < 2.0
        widths.append(float(np.ptp(x[mid, 1])))
    assert widths[1] > widths[0] * 1.02
