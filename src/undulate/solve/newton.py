"""Newton energy minimisation that finds minima, not saddles.

Each iteration assembles the gradient g and the sparse Hessian H and factors H
(:func:`~undulate.solve.linear.factor_lazily`: whether H is positive definite decides the
step; its negative pivots are not counted where that would cost a second factorization):

* H positive definite: Newton step ``d = -H^-1 g`` with a backtracking (Armijo) line search.
* H indefinite (e.g. the flat rod just past its buckling load, a saddle): the most negative
  curvature direction ``v`` of the pencil (H, S) is computed with LOBPCG, preconditioned by the
  factorization of the shifted matrix ``K = H + tau S``, where S = |diag H| (Jacobi scaling, so
  the shift is in proportion to each unknown's own stiffness: an identity shift is hopeless
  when the rod is 10^4 times stiffer than the fabric). The step is the curvilinear path
  ``x(alpha) = x + alpha^2 d_K + alpha v`` (More & Sorensen 1979) with ``d_K = -K^-1 g`` and the
  sign of v chosen downhill; alpha is expanded while the energy keeps falling, so one iteration
  can carry a saddle all the way onto the buckled branch.

With the mixed iteration (stresses of the stiff rod groups carried from the linearized
strains, as in the MIP Newton of Magisano, Leonetti and Garcea) the line searches judge a step
by the mixed merit, not by the energy: the rod groups' quadratic terms are evaluated as
``s e - s^2 / (2 k)`` with the carried stress ``s`` (:meth:`Assembly.merit`), which is the
energy less the second-order stretch that a straight step gives a rotating, nearly
inextensible rod; the next iteration removes that stretch. Measured on the demo's last
release step (a snap from five to three arcs): 222-225 iterations judged by the energy,
126-142 by the merit, same final state. A step whose energy itself rises above the recent
ones by more than ``merit_energy_cap`` (10 %) is refused.

Convergence means ``max|g| <= rtol * force_scale`` *and* H positive definite (a stable
equilibrium), or, when the factorization reports negative pivots, a lowest relative eigenvalue
of (H, S) above ``-marginal`` (1e-7): a neutral mode that roundoff puts on either side of zero,
met just past a bifurcation (measured on thin rods: mu = -5e-9 at max|g| = 1e-7, where the
escape along it lowered the energy by 1e-9 per iteration and never ended). Anything else
after ``max_iter`` iterations is reported as non-convergence, never returned as a shape.
"""

from __future__ import annotations

import time
import warnings
from collections import deque
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.linalg import eigh
from scipy.sparse.linalg import LinearOperator, lobpcg

from ..mechanics.assemble import Assembly
from .linear import (
    NOT_COUNTED,
    SingularMatrixError,
    factor_lazily,
    is_definite,
    make_solver,
)

__all__ = ["NewtonOptions", "NewtonResult", "ConvergenceError", "minimize"]


class ConvergenceError(RuntimeError):
    """The solver did not reach a stable equilibrium. ``step`` and ``residual`` say where."""

    def __init__(self, message: str, *, step: int | None = None,
                 residual: float | None = None, release_strain: float | None = None) -> None:
        super().__init__(message)
        self.step = step
        self.residual = residual
        self.release_strain = release_strain


@dataclass
class NewtonOptions:
    rtol: float = 1e-6
    force_scale: float = 1.0
    max_iter: int = 300
    negative_curvature: bool = True
    require_stable: bool = True
    linear_solver: str = "auto"
    #: an equilibrium counts as stable when the lowest eigenvalue of (H, |diag H|) is above
    #: -marginal (a relative curvature; -1e-7 means 1e-7 of each unknown's own stiffness)
    marginal: float = 1e-7
    #: mixed Newton: carry the stresses of the strain-form (stiff rod) groups as unknowns of
    #: the iteration instead of recomputing them from the displacements
    mixed: bool = True
    #: Newton steps (positive definite Hessian) are accepted against the highest energy of
    #: the last ``nonmonotone`` iterates (0: monotone Armijo)
    nonmonotone: int = 5
    #: how many of the lowest negative-curvature modes one curved step follows at most
    modes: int = 1
    #: with ``mixed``, line searches judge a step by the mixed merit (:meth:`Assembly.merit`:
    #: the second-order stretch of stiff rods along a straight step is not charged to it)
    #: instead of the energy, as long as the energy itself stays below the highest recent one
    #: plus ``merit_energy_cap`` times its size
    mixed_merit: bool = True
    merit_energy_cap: float = 0.1
    #: give up (not converged) after this many iterations once a step along negative curvature
    #: of the ``watch`` unknowns has been taken (0: never): the release loop's budget for a
    #: grown step in which the rods' pattern changes (``release.snap_iterations``)
    curved_budget: int = 0
    #: give up at once (``NewtonResult.unstable_start``) when the start's Hessian is not
    #: positive definite:
    #: the release loop's rule for a grown step (``release.GROWN_STEP_DEFINITE_START``)
    definite_start: bool = False


