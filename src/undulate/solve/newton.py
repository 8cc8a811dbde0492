"""Newton energy minimisation that finds minima, not saddles.

Each iteration assembles the gradient g and the sparse Hessian H and factors H (LDL^T). The
inertia of H decides the step:

* H positive definite: Newton step ``d = -H^-1 g`` with a backtracking (Armijo) line search.
* H indefinite (e.g. the flat rod just past its buckling load, a saddle): the most negative
  curvature direction ``v`` of the pencil (H, S) is computed with LOBPCG, preconditioned by the
  factorization of the shifted matrix ``K = H + tau S``, where S = |diag H| (Jacobi scaling, so
  the shift is in proportion to each unknown's own stiffness: an identity shift is hopeless
  when the rod is 10^4 times stiffer than the fabric). The step is the curvilinear path
  ``x(alpha) = x + alpha^2 d_K + alpha v`` (More & Sorensen 1979) with ``d_K = -K^-1 g`` and the
  sign of v chosen downhill; alpha is expanded while the energy keeps falling, so one iteration
  can carry a saddle all the way onto the buckled branch.

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
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import LinearOperator, lobpcg

from ..mechanics.assemble import Assembly
from .linear import SingularMatrixError, make_solver

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


def _lowest_mode(H: sp.csr_matrix, S: np.ndarray, K_solve, n: int, rng: np.random.Generator,
                 x0: np.ndarray | None) -> tuple[float, np.ndarray]:
    """Smallest eigenpair of H v = mu S v (S diagonal), preconditioned by K^-1."""
    X = rng.standard_normal((n, 1)) if x0 is None else x0.reshape(n, 1).copy()
    Sm = sp.diags(S)
    Mop = LinearOperator((n, n), matvec=lambda r: K_solve(np.ravel(r)), dtype=float)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # "not reaching the requested tolerance": fine here
            w, V = lobpcg(H, X, B=Sm, M=Mop, largest=False, tol=1e-4, maxiter=40)
        return float(w[0]), np.ravel(V[:, 0])
    except Exception:  # pragma: no cover - LOBPCG can fail on tiny problems
        return float("nan"), np.ravel(X)


def minimize(asm: Assembly, x_fixed: np.ndarray, u0: np.ndarray,
             opts: NewtonOptions | None = None, *, solver=None,
             rng: np.random.Generator | None = None) -> NewtonResult:
    """Minimise the assembly's energy over the free unknowns starting from ``u0``."""
    opts = opts or NewtonOptions()
    solver = solver or make_solver(opts.linear_solver)
    rng = rng or np.random.default_rng(0)
    u = np.array(u0, dtype=float)
    x = asm.full(u, x_fixed)
    E = asm.energy(x)
    tol = opts.rtol * opts.force_scale
    tau = 1e-6
    neg_steps = 0
    t_asm = t_fac = t_eig = t_ls = 0.0
    n_neg = -1
    res = float("inf")
    v_prev = None
    for it in range(opts.max_iter + 1):
        t0 = time.perf_counter()
        g, H = asm.gradient_hessian(x)
        t_asm += time.perf_counter() - t0
        res = float(np.max(np.abs(g))) if g.size else 0.0
        t0 = time.perf_counter()
        try:
            n_neg = solver.factor(H)
        except SingularMatrixError:
            n_neg = 1  # treat a singular Hessian like an indefinite one: shift it
        t_fac += time.perf_counter() - t0
        if not np.isfinite(res):
            break
        stable = n_neg == 0 or not opts.require_stable
        if res <= tol and stable:
            return NewtonResult(u, True, it, res, E, n_neg, neg_steps,
                                dict(assembly=t_asm, factor=t_fac, eig=t_eig, line_search=t_ls))
        if it == opts.max_iter:
            break
        t0 = time.perf_counter()
        if n_neg == 0:
            d = _refined_solve(solver, asm.symmetric(H), -g)
            v = None
        else:
            # shifted factorization K = H + tau S, tau grown until K is positive definite
            S = np.abs(H.diagonal())
            S = np.maximum(S, 1e-12 * max(S.max(), 1e-300))
            while True:
                K = H.copy()  # same pattern as H: the symbolic factorization is reused
                K.data[asm.diag_pos] += tau * S
                try:
                    if solver.factor(K) == 0:
                        break
                except SingularMatrixError:
                    pass
                tau *= 10.0
                if tau > 1e12:
                    raise ConvergenceError("could not make the Hessian positive definite",
                                           residual=res)
            t_fac += time.perf_counter() - t0
            d = -solver.solve(g)
            v = None
            if opts.negative_curvature:
                t1 = time.perf_counter()
                Hs = asm.symmetric(H)
                mu, v = _lowest_mode(Hs, S, solver.solve, u.size, rng, v_prev)
                t_eig += time.perf_counter() - t1
                if res <= tol and np.isfinite(mu) and mu >= -opts.marginal:
                    # equilibrium whose only "negative" curvature is at the level of the
                    # factorization's roundoff relative to the stiffness: marginally stable
                    return NewtonResult(u, True, it, res, E, n_neg, neg_steps,
                                        dict(assembly=t_asm, factor=t_fac, eig=t_eig,
                                             line_search=t_ls),
                                        f"marginally stable: lowest relative eigenvalue "
                                        f"{mu:.2e}")
                if not (np.isfinite(mu) and mu < 0):
                    v = None
                else:
                    v_prev = v
                    if g @ v > 0:
                        v = -v
                    # give v the size of the shifted Newton step (in the S-norm), at least
                    # a small fraction of the typical node spacing
                    dn = np.sqrt(np.sum(S * d * d))
                    vn = np.sqrt(np.sum(S * v * v))
                    v = v * max(dn, 1e-3 * np.sqrt(np.sum(S))) / vn
            tau = max(tau / 10.0, 1e-8)
        t0 = time.perf_counter()
        x_new, E_new, ok, curved = _line_search(asm, x_fixed, u, d, v, g, E, H)
        t_ls += time.perf_counter() - t0
        if not ok:
            if v is None and n_neg == 0:
                # a Newton step that cannot decrease the energy at tiny residual is roundoff
                if res <= 10 * tol:
                    return NewtonResult(u, True, it, res, E, n_neg, neg_steps,
                                        dict(assembly=t_asm, factor=t_fac, eig=t_eig,
                                             line_search=t_ls),
                                        "stopped at roundoff")
            break
        neg_steps += int(curved)
        u = asm.free(x_new)
        x = x_new
        E = E_new
    return NewtonResult(u, False, it, res, E, n_neg, neg_steps,
                        dict(assembly=t_asm, factor=t_fac, eig=t_eig, line_search=t_ls),
                        f"no stable equilibrium after {it} iterations: max|g| = {res:.3e} "
                        f"(tolerance {tol:.3e}), negative eigenvalues: {n_neg}")


