"""Sparse direct solvers for symmetric (possibly indefinite) Hessians, with inertia.

:class:`LDLSolver` wraps QDLDL (an LDL^T factorization with AMD ordering, from PyPI ``qdldl``):
the symbolic analysis (ordering, elimination tree, fill pattern) is done once for a matrix
pattern and reused by every numeric refactorization (``update``). The signs of D give the
matrix's inertia (Sylvester), which tells the Newton solver whether it stands at a minimum or at
a saddle. :class:`LUSolver` (SciPy SuperLU in symmetric mode) is the always-available fallback.
:class:`PardisoSolver` (MKL PARDISO, symmetric indefinite, optional extra ``fast``) reuses the
analysis too and reports the inertia itself. ``auto`` chooses among them by a fixed rule on the
matrix size and the installed packages (:func:`auto_choice`), never by timing, so two runs of a
case on the same installation use the same solver.

Interface shared by all solvers: ``name``; ``factor(H_upper)`` (upper triangle, CSC; a repeated
pattern reuses the analysis) returns the number of negative eigenvalues and raises
:class:`SingularMatrixError` on a zero pivot; ``solve(b)`` uses the last factorization, for one
right-hand side (n,) or a block of them (n, k). :func:`is_definite` asks only whether a matrix
is positive definite; :func:`factor_lazily` factors for ``solve`` without paying for the
inertia where a solver would pay extra for it (PARDISO).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Protocol, runtime_checkable

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .errors import NOT_COUNTED, SingularMatrixError
from .pardiso import (  # re-exported: the solvers by one address
    PardisoSolver,
    SettingError,
    pardiso_available,
    pardiso_threads,
)

__all__ = ["LinearSolver", "LDLSolver", "LUSolver", "PardisoSolver", "AutoSolver", "make_solver",
           "pardiso_available", "pardiso_threads", "SettingError", "SingularMatrixError",
           "is_definite", "factor_lazily", "NOT_COUNTED", "single_threaded_blas"]



@runtime_checkable
class LinearSolver(Protocol):
    """What the Newton solver needs from a sparse direct solver (every kind here has it)."""

    name: str

    def factor(self, H_upper: sp.csc_matrix) -> int:
        """Factor the upper triangle (CSC) of a symmetric matrix; return its number of
        negative eigenvalues; raise SingularMatrixError on a zero pivot. A matrix of the
        pattern of the last one reuses its symbolic analysis."""
        ...

    def solve(self, b: np.ndarray) -> np.ndarray:
        """Solve with the last factorization, for (n,) or a block (n, k)."""
        ...


def _same_pattern(H: sp.csc_matrix, ref: tuple[np.ndarray, np.ndarray] | None) -> bool:
    """Whether ``H`` has the sparsity pattern ``ref`` = (indptr, indices): at once when it
    shares the assembly's index arrays (every Hessian of one pattern does), else compared."""
    if ref is None:
        return False
    indptr, indices = ref
    if H.indptr.shape != indptr.shape or H.indices.shape != indices.shape:
        return False
    if H.indptr is indptr and H.indices is indices:
        return True
    return bool(np.array_equal(H.indptr, indptr) and np.array_equal(H.indices, indices))


class LDLSolver:
    """LDL^T of the upper triangle (CSC) of a symmetric matrix; symbolic analysis reused."""

    name = "qdldl"

    def __init__(self) -> None:
        self._solver = None
        self._pattern: tuple[np.ndarray, np.ndarray] | None = None
        self.factor_time = 0.0
        self.n_factor = 0

    def factor(self, H_upper: sp.csc_matrix) -> int:
        """Factor; return the number of negative eigenvalues (inertia)."""
        import qdldl

        t0 = time.perf_counter()
        try:
            if self._solver is None or not _same_pattern(H_upper, self._pattern):
                self._solver = qdldl.Solver(H_upper, upper=True)
                self._pattern = (H_upper.indptr, H_upper.indices)
            else:
                self._solver.update(H_upper, upper=True)
        except (ValueError, RuntimeError) as err:  # zero pivot
            self._solver = None
            raise SingularMatrixError(str(err)) from None
        _, D, _ = self._solver.factors()
        self.factor_time += time.perf_counter() - t0
        self.n_factor += 1
        if not np.all(np.isfinite(D)) or np.any(D == 0.0):
            raise SingularMatrixError("zero or non-finite pivot")
        return int(np.count_nonzero(D < 0.0))

    def solve(self, b: np.ndarray) -> np.ndarray:
        assert self._solver is not None
        if b.ndim == 2:  # QDLDL solves one right-hand side at a time
            return np.column_stack([self.solve(b[:, j]) for j in range(b.shape[1])])
        return np.asarray(self._solver.solve(np.ascontiguousarray(b)))


