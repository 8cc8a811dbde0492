"""Sparse solvers of undulate.solve.linear: inertia, accuracy, refactorization, auto choice."""

import numpy as np
import pytest
import scipy.sparse as sp

from undulate.solve import linear, pardiso
from undulate.solve.linear import (
    AutoSolver,
    LDLSolver,
    LUSolver,
    PardisoSolver,
    SingularMatrixError,
    auto_choice,
    make_solver,
)

pytest.importorskip("qdldl")
HAVE_PARDISO = linear.pardiso_available()
KINDS = ["qdldl", "splu", pytest.param("pardiso", marks=pytest.mark.skipif(
    not HAVE_PARDISO, reason="MKL PARDISO not installed (extra 'fast')"))]


def laplacian_2d(m: int) -> sp.csc_matrix:
    t = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], shape=(m, m))
    eye = sp.identity(m)
    return (sp.kron(eye, t) + sp.kron(t, eye)).tocsc()


def upper(A) -> sp.csc_matrix:
    U = sp.triu(A, format="csc")
    U.sort_indices()
    return U


def shifted(U: sp.csc_matrix, sigma: float) -> sp.csc_matrix:
    """U - sigma I with U's pattern (the diagonal is the last entry of each sorted column)."""
    K = U.copy()
    K.data[K.indptr[1:] - 1] -= sigma
    return K


@pytest.mark.parametrize("kind", KINDS)
def test_inertia_of_shifted_laplacian(kind):
    A = laplacian_2d(12)
    ev = np.linalg.eigvalsh(A.toarray())
    U = upper(A)
    s = make_solver(kind)
    for k in (0, 1, 4, 17):  # shift between eigenvalues k-1 and k: exactly k negative
        sigma = 0.0 if k == 0 else 0.5 * (ev[k - 1] + ev[k])
        if k and ev[k] - ev[k - 1] < 1e-9:
            continue
        assert s.factor(shifted(U, sigma)) == int(np.count_nonzero(ev < sigma))


@pytest.mark.parametrize("kind", KINDS)
def test_inertia_of_random_indefinite(kind):
    rng = np.random.default_rng(3)
    n = 60
    R = sp.random(n, n, density=0.08, random_state=rng)
    A = (R + R.T + sp.diags(rng.uniform(-3.0, 3.0, n))).tocsc()
    A = A + sp.diags(np.where(A.diagonal() == 0, 1.0, 0.0))  # structurally full diagonal
    ev = np.linalg.eigvalsh(A.toarray())
    assert min(np.abs(ev)) > 1e-6
    assert make_solver(kind).factor(upper(A)) == int(np.count_nonzero(ev < 0))


@pytest.mark.parametrize("kind", KINDS)
def test_solve_and_refactor_same_pattern(kind):
    U = upper(laplacian_2d(20))
    A_full = U + sp.triu(U, 1).T
    rng = np.random.default_rng(0)
    b = rng.standard_normal(U.shape[0])
    s = make_solver(kind)
    for sigma in (0.0, -0.5, 0.3, 0.0):  # same pattern, new values (one indefinite)
        K = shifted(U, sigma)
        n_neg = s.factor(K)
        assert (n_neg > 0) == (sigma > 0.2)
        x = s.solve(b)
        r = (A_full - sigma * sp.identity(U.shape[0])) @ x - b
        assert np.linalg.norm(r) <= 1e-8 * np.linalg.norm(b)


@pytest.mark.skipif(not HAVE_PARDISO, reason="MKL PARDISO not installed (extra 'fast')")
def test_pardiso_several_rhs_and_new_pattern():
    s = PardisoSolver()
    U = upper(laplacian_2d(10))
    A = (U + sp.triu(U, 1).T).toarray()
    B = np.random.default_rng(1).standard_normal((U.shape[0], 3))
    s.factor(U)
    np.testing.assert_allclose(A @ s.solve(B), B, atol=1e-9)
    U2 = upper(laplacian_2d(7))  # another pattern: a fresh analysis
    assert s.factor(U2) == 0
    b2 = np.ones(U2.shape[0])
    np.testing.assert_allclose((U2 + sp.triu(U2, 1).T) @ s.solve(b2), b2, atol=1e-9)