def _refined_solve(solver, Hs: sp.csr_matrix, b: np.ndarray, sweeps: int = 2) -> np.ndarray:
    """Solve ``H d = b`` with the current factorization plus iterative refinement.

    LDL^T without pivoting on the stiff, nearly singular Hessians met just past a bifurcation
    loses digits; a refinement sweep (residual r = b - H d, d += H^-1 r) restores them at the
    cost of one solve and one sparse product, so Newton keeps converging quadratically.
    """
    d = solver.solve(b)
    nb = np.linalg.norm(b)
    for _ in range(sweeps):
        r = b - Hs @ d
        if not np.linalg.norm(r) > 1e-12 * nb:
            break
        d = d + solver.solve(r)
    return d


def _line_search(asm: Assembly, x_fixed, u, d, v, g, E0, H) -> tuple:
    """Backtracking on x(a) = u + a^2 d + a v (or u + a d when v is None); expand along v.

    Near convergence the energy change of a Newton step falls below the energy's roundoff; then
    the step is accepted when it lowers max|g| instead (the energy cannot tell).
    """
    slope = float(g @ d)
    if v is None:
        if slope >= 0:
            return None, E0, False, False
        noise = 1e-13 * abs(E0)
        res0 = float(np.max(np.abs(g)))
        a = 1.0
        for _ in range(30):
            x = asm.full(u + a * d, x_fixed)
            E = asm.energy(x)
            if np.isfinite(E) and E <= E0 + 1e-4 * a * slope:
                return x, E, True, False
            if np.isfinite(E) and -a * slope <= 100 * noise and abs(E - E0) <= 100 * noise \
                    and float(np.max(np.abs(asm.gradient(x)))) < res0:
                return x, E, True, False
            a *= 0.5
        return None, E0, False, False
    Hs_v = asm.symmetric(H) @ v
    curv = float(v @ Hs_v)

    def model(a: float) -> float:
        return 1e-4 * (a * a * slope + a * float(g @ v) + 0.5 * a * a * curv)

    def path(a: float) -> np.ndarray:
        return u + min(a, 1.0) ** 2 * d + a * v

    a = 1.0
    best = None
    for _ in range(40):
        x = asm.full(path(a), x_fixed)
        E = asm.energy(x)
        if np.isfinite(E) and E < E0 + model(a):
            best = (x, E, a)
            break
        a *= 0.5
    if best is None:
        return None, E0, False, False
    # expand while the energy keeps decreasing (escape from the saddle in one go)
    x_b, E_b, a_b = best
    if a_b == 1.0:
        a = 2.0
        for _ in range(30):
            x = asm.full(path(a), x_fixed)
            E = asm.energy(x)
            if not (np.isfinite(E) and E < E_b):
                break
            x_b, E_b, a_b = x, E, a
            a *= 2.0
    return x_b, E_b, True, True