@dataclass
class NewtonResult:
    u: np.ndarray
    converged: bool
    iterations: int
    residual: float
    energy: float
    n_negative: int
    negative_steps: int = 0
    times: dict = field(default_factory=dict)
    message: str = ""
    #: per iteration: (max|g|, negative pivots, kind of step, step length, energy, share of a
    #: curved step's direction on the ``watch`` unknowns (nan otherwise))
    trace: list = field(default_factory=list)
    #: curved steps with at least WATCH_SHARE of their direction on the ``watch`` unknowns
    watched_steps: int = 0
    #: stopped by ``opts.curved_budget`` (a change of pattern), not by max_iter or a failure
    over_budget: bool = False
    #: stopped at once by ``opts.definite_start`` (the start's Hessian is not positive definite)
    unstable_start: bool = False


#: a curved step counts towards ``curved_budget`` when at least this share of its direction
#: (sum of squares) lies on the ``watch`` unknowns (the rods' nodes). Measured on the demo:
#: the slack fabric's wrinkles are followed with shares of 0.00-0.02, the rod's changes of
#: pattern with 0.2-0.6.
WATCH_SHARE = 0.1
LOOSE_ITER = 8
#: a refinement sweep of a Newton step that changes it by less than this (relative) is the
#: last: measured on PARDISO's Cholesky of five-rod Hessians (21,063 unknowns), every sweep
#: changes d by 0.4-9e-9 and leaves the residual where it was (1e-13 to 3e-10 of |g|)
REFINED_ENOUGH = 1e-8
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


