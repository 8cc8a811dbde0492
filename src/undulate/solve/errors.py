"""What the linear solvers report besides a solution (shared by every solver)."""

from __future__ import annotations

__all__ = ["NOT_COUNTED", "SingularMatrixError"]

#: what :func:`factor_lazily` returns for a matrix that is not positive definite when its
#: negative pivots were not counted
NOT_COUNTED = -1


class SingularMatrixError(RuntimeError):
    """The factorization met a zero pivot."""