@pytest.mark.skipif(not HAVE_PARDISO, reason="MKL PARDISO not installed (extra 'fast')")
def test_pardiso_cholesky_first_then_ldl():
    """PARDISO factors a positive definite matrix by Cholesky and an indefinite one by LDL^T
    (after a failed Cholesky), with the right inertia and solution either way; alternating
    between the two on one pattern keeps both analyses."""
    s = PardisoSolver()
    U = upper(laplacian_2d(20))
    A_full = U + sp.triu(U, 1).T
    n = U.shape[0]
    b = np.random.default_rng(3).standard_normal(n)
    ev = np.linalg.eigvalsh(A_full.toarray())
    for sigma in (0.0, 0.5, 0.0, 0.5):
        K = shifted(U, sigma)
        n_neg = s.factor(K)
        assert n_neg == int(np.count_nonzero(ev - sigma < 0))
        x = s.solve(b)
        r = (A_full - sigma * sp.identity(n)) @ x - b
        assert np.linalg.norm(r) <= 1e-8 * np.linalg.norm(b)
    assert s.counts == {"cholesky": 2, "cholesky_failed": 2, "ldl": 2}


@pytest.mark.parametrize("kind", KINDS)
def test_is_definite(kind):
    """The shift search's question: True (and factored for solve) for a positive definite
    matrix, False for an indefinite or a singular one."""
    U = upper(laplacian_2d(12))
    A_full = U + sp.triu(U, 1).T
    s = make_solver(kind)
    assert linear.is_definite(s, U)
    b = np.ones(U.shape[0])
    np.testing.assert_allclose(A_full @ s.solve(b), b, atol=1e-9)
    assert not linear.is_definite(s, shifted(U, 0.5))
    assert not linear.is_definite(s, upper(sp.csc_matrix(np.ones((2, 2)))))


@pytest.mark.parametrize("kind", KINDS + ["auto"])
def test_factor_lazily(kind):
    """The Newton iteration's question, "positive definite or not": 0 for a positive definite
    matrix; for an indefinite one the inertia where the factorization gives it anyway, or
    NOT_COUNTED (PARDISO: no LDL^T until a solve needs it); the solve is right either way."""
    U = upper(laplacian_2d(12))
    A_full = U + sp.triu(U, 1).T
    n = U.shape[0]
    b = np.random.default_rng(5).standard_normal(n)
    n_true = int(np.count_nonzero(np.linalg.eigvalsh(A_full.toarray()) - 0.5 < 0))
    s = make_solver(kind)
    assert linear.factor_lazily(s, U) == 0
    np.testing.assert_allclose(A_full @ s.solve(b), b, atol=1e-9)
    K = shifted(U, 0.5)
    assert linear.factor_lazily(s, K) in (n_true, linear.NOT_COUNTED)
    r = (A_full - 0.5 * sp.identity(n)) @ s.solve(b) - b
    assert np.linalg.norm(r) <= 1e-8 * np.linalg.norm(b)


@pytest.mark.skipif(not HAVE_PARDISO, reason="MKL PARDISO not installed (extra 'fast')")
def test_pardiso_factor_lazily_defers_ldl():
    """PARDISO: a failed Cholesky leaves the LDL^T to the first solve (none without a solve,
    made once however many solves); a singular pending matrix raises from solve."""
    s = PardisoSolver()
    U = upper(laplacian_2d(10))
    K = shifted(U, 0.5)
    assert s.factor_lazily(K) == linear.NOT_COUNTED
    assert s.counts == {"cholesky": 0, "cholesky_failed": 1, "ldl": 0}
    assert s.factor_lazily(U) == 0  # no solve asked for the pending LDL^T: never made
    assert s.counts == {"cholesky": 1, "cholesky_failed": 1, "ldl": 0}
    assert s.factor_lazily(K) == linear.NOT_COUNTED
    s.solve(np.ones(U.shape[0]))
    s.solve(np.ones(U.shape[0]))  # the LDL^T is made once
    assert s.counts == {"cholesky": 1, "cholesky_failed": 2, "ldl": 1}
    s2 = PardisoSolver()
    assert s2.factor_lazily(upper(sp.csc_matrix(np.ones((2, 2))))) == linear.NOT_COUNTED
    with pytest.raises(SingularMatrixError):
        s2.solve(np.ones(2))


@pytest.mark.parametrize("kind", ["qdldl", "splu"])
def test_singular_raises(kind):
    U = upper(sp.csc_matrix(np.ones((2, 2))))  # rank 1: the second pivot is zero
    with pytest.raises(SingularMatrixError):
        make_solver(kind).factor(U)


