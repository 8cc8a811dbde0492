"""The Newton solver's decisions on tiny energies with known answers."""

import jax.numpy as jnp
import numpy as np
import pytest
import scipy.sparse as sp

from undulate.mechanics.assemble import Assembly, ElementGroup
from undulate.solve.linear import make_solver
from undulate.solve.newton import NewtonOptions, _refined_solve, minimize


def _pair(eps: float) -> Assembly:
    """Two coupled unknowns: E = (x-y)^4 - eps (x-y)^2 + (x+y)^2 (+ z terms), x = node coords."""

    def fn(xl, e):
        d = xl[0, 0] - xl[1, 0]
        return d**4 - e * d**2 + (xl[0, 0] + xl[1, 0]) ** 2 + jnp.sum(xl[:, 1:] ** 2)

    g = ElementGroup("pair", fn, np.array([[0, 1]]), (np.array([eps]),))
    return Assembly(2, [g], np.zeros((2, 3), bool))


def test_saddle_is_left_for_the_minimum():
    eps = 0.02
    asm = _pair(eps)
    x0 = np.zeros((2, 3))
    res = minimize(asm, x0, asm.free(x0), NewtonOptions(rtol=1e-10))
    assert res.converged and res.n_negative == 0
    x = asm.full(res.u, x0)
    assert abs(x[0, 0] - x[1, 0]) == pytest.approx(np.sqrt(eps / 2), rel=1e-6)


def test_curved_budget_counts_only_steps_along_the_watched_unknowns():
    """``curved_budget``: after that many iterations with a step along negative curvature of
    the watched unknowns, minimize gives up (the release loop then halves its step). A
    negative mode outside the watched unknowns (the slack fabric's wrinkles, for the release)
    does not count."""
    asm = _pair(0.02)  # the negative mode is x0 - x1 (free unknowns 0 and 3)
    x0 = np.zeros((2, 3))
    opts = NewtonOptions(rtol=1e-10, curved_budget=1)
    on_mode = np.zeros(6, bool)
    on_mode[[0, 3]] = True
    stopped = minimize(asm, x0, asm.free(x0), opts, watch=on_mode)
    assert not stopped.converged and stopped.message.startswith("change of pattern")
    elsewhere = minimize(asm, x0, asm.free(x0), opts, watch=~on_mode)
    assert elsewhere.converged and elsewhere.negative_steps > 0
    assert stopped.over_budget and not elsewhere.over_budget
    assert minimize(asm, x0, asm.free(x0), NewtonOptions(rtol=1e-10),
                    watch=on_mode).converged


def test_curved_limit_stops_after_that_many_watched_curved_steps():
    """``curved_limit``: minimize gives up (``stalled``) once that many steps have followed
    negative curvature of the watched unknowns, whatever the iteration count (the release
    loop's limit for a step whose rods wander from one unstable state to the next); steps
    along other unknowns' negative curvature do not count, and 0 means no limit."""
    asm = _pair(0.02)  # the saddle: one curved step along x0 - x1 leaves it
    x0 = np.zeros((2, 3))
    on_mode = np.zeros(6, bool)
    on_mode[[0, 3]] = True
    stopped = minimize(asm, x0, asm.free(x0), NewtonOptions(rtol=1e-10, curved_limit=1),
                       watch=on_mode)
    assert not stopped.converged and stopped.stalled and not stopped.over_budget
    assert stopped.watched_steps == 1 and stopped.message.startswith("no settling")
    for opts, watch in ((NewtonOptions(rtol=1e-10, curved_limit=1), ~on_mode),
                        (NewtonOptions(rtol=1e-10, curved_limit=2), on_mode),
                        (NewtonOptions(rtol=1e-10, curved_limit=0), on_mode)):
        res = minimize(asm, x0, asm.free(x0), opts, watch=watch)
        assert res.converged and not res.stalled and res.negative_steps == 1


def test_definite_start_gives_up_at_once_on_an_unstable_start():
    """``definite_start``: a start whose Hessian has negative pivots ends before any iteration
    (the release loop then halves its grown step); a stable start is solved as usual."""
    asm = _pair(0.02)
    x0 = np.zeros((2, 3))  # the saddle
    opts = NewtonOptions(rtol=1e-10, definite_start=True)
    res = minimize(asm, x0, asm.free(x0), opts)
    assert not res.converged and res.unstable_start and not res.over_budget
    assert res.iterations == 0 and "not stable" in res.message
    x1 = x0.copy()
    x1[0, 0], x1[1, 0] = 0.1, -0.1  # beside the minimum: positive definite
    ok = minimize(asm, x1, asm.free(x1), opts)
    assert ok.converged and not ok.unstable_start


def test_neutral_mode_within_roundoff_counts_as_stable_but_not_beyond():
    asm = _pair(1e-10)  # relative lowest eigenvalue about -1e-10: a neutral mode
    x0 = np.zeros((2, 3))
    res = minimize(asm, x0, asm.free(x0), NewtonOptions(rtol=1e-10))
    assert res.converged and "marginally stable" in res.message
    strict = minimize(asm, x0, asm.free(x0), NewtonOptions(rtol=1e-10, marginal=0.0))
    assert strict.converged and "marginally" not in strict.message
    x = asm.full(strict.u, x0)
    # it left the neutral point for the (very shallow) minimum at |x - y| = sqrt(eps / 2)
    assert abs(x[0, 0] - x[1, 0]) == pytest.approx(np.sqrt(0.5e-10), rel=0.1)


def test_iterative_refinement_recovers_digits_on_an_ill_conditioned_system():
    """A factorization that lost digits (here: of a matrix perturbed by 1e-9 relative, as
    roundoff does on stiff Hessians) still gives an accurate solve after refinement."""
    rng = np.random.default_rng(0)
    n = 40
    Q, _ = np.linalg.qr(rng.standard_normal((n, n)))
    A = (Q * np.logspace(0, 6, n)) @ Q.T
    A = 0.5 * (A + A.T)
    E = rng.standard_normal((n, n))
    A_lossy = A + 1e-9 * np.abs(A).max() * 0.5 * (E + E.T)
    b = rng.standard_normal(n)
    solver = make_solver()
    solver.factor(sp.csc_matrix(np.triu(A_lossy)))
    d0 = solver.solve(b)
    d = _refined_solve(solver, sp.csr_matrix(A), b)
    r0 = np.linalg.norm(A @ d0 - b)
    r = np.linalg.norm(A @ d - b)
    assert r0 > 1e-8 * np.linalg.norm(b)  # the plain solve did lose digits
    assert r < 1e-3 * r0


def test_auto_solver_picks_one_and_keeps_the_inertia():
    from undulate.solve.linear import AutoSolver

    A = sp.diags([2.0, -1.0, 3.0, -4.0]) + sp.diags([0.1, 0.1, 0.1], 1)
    s = AutoSolver()
    assert s.factor(sp.csc_matrix(sp.triu(A))) == 2
    assert s.name in ("auto:qdldl", "auto:splu")
    b = np.arange(1.0, 5.0)
    full = (A + sp.triu(A, 1).T).toarray()
    np.testing.assert_allclose(full @ s.solve(b), b, atol=1e-12)
