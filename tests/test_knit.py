"""Orthotropic knit: uniaxial stretch gives the analytical lateral contraction, the law is
linear orthotropic elasticity at small strains, and a case with it runs."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from test_gravity import _strip  # tests/ is on sys.path under pytest

from undulate.mechanics.assemble import Assembly
from undulate.mechanics.build import fabric_groups, lateral_stretch
from undulate.mechanics.fabric import orthotropic_membrane, orthotropic_stiffness
from undulate.model import ConfigError, case_from_dict
from undulate.solve.newton import NewtonOptions, minimize


def test_small_strain_stresses_are_linear_orthotropic_elasticity() -> None:
    """A unit right triangle strained by 1e-6 along each axis and in shear: stresses
    (dW/de / area) match Q e, with Q from (E1, E2, nu12, G12)."""
    E1, E2, nu, G = 0.45, 0.15, 0.4, 0.05
    Q = jnp.asarray(orthotropic_stiffness(E1, E2, nu, G))
    X = jnp.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    Dm_inv, A0, R, t = jnp.eye(2), 0.5, jnp.eye(2), 1.0

    def W(eps):  # eps = (exx, eyy, gxy) applied as a small displacement gradient
        Fm = jnp.array([[1.0 + eps[0], 0.5 * eps[2]], [0.5 * eps[2], 1.0 + eps[1]]])
        x = X.at[:, :2].set(X[:, :2] @ Fm.T)
        return orthotropic_membrane(x, Dm_inv, A0, Q, R, t) / A0

    sig = jax.grad(W)(jnp.array([1e-6, -2e-6, 3e-6]))
    nu21 = nu * E2 / E1
    d = 1 - nu * nu21
    want = np.array([(E1 * 1e-6 + nu * E2 * -2e-6) / d, (nu * E2 * 1e-6 + E2 * -2e-6) / d,
                     G * 3e-6])
    assert np.asarray(sig) == pytest.approx(want, rel=1e-4)


@pytest.mark.parametrize("E_y", [0.15, 0.9])
def test_uniaxial_stretch_gives_the_analytical_lateral_contraction(E_y: float) -> None:
    """A strip 5 times longer than wide, stretched by 30 % between clamps, long edges free:
    at mid-length it narrows to lam_y = sqrt(1 - nu ((1 + eps)^2 - 1)) (S_yy = 0), whatever
    E_y and G; the clamped ends hold their width."""
    E, nu, t, eps = 0.45, 0.35, 0.4, 0.3
    mesh = _strip(100.0, 20.0, 101, 21)
    groups = fabric_groups(mesh, E, nu, t, E_y=E_y, G=0.08)
    n = mesh.n_nodes
    x = np.c_[mesh.X, np.zeros(n)]
    x[:, 0] *= 1.0 + eps
    fixed = np.zeros((n, 3), bool)
    fixed[mesh.left] = fixed[mesh.right] = True
    fixed[:, 2] = True
    asm = Assembly(n, groups, fixed)
    res = minimize(asm, x, asm.free(x), NewtonOptions(negative_curvature=False, mixed=False))
    assert res.converged
    x = asm.full(res.u, x)
    mid = np.abs(mesh.X[:, 0] - 50.0) < 1e-9
    width = float(np.ptp(x[mid, 1]))
    want = lateral_stretch(eps, nu, orthotropic=True)
    assert want == pytest.approx(np.sqrt(1 - nu * ((1 + eps) ** 2 - 1)))
    assert width / 20.0 == pytest.approx(want, rel=5e-3)


def test_knit_settings_are_checked_and_a_case_runs() -> None:
    with pytest.raises(ConfigError, match="needs both E_y and G"):
        case_from_dict({"fabric": {"G": 0.1}})
    with pytest.raises(ConfigError, match=r"fabric.nu: must be below sqrt\(E / E_y\)"):
        case_from_dict({"fabric": {"E_y": 9.0, "G": 0.1, "nu": 0.45}})
    from undulate import api

    base = {"rods": {"h": 0.2, "L": 30.0}, "fabric": {"margin_x": 8.0, "margin_y": 8.0,
                                                      "E_y": 0.2, "G": 0.1},
            "release": {"steps": 6}, "mesh": {"dx_rod": 1.5, "h_far": 6.0}}
    rec = api.run_case(case_from_dict(base), None, artifacts=False)
    assert rec["n"] >= 1 and rec["max_height"] > 0.5