def test_auto_choice_is_a_fixed_rule():
    small, large = 500, 50_000
    assert auto_choice(small, pardiso=False, qdldl=True) == "qdldl"
    assert auto_choice(large, pardiso=False, qdldl=True) == "splu"
    assert auto_choice(small, pardiso=False, qdldl=False) == "splu"
    assert auto_choice(large, pardiso=True, qdldl=True) == "pardiso"
    assert auto_choice(small, pardiso=True, qdldl=True) == "qdldl"
    assert auto_choice(small, pardiso=True, qdldl=False) == "pardiso"
    assert auto_choice(linear.AUTO_PARDISO_N, pardiso=True, qdldl=True) == "pardiso"
    assert auto_choice(linear.AUTO_PARDISO_N - 1, pardiso=True, qdldl=True) == "qdldl"
    mid = (linear.AUTO_PARDISO_N + linear.AUTO_LARGE_N) // 2  # e.g. the default sheet
    assert auto_choice(mid, pardiso=True, qdldl=True) == "pardiso"
    assert auto_choice(mid, pardiso=False, qdldl=True) == "qdldl"
    assert auto_choice(linear.AUTO_LARGE_N, pardiso=False, qdldl=True) == "splu"


@pytest.mark.parametrize("m", [30, 101])  # 900 and 10,201 unknowns: both sides of the threshold
def test_auto_solver_is_deterministic(m):
    U = upper(laplacian_2d(m))
    names = set()
    for _ in range(2):
        s = AutoSolver()
        assert s.factor(U) == 0
        names.add(s.name)
    assert names == {f"auto:{auto_choice(U.shape[0])}"}


def test_make_solver_kinds():
    assert isinstance(make_solver("qdldl"), LDLSolver)
    assert isinstance(make_solver("splu"), LUSolver)
    assert isinstance(make_solver("auto"), AutoSolver)
    with pytest.raises(ValueError):
        make_solver("nope")
    if not HAVE_PARDISO:
        with pytest.raises(ImportError):
            make_solver("pardiso")


def test_pardiso_threads_are_fixed_and_reproducible():
    """Same case + seed, same bits: PARDISO factors on a fixed number of threads
    (UNDULATE_PARDISO_THREADS, default 2, not the machine's cores) in MKL's reproducible
    mode: refactoring one matrix gives the same solution to the last bit every time."""
    if not linear.pardiso_available():
        pytest.skip("MKL PARDISO not installed (extra 'fast')")
    import ctypes
    import hashlib

    from pypardiso.pardiso_wrapper import PyPardisoSolver

    get = PyPardisoSolver().libmkl.MKL_Domain_Get_Max_Threads
    get.restype = ctypes.c_int
    assert get(pardiso._MKL_DOMAIN_PARDISO) == linear.pardiso_threads()
    # an indefinite 2D Laplacian-like matrix, large enough to be factored in parallel
    m = 140
    T = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], shape=(m, m))
    A = (sp.kron(sp.eye(m), T) + sp.kron(T, sp.eye(m)) - 0.05 * sp.eye(m * m)).tocsc()
    b = np.random.default_rng(0).standard_normal(m * m)
    s = linear.PardisoSolver()
    digests = set()
    for _ in range(12):
        n_neg = s.factor(sp.triu(A).tocsc())
        digests.add(hashlib.sha256(s.solve(b).tobytes()).hexdigest())
    assert n_neg > 0 and len(digests) == 1


def test_single_threaded_blas_nests_and_restores():
    """OpenBLAS runs on one thread inside the block (nested blocks share the limit) and gets
    its thread count back after the last one; MKL (PARDISO) is left alone."""
    threadpoolctl = pytest.importorskip("threadpoolctl")

    def threads(api):
        return [d["num_threads"] for d in threadpoolctl.threadpool_info()
                if d["internal_api"] == api]

    before, mkl_before = threads("openblas"), threads("mkl")
    if not before:
        pytest.skip("NumPy is not linked with OpenBLAS here")
    with linear.single_threaded_blas():
        with linear.single_threaded_blas():
            assert set(threads("openblas")) == {1}
        assert set(threads("openblas")) == {1}
        assert threads("mkl") == mkl_before
    assert threads("openblas") == before
