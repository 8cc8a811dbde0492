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

The parts: the options and result (:mod:`undulate.solve.options`), the directions
(:mod:`undulate.solve.descent`, with the negative-curvature modes of
:mod:`undulate.solve.modes`), the line searches (:mod:`undulate.solve.search`); this module
holds the iteration itself and its explicit state (:class:`_State`).
"""

from __future__ import annotations

import time
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from ..mechanics.assemble import Assembly
from .descent import (
    Direction,
    nan_if_singular,
    refined_solve,
    shift_until_definite,
    twin,
)
from .linear import NOT_COUNTED, SingularMatrixError, factor_lazily, make_solver
from .modes import downhill_combination, jacobi_scale, lowest_modes, ritz_floor
from .options import ConvergenceError, NewtonOptions, NewtonResult
from .search import energy_function, line_search, merit_function

__all__ = ["NewtonOptions", "NewtonResult", "ConvergenceError", "minimize"]

#: the refined solve under its old name (tests)
_refined_solve = refined_solve

#: a curved step counts towards ``curved_budget`` when at least this share of its direction
#: (sum of squares) lies on the ``watch`` unknowns (the rods' nodes). Measured on the demo:
#: the slack fabric's wrinkles are followed with shares of 0.00-0.02, the rod's changes of
#: pattern with 0.2-0.6.
WATCH_SHARE = 0.1


@dataclass
class _State:
    """What one Newton iteration hands the next."""

    u: np.ndarray  # free unknowns
    x: np.ndarray  # all node positions
    E: float  # energy at x
    recent: deque  # energies of the last iterates (non-monotone acceptance)
    stress: dict | None = None  # carried stresses of the mixed iteration
    res: float = float("inf")  # max|g|
    n_neg: int = -1  # negative pivots of the last Hessian (NOT_COUNTED: some)
    tau: float = 1e-6  # the last shift
    neg_steps: int = 0
    watched_steps: int = 0
    v_prev: np.ndarray | None = None  # the last negative modes (warm start)
    k_next: int = 1  # modes to seek where the pivots were not counted
    mu: float = float("nan")  # the lowest relative eigenvalue found last
    times: dict = field(default_factory=lambda: dict(assembly=0.0, factor=0.0, eig=0.0,
                                                     line_search=0.0))
    trace: list = field(default_factory=list)

    def result(self, converged: bool, it: int, message: str = "",
               over_budget: bool = False, unstable_start: bool = False,
               stalled: bool = False) -> NewtonResult:
        return NewtonResult(self.u, converged, it, self.res, self.E, self.n_neg,
                            self.neg_steps, dict(self.times), message, self.trace,
                            self.watched_steps, over_budget, unstable_start, stalled)


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
    tol = opts.rtol * opts.force_scale
    mixed = opts.mixed and bool(asm.mixed_groups)
    st = _start(asm, x_fixed, u0, opts, x_ref if mixed else None)
    it = 0
    for it in range(opts.max_iter + 1):
        g, H, H_factored = _assemble_and_factor(asm, solver, st, tol)
        if not np.isfinite(st.res):
            break
        if st.res <= tol and (st.n_neg == 0 or not opts.require_stable):
            return st.result(True, it)
        if it == opts.max_iter:
            break
        stop = _give_up(st, opts, it)
        if stop is None:
            step = _direction(asm, solver, H, H_factored, g, st, opts, tol, rng)
            stop = _marginal(st, it) if step is None else None
        if stop is not None:
            return stop
        if not _search_and_move(asm, x_fixed, st, step, g, opts, mixed, watch):
            if step.v is None and st.n_neg == 0 and st.res <= 10 * tol:
                # a Newton step that cannot decrease the energy at tiny residual is roundoff
                return st.result(True, it, "stopped at roundoff")
            break
    return st.result(False, it, f"no stable equilibrium after {it} iterations: max|g| = "
                                f"{st.res:.3e} (tolerance {tol:.3e}), Hessian: "
                                f"{_pivots(st.n_neg)}")


def _start(asm: Assembly, x_fixed: np.ndarray, u0: np.ndarray, opts: NewtonOptions,
           x_ref: np.ndarray | None) -> _State:
    u = np.array(u0, dtype=float)
    x = asm.full(u, x_fixed)
    E = asm.energy(x)
    # modes sought where the Hessian's negative pivots were not counted: all ``opts.modes``
    # at first, then one more than the last search found
    st = _State(u, x, E, deque([E], maxlen=max(opts.nonmonotone, 1)), k_next=opts.modes)
    if x_ref is not None:
        st.stress = asm.stress_linearized(x_ref, x - x_ref)
    return st


def _assemble_and_factor(asm: Assembly, solver, st: _State, tol: float) -> tuple:
    """g and H at st.x (with the carried stresses), and whether H could be factored."""
    t0 = time.perf_counter()
    g, H = asm.gradient_hessian(st.x, st.stress)
    st.res = float(np.max(np.abs(g))) if g.size else 0.0
    if st.stress is not None and st.res <= tol:
        # converged in force: judge stability on the exact Hessian
        st.stress = None
        g, H = asm.gradient_hessian(st.x)
    st.times["assembly"] += time.perf_counter() - t0
    t0 = time.perf_counter()
    H_factored = True
    try:
        # only "positive definite or not" is needed: PARDISO's LDL^T (the inertia) is
        # made only if a solve asks for it (the inverse iteration of lowest_modes)
        st.n_neg = factor_lazily(solver, H)
    except SingularMatrixError:
        st.n_neg = 1  # treat a singular Hessian like an indefinite one: shift it
        H_factored = False
    st.times["factor"] += time.perf_counter() - t0
    return g, H, H_factored


def _give_up(st: _State, opts: NewtonOptions, it: int) -> NewtonResult | None:
    """The release loop's early stops: an unstable start, a change of pattern over budget,
    rods that keep following negative curvature without settling."""
    if opts.definite_start and it == 0 and st.n_neg != 0:
        return st.result(False, it, f"the start is not stable ({_pivots(st.n_neg)})",
                         unstable_start=True)
    if opts.curved_budget and st.watched_steps and it >= opts.curved_budget:
        return st.result(False, it, f"change of pattern: {it} iterations, "
                                    f"{st.watched_steps} along negative curvature of the "
                                    f"watched unknowns (budget {opts.curved_budget})",
                         over_budget=True)
    if opts.curved_limit and st.watched_steps >= opts.curved_limit:
        return st.result(False, it, f"no settling: {st.watched_steps} steps along negative "
                                    f"curvature of the watched unknowns in {it} iterations "
                                    f"(limit {opts.curved_limit})", stalled=True)
    return None


def _marginal(st: _State, it: int) -> NewtonResult:
    """An equilibrium whose only "negative" curvature is at the level of the factorization's
    roundoff relative to the stiffness: marginally stable."""
    return st.result(True, it, f"marginally stable: lowest relative eigenvalue "
                               f"{st.mu:.2e}")


def _direction(asm: Assembly, solver, H, H_factored: bool, g: np.ndarray, st: _State,
               opts: NewtonOptions, tol: float, rng: np.random.Generator) -> Direction | None:
    """The step of this iteration (:mod:`undulate.solve.descent`); None when the point is
    a marginally stable equilibrium (st.mu holds the lowest relative eigenvalue)."""
    t0 = time.perf_counter()
    Hs = asm.symmetric(H)  # the full matrix, formed once per iteration
    if st.n_neg == 0:
        return Direction(refined_solve(solver, Hs, -g), None, Hs)
    # the shifted matrix is factored by a twin solver: H's own (indefinite) factorization
    # stays at hand for the inverse iteration of lowest_modes
    shift_solver = twin(solver, opts.linear_solver) if H_factored else solver
    S = jacobi_scale(H)
    st.tau = shift_until_definite(asm, shift_solver, H, S, st.tau, st.res,
                                  ritz_floor(Hs, S, st.v_prev))
    st.times["factor"] += time.perf_counter() - t0
    d = -shift_solver.solve(g)
    v = None
    if opts.negative_curvature:
        v = _curvature_direction(Hs, S, shift_solver, solver if H_factored else None, g, d,
                                 st, opts, tol, rng)
        if v is _MARGINAL:
            return None
    st.tau = max(st.tau / 10.0, 1e-8)
    return Direction(d, v, Hs)


#: what _curvature_direction returns at a marginally stable equilibrium
_MARGINAL = np.empty(0)


def _curvature_direction(Hs, S: np.ndarray, shift_solver, H_solver, g: np.ndarray,
                         d: np.ndarray, st: _State, opts: NewtonOptions, tol: float,
                         rng: np.random.Generator) -> np.ndarray | None:
    """A direction of negative curvature sized like ``d`` (S-norm), None if there is none,
    or _MARGINAL at an equilibrium that is stable up to roundoff."""
    t1 = time.perf_counter()
    k = int(min(st.n_neg, opts.modes)) if st.n_neg > 0 else st.k_next
    mus, V = lowest_modes(Hs, S, shift_solver.solve, st.u.size, rng, st.v_prev, st.tau, k,
                          nan_if_singular(H_solver.solve) if H_solver is not None else None)
    mu = float(mus[0])
    st.times["eig"] += time.perf_counter() - t1
    if st.res <= tol and np.isfinite(mu) and mu >= -opts.marginal:
        st.mu = mu
        return _MARGINAL
    if not (np.isfinite(mu) and mu < 0):
        return None
    # the negative modes found warm-start the next search (all of them: with one, the other
    # k - 1 start from random vectors every time)
    neg = np.asarray(mus) < 0
    st.k_next = int(min(opts.modes, np.count_nonzero(neg) + 1))
    st.v_prev = V[:, neg] if np.all(np.isfinite(mus)) else V[:, :1]
    v = downhill_combination(mus, V, g, S, rng)
    # give v the size of the shifted Newton step (in the S-norm), at least a small fraction
    # of the typical node spacing
    dn = np.sqrt(np.sum(S * d * d))
    vn = np.sqrt(np.sum(S * v * v))
    return v * max(dn, 1e-3 * np.sqrt(np.sum(S))) / vn


def _search_and_move(asm: Assembly, x_fixed: np.ndarray, st: _State, step: Direction,
                     g: np.ndarray, opts: NewtonOptions, mixed: bool,
                     watch: np.ndarray | None) -> bool:
    """Line search along ``step`` (:mod:`undulate.solve.search`); move st there. False when
    no step lowers the merit."""
    t0 = time.perf_counter()
    # the merit of a step from x starts at E (x is its own linearization point)
    merit = merit_function(asm, st.x, opts, st.recent) if mixed else energy_function(asm)
    E_ref = max(st.recent) if (opts.nonmonotone and step.v is None) else st.E
    x_new, E_new, alpha, curved = line_search(asm, x_fixed, st.u, step.d, step.v, g, st.E,
                                              step.Hs, merit, E_ref)
    st.times["line_search"] += time.perf_counter() - t0
    share = float("nan")
    if curved and watch is not None:
        share = float(np.sum(step.v[watch] ** 2) / max(np.sum(step.v * step.v), 1e-300))
    st.watched_steps += int(curved and (watch is None or share >= WATCH_SHARE))
    kind = "curved" if curved else ("newton" if st.n_neg == 0 else "shifted")
    st.trace.append((st.res, st.n_neg, kind, alpha, st.E, share))
    if x_new is None:
        return False
    st.neg_steps += int(curved)
    if mixed:
        # the stresses follow the linearized strains (mixed Newton): a step that rotates a
        # stiff rod edge does not load it with the step's second-order stretch
        t1 = time.perf_counter()
        st.stress = asm.stress_linearized(st.x, x_new - st.x)
        st.times["assembly"] += time.perf_counter() - t1
    st.u = asm.free(x_new)
    st.x = x_new
    st.E = E_new
    st.recent.append(E_new)
    return True


def _pivots(n_neg: int) -> str:
    """How a message names a Hessian's negative pivots (``NOT_COUNTED``: known, not counted)."""
    if n_neg == NOT_COUNTED:
        return "not positive definite"
    return f"{n_neg} negative pivots"