class LUSolver:
    """SuperLU without numerical pivoting (symmetric mode); inertia from U's diagonal."""

    name = "splu"

    def __init__(self) -> None:
        self._lu = None
        self.factor_time = 0.0
        self.n_factor = 0

    def factor(self, H_upper: sp.csc_matrix) -> int:
        t0 = time.perf_counter()
        d = H_upper.diagonal()
        H = (H_upper + H_upper.T - sp.diags(d)).tocsc()
        try:
            self._lu = spla.splu(
                H, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                options={"SymmetricMode": True},
            )
        except RuntimeError as err:
            raise SingularMatrixError(str(err)) from None
        self.factor_time += time.perf_counter() - t0
        self.n_factor += 1
        u = self._lu.U.diagonal()
        if not np.all(np.isfinite(u)) or np.any(u == 0.0):
            raise SingularMatrixError("zero or non-finite pivot")
        return int(np.count_nonzero(u < 0.0))

    def solve(self, b: np.ndarray) -> np.ndarray:
        assert self._lu is not None
        return self._lu.solve(b)


#: ``auto``'s size thresholds (unknowns), measured on the project's Hessians (docs/benchmarks.md,
#: "Sparse factorization", 2 cores). PARDISO (when installed) from AUTO_PARDISO_N on: on the
#: default sheet (5,256 unknowns, graded unstructured mesh, nnz(L) 0.6 M) one refactorization
#: took 29-32 ms against 79-87 ms for QDLDL and 91 ms for SuperLU, with equally fast solves;
#: 16-18k unknowns: 56-75 ms against 170-300 ms (QDLDL) and 180-260 ms (SuperLU). Below it
#: (2,091 unknowns: 3.9 ms against 4.6 ms) its 3x slower solves and its start-up eat the gain.
#: Without PARDISO: QDLDL below AUTO_LARGE_N, SuperLU from it on (five rods, 17,649 unknowns:
#: 0.87-0.91 x QDLDL's time; on the default sheet the two are within 5-15 %).
AUTO_PARDISO_N = 3_000
AUTO_LARGE_N = 10_000


def auto_choice(n: int, pardiso: bool | None = None, qdldl: bool | None = None) -> str:
    """The solver ``auto`` takes for an n x n Hessian: a fixed rule on n and on which packages
    are installed (``pardiso`` and ``qdldl`` default to what is importable); no timing."""
    if qdldl is None:
        qdldl = _qdldl_available()
    if n < AUTO_PARDISO_N and qdldl:
        return "qdldl"
    if pardiso is None:
        # only asked for larger matrices: loading MKL takes a moment and memory
        pardiso = pardiso_available()
    if pardiso:
        return "pardiso"
    return "qdldl" if (n < AUTO_LARGE_N and qdldl) else "splu"


def _qdldl_available() -> bool:
    try:
        import qdldl  # noqa: F401
    except ImportError:
        return False
    return True


_KINDS = {"qdldl": LDLSolver, "splu": LUSolver, "pardiso": PardisoSolver}


