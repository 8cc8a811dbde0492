"""MKL PARDISO (symmetric indefinite, optional extra ``fast``) for :mod:`undulate.solve.linear`:
the library found through ``mkl`` (or MKL's runtime wheels), its thread count
(``UNDULATE_PARDISO_THREADS``), and :class:`PardisoSolver`, which reuses the symbolic analysis
of a pattern and reports the inertia itself."""

from __future__ import annotations

import ctypes
import os
from functools import cache

import numpy as np
import scipy.sparse as sp

from .errors import NOT_COUNTED, SingularMatrixError

__all__ = ["PARDISO_THREADS", "PardisoSolver", "SettingError", "pardiso_available",
           "pardiso_threads"]


@cache
def _mkl_pardiso():
    """MKL's ``pardiso`` entry point (:func:`_mkl_library`; extra ``fast``); None if absent."""
    # Intel OpenMP's threads spin for 200 ms after each parallel region by default, taking a
    # core from the assembly that follows (two single-rod runs, h = 0.2, at once on 2 cores,
    # PARDISO on 2 threads: 30.1 s with the spin, 25.3 s without; 32.1 s on one thread). Read
    # when MKL's OpenMP runtime starts, so it is set before MKL is loaded; a user's value stays.
    os.environ.setdefault("KMP_BLOCKTIME", "0")
    lib = _mkl_library()
    if lib is None:
        return None
    fn = lib.pardiso
    fn.restype = None
    try:
        set_threads = lib.MKL_Domain_Set_Num_Threads
        set_threads.restype = ctypes.c_int
        set_threads.argtypes = [ctypes.c_int, ctypes.c_int]
        set_threads(pardiso_threads(), _MKL_DOMAIN_PARDISO)
    except AttributeError:  # pragma: no cover - other MKL builds
        pass
    return fn


def _mkl_library() -> ctypes.CDLL | None:
    """MKL's runtime library (``mkl_rt``, from the ``mkl`` wheel that pypardiso pulls), or None.

    In order: the file ``PYPARDISO_MKL_RT`` names (pypardiso's own setting); the ``mkl`` wheel's
    file list; ``<prefix>/lib`` and ``<prefix>/Library/bin`` of this environment, its base and
    (when enabled) the user site; pypardiso's own search last: it globs the whole environment
    recursively, which took 1.4 s of every run's start (measured on the demo). A library
    without a ``pardiso`` entry point is skipped.
    """
    import glob
    from importlib.util import find_spec

    if find_spec("pypardiso") is None:  # the extra that brings MKL
        return None
    import site
    import sys

    cands: list[str] = []
    if os.environ.get("PYPARDISO_MKL_RT"):
        cands.append(os.environ["PYPARDISO_MKL_RT"])
    try:
        from importlib.metadata import PackageNotFoundError, distribution

        files = distribution("mkl").files or []
        cands += sorted((str(f.locate()) for f in files if "mkl_rt" in f.name), key=len)
    except (PackageNotFoundError, ImportError):
        pass
    bases = [sys.prefix, sys.base_prefix]
    if site.ENABLE_USER_SITE and getattr(site, "USER_BASE", None):
        bases.append(site.USER_BASE)
    for base in dict.fromkeys(glob.escape(b) for b in bases if b):
        cands += sorted(glob.glob(os.path.join(base, "lib", "libmkl_rt.so*")), key=len)
        cands += sorted(glob.glob(os.path.join(base, "Library", "bin", "mkl_rt*.dll")), key=len)
    for path in dict.fromkeys(cands):
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        if hasattr(lib, "pardiso"):
            return lib
    try:
        from pypardiso.pardiso_wrapper import PyPardisoSolver

        return PyPardisoSolver().libmkl
    except (ImportError, OSError):
        return None


#: PARDISO's threads unless UNDULATE_PARDISO_THREADS says otherwise. Fixed, not the machine's
#: core count, and run in MKL's conditional numerical reproducibility mode (iparm(34)), so a
#: case and seed give the same bits on every machine. Measured on the five-rod Hessian (21,063
#: unknowns, 2-core machine, idle): one refactorization 102-108 ms on one thread, 54-69 ms on
#: two in this mode; two threads without it gave two different solutions in 20 factorizations
#: of one matrix.
PARDISO_THREADS = 2


class SettingError(ValueError):
    """An environment setting of undulate is invalid (the message names it and its range)."""


def pardiso_threads() -> int:
    """The number of threads PARDISO factors with (``UNDULATE_PARDISO_THREADS``, default
    :data:`PARDISO_THREADS`); anything but a whole number from 1 to 256 raises
    :class:`SettingError`."""
    raw = os.environ.get("UNDULATE_PARDISO_THREADS", str(PARDISO_THREADS))
    try:
        n = int(raw.strip())
    except ValueError:
        n = 0
    if not 1 <= n <= 256:
        raise SettingError(f"UNDULATE_PARDISO_THREADS: must be a whole number from 1 to 256 "
                           f"(got {raw!r})")
    return n


