"""Verification of the energies: patch test, derivatives, fabric bending calibration."""

import numpy as np
import pytest

from undulate.mechanics.assemble import Assembly
from undulate.mechanics.build import (
    RodSection,
    fabric_groups,
    lame_plane_stress,
    lateral_stretch,
    rod_groups,
)
from undulate.mesh import build_mesh
from undulate.model import Case


def _small_mesh(L=20.0, margin=4.0, dx=1.0):
    c = Case.model_validate(
        {"rods": {"L": L}, "fabric": {"margin_x": margin, "margin_y": margin},
         "mesh": {"dx_rod": dx, "dx_far": 2.0, "dy_far": 2.0}}
    )
    ly = lateral_stretch(0.5, 0.3)
    m = build_mesh(c.segments(), 1.0, c.fabric_extent(), eps0=0.5, lam_y=ly, dx_rod=dx,
                   dx_far=2.0, dy_far=2.0, grading=1.5)
    return c, m


def test_patch_uniform_stretch_energy_and_stress():
    """A homogeneously stretched sheet stores exactly t * A * W and carries uniaxial stress."""
    E, nu, t = 0.45, 0.3, 0.4
    _, m = _small_mesh()
    groups = fabric_groups(m, E, nu, t)
    lx = 1.3
    ly = lateral_stretch(lx - 1.0, nu)
    X3 = np.c_[m.X, np.zeros(m.n_nodes)]
    x = X3 * [lx, ly, 1.0]
    free = np.zeros((m.n_nodes, 3), bool)
    asm = Assembly(m.n_nodes, groups, ~free)
    mu, lam2 = lame_plane_stress(E, nu)
    J = lx * ly
    W = 0.5 * mu * (lx**2 + ly**2 - 2 - 2 * np.log(J)) + 0.5 * lam2 * np.log(J) ** 2
    area = (m.xs[-1] - m.xs[0]) * (m.ys[-1] - m.ys[0])
    assert asm.energy(x) == pytest.approx(t * area * W, rel=1e-10)
    # interior nodes are in equilibrium (homogeneous state); the edge x = max carries the
    # uniaxial force  N = t * width * P_11, with P_11 = dW/dlx (1st Piola) and dW/dly = 0
    g = asm.gradient_full(x)
    interior = np.ones(m.n_nodes, bool)
    interior[m.left] = interior[m.right] = False
    on_y_edges = np.isclose(m.X[:, 1], m.ys[0]) | np.isclose(m.X[:, 1], m.ys[-1])
    assert np.max(np.abs(g[interior & ~on_y_edges])) < 1e-10
    P11 = mu * (lx - 1 / lx) + lam2 * np.log(J) / lx
    assert g[m.right, 0].sum() == pytest.approx(t * (m.ys[-1] - m.ys[0]) * P11, rel=1e-9)
    # free long edges carry no transverse force
    assert abs(g[on_y_edges & interior, 1].sum()) < 1e-10


def test_small_strain_limit_is_linear_plane_stress():
    """For small uniaxial strain the law reduces to sigma = E eps, eps_y = -nu eps."""
    eps = 1e-5
    nu = 0.3
    ly = lateral_stretch(eps, nu)
    assert (ly - 1.0) / eps == pytest.approx(-nu, rel=1e-3)


def test_gradient_and_hessian_match_finite_differences():
    c, m = _small_mesh(L=10.0, margin=3.0)
    ly = lateral_stretch(0.5, 0.3)
    X3 = np.c_[m.X, np.zeros(m.n_nodes)]
    xp = X3 * [1.5, ly, 1.0]
    sec = RodSection(h=0.3, b=1.0, E_B=3000.0, nu_B=0.35, t=0.4)
    groups = fabric_groups(m, 0.45, 0.3, 0.4) + rod_groups(m.rods, xp, sec)
    fixed = np.zeros((m.n_nodes, 3), bool)
    fixed[m.left] = fixed[m.right] = True
    asm = Assembly(m.n_nodes, groups, fixed)
    rng = np.random.default_rng(1)
    x = xp + rng.normal(scale=0.05, size=xp.shape)
    g, H = asm.gradient_hessian(x)
    u = asm.free(x)
    d = rng.normal(size=u.size)
    h = 1e-6
    fd = (asm.energy(asm.full(u + h * d, x)) - asm.energy(asm.full(u - h * d, x))) / (2 * h)
    assert fd == pytest.approx(g @ d, rel=1e-6)
    Hs = asm.symmetric(H)
    gp = asm.gradient(asm.full(u + h * d, x))
    gm = asm.gradient(asm.full(u - h * d, x))
    err = np.linalg.norm((gp - gm) / (2 * h) - Hs @ d) / np.linalg.norm(Hs @ d)
    assert err < 1e-6