class AutoSolver:
    """Picks its solver on the first matrix by :func:`auto_choice` (size and installed
    packages only), so the choice, hence the run, is deterministic."""

    def __init__(self) -> None:
        self._choice: LDLSolver | LUSolver | PardisoSolver | None = None

    @property
    def name(self) -> str:
        return f"auto:{self._choice.name}" if self._choice is not None else "auto"

    def _pick(self, H_upper: sp.csc_matrix) -> LDLSolver | LUSolver | PardisoSolver:
        if self._choice is None:
            self._choice = _KINDS[auto_choice(H_upper.shape[0])]()
        return self._choice

    def factor(self, H_upper: sp.csc_matrix) -> int:
        return self._pick(H_upper).factor(H_upper)

    def solve(self, b: np.ndarray) -> np.ndarray:
        assert self._choice is not None
        return self._choice.solve(b)

    def is_definite(self, H_upper: sp.csc_matrix) -> bool:
        return is_definite(self._pick(H_upper), H_upper)

    def factor_lazily(self, H_upper: sp.csc_matrix) -> int:
        return factor_lazily(self._pick(H_upper), H_upper)


def is_definite(solver, H_upper: sp.csc_matrix) -> bool:
    """Whether ``solver`` finds ``H_upper`` positive definite, leaving it factored for
    ``solve`` when it is: the solver's own test where it has one (PARDISO's Cholesky), else
    its factorization's inertia. A singular matrix is not."""
    own = getattr(solver, "is_definite", None)
    if own is not None:
        return bool(own(H_upper))
    try:
        return solver.factor(H_upper) == 0
    except SingularMatrixError:
        return False


def factor_lazily(solver, H_upper: sp.csc_matrix) -> int:
    """Factor ``H_upper`` for ``solver.solve`` where the caller needs to know only whether it
    is positive definite: 0 when it is; otherwise its number of negative eigenvalues where the
    solver's factorization gives it anyway (QDLDL, SuperLU), or :data:`NOT_COUNTED` where
    counting would cost a second factorization (PARDISO: the LDL^T after a failed Cholesky,
    made by the first ``solve`` instead, if any). A zero pivot raises
    :class:`SingularMatrixError`, here or (deferred) from ``solve``."""
    own = getattr(solver, "factor_lazily", None)
    if own is not None:
        return int(own(H_upper))
    return solver.factor(H_upper)


_blas_lock = threading.Lock()
_blas_users = 0
_blas_limiter = None


@contextmanager
def single_threaded_blas() -> Iterator[None]:
    """OpenBLAS (NumPy's and SciPy's dense linear algebra) on one thread while the block runs;
    nested and concurrent uses share one limit, lifted when the last one ends.

    OpenBLAS's worker threads spin for a while after each threaded call (a norm or a dot of a
    21,063-vector is one), and on a 2-core machine they take a core from the PARDISO
    factorization and the JAX kernels that follow: measured on five rods at s = 50, a
    Cholesky right after the rest of a Newton iteration took 45.9 ms (median), the same
    factorization repeated at once 29.6 ms; with OpenBLAS on one thread 25.9 ms both times,
    and the whole run 49 s against 64-68 s. The engine's dense products are small (blocks of
    at most a few dozen vectors), so they lose nothing measurable, and their sums no longer
    depend on the machine's core count. MKL (PARDISO's own threads) is not touched.
    """
    global _blas_users, _blas_limiter
    with _blas_lock:
        if _blas_users == 0:
            try:
                from threadpoolctl import ThreadpoolController

                _blas_limiter = (ThreadpoolController().select(internal_api="openblas")
                                 .limit(limits=1))
            except Exception:  # noqa: BLE001 - no threadpoolctl or no OpenBLAS: nothing to do
                _blas_limiter = None
        _blas_users += 1
    try:
        yield
    finally:
        with _blas_lock:
            _blas_users -= 1
            if _blas_users == 0 and _blas_limiter is not None:
                _blas_limiter.restore_original_limits()
                _blas_limiter = None


def make_solver(kind: str = "auto") -> LDLSolver | LUSolver | PardisoSolver | AutoSolver:
    """``auto``: by :func:`auto_choice` on the first matrix; ``qdldl``, ``splu`` or
    ``pardiso`` force one (ImportError when its package is missing)."""
    if kind == "auto":
        return AutoSolver()
    if kind == "qdldl":
        import qdldl  # noqa: F401
    if kind not in _KINDS:
        raise ValueError(f"unknown linear solver {kind!r}: auto, {', '.join(_KINDS)}")
    return _KINDS[kind]()