_MKL_DOMAIN_PARDISO = 4  # MKL's domain number for PARDISO (mkl_service.h)


def pardiso_available() -> bool:
    """True when MKL PARDISO can be loaded (``pip install undulate[fast]``)."""
    return _mkl_pardiso() is not None


class _PardisoHandle:
    """One MKL PARDISO instance for one matrix type: ``mtype`` -2 (real symmetric indefinite,
    Bunch-Kaufman pivoting: LDL^T with the inertia in iparm(23)) or 2 (real symmetric positive
    definite: Cholesky, which stops at the first non-positive pivot with error -4). The
    analysis (phase 11, minimum-degree ordering) is done once per pattern, every ``factor`` is
    a numeric refactorization (phase 22).

    In LDL^T mode PARDISO perturbs tiny pivots (iparm(10) = 8, i.e. 1e-8 times the norm)
    instead of stopping; any perturbed pivot (iparm(14) > 0) is reported as
    :class:`SingularMatrixError`, as QDLDL's zero pivot is.
    """

    def __init__(self, mtype: int) -> None:
        self._fn = _mkl_pardiso()
        if self._fn is None:
            raise ImportError("MKL PARDISO not found: pip install 'undulate[fast]'")
        self._mtype = int(mtype)
        self._pt = np.zeros(64, dtype=np.int64)  # PARDISO's opaque handle
        self._iparm = np.zeros(64, dtype=np.int32)
        # iparm(34): reproducible results for this many threads (MKL's CNR mode).
        # iparm(2) = 0: minimum-degree ordering. On this project's Hessians it fills
        # less than METIS (iparm(2) = 2): five rods at s = 50 (21,063 unknowns) 645 against
        # 846 Mflop per factorization, nnz(L) 3.09 M against 3.45 M; the demo 119 against 140
        # Mflop; one 5 mm rod 33 against 43; five rods at s = 10 849 against 809 (the one case
        # where METIS is lighter; same time). Measured with iparm(18), iparm(19).
        for k, v in {1: 1, 2: 0, 10: 8, 11: 0, 13: 0, 21: 1 if mtype == -2 else 0,
                     34: pardiso_threads(), 35: 0}.items():
            self._iparm[k - 1] = v  # 1-based numbers as in MKL's documentation
        self._key: tuple | None = None
        self._factored = False

    def _call(self, phase: int, b: np.ndarray | None = None) -> np.ndarray | None:
        i32, f64 = ctypes.POINTER(ctypes.c_int32), ctypes.POINTER(ctypes.c_double)
        n = self._n
        if b is None:
            b = x = np.zeros((n, 1), order="F")
        else:
            x = np.zeros_like(b)
        err = ctypes.c_int32(0)
        one = ctypes.c_int32(1)
        # the arrays stay referenced by self between phases: PARDISO keeps pointers to them
        self._fn(self._pt.ctypes.data_as(ctypes.POINTER(ctypes.c_int64)), ctypes.byref(one),
                 ctypes.byref(one), ctypes.byref(ctypes.c_int32(self._mtype)),
                 ctypes.byref(ctypes.c_int32(phase)), ctypes.byref(ctypes.c_int32(n)),
                 self._a.ctypes.data_as(f64), self._ia.ctypes.data_as(i32),
                 self._ja.ctypes.data_as(i32), self._perm.ctypes.data_as(i32),
                 ctypes.byref(ctypes.c_int32(b.shape[1])), self._iparm.ctypes.data_as(i32),
                 ctypes.byref(ctypes.c_int32(0)), b.ctypes.data_as(f64), x.ctypes.data_as(f64),
                 ctypes.byref(err))
        if err.value == -4:
            raise SingularMatrixError("PARDISO: zero pivot" if self._mtype == -2 else
                                      "PARDISO: not positive definite")
        if err.value != 0:
            raise RuntimeError(f"PARDISO error {err.value}")
        return x

    def _release(self) -> None:
        if self._key is not None:
            self._call(-1)
            self._key = None
            self._factored = False

    def __del__(self) -> None:
        try:
            self._release()
        except Exception:  # noqa: BLE001 (interpreter shutdown)
            pass

    def factor(self, H_upper: sp.csc_matrix) -> int:
        """Factor; return the number of negative eigenvalues (LDL^T) or 0 (Cholesky, which
        raises :class:`SingularMatrixError` when the matrix is not positive definite)."""
        key = (H_upper.shape[0], H_upper.nnz, H_upper.indptr.tobytes(), H_upper.indices.tobytes())
        self._factored = False
        if key != self._key:
            self._release()
            n = H_upper.shape[0]
            # CSC of the upper triangle -> CSR of the upper triangle (what PARDISO reads):
            # the permutation of the values is computed once per pattern
            pos = sp.csc_matrix((np.arange(1, H_upper.nnz + 1, dtype=float), H_upper.indices,
                                 H_upper.indptr), shape=(n, n)).tocsr()
            pos.sort_indices()
            self._n = n
            self._to_csr = pos.data.astype(np.int64) - 1
            self._ia = (pos.indptr + 1).astype(np.int32)
            self._ja = (pos.indices + 1).astype(np.int32)
            self._perm = np.zeros(n, dtype=np.int32)
            self._a = np.ascontiguousarray(H_upper.data[self._to_csr], dtype=np.float64)
            self._call(11)
            self._key = key
        else:
            self._a[:] = H_upper.data[self._to_csr]
        self._call(22)
        if not np.all(np.isfinite(self._a)) or self._iparm[13] > 0:
            raise SingularMatrixError(f"PARDISO perturbed {self._iparm[13]} pivots")
        self._factored = True
        return int(self._iparm[22]) if self._mtype == -2 else 0

    def solve(self, b: np.ndarray) -> np.ndarray:
        assert self._factored
        b = np.asarray(b, dtype=np.float64)
        x = self._call(33, np.asfortranarray(b.reshape(b.shape[0], -1)))
        return np.ascontiguousarray(x).reshape(b.shape)


