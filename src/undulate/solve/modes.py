"""Directions of negative curvature: the lowest modes of the pencil (H, S).

S = |diag H| (:func:`jacobi_scale`) is the metric: each unknown's own stiffness, so a mode is
measured in proportion to how stiff its unknowns are (the rods are 10^4 times stiffer than the
fabric). :func:`lowest_modes` finds the lowest eigenpairs with a cheap, loose LOBPCG pass first
and a tight pass (inverse iteration on H's own factorization, else SciPy's LOBPCG) only when the
loose one found no negative curvature; :func:`downhill_combination` makes one direction of them.
"""

from __future__ import annotations

import warnings

import numpy as np
import scipy.sparse as sp
from scipy.linalg import eigh
from scipy.sparse.linalg import LinearOperator, lobpcg

__all__ = ["downhill_combination", "jacobi_scale", "lowest_modes", "ritz_floor"]

#: sweeps of LOBPCG's loose pass
LOOSE_ITER = 8
#: sweeps of the inverse iteration that replaces LOBPCG's tight pass
INVERSE_ITER = 12


def _inverse_iteration(H: sp.csr_matrix, S: np.ndarray, H_solve, X: np.ndarray,
                       rng: np.random.Generator, iters: int = INVERSE_ITER
                       ) -> tuple[np.ndarray, np.ndarray]:
    """Eigenpairs of H v = mu S v nearest zero by block inverse iteration on H's own (indefinite)
    factorization, with a Rayleigh-Ritz step per sweep; returns (mu, V), lowest first.

    The modes LOBPCG's loose pass cannot resolve are the ones barely below zero, met just past
    a bifurcation and at the end of a snap: nearest zero, they are the ones inverse iteration
    finds first, and fast (rate |mu_1 / mu_2| per sweep).
    """
    n = H.shape[0]
    X = np.column_stack([X, rng.standard_normal((n, max(3 - X.shape[1], 1)))])
    mu = np.array([np.nan])
    V = X[:, :1]
    for _ in range(iters):
        Y = H_solve(S[:, None] * X)
        if not np.all(np.isfinite(Y)):
            return np.array([np.nan]), V
        Y, _ = np.linalg.qr(Y)
        A = Y.T @ (H @ Y)
        B = Y.T @ (S[:, None] * Y)
        try:
            w, Z = eigh(0.5 * (A + A.T), 0.5 * (B + B.T))
        except np.linalg.LinAlgError:
            return np.array([np.nan]), V
        X = Y @ Z
        converged = abs(w[0] - mu[0]) <= 1e-3 * abs(w[0]) if np.isfinite(mu[0]) else False
        mu, V = w, X
        if converged:
            break
    return mu, V


