"""The rod model alone and bonded: Euler buckling, beam on a Winkler foundation, bilayer curl."""

import numpy as np
import pytest

from undulate.mechanics.assemble import Assembly, ElementGroup
from undulate.mechanics.build import (
    RodSection,
    fabric_groups,
    free_rod,
    rod_centrelines,
    rod_groups,
)
from undulate.mechanics.fabric import winkler_foundation
from undulate.mesh import FabricMesh, RodChain
from undulate.solve import NewtonOptions, make_solver, minimize


def _compressed(x, delta, length):
    y = x.copy()
    y[:, 0] = x[:, 0] * (1.0 - delta)
    return y


def _critical_shortening(asm_for, x0, length, lo, hi, iters=40):
    """Bisection on the end shortening where the Hessian's inertia first turns negative."""
    solver = make_solver()
    for _ in range(iters):
        mid = np.sqrt(lo * hi)
        asm = asm_for()
        _, H = asm.gradient_hessian(_compressed(x0, mid, length))
        if solver.factor(H) > 0:
            hi = mid
        else:
            lo = mid
    return np.sqrt(lo * hi)


def _pinned_rod(n, length, sec, extra=()):
    chain, x0 = free_rod(n, length, sec.b)
    groups = rod_groups([chain], x0, sec) + list(extra)
    fixed = np.zeros((3 * n, 3), bool)
    for k in (0, n - 1):  # whole cross-section fixed at both ends, slope free: pinned
        fixed[[chain.p[k], chain.qp[k], chain.qm[k]]] = True
    return chain, x0, groups, fixed


def test_euler_buckling_pinned_rod_within_1_percent():
    sec = RodSection(h=0.3, b=1.0, E_B=3000.0, nu_B=0.35, t=0.0, d=0.0)
    L, n = 100.0, 101
    chain, x0, groups, fixed = _pinned_rod(n, L, sec)
    d = _critical_shortening(lambda: Assembly(3 * n, groups, fixed), x0, L, 1e-8, 1e-3)
    P_cr = sec.EA * d  # axial force at the critical shortening
    assert P_cr == pytest.approx(np.pi**2 * sec.EI_out / L**2, rel=0.01)


def test_winkler_wrinkling_wavelength():
    """A long rod on an elastic foundation buckles at P = 2 sqrt(K B), lambda = 2 pi (B/K)^1/4."""
    sec = RodSection(h=0.3, b=1.0, E_B=3000.0, nu_B=0.35, t=0.0, d=0.0)
    K = 0.5  # N/mm per mm of rod
    lam_th = 2 * np.pi * (sec.EI_out / K) ** 0.25
    L = 12 * lam_th
    n = int(L / (lam_th / 24)) + 1
    chain0, xr = free_rod(n, L, sec.b)
    dx = L / (n - 1)
    found = ElementGroup("foundation", winkler_foundation, chain0.p[:, None],
                         (np.full(n, K * dx), np.zeros(n)))
    chain, x0, groups, fixed = _pinned_rod(n, L, sec, extra=[found])
    fixed[:, 1] = True  # the foundation is out of plane: hold the rod in plane (no y buckling)
    P_th = 2 * np.sqrt(K * sec.EI_out)
    d = _critical_shortening(lambda: Assembly(3 * n, groups, fixed), x0, L,
                             0.5 * P_th / sec.EA, 2 * P_th / sec.EA)
    assert sec.EA * d == pytest.approx(P_th, rel=0.02)
    # wavelength of the critical mode: lowest eigenvector just past the critical load
    asm = Assembly(3 * n, groups, fixed)
    _, H = asm.gradient_hessian(_compressed(x0, d * 1.001, L))
    import scipy.sparse.linalg as spla

    w, V = spla.eigsh(asm.symmetric(H).tocsc(), k=1, sigma=-1e-9, which="LM")
    mode = asm.full(V[:, 0], np.zeros_like(x0))[chain.p, 2]
    spec = np.abs(np.fft.rfft(mode * np.hanning(n)))
    k = np.argmax(spec[1:]) + 1
    lam = L / k
    assert lam == pytest.approx(lam_th, rel=0.05)


def _strip_mesh(L0, b, dx):
    xs = np.arange(0.0, L0 + 1e-9, dx)
    ys = np.array([-b / 2, 0.0, b / 2])
    nx = xs.size
    XX, YY = np.meshgrid(xs, ys)
    X = np.stack([XX.ravel(), YY.ravel()], 1)
    tris = []
    for j in range(2):
        for i in range(nx - 1):
            a = j * nx + i
            tris += [(a, a + 1, a + nx + 1), (a, a + nx + 1, a + nx)]
    cols = np.arange(nx)
    chain = RodChain(p=nx + cols, qm=cols, qp=2 * nx + cols)
    return FabricMesh(X=X, tris=np.array(tris), xs=xs, ys=ys, rods=[chain],
                      left=np.array([0, nx, 2 * nx]),
                      right=np.array([nx - 1, 2 * nx - 1, 3 * nx - 1]))


def test_bilayer_curvature_matches_timoshenko():
    """Fabric pre-stretched by eps under a rod printed on it: releasing one end curls the pair.

    Timoshenko (1925): kappa = 6 de (1+m)^2 / (H (3 (1+m)^2 + (1+mn)(m^2 + 1/(mn)))),
    m = t/h, n = E/E_B, H = t + h, de = the fabric's free shrinkage relative to the rod.
    Moduli are chosen close so the curl is large enough to measure (this checks the offset).
    """
    E, t, E_B, h, b = 2.0, 0.4, 20.0, 0.4, 1.0
    eps = 0.01
    L0, dx = 40.0, 0.5
    mesh = _strip_mesh(L0, b, dx)
    X3 = np.c_[mesh.X, np.zeros(mesh.n_nodes)]
    xp = X3 * [1.0 + eps, 1.0, 1.0]
    sec = RodSection(h=h, b=b, E_B=E_B, nu_B=0.0, t=t)
    groups = fabric_groups(mesh, E, 0.0, t) + rod_groups(mesh.rods, xp, sec)
    fixed = np.zeros((mesh.n_nodes, 3), bool)
    nx = mesh.xs.size
    for col in (0, 1):  # cantilever: first two columns clamped
        fixed[[col, nx + col, 2 * nx + col]] = True
    asm = Assembly(mesh.n_nodes, groups, fixed)
    res = minimize(asm, xp, asm.free(xp),
                   NewtonOptions(rtol=1e-8, force_scale=E * t * dx, max_iter=100))
    assert res.converged
    x = asm.full(res.u, xp)
    cl = rod_centrelines(mesh.rods, x, sec)[0]
    # curvature from the turning of the tangent over the middle half of the strip
    tang = np.diff(cl[:, [0, 2]], axis=0)
    ang = np.unwrap(np.arctan2(tang[:, 1], tang[:, 0]))
    s = np.cumsum(np.linalg.norm(tang, axis=1))
    mid = slice(len(s) // 4, 3 * len(s) // 4)
    kappa = abs(np.polyfit(s[mid], ang[mid], 1)[0])
    m, nn, H = t / h, E / E_B, t + h
    de = eps / (1 + eps)
    k_th = 6 * de * (1 + m) ** 2 / (H * (3 * (1 + m) ** 2 + (1 + m * nn) * (m**2 + 1 / (m * nn))))
    assert kappa == pytest.approx(k_th, rel=0.05)
    # the shrinking fabric is below the rod, so it ends on the concave side: the centre of
    # curvature lies below and the free end of the (horizontally clamped) strip goes down
    assert cl[-1, 2] < cl[0, 2] - 1.0