class PardisoSolver:
    """MKL PARDISO: Cholesky first, LDL^T (Bunch-Kaufman pivoting, with the inertia) when the
    matrix is not positive definite.

    Most Hessians of a release are positive definite (every converging Newton step, every
    accepted shift), and PARDISO's Cholesky refactorization of them costs about 60 % of its
    symmetric indefinite one (demo's Hessian, 4,836 unknowns: 3.8 against 6.2 ms; five rods at
    s = 50, 21,063 unknowns: 22.6 against 34-37 ms). A matrix that is not positive definite
    stops the Cholesky at its first non-positive pivot, which on the wide sheets' wrinkled
    Hessians comes late (five rods at s = 50: 23 ms against 30 ms for a whole Cholesky). So
    ``factor`` tries Cholesky and falls back to LDL^T, whose factorization then serves
    ``solve`` and whose inertia is returned; ``is_definite`` (the shift search's question) tries
    Cholesky only; ``factor_lazily`` (a Newton iteration that needs only "positive definite or
    not") leaves the LDL^T of an indefinite matrix to the first ``solve`` that needs it.
    ``solve`` takes one right-hand side (n,) or several (n, k).
    """

    name = "pardiso"

    def __init__(self) -> None:
        self._ldl = _PardisoHandle(-2)
        self._chol = _PardisoHandle(2)
        self._active: _PardisoHandle | None = None
        #: an indefinite matrix whose LDL^T waits for the first solve (``factor_lazily``)
        self._pending: sp.csc_matrix | None = None
        #: factorizations by kind (Cholesky, Cholesky that failed, LDL^T)
        self.counts = {"cholesky": 0, "cholesky_failed": 0, "ldl": 0}

    def is_definite(self, H_upper: sp.csc_matrix) -> bool:
        """True when Cholesky succeeds (its factorization then serves ``solve``)."""
        self._active = None
        self._pending = None
        try:
            self._chol.factor(H_upper)
        except SingularMatrixError:
            self.counts["cholesky_failed"] += 1
            return False
        self.counts["cholesky"] += 1
        self._active = self._chol
        return True

    def factor(self, H_upper: sp.csc_matrix) -> int:
        """Factor; return the number of negative eigenvalues (inertia)."""
        if self.is_definite(H_upper):
            return 0
        return self._factor_ldl(H_upper)

    def factor_lazily(self, H_upper: sp.csc_matrix) -> int:
        """0 when ``H_upper`` is positive definite (Cholesky, kept for ``solve``), else
        :data:`NOT_COUNTED`, its LDL^T made by the first ``solve``."""
        if self.is_definite(H_upper):
            return 0
        self._active = None
        self._pending = H_upper
        return NOT_COUNTED

    def _factor_ldl(self, H_upper: sp.csc_matrix) -> int:
        self._active = None
        self._pending = None
        n_neg = self._ldl.factor(H_upper)
        self.counts["ldl"] += 1
        self._active = self._ldl
        return n_neg

    def solve(self, b: np.ndarray) -> np.ndarray:
        """Solve with the last factorization (a pending LDL^T is made first: it may raise
        :class:`SingularMatrixError`)."""
        if self._active is None and self._pending is not None:
            self._factor_ldl(self._pending)
        assert self._active is not None
        return self._active.solve(b)
