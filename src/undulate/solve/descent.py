"""The directions of a Newton iteration: Newton, shifted Newton and the curved pair.

* H positive definite: the Newton step ``d = -H^-1 g`` (:func:`refined_solve`: the
  factorization plus iterative refinement).
* H indefinite: the shifted step ``d = -K^-1 g`` with ``K = H + tau S`` made positive definite
  (:func:`shift_until_definite`, factored by a twin solver so H's own factorization stays at
  hand), and, along with it, a direction ``v`` of negative curvature
  (:mod:`undulate.solve.modes`) sized like ``d``: the curved path ``x + a^2 d + a v`` of
  :mod:`undulate.solve.search`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..mechanics.assemble import Assembly
from .linear import SingularMatrixError, is_definite, make_solver
from .options import ConvergenceError

__all__ = ["REFINED_ENOUGH", "Direction", "nan_if_singular", "refined_solve",
           "shift_until_definite", "twin"]

#: a refinement sweep of a Newton step that changes it by less than this (relative) is the
#: last: measured on PARDISO's Cholesky of five-rod Hessians (21,063 unknowns), every sweep
#: changes d by 0.4-9e-9 and leaves the residual where it was (1e-13 to 3e-10 of |g|)
REFINED_ENOUGH = 1e-8


@dataclass
class Direction:
    """One iteration's step: ``d`` (Newton or shifted Newton), ``v`` (negative curvature, or
    None) and the full symmetric Hessian ``Hs`` the search's model uses."""

    d: np.ndarray
    v: np.ndarray | None
    Hs: sp.csr_matrix


def nan_if_singular(solve):
    """``solve`` returning NaN instead of raising on a singular matrix (a deferred LDL^T):
    the inverse iteration then gives way to LOBPCG, as when H could not be factored."""
    def f(b: np.ndarray) -> np.ndarray:
        try:
            return solve(b)
        except SingularMatrixError:
            return np.full(np.shape(b), np.nan)
    return f


def twin(solver, kind: str):
    """A second solver of the same kind, kept on ``solver`` (its analysis is reused)."""
    twin = getattr(solver, "shift_twin", None)
    if twin is None:
        twin = make_solver(kind)
        solver.shift_twin = twin
    return twin


def shift_until_definite(asm: Assembly, solver, H: sp.csc_matrix, S: np.ndarray,
                         tau: float, res: float, floor: float = 0.0) -> float:
    """Factor K = H + tau S (S = :func:`undulate.solve.modes.jacobi_scale` of H) with tau
    grown by 10 until K is positive definite; return tau.

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


def refined_solve(solver, Hs: sp.csr_matrix, b: np.ndarray, sweeps: int = 2,
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