def _lowest_modes(H: sp.csr_matrix, S: np.ndarray, K_solve, n: int,
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


def minimize(asm: Assembly, x_fixed: np.ndarray, u0: np.ndarray,
             opts: NewtonOptions | None = None, *, solver=None,
             rng: np.random.Generator | None = None,
             x_ref: np.ndarray | None = None,
             watch: np.ndarray | None = None) -> NewtonResult:
    """Minimise the assembly's energy over the free unknowns starting from ``u0``.

    ``x_ref``: an equilibrium the start was predicted from (the previous load step). With
    ``opts.mixed`` the carried stresses start from the strains linearized at ``x_ref``
    rather than from those of the predicted start (which a predictor may stretch wrongly).
    ``watch``: a boolean mask of the free unknowns (the rods' nodes) whose negative curvature
    counts towards ``opts.curved_budget`` (all of them when None).
    """
    opts = opts or NewtonOptions()
    solver = solver or make_solver(opts.linear_solver)
    rng = rng or np.random.default_rng(0)
    u = np.array(u0, dtype=float)
    x = asm.full(u, x_fixed)
    E = asm.energy(x)
    tol = opts.rtol * opts.force_scale
    tau = 1e-6
    neg_steps = 0
    watched_steps = 0
    times = dict(assembly=0.0, factor=0.0, eig=0.0, line_search=0.0)
    trace: list[tuple] = []
    n_neg = -1
    res = float("inf")
    v_prev = None
    # modes sought where the Hessian's negative pivots were not counted: all ``opts.modes``
    # at first, then one more than the last search found
    k_next = opts.modes
    mixed = opts.mixed and bool(asm.mixed_groups)
    recent: deque[float] = deque([E], maxlen=max(opts.nonmonotone, 1))
    stress = None
    if mixed and x_ref is not None:
        stress = asm.stress_linearized(x_ref, x - x_ref)

    def result(converged: bool, it: int, message: str = "",
               over_budget: bool = False, unstable_start: bool = False) -> NewtonResult:
        return NewtonResult(u, converged, it, res, E, n_neg, neg_steps, dict(times), message,
                            trace, watched_steps, over_budget, unstable_start)

    for it in range(opts.max_iter + 1):
        t0 = time.perf_counter()
        g, H = asm.gradient_hessian(x, stress)
        res = float(np.max(np.abs(g))) if g.size else 0.0
        if stress is not None and res <= tol:
            # converged in force: judge stability on the exact Hessian
            stress = None
            g, H = asm.gradient_hessian(x)
        times["assembly"] += time.perf_counter() - t0
        t0 = time.perf_counter()
        H_factored = True
        try:
            # only "positive definite or not" is needed: PARDISO's LDL^T (the inertia) is
            # made only if a solve asks for it (the inverse iteration of _lowest_modes)
            n_neg = factor_lazily(solver, H)
        except SingularMatrixError:
            n_neg = 1  # treat a singular Hessian like an indefinite one: shift it
            H_factored = False
        times["factor"] += time.perf_counter() - t0
        if not np.isfinite(res):
            break
        stable = n_neg == 0 or not opts.require_stable
        if res <= tol and stable:
            return result(True, it)
        if it == opts.max_iter:
            break
        if opts.definite_start and it == 0 and n_neg != 0:
            return result(False, it, f"the start is not stable ({_pivots(n_neg)})",
                          unstable_start=True)
        if opts.curved_budget and watched_steps and it >= opts.curved_budget:
            return result(False, it, f"change of pattern: {it} iterations, {watched_steps} "
                                     f"along negative curvature of the watched unknowns "
                                     f"(budget {opts.curved_budget})", over_budget=True)
        t0 = time.perf_counter()
        v = None
        Hs = asm.symmetric(H)  # the full matrix, formed once per iteration
        if n_neg == 0:
            d = _refined_solve(solver, Hs, -g)
        else:
            # the shifted matrix is factored by a twin solver: H's own (indefinite)
            # factorization stays at hand for the inverse iteration of _lowest_modes
            shift_solver = _twin(solver, opts.linear_solver) if H_factored else solver
            S = _jacobi_scale(H)
            tau = _shift_until_definite(asm, shift_solver, H, S, tau, res,
                                        _ritz_floor(Hs, S, v_prev))
            times["factor"] += time.perf_counter() - t0
            d = -shift_solver.solve(g)
            if opts.negative_curvature:
                t1 = time.perf_counter()
                k = int(min(n_neg, opts.modes)) if n_neg > 0 else k_next
                mus, V = _lowest_modes(Hs, S, shift_solver.solve, u.size, rng, v_prev,
                                       tau, k, _nan_if_singular(solver.solve)
                                       if H_factored else None)
                mu = float(mus[0])
                times["eig"] += time.perf_counter() - t1
                if res <= tol and np.isfinite(mu) and mu >= -opts.marginal:
                    # equilibrium whose only "negative" curvature is at the level of the
                    # factorization's roundoff relative to the stiffness: marginally stable
                    return result(True, it, f"marginally stable: lowest relative eigenvalue "
                                            f"{mu:.2e}")
                if np.isfinite(mu) and mu < 0:
                    # the negative modes found warm-start the next search (all of them: with
                    # one, the other k - 1 start from random vectors every time)
                    neg = np.asarray(mus) < 0
                    k_next = int(min(opts.modes, np.count_nonzero(neg) + 1))
                    v_prev = V[:, neg] if np.all(np.isfinite(mus)) else V[:, :1]
                    v = _downhill_combination(mus, V, g, S, rng)
                    # give v the size of the shifted Newton step (in the S-norm), at least
                    # a small fraction of the typical node spacing
                    dn = np.sqrt(np.sum(S * d * d))
                    vn = np.sqrt(np.sum(S * v * v))
                    v = v * max(dn, 1e-3 * np.sqrt(np.sum(S))) / vn
            tau = max(tau / 10.0, 1e-8)
        t0 = time.perf_counter()
        # the merit of a step from x starts at E (x is its own linearization point)
        merit = _merit_function(asm, x, opts, recent) if mixed else _energy_function(asm)
        E_ref = max(recent) if (opts.nonmonotone and v is None) else E
        x_new, E_new, alpha, curved = _line_search(asm, x_fixed, u, d, v, g, E, Hs, merit,
                                                   E_ref)
        times["line_search"] += time.perf_counter() - t0
        share = float("nan")
        if curved and watch is not None:
            share = float(np.sum(v[watch] ** 2) / max(np.sum(v * v), 1e-300))
        watched_steps += int(curved and (watch is None or share >= WATCH_SHARE))
        trace.append((res, n_neg, "curved" if curved else ("newton" if n_neg == 0 else
                                                            "shifted"), alpha, E, share))
        if x_new is None:
            if v is None and n_neg == 0 and res <= 10 * tol:
                # a Newton step that cannot decrease the energy at tiny residual is roundoff
                return result(True, it, "stopped at roundoff")
            break
        neg_steps += int(curved)
        if mixed:
            # the stresses follow the linearized strains (mixed Newton): a step that rotates
            # a stiff rod edge does not load it with the step's second-order stretch
            t1 = time.perf_counter()
            stress = asm.stress_linearized(x, x_new - x)
            times["assembly"] += time.perf_counter() - t1
        u = asm.free(x_new)
        x = x_new
        E = E_new
        recent.append(E)
    return result(False, it, f"no stable equilibrium after {it} iterations: max|g| = "
                             f"{res:.3e} (tolerance {tol:.3e}), Hessian: {_pivots(n_neg)}")


def _pivots(n_neg: int) -> str:
    """How a message names a Hessian's negative pivots (``NOT_COUNTED``: known, not counted)."""
    if n_neg == NOT_COUNTED:
        return "not positive definite"
    return f"{n_neg} negative pivots"


def _nan_if_singular(solve):
    """``solve`` returning NaN instead of raising on a singular matrix (a deferred LDL^T):
    the inverse iteration then gives way to LOBPCG, as when H could not be factored."""
    def f(b: np.ndarray) -> np.ndarray:
        try:
            return solve(b)
        except SingularMatrixError:
            return np.full(np.shape(b), np.nan)
    return f


def _twin(solver, kind: str):
    """A second solver of the same kind, kept on ``solver`` (its analysis is reused)."""
    twin = getattr(solver, "shift_twin", None)
    if twin is None:
        twin = make_solver(kind)
        solver.shift_twin = twin
    return twin


def _downhill_combination(mus: np.ndarray, V: np.ndarray, g: np.ndarray, S: np.ndarray,
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


def _jacobi_scale(H: sp.csc_matrix) -> np.ndarray:
    """S = |diag H| (floored): each unknown's own stiffness, the metric of shifts and modes."""
    S = np.abs(H.diagonal())
    return np.maximum(S, 1e-12 * max(S.max(), 1e-300))


def _ritz_floor(Hs: sp.csr_matrix, S: np.ndarray, V: np.ndarray | None) -> float:
    """The lowest Ritz value of (H, S) on span(V) (the last iteration's modes): an upper
    bound of the lowest eigenvalue, so any shift tau <= -value cannot make H + tau S positive
    definite. 0 when there are no modes or they show no negative curvature."""
    if V is None or not np.all(np.isfinite(V)):
        return 0.0
    V = V.reshape(V.shape[0], -1)
    theta, _, _ = _rayleigh_ritz(V, Hs @ V, S, 1)
    return float(min(theta[0], 0.0)) if theta.size else 0.0


def _shift_until_definite(asm: Assembly, solver, H: sp.csc_matrix, S: np.ndarray,
                          tau: float, res: float, floor: float = 0.0) -> float:
    """Factor K = H + tau S (S = :func:`_jacobi_scale` of H) with tau grown by 10 until K is
    positive definite; return tau.

    K keeps H's pattern, so the symbolic factorization is reused. A shift that a known
    negative Ritz value ``floor`` of (H, S) already rules out (tau <= -floor) is skipped
    without factoring: it would fail, so the shift found is the same, for fewer
    factorizations.
    """
    while True:
        if tau > -floor:
            K = H.copy()
            K.data[asm.diag_pos] += tau * S
            if is_definite(solver, K):
                return tau
        tau *= 10.0
        if tau > 1e12:
            raise ConvergenceError("could not make the Hessian positive definite", residual=res)


def _refined_solve(solver, Hs: sp.csr_matrix, b: np.ndarray, sweeps: int = 2,
                   enough: float = REFINED_ENOUGH) -> np.ndarray:
    """Solve ``H d = b`` with the current factorization plus iterative refinement.

    LDL^T without pivoting on the stiff, nearly singular Hessians met just past a bifurcation
    loses digits; a refinement sweep (residual r = b - H d, d += H^-1 r) restores them at the
    cost of one solve and one sparse product, so Newton keeps converging quadratically. The
    sweeps stop once a correction changes d by less than ``enough`` (relative): then d is as
    accurate as the factorization can make it.
    """
    d = solver.solve(b)
    nb = np.linalg.norm(b)
    for _ in range(sweeps):
        r = b - Hs @ d
        if not np.linalg.norm(r) > 1e-12 * nb:
            break
        dd = solver.solve(r)
        d = d + dd
        if np.linalg.norm(dd) <= enough * np.linalg.norm(d):
            break
    return d


def _curved_backtrack(dM: float, q: float) -> float:
    """Factor to shorten a refused curved step by: its merit rose by ``dM`` where the quadratic
    model of the path predicted ``q`` (< 0). The excess ``dM - q`` of a curved path grows like
    the fourth power of the step (measured on the demo's snap: it fell by 8-16 per halving),
    the model's decrease like the square: the factor that makes the excess half the predicted
    decrease, between 0.1 and 0.5. A refused merit (energy over its cap): 0.25."""
    if not np.isfinite(dM):
        return 0.25
    excess = dM - q
    if not (q < 0.0 and excess > 0.0):
        return 0.5
    return float(min(0.5, max(0.1, np.sqrt(-q / (2.0 * excess)))))


def _energy_function(asm: Assembly):
    """The line searches' function when no stresses are carried: (energy, energy)."""
    def f(x: np.ndarray) -> tuple[float, float]:
        E = asm.energy(x)
        return E, E
    return f


def _merit_function(asm: Assembly, x0: np.ndarray, opts: NewtonOptions, recent_E):
    """(merit, energy) of a trial point of a mixed Newton step from ``x0``.

    Without ``opts.mixed_merit`` the merit is the energy. With it, a trial point whose energy
    exceeds the highest recent energy by more than ``opts.merit_energy_cap`` of its size is
    refused (merit +inf): the merit forgives the stretch of the stiff rods along a straight
    step, not a step that tears the structure apart (measured: without the cap a curved step
    accepted a state of energy 1.8e5 N mm from 12).
    """
    if not opts.mixed_merit:
        return _energy_function(asm)
    E_top = max(recent_E)
    cap = E_top + opts.merit_energy_cap * abs(E_top)

    def f(x: np.ndarray) -> tuple[float, float]:
        m, E = asm.merit(x0, x - x0)
        return (m if np.isfinite(E) and E <= cap else np.inf), E
    return f


def _line_search(asm: Assembly, x_fixed, u, d, v, g, M0, Hs, merit,
                 M_ref: float | None = None) -> tuple:
    """Backtracking on x(a) = u + a^2 d + a v (or u + a d when v is None); expand along v.

    ``merit(x)`` returns (merit, energy) of a trial point; ``M0`` is the current merit and
    ``M_ref`` the one a Newton step must beat (the highest recent one: non-monotone).
    Returns (x, energy, step length a, curved) with x None when no step lowers the merit.
    Near convergence the merit change of a Newton step falls below its roundoff; then the step
    is accepted when it lowers max|g| instead (the merit cannot tell).
    """
    slope = float(g @ d)
    if v is None:
        if slope >= 0:
            return None, M0, 0.0, False
        noise = 1e-13 * abs(M0)
        res0 = float(np.max(np.abs(g)))
        M_acc = M0 if M_ref is None else max(M0, M_ref)
        a = 1.0
        for _ in range(30):
            x = asm.full(u + a * d, x_fixed)
            M, E = merit(x)
            if np.isfinite(M) and M <= M_acc + 1e-4 * a * slope:
                return x, E, a, False
            if np.isfinite(M) and -a * slope <= 100 * noise and abs(M - M0) <= 100 * noise \
                    and float(np.max(np.abs(asm.gradient(x)))) < res0:
                return x, E, a, False
            a *= 0.5
        return None, M0, 0.0, False
    Hs_v = Hs @ v
    curv = float(v @ Hs_v)

    def model(a: float) -> float:
        return 1e-4 * (a * a * slope + a * float(g @ v) + 0.5 * a * a * curv)

    def path(a: float) -> np.ndarray:
        return u + min(a, 1.0) ** 2 * d + a * v

    a = 1.0
    best = None
    for _ in range(40):
        x = asm.full(path(a), x_fixed)
        M, E = merit(x)
        if np.isfinite(M) and M < M0 + model(a):
            best = (x, M, E, a)
            break
        # model() is the Armijo threshold, 1e-4 of the quadratic model's decrease
        a *= _curved_backtrack(M - M0, 1e4 * model(a))
    if best is None:
        return None, M0, 0.0, False
    # expand while the merit keeps decreasing (escape from the saddle in one go)
    x_b, M_b, E_b, a_b = best
    if a_b == 1.0:
        a = 2.0
        for _ in range(30):
            x = asm.full(path(a), x_fixed)
            M, E = merit(x)
            if not (np.isfinite(M) and M < M_b):
                break
            x_b, M_b, E_b, a_b = x, M, E, a
            a *= 2.0
    return x_b, E_b, a_b, True
