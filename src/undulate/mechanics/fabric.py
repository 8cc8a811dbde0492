"""Energies of the fabric: a finite-strain hyperelastic membrane plus discrete-shell bending.

All functions are pure, act on one element, and are written for ``jax.vmap``/``jax.hessian``.

Membrane (per triangle, reference = unstretched fabric)::

    F = [x1 - x0, x2 - x0] @ Dm^-1          (3 x 2 surface deformation gradient)
    C = F^T F,  J = sqrt(det C)             (in-plane area ratio)
    W = mu/2 (tr C - 2 - 2 ln J) + lam2/2 (ln J)^2
    energy = t * A0 * W

a compressible neo-Hookean law in 2D with the plane-stress Lame constant
lam2 = E nu / (1 - nu^2) and mu = E / (2 (1 + nu)), so that for small strains it is exactly
linear plane-stress elasticity with (E, nu). Unlike St Venant-Kirchhoff it stiffens, not
softens, in compression (W -> inf as J -> 0).

Bending (per interior edge, discrete shell hinge, flat rest state)::

    energy = D * f * |e|^2 / (A_a + A_b) * theta^2,    D = E t^3 / (12 (1 - nu^2))

where theta is the dihedral angle between the two triangles sharing the edge and f the mesh's
``hinge_factor`` (a property of the mesh kind). On an equilateral mesh f = 1 reproduces
(D/2) * integral (2H)^2 dA for a cylinder of any orientation. On the structured meshes with
alternating diagonals the diagonal hinges also bend, and f = HINGE_FACTOR = 0.57 reproduces
cylinders along x and along y within 10 % (``tests/test_mechanics.py``), but that mesh is
anisotropic: a cylinder at 45 degrees stores 6.9 times too much. On Triangle's quality meshes
f = 0.44 (``undulate.mesh.unstructured.UNSTRUCTURED_HINGE_FACTOR``; x, y and 45 degrees within
15 %, ``tests/test_mesh_unstructured.py``).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

HINGE_FACTOR = 0.57


def neo_hookean_membrane(x: jnp.ndarray, Dm_inv: jnp.ndarray, A0: jnp.ndarray,
                         mu: jnp.ndarray, lam2: jnp.ndarray, t: jnp.ndarray) -> jnp.ndarray:
    """Strain energy [N mm] of one triangle with deformed nodes ``x`` (3, 3)."""
    Ds = jnp.stack([x[1] - x[0], x[2] - x[0]], axis=1)  # (3, 2)
    F = Ds @ Dm_inv
    C = F.T @ F
    detC = C[0, 0] * C[1, 1] - C[0, 1] * C[1, 0]
    lnJ = 0.5 * jnp.log(detC)
    W = 0.5 * mu * (C[0, 0] + C[1, 1] - 2.0 - 2.0 * lnJ) + 0.5 * lam2 * lnJ**2
    return t * A0 * W


def orthotropic_membrane(x: jnp.ndarray, Dm_inv: jnp.ndarray, A0: jnp.ndarray,
                         Q: jnp.ndarray, R: jnp.ndarray, t: jnp.ndarray) -> jnp.ndarray:
    """Strain energy [N mm] of one triangle of an orthotropic knit (St Venant-Kirchhoff).

    The Green strain E = (C - I) / 2 is turned into the material axes (``R``: 2 x 2, columns
    the axes in the mesh's frame) and W = 1/2 [Q11 e11^2 + 2 Q12 e11 e22 + Q22 e22^2 +
    4 Q66 e12^2] with ``Q = (Q11, Q12, Q22, Q66)`` the plane-stress stiffnesses of
    (E1, E2, nu12, G12): exact linear orthotropic elasticity at small strains. Unlike the
    neo-Hookean law it softens in strong compression (stretches below about 0.6).
    """
    Ds = jnp.stack([x[1] - x[0], x[2] - x[0]], axis=1)
    F = Ds @ Dm_inv
    Eg = 0.5 * (F.T @ F - jnp.eye(2))
    e = R.T @ Eg @ R
    W = 0.5 * (Q[0] * e[0, 0] ** 2 + 2.0 * Q[1] * e[0, 0] * e[1, 1] + Q[2] * e[1, 1] ** 2
               + 4.0 * Q[3] * e[0, 1] ** 2)
    return t * A0 * W


def orthotropic_stiffness(E1: float, E2: float, nu12: float, G12: float
                          ) -> tuple[float, float, float, float]:
    """(Q11, Q12, Q22, Q66) of plane-stress orthotropic elasticity (nu21 = nu12 E2 / E1)."""
    nu21 = nu12 * E2 / E1
    d = 1.0 - nu12 * nu21
    return E1 / d, nu12 * E2 / d, E2 / d, G12


def _membrane_grad_hess(x: jnp.ndarray, Dm_inv: jnp.ndarray, A0: jnp.ndarray,
                        mu: jnp.ndarray, lam2: jnp.ndarray, t: jnp.ndarray
                        ) -> tuple[jnp.ndarray, jnp.ndarray]:
    """Gradient (3, 3) and Hessian (9, 9) of :func:`neo_hookean_membrane`, in closed form.

    With G = F C^-1 (so d lnJ = G : dF), the first Piola stress is P = mu F + (lam2 lnJ - mu) G
    and its derivative

        dP = mu dF + lam2 (G : dF) G + (lam2 lnJ - mu) (dF C^-1 - G dF^T G - G F^T dF C^-1).

    F = x^T D with D (3 nodes, 2) = [-1 -1; 1 0; 0 1] Dm^-1, so node k's gradient is t A0 P D[k]
    and the Hessian block (k, l) is t A0 sum_ab D[k, a] dP_ia/dF_jb D[l, b], here with the
    sums over a, b done by hand (below). Checked against autodiff of the energy in the tests;
    3.4 times faster than ``jax.hessian`` of it with the sums as one einsum over the 4-index
    tensor (4,096 triangles: 3.5 ms against 11.8 ms, CPU), and 2.4 times faster again with
    them written out (14,208 triangles: 6.3 -> 2.6 ms; 3,312: 1.7 -> 0.8 ms).
    """
    D = jnp.stack([-Dm_inv[0] - Dm_inv[1], Dm_inv[0], Dm_inv[1]])
    F = x.T @ D  # (3, 2)
    C = F.T @ F
    det = C[0, 0] * C[1, 1] - C[0, 1] * C[1, 0]
    Ci = jnp.stack([jnp.stack([C[1, 1], -C[0, 1]]), jnp.stack([-C[1, 0], C[0, 0]])]) / det
    lnJ = 0.5 * jnp.log(det)
    G = F @ Ci
    c1 = lam2 * lnJ - mu
    w = t * A0
    grad = w * (D @ (mu * F + c1 * G).T)
    # the contraction with D written out, node pair (k, l), components (i, j):
    # H_kilj = w [(mu P + c1 Q)_kl d_ij + lam2 g_ki g_lj - c1 g_li g_kj - c1 Q_kl M_ij]
    # with P = D D^T, Q = D C^-1 D^T, g_k = G D[k] (rows of D G^T) and M = G F^T
    P = D @ D.T
    Q = D @ Ci @ D.T
    Gd = D @ G.T
    M = G @ F.T
    H = ((mu * P + c1 * Q)[:, None, :, None] * jnp.eye(3)[None, :, None, :]
         + lam2 * Gd[:, :, None, None] * Gd[None, None, :, :]
         - c1 * jnp.einsum("li,kj->kilj", Gd, Gd)
         - c1 * Q[:, None, :, None] * M[None, :, None, :])
    return grad, w * H.reshape(9, 9)


def _membrane_kernels() -> dict:
    """Batched membrane kernels with the closed-form gradient and Hessian."""

    def grad_one(x, *p):
        return _membrane_grad_hess(x, *p)[0]

    return {
        "per_element": jax.vmap(neo_hookean_membrane),
        "grad": jax.vmap(grad_one),
        "grad_hess": jax.vmap(_membrane_grad_hess),
    }


neo_hookean_membrane.kernels = _membrane_kernels  # type: ignore[attr-defined]


def dihedral_angle(x: jnp.ndarray) -> jnp.ndarray:
    """Signed dihedral angle at edge (x0, x1) between triangles (x0, x1, x2) and (x1, x0, x3)."""
    e = x[1] - x[0]
    na = jnp.cross(e, x[2] - x[0])
    nb = jnp.cross(x[3] - x[0], e)
    ehat = e / jnp.linalg.norm(e)
    return jnp.arctan2(jnp.dot(jnp.cross(na, nb), ehat), jnp.dot(na, nb))


def hinge_bending(x: jnp.ndarray, k: jnp.ndarray) -> jnp.ndarray:
    """Bending energy [N mm] of one hinge (4, 3); ``k = D * f * |e|^2 / (A_a + A_b)``."""
    return k * dihedral_angle(x) ** 2


def dihedral_angle_grad(xf: jnp.ndarray) -> jnp.ndarray:
    """Closed-form gradient (12,) of :func:`dihedral_angle` w.r.t. the flattened hinge (12,).

    A flap vertex moving along its triangle's unit normal by delta turns the triangle by
    delta / (its height over the edge) = delta |e| / |n|; the edge vertices share the flaps'
    gradients by the lever rule (translation and rotation invariance). Checked against
    autodiff in the tests.
    """
    x = xf.reshape(4, 3)
    e = x[1] - x[0]
    na = jnp.cross(e, x[2] - x[0])
    nb = jnp.cross(x[3] - x[0], e)
    le = jnp.linalg.norm(e)
    e2 = le * le
    g2 = -le * na / jnp.dot(na, na)
    g3 = -le * nb / jnp.dot(nb, nb)
    t2 = jnp.dot(x[2] - x[0], e) / e2
    t3 = jnp.dot(x[3] - x[0], e) / e2
    g1 = -(t2 * g2 + t3 * g3)
    g0 = -((1.0 - t2) * g2 + (1.0 - t3) * g3)
    return jnp.concatenate([g0, g1, g2, g3])


def _skew(v: jnp.ndarray) -> jnp.ndarray:
    """[v]x: the matrix of the cross product v x ."""
    z = jnp.zeros_like(v[0])
    return jnp.array([[z, -v[2], v[1]], [v[2], z, -v[0]], [-v[1], v[0], z]])


def dihedral_angle_hessian(xf: jnp.ndarray) -> tuple[jnp.ndarray, jnp.ndarray]:
    """Gradient (12,) and Hessian (12, 12) of :func:`dihedral_angle`, in closed form.

    The gradient is that of :func:`dihedral_angle_grad`: the flaps' g_2 = -|e| n_a / |n_a|^2
    and g_3 = -|e| n_b / |n_b|^2, shared with the edge vertices by the lever rule with
    t_2 = a.e / |e|^2, t_3 = b.e / |e|^2 (e = x1 - x0, a = x2 - x0, b = x3 - x0,
    n_a = e x a, n_b = b x e). Its derivative, with dn_a = -[a]x de + [e]x da and
    dn_b = [b]x de - [e]x db,

        dg_2 = -(e^.de) n_a / |n_a|^2 - |e| / |n_a|^2 (I - 2 n_a n_a^T / |n_a|^2) dn_a

    (g_3 alike), dg_1 = -(t_2 dg_2 + g_2 dt_2^T + t_3 dg_3 + g_3 dt_3^T),
    dg_0 = -(dg_1 + dg_2 + dg_3); every row sums to zero over the four vertices (translation
    invariance), which gives the x0 column. Equal to ``jax.jacfwd`` of the gradient to
    roundoff (``tests/test_mechanics.py``) at half its cost (21,216 hinges on the CPU:
    10.4 ms against 20.4 ms for the kernel below; 4,896: 2.0 against 3.1 ms).
    """
    x = xf.reshape(4, 3)
    e, a, b = x[1] - x[0], x[2] - x[0], x[3] - x[0]
    na, nb = jnp.cross(e, a), jnp.cross(b, e)
    e2 = jnp.dot(e, e)
    le = jnp.sqrt(e2)
    sa, sb = jnp.dot(na, na), jnp.dot(nb, nb)
    g2, g3 = -le * na / sa, -le * nb / sb
    t2, t3 = jnp.dot(a, e) / e2, jnp.dot(b, e) / e2
    Se = _skew(e)

    def flap(n, s, dn_de, dn_df):
        P = -le / s * (jnp.eye(3) - 2.0 * jnp.outer(n, n) / s)
        return -jnp.outer(n, e / le) / s + P @ dn_de, P @ dn_df

    G2e, G2a = flap(na, sa, -_skew(a), Se)
    G3e, G3b = flap(nb, sb, _skew(b), -Se)
    Z, z = jnp.zeros((3, 3)), jnp.zeros(3)
    # blocks of the columns x1, x2, x3 (de = dx1 - dx0, da = dx2 - dx0, db = dx3 - dx0)
    dg2, dg3 = (G2e, G2a, Z), (G3e, Z, G3b)
    dt2 = (a / e2 - 2.0 * t2 * e / e2, e / e2, z)
    dt3 = (b / e2 - 2.0 * t3 * e / e2, z, e / e2)
    dg1 = [-(t2 * dg2[c] + jnp.outer(g2, dt2[c]) + t3 * dg3[c] + jnp.outer(g3, dt3[c]))
           for c in range(3)]
    dg0 = [-(dg1[c] + dg2[c] + dg3[c]) for c in range(3)]
    rows = [jnp.concatenate([-(R[0] + R[1] + R[2]), *R], axis=1) for R in (dg0, dg1, dg2, dg3)]
    g1 = -(t2 * g2 + t3 * g3)
    return jnp.concatenate([-(g1 + g2 + g3), g1, g2, g3]), jnp.concatenate(rows, axis=0)


def _hinge_kernels() -> dict:
    """Batched hinge kernels: H = 2k (g g^T + theta dg/dx) with g and dg/dx in closed form
    (:func:`dihedral_angle_grad`, :func:`dihedral_angle_hessian`).

    Measured on 2048 hinges (CPU): 3.2 ms with ``jax.jacfwd`` of the closed-form gradient
    against 11.6 ms for ``jax.hessian`` of the energy; the closed-form Hessian halves it again.
    """

    def grad_one(x, k):
        return (2.0 * k * dihedral_angle(x) * dihedral_angle_grad(x.ravel())).reshape(4, 3)

    def grad_hess_one(x, k):
        th = dihedral_angle(x)
        g, Hth = dihedral_angle_hessian(x.ravel())
        return (2.0 * k * th * g).reshape(4, 3), 2.0 * k * (jnp.outer(g, g) + th * Hth)

    return {
        "per_element": jax.vmap(hinge_bending),
        "grad": jax.vmap(grad_one),
        "grad_hess": jax.vmap(grad_hess_one),
    }


hinge_bending.kernels = _hinge_kernels  # type: ignore[attr-defined]


def body_force(x: jnp.ndarray, f: jnp.ndarray) -> jnp.ndarray:
    """Potential of a constant nodal force ``f`` (3,) [N] at node ``x`` (1, 3): -f . x."""
    return -jnp.dot(f, x[0])


def winkler_foundation(x: jnp.ndarray, k: jnp.ndarray, z0: jnp.ndarray) -> jnp.ndarray:
    """Elastic (Winkler) support of one node (1, 3) out of plane: 0.5 k (z - z0)^2, k in N/mm."""
    return 0.5 * k * (x[0, 2] - z0) ** 2


def inertia(x: jnp.ndarray, m_h2: jnp.ndarray, x_hat: jnp.ndarray) -> jnp.ndarray:
    """Implicit-Euler inertia term of one node: m / (2 dt^2) |x - x_hat|^2 (x_hat: predicted)."""
    r = x[0] - x_hat
    return 0.5 * m_h2 * jnp.dot(r, r)


def dead_load(x: jnp.ndarray, w: jnp.ndarray) -> jnp.ndarray:
    """Potential of a constant force ``w`` [N] on one node (its weight m g, or its share of
    a tension on an edge): -w . x."""
    return -jnp.dot(w, x[0])