def test_rods_are_stress_free_at_printing():
    _, m = _small_mesh()
    ly = lateral_stretch(0.5, 0.3)
    xp = np.c_[m.X, np.zeros(m.n_nodes)] * [1.5, ly, 1.0]
    sec = RodSection(h=0.5, b=1.0, E_B=3000.0, nu_B=0.35, t=0.4)
    asm = Assembly(m.n_nodes, rod_groups(m.rods, xp, sec), np.zeros((m.n_nodes, 3), bool))
    assert asm.energy(xp) == pytest.approx(0.0, abs=1e-20)
    assert np.max(np.abs(asm.gradient(xp))) < 1e-9


@pytest.mark.parametrize("axis", [0, 1])
def test_fabric_bending_cylinder(axis):
    """Bending a flat sheet into a cylinder of radius R stores D/2 * A / R^2 (within 10 %)."""
    E, nu, t = 0.45, 0.0, 0.4
    _, m = _small_mesh(L=30.0, margin=6.0, dx=0.5)
    groups = [g for g in fabric_groups(m, E, nu, t) if g.name == "fabric_bending"]
    R = 200.0
    X = m.X
    s = X[:, axis]
    x = np.zeros((m.n_nodes, 3))
    x[:, axis] = R * np.sin(s / R)
    x[:, 1 - axis] = X[:, 1 - axis]
    x[:, 2] = R * (1 - np.cos(s / R))
    asm = Assembly(m.n_nodes, groups, np.ones((m.n_nodes, 3), bool))
    D = E * t**3 / 12.0
    area = (m.xs[-1] - m.xs[0]) * (m.ys[-1] - m.ys[0])
    assert asm.energy(x) == pytest.approx(0.5 * D * area / R**2, rel=0.10)


def test_hinge_kernels_match_autodiff_of_the_energy():
    """The closed-form hinge gradient/Hessian equal jax.grad/jax.hessian of k theta^2."""
    import jax
    import jax.numpy as jnp

    from undulate.mechanics.fabric import hinge_bending
    from undulate.mechanics.forms import kernels_for

    rng = np.random.default_rng(3)
    base = np.array([[0.0, 0, 0], [1, 0, 0], [0.5, 1, 0], [0.5, -1, 0]])
    x = jnp.asarray(base[None] + 0.2 * rng.standard_normal((64, 4, 3)))
    k = jnp.asarray(rng.uniform(0.5, 2.0, 64))
    nodes = jnp.arange(256).reshape(64, 4)
    xall = x.reshape(256, 3)
    g, H = kernels_for(hinge_bending)["grad_hess"](xall, nodes, k)
    g_ad = jax.vmap(jax.grad(hinge_bending))(x, k)
    H_ad = jax.vmap(jax.hessian(lambda y, kk: hinge_bending(y.reshape(4, 3), kk)))(
        x.reshape(64, 12), k)
    np.testing.assert_allclose(np.asarray(g), np.asarray(g_ad), atol=1e-10)
    np.testing.assert_allclose(np.asarray(H), np.asarray(H_ad), atol=1e-9)
    g2 = kernels_for(hinge_bending)["grad"](xall, nodes, k)
    np.testing.assert_allclose(np.asarray(g2), np.asarray(g_ad), atol=1e-10)


def test_membrane_kernels_match_autodiff_of_the_energy():
    """The closed-form neo-Hookean gradient/Hessian equal jax.grad/jax.hessian of the energy,
    on distorted, stretched, compressed and out-of-plane triangles."""
    import jax
    import jax.numpy as jnp

    from undulate.mechanics.fabric import neo_hookean_membrane
    from undulate.mechanics.forms import kernels_for

    rng = np.random.default_rng(5)
    n = 64
    ref = np.array([[0.0, 0.0], [1.3, 0.1], [0.2, 0.9]])
    Dm = np.stack([ref[1] - ref[0], ref[2] - ref[0]], axis=1)
    Dm_inv = np.tile(np.linalg.inv(Dm), (n, 1, 1))
    stretch = rng.uniform(0.6, 1.6, (n, 1, 3))
    x = np.c_[ref, np.zeros(3)][None] * stretch + 0.15 * rng.standard_normal((n, 3, 3))
    params = (jnp.asarray(Dm_inv), jnp.full(n, 0.5 * np.linalg.det(Dm)),
              jnp.asarray(rng.uniform(0.1, 0.2, n)), jnp.asarray(rng.uniform(0.0, 0.3, n)),
              jnp.full(n, 0.4))
    nodes = jnp.arange(3 * n).reshape(n, 3)
    xall = jnp.asarray(x.reshape(3 * n, 3))
    g, H = kernels_for(neo_hookean_membrane)["grad_hess"](xall, nodes, *params)
    g_ad = jax.vmap(jax.grad(neo_hookean_membrane))(jnp.asarray(x), *params)
    H_ad = jax.vmap(jax.hessian(lambda y, *p: neo_hookean_membrane(y.reshape(3, 3), *p)))(
        jnp.asarray(x.reshape(n, 9)), *params)
    scale = float(np.max(np.abs(H_ad)))
    np.testing.assert_allclose(np.asarray(g), np.asarray(g_ad), atol=1e-12 * scale)
    np.testing.assert_allclose(np.asarray(H), np.asarray(H_ad), atol=1e-11 * scale)
    g2 = kernels_for(neo_hookean_membrane)["grad"](xall, nodes, *params)
    np.testing.assert_allclose(np.asarray(g2), np.asarray(g_ad), atol=1e-12 * scale)