def _rayleigh_ritz(Z: np.ndarray, HZ: np.ndarray, S: np.ndarray, k: int
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The k lowest Ritz pairs of (H, S) on span(Z), given HZ = H Z: (theta, V, H V), V
    S-orthonormal. The basis is S-orthonormalized first, its near-dependent part dropped."""
    G = Z.T @ (S[:, None] * Z)
    w, U = np.linalg.eigh(0.5 * (G + G.T))
    keep = w > 1e-12 * max(w.max(), 1e-300)
    T = U[:, keep] / np.sqrt(w[keep])
    A = T.T @ (Z.T @ HZ) @ T
    theta, C = np.linalg.eigh(0.5 * (A + A.T))
    TC = T @ C[:, :k]
    return theta[:k], Z @ TC, HZ @ TC


def _lobpcg(H: sp.csr_matrix, S: np.ndarray, M, X: np.ndarray, maxiter: int,
            rtol: float = 1e-2) -> tuple[np.ndarray, np.ndarray, bool]:
    """Lowest eigenpairs of H v = mu S v (S diagonal) by a small LOBPCG, preconditioned by M.

    Rayleigh-Ritz on span[X, M R, P] each sweep (one block solve with M, a few sparse
    products). It stops as soon as the lowest Ritz value is negative and has settled (relative
    change <= ``rtol``): a curved step needs a direction of clearly negative curvature, not an
    eigenvector to many digits. Returns (mu, V, settled), lowest first, V S-orthonormal.
    """
    k = X.shape[1]
    mu, X, HX = _rayleigh_ritz(X, H @ X, S, k)
    P = HP = None
    for _ in range(maxiter):
        R = HX - (S[:, None] * X) * mu
        W = np.asarray(M(R)).reshape(X.shape[0], -1)
        HW = H @ W
        Z = np.column_stack([X, W] if P is None else [X, W, P])
        HZ = np.column_stack([HX, HW] if P is None else [HX, HW, HP])
        mu_new, Xn, HXn = _rayleigh_ritz(Z, HZ, S, k)
        settled = mu_new[0] < 0 and abs(mu_new[0] - mu[0]) <= rtol * abs(mu_new[0])
        # the previous direction: what the new vectors add to the old ones
        c = X.T @ (S[:, None] * Xn)
        P, HP = Xn - X @ c, HXn - HX @ c
        mu, X, HX = mu_new, Xn, HXn
        if settled:
            return mu, X, True
    return mu, X, False


def lowest_modes(H: sp.csr_matrix, S: np.ndarray, K_solve, n: int,
                 rng: np.random.Generator, x0: np.ndarray | None, tau: float = 1e-4,
                 k: int = 1, H_solve=None) -> tuple[np.ndarray, np.ndarray]:
    """The ``k`` smallest eigenpairs of H v = mu S v (S diagonal), preconditioned by
    K^-1 = (H + tau S)^-1; returns (mu (k,), V (n, k)), lowest first.

    The start block is the previous iteration's modes ``x0`` (n,) or (n, j) when there are
    any, filled up with random vectors, and random otherwise: a warm start alone can lock onto a
    positive mode while a weaker negative one exists (measured on a thin rod: +4.5e-6 returned
    while mu = -1.1e-5 existed). A cheap, loose pass comes first (:func:`_lobpcg`, stopped once
    a negative Ritz value has settled); a tight one only when it found no negative curvature:
    inverse iteration on H's own factorization when it is at hand, else SciPy's LOBPCG with a
    residual tolerance following the shift tau (the eigenvalues that matter here can be 1e-5 of
    the stiffness).
    """
    X = rng.standard_normal((n, max(k, 1)))
    if x0 is not None:
        # with a block, keep one random column: the warm modes alone may miss a new one
        x0 = x0.reshape(n, -1)[:, : max(X.shape[1] - 1, 1)]
        X[:, : x0.shape[1]] = x0

    def M(R: np.ndarray) -> np.ndarray:
        # the preconditioner takes the whole block in one solve (PARDISO solves k right-hand
        # sides at once)
        return K_solve(R if R.shape[1] > 1 else R[:, 0])

    mu, V, _ = _lobpcg(H, S, M, X, LOOSE_ITER)
    if np.isfinite(mu[0]) and mu[0] < 0:
        return mu, V
    X = V if np.all(np.isfinite(V)) else X
    if H_solve is not None:
        # the tight pass: inverse iteration on H when its factorization is at hand
        # (measured on the demo: 14 tight LOBPCG passes of 49 iterations, 137 ms each)
        mu_i, V_i = _inverse_iteration(H, S, H_solve, X, rng)
        if np.isfinite(mu_i[0]) and mu_i[0] < 0:
            return mu_i, V_i
    Mop = LinearOperator((n, n), matvec=lambda r: K_solve(np.ravel(r)),
                         matmat=lambda R: K_solve(np.asarray(R)), dtype=float)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # "not reaching the requested tolerance"
            w, W = lobpcg(H, X, B=sp.diags(S), M=Mop, largest=False,
                          tol=min(1e-4, 1e-2 * tau), maxiter=60)
    except Exception:  # pragma: no cover - LOBPCG can fail on tiny problems
        return mu, V
    order = np.argsort(w)
    return np.asarray(w)[order], np.asarray(W)[:, order]


def downhill_combination(mus: np.ndarray, V: np.ndarray, g: np.ndarray, S: np.ndarray,
                         rng: np.random.Generator) -> np.ndarray:
    """Sum of the negative-curvature modes, each S-normalized, weighted by sqrt(-mu) and signed
    downhill (g . v <= 0; a random sign where g does not tell): several unstable modes are
    left in one step, not one per Newton iteration (measured: a wide sheet fully released
    starts its last step with 92 negative pivots, wrinkles of the slack fabric)."""
    v = np.zeros(V.shape[0])
    for m, col in zip(mus, V.T, strict=True):
        if not (np.isfinite(m) and m < 0):
            continue
        c = col / np.sqrt(np.sum(S * col * col))
        gv = float(g @ c)
        sign = -np.sign(gv) if gv != 0.0 else rng.choice([-1.0, 1.0])
        v += sign * np.sqrt(-m) * c
    return v


def jacobi_scale(H: sp.csc_matrix) -> np.ndarray:
    """S = |diag H| (floored): each unknown's own stiffness, the metric of shifts and modes."""
    S = np.abs(H.diagonal())
    return np.maximum(S, 1e-12 * max(S.max(), 1e-300))


def ritz_floor(Hs: sp.csr_matrix, S: np.ndarray, V: np.ndarray | None) -> float:
    """The lowest Ritz value of (H, S) on span(V) (the last iteration's modes): an upper
    bound of the lowest eigenvalue, so any shift tau <= -value cannot make H + tau S positive
    definite. 0 when there are no modes or they show no negative curvature."""
    if V is None or not np.all(np.isfinite(V)):
        return 0.0
    V = V.reshape(V.shape[0], -1)
    theta, _, _ = _rayleigh_ritz(V, Hs @ V, S, 1)
    return float(min(theta[0], 0.0)) if theta.size else 0.0
