"""Strain-form rod energies: exact derivatives, and the mixed (carried-stress) Newton pieces."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from undulate.mechanics.forms import kernels_for, strain_form
from undulate.mechanics.rod import rod_bend_twist, rod_footprint, rod_stretch


def _stencil(rng, n_blocks):
    """n_blocks rod nodes along x, each (p_a, p_b, p, qp, qm), randomly perturbed."""
    pts = []
    for k in range(n_blocks):
        x0 = 1.0 * k
        pts += [[x0 - 1, 0, 0], [x0 + 1, 0, 0], [x0, 0, 0], [x0, 0.5, 0], [x0, -0.5, 0]]
    return np.asarray(pts) + 0.05 * rng.standard_normal((5 * n_blocks, 3))


CASES = [
    (rod_stretch, 2, lambda: (0.35, 1.02, 900.0)),
    (rod_bend_twist, 3, lambda: (0.35, np.array([0.01, -0.02, 0.003, 0.001]), 1.0, 6.75, 75.0,
                                 8.1)),
    (rod_footprint, 1, lambda: (np.array([1.0, 0.01, 0.0, 0.0, 0.0]),
                                np.array([900.0, 333.0, 900.0]))),
]


@pytest.mark.parametrize("fn, nb, params", CASES, ids=["stretch", "bend_twist", "footprint"])
def test_strain_form_kernels_are_exact(fn, nb, params):
    rng = np.random.default_rng(1)
    p = params()
    x = _stencil(rng, nb)
    assert strain_form(fn) is not None
    k = kernels_for(fn)
    nodes = jnp.arange(x.shape[0])[None, :]
    P = tuple(jnp.asarray(np.asarray(v, dtype=float))[None] for v in p)
    g, H = k["grad_hess"](jnp.asarray(x), nodes, *P)

    def flat(xf):
        return fn(xf.reshape(-1, 3), *[jnp.asarray(v) for v in p])

    g_ref = jax.grad(flat)(jnp.asarray(x).ravel())
    H_ref = jax.hessian(flat)(jnp.asarray(x).ravel())
    scale = float(jnp.max(jnp.abs(H_ref)))
    np.testing.assert_allclose(np.ravel(g[0]), g_ref, atol=1e-9 * scale)
    np.testing.assert_allclose(H[0], H_ref, atol=1e-9 * scale)
    E = k["per_element"](jnp.asarray(x), nodes, *P)
    assert float(E[0]) == pytest.approx(float(flat(jnp.asarray(x).ravel())), rel=1e-12)
    # the mixed Hessian with the consistent stress is the exact Hessian
    s = k["stress"](jnp.asarray(x), nodes, *P)
    g2, H2 = k["grad_hess_mixed"](jnp.asarray(x), nodes, *P, s)
    np.testing.assert_allclose(H2[0], H_ref, atol=1e-9 * scale)
    np.testing.assert_allclose(np.ravel(g2[0]), g_ref, atol=1e-9 * scale)
    # ... and with another stress it differs in the geometric term only (the gradient not)
    g3, H3 = k["grad_hess_mixed"](jnp.asarray(x), nodes, *P, 0.0 * s)
    np.testing.assert_allclose(np.ravel(g3[0]), g_ref, atol=1e-9 * scale)
    assert float(jnp.max(jnp.abs(H3[0] - H_ref))) > 1e-6 * scale
    # linearized stress: its error along a small move is second order (the plain stress's first)
    dx = 1e-4 * rng.standard_normal(x.shape)
    s_lin = k["stress_lin"](jnp.asarray(x), nodes, *P, jnp.asarray(dx))
    s_new = k["stress"](jnp.asarray(x + dx), nodes, *P)
    err_lin = float(jnp.max(jnp.abs(s_lin - s_new)))
    err_old = float(jnp.max(jnp.abs(s - s_new)))
    assert err_lin <= 1e-2 * err_old
    # the mixed merit of a step: the energy at x + dx less k (e - e_lin)^2 / 2, so it equals the
    # energy for dx = 0 and falls short of it by a fourth-order amount (dx doubled: x 16)
    m0 = k["merit_step"](jnp.asarray(x), nodes, *P, jnp.zeros_like(jnp.asarray(x)))
    assert float(m0[0, 0]) == pytest.approx(float(E[0]), rel=1e-12)
    assert float(m0[0, 1]) == pytest.approx(float(E[0]), rel=1e-12)
    gaps = []
    for f in (1.0, 2.0):
        dxf = jnp.asarray(1e2 * f * dx)
        m = k["merit_step"](jnp.asarray(x), nodes, *P, dxf)
        E1 = float(k["per_element"](jnp.asarray(x) + dxf, nodes, *P)[0])
        assert float(m[0, 1]) == pytest.approx(E1, rel=1e-12)
        gaps.append(E1 - float(m[0, 0]))
    assert gaps[0] > 0.0
    assert gaps[1] / gaps[0] == pytest.approx(16.0, rel=0.2)


def test_mixed_newton_reaches_the_same_elastica():
    """A pinned rod pushed far past Euler buckling (large rotations of stiff edges): the mixed
    iteration (carried stresses) reaches the same post-buckled equilibrium as plain Newton.
    (Its gain in iterations is measured on the real release in docs/benchmarks.md.)"""
    from undulate.mechanics.assemble import Assembly
    from undulate.mechanics.build import RodSection, free_rod, rod_groups
    from undulate.solve import NewtonOptions, minimize

    sec = RodSection(h=0.3, b=1.0, E_B=3000.0, nu_B=0.35, t=0.0, d=0.0)
    L, n = 100.0, 51
    chain, x0 = free_rod(n, L, sec.b)
    groups = rod_groups([chain], x0, sec)
    fixed = np.zeros((3 * n, 3), bool)
    for k in (0, n - 1):
        fixed[[chain.p[k], chain.qp[k], chain.qm[k]]] = True
    fixed[:, 1] = True  # planar
    asm = Assembly(3 * n, groups, fixed)
    # the buckled start: a small half-sine, ends pushed in by 20 % (an elastica of ~60 deg)
    start = x0.copy()
    start[:, 0] *= 0.8
    start[:, 2] = 1.0 * np.sin(np.pi * x0[:, 0] / L)
    out = {}
    for mixed, merit in ((False, False), (True, False), (True, True)):
        opts = NewtonOptions(rtol=1e-8, force_scale=1.0, mixed=mixed, mixed_merit=merit,
                             max_iter=300)
        res = minimize(asm, start, asm.free(start), opts)
        assert res.converged, res.message
        out[mixed, merit] = res
    x_plain = asm.full(out[False, False].u, start)
    for key in ((True, False), (True, True)):
        # the start is far from equilibrium (ends pushed in by 20 % with a 1 mm bump): a
        # solver may end on the mirror image z -> -z of the same elastica
        x_key = asm.full(out[key].u, start)
        mid = chain.p[n // 2]
        if x_key[mid, 2] * x_plain[mid, 2] < 0:
            x_key = x_key * np.array([1.0, 1.0, -1.0])
        np.testing.assert_allclose(x_key, x_plain, atol=1e-6)
        assert out[key].energy == pytest.approx(out[False, False].energy, rel=1e-9)
        assert out[key].n_negative == 0


@pytest.mark.parametrize("fn, nb, params", CASES, ids=["stretch", "bend_twist", "footprint"])
def test_merit_kernel_returns_the_linearized_stress(fn, nb, params):
    """``merit_step`` ends with the stress of the strains linearized along the step, the
    numbers of ``stress_lin`` (to roundoff): the stress a Newton iteration carries on."""
    rng = np.random.default_rng(5)
    x = _stencil(rng, nb)
    nodes = jnp.asarray(np.arange(5 * nb)[None, :])
    P = [jnp.asarray(np.asarray(p, dtype=float))[None] for p in params()]
    k = kernels_for(fn)
    dx = jnp.asarray(1e-3 * rng.standard_normal(x.shape))
    m = np.asarray(k["merit_step"](jnp.asarray(x), nodes, *P, dx))[0]
    s = np.asarray(k["stress_lin"](jnp.asarray(x), nodes, *P, dx))[0]
    assert m.shape == (2 + s.size,)
    np.testing.assert_allclose(m[2:], s, rtol=1e-12, atol=1e-12 * np.max(np.abs(s)))


def test_assembly_reuses_the_stresses_of_a_merit_evaluation():
    """After a line search evaluated a step's merit, the stresses of that step come from it
    (no kernel call), the same bits as evaluated afresh."""
    from undulate.mechanics.assemble import Assembly, ElementGroup
    from undulate.mechanics.build import RodSection, free_rod, rod_groups

    chain, X = free_rod(12, 11.0, 2.0)
    sec = RodSection(h=0.5, b=2.0, E_B=1e3, nu_B=0.35, t=0.4)
    gs = rod_groups([chain], X, sec)
    fixed = np.zeros((X.shape[0], 3), bool)
    fixed[:5] = True
    asm = Assembly(X.shape[0], gs, fixed)
    rng = np.random.default_rng(2)
    dx = 1e-2 * rng.standard_normal(X.shape)
    fresh = asm.stress_linearized(X, dx)
    asm.merit(X, dx)
    calls = []
    run0 = ElementGroup.run
    try:
        ElementGroup.run = lambda self, *a, **k: calls.append(a) or run0(self, *a, **k)
        again = asm.stress_linearized(X, dx)
        other = asm.stress_linearized(X, 2 * dx)
    finally:
        ElementGroup.run = run0
    assert set(again) == set(fresh) == set(asm.mixed_groups) and asm.mixed_groups
    for i in fresh:
        assert np.array_equal(again[i], fresh[i])
    assert len(calls) == len(asm.mixed_groups)  # only the step never evaluated
    assert not all(np.array_equal(other[i], fresh[i]) for i in fresh)
    # new parameters of a rod group: the kept stresses are not theirs
    g = asm.groups[asm.mixed_groups[0]]
    g.set_params(*g.params)
    calls.clear()
    try:
        ElementGroup.run = lambda self, *a, **k: calls.append(a) or run0(self, *a, **k)
        asm.stress_linearized(X, dx)
    finally:
        ElementGroup.run = run0
    assert len(calls) == len(asm.mixed_groups)