def test_element_groups_split_into_calls_and_empty_groups():
    """Kernel calls cover every element once (padding only at the end), an empty group is
    allowed, and the full symmetric Hessian from the map equals H + H^T - diag(H) and does not
    share its index arrays with the assembly."""
    import scipy.sparse as sp

    from undulate.mechanics.assemble import Assembly, ElementGroup
    from undulate.mechanics.fabric import hinge_bending, winkler_foundation

    for n in (0, 1, 15, 99, 129, 495, 3298, 4895):
        g = ElementGroup("t", hinge_bending, np.zeros((n, 4), int), (np.ones(n),))
        assert sum(g._sizes) >= n and sum(g._sizes) - n < 16
        assert len(set(g._sizes)) <= 2
        assert [len(c[0]) for c in g._chunks] == g._sizes
        assert list(g._starts) == list(np.cumsum([0, *g._sizes])[:-1])
    assert ElementGroup("t", hinge_bending, np.zeros((3298, 4), int),
                        (np.ones(3298),))._sizes == [3312]
    assert ElementGroup("t", hinge_bending, np.zeros((20000, 4), int),
                        (np.ones(20000),))._sizes == [4096] * 4 + [3616]
    # an assembly with an empty group next to a real one
    rng = np.random.default_rng(0)
    n_nodes = 40
    x = rng.standard_normal((n_nodes, 3))
    hinges = np.array([rng.choice(n_nodes, 4, replace=False) for _ in range(60)])
    groups = [ElementGroup("bend", hinge_bending, hinges, (rng.uniform(0.5, 2, 60),)),
              ElementGroup("none", winkler_foundation, np.zeros((0, 1), int),
                           (np.zeros(0), np.zeros(0)))]
    fixed = np.zeros((n_nodes, 3), bool)
    fixed[:2] = True
    asm = Assembly(n_nodes, groups, fixed)
    _, H = asm.gradient_hessian(x)
    S = asm.symmetric(H)
    ref = (H + H.T - sp.diags(H.diagonal())).tocsr()
    assert abs(S - ref).max() == 0.0
    S.data[:] = 0.0
    S.eliminate_zeros()  # a caller's structural change must not reach the next call
    assert abs(asm.symmetric(H) - ref).max() == 0.0


def test_footprint_energy_is_invariant_under_rotations() -> None:
    """The footprint's rest offsets are measured in the node's own frame: turning rod and
    fabric together (as a free sample that rolls up) changes no energy."""
    import jax.numpy as jnp
    from scipy.spatial.transform import Rotation

    from undulate.mechanics.rod import node_strains, rod_footprint

    rng = np.random.default_rng(3)
    x5 = np.array([[-1.0, 0, 0], [1.0, 0, 0], [0.002, 0, 0], [0, 0.5, 0], [0, -0.5, 0]])
    rest = np.asarray(node_strains(jnp.asarray(x5)))
    assert abs(rest[2]) > 1e-3  # an off-centre p at printing, as meshes leave it
    bent = x5 + 0.05 * rng.standard_normal((5, 3))
    k = jnp.array([1.0, 1.0, 10.0])
    e0 = float(rod_footprint(jnp.asarray(bent), jnp.asarray(rest), k))
    for R in Rotation.random(3, random_state=1).as_matrix():
        e = float(rod_footprint(jnp.asarray(bent @ R.T + 3.0), jnp.asarray(rest), k))
        assert e == pytest.approx(e0, rel=1e-9, abs=1e-15)
