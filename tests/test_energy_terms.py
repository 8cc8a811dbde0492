"""The assembler's seam: any :class:`EnergyTerm`, and a pattern that grows between solves.

A toy contact: two strings of nodes under tension, one pushed onto the other by a dead
load. The contact term (a pair energy between nodes of the two strings that come closer than
``gap``) only exists once the strings are near: its pairs are found after a first solve and
added with ``Assembly.set_groups``, which brings Hessian entries between the strings that the
first pattern did not have. The same solver object then factors the grown pattern (its
symbolic analysis redone) and the contact holds the strings apart.
"""

import jax.numpy as jnp
import numpy as np
import pytest

from undulate.mechanics.assemble import Assembly, ElementGroup, EnergyTerm
from undulate.mechanics.fabric import dead_load
from undulate.solve.linear import make_solver
from undulate.solve.newton import NewtonOptions, minimize

N = 9  # nodes per string
GAP = 0.5  # contact distance


def spring(xl, rest, k):
    d = jnp.linalg.norm(xl[1] - xl[0])
    return 0.5 * k * (d - rest) ** 2


def contact(xl, gap, k):
    """Penalty on two nodes closer than ``gap`` (zero, with its derivatives, beyond)."""
    d = jnp.sqrt(jnp.sum((xl[1] - xl[0]) ** 2) + 1e-12)
    return 0.5 * k * jnp.maximum(gap - d, 0.0) ** 3 / gap


def strings() -> tuple[np.ndarray, list[ElementGroup], np.ndarray]:
    """Two strings along x, 2 apart in y, ends held; the upper one loaded towards the lower."""
    xs = np.linspace(0.0, 8.0, N)
    x = np.concatenate([np.c_[xs, np.zeros(N), np.zeros(N)],
                        np.c_[xs, np.full(N, 2.0), np.zeros(N)]])
    edges = np.array([[s * N + i, s * N + i + 1] for s in (0, 1) for i in range(N - 1)])
    springs = ElementGroup("springs", spring, edges,
                           (np.full(len(edges), 0.9), np.full(len(edges), 50.0)))  # taut
    inner = np.array([N + i for i in range(1, N - 1)])
    load = ElementGroup("load", dead_load, inner[:, None],
                        (np.tile([0.0, -6.0, 0.0], (inner.size, 1)),))
    fixed = np.zeros((2 * N, 3), bool)
    fixed[[0, N - 1, N, 2 * N - 1]] = True
    fixed[:, 2] = True  # in the plane
    return x, [springs, load], fixed


def pairs_within(x: np.ndarray, radius: float) -> np.ndarray:
    """Pairs of inner nodes of the two strings closer than ``radius`` (a contact search)."""
    a = np.arange(1, N - 1)
    b = np.arange(N + 1, 2 * N - 1)
    d = np.linalg.norm(x[a][:, None, :2] - x[b][None, :, :2], axis=2)
    i, j = np.nonzero(d < radius)
    return np.c_[a[i], b[j]]


def test_every_group_is_an_energy_term() -> None:
    _, groups, _ = strings()
    assert all(isinstance(g, EnergyTerm) for g in groups)


def test_a_contact_term_grows_the_pattern_and_the_solver_follows() -> None:
    x0, groups, fixed = strings()
    asm = Assembly(2 * N, groups, fixed)
    solver = make_solver("auto")
    opts = NewtonOptions(rtol=1e-9)
    free = minimize(asm, x0, asm.free(x0), opts, solver=solver)
    assert free.converged
    x1 = asm.full(free.u, x0)
    # without contact the loaded string passes through the lower one
    assert np.min(x1[N + 1:2 * N - 1, 1]) < -0.5

    # contact pairs where the strings would meet: nodes across from each other
    pairs = pairs_within(x0, 2.5)
    assert len(pairs) > 0
    nnz_before = asm.nnz
    cont = ElementGroup("contact", contact, pairs,
                        (np.full(len(pairs), GAP), np.full(len(pairs), 4e4)))
    asm.set_groups(groups + [cont])
    assert asm.nnz > nnz_before  # entries between the strings that were not there
    assert len(asm.groups) == 3

    # the grown Hessian is the derivative of the grown gradient (finite differences)
    rng = np.random.default_rng(1)
    xt = x0 + 0.05 * rng.standard_normal(x0.shape) * ~fixed
    xt[N:, 1] -= 1.6  # strings within the contact distance
    g, H = asm.gradient_hessian(xt)
    Hs = asm.symmetric(H).toarray()
    u, du = asm.free(xt), 1e-6 * rng.standard_normal(asm.n_free)
    g2 = asm.gradient(asm.full(u + du, xt))
    assert np.allclose(Hs @ du, g2 - g, rtol=1e-3, atol=1e-9 * np.abs(g).max())

    # the load in steps (a contact engages within a step, not jumped over by one)
    load, x2 = groups[1], x0
    w = load.params[0].copy()
    for f in np.linspace(0.1, 1.0, 10):
        load.set_params(f * w)
        res = minimize(asm, x2, asm.free(x2), opts, solver=solver)
        assert res.converged and res.n_negative == 0
        x2 = asm.full(res.u, x2)
    gaps = np.linalg.norm(x2[pairs[:, 1], :2] - x2[pairs[:, 0], :2], axis=1)
    # the contact holds the strings apart: within a fraction of the gap, not through
    assert gaps.min() > 0.5 * GAP
    inner = np.arange(1, N - 1)
    assert np.all(x2[N + inner, 1] > x2[inner, 1])  # the loaded string stays on top
    assert np.min(x2[inner, 1]) < -0.1  # and pushes the lower one down through the contact


def test_set_groups_with_the_same_terms_keeps_the_pattern() -> None:
    x0, groups, fixed = strings()
    asm = Assembly(2 * N, groups, fixed)
    before = (asm.nnz, asm._indptr.copy(), asm._indices.copy())
    asm.set_groups(groups)
    assert asm.nnz == before[0]
    assert np.array_equal(asm._indptr, before[1]) and np.array_equal(asm._indices, before[2])
    with pytest.raises(ValueError, match="parameter rows"):
        ElementGroup("bad", spring, np.array([[0, 1]]), (np.ones(2), np.ones(1)))


@pytest.mark.parametrize("kind", ["qdldl", "splu", "pardiso"])
def test_every_linear_solver_follows_a_changed_pattern(kind: str) -> None:
    """Two matrices of one size and one number of entries but another pattern (a contact that
    moved): the second factorization must analyse its own pattern, not reuse the first's."""
    import scipy.sparse as sp

    from undulate.solve import linear

    if kind == "pardiso" and not linear.pardiso_available():
        pytest.skip("PARDISO not installed")
    solver = make_solver(kind)
    assert isinstance(solver, linear.LinearSolver)
    n = 6
    A = sp.diags([4.0] * n).tolil()
    B = A.copy()
    A[0, 1] = A[1, 0] = 1.0  # coupling 0-1
    B[0, 5] = B[5, 0] = 1.0  # coupling 0-5 instead: same nnz, other pattern
    b = np.arange(1.0, n + 1)
    for M in (A, B):
        M = sp.csc_matrix(M)
        assert solver.factor(sp.triu(M, format="csc")) == 0
        assert np.allclose(M @ solver.solve(b), b)
