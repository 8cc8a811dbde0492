"""Line searches along a Newton iteration's direction: backtracking on the straight step and
on the curved path ``x(a) = x + a^2 d + a v``, expanded along v while the merit keeps falling.

A trial point is judged by ``merit(x) -> (merit, energy)``: the energy itself, or the mixed
merit of :meth:`undulate.mechanics.assemble.Assembly.merit` (the stiff rods' second-order
stretch along a straight step not charged to it) capped by the energy.
"""

from __future__ import annotations

import numpy as np

from ..mechanics.assemble import Assembly
from .options import NewtonOptions

__all__ = ["curved_backtrack", "energy_function", "line_search", "merit_function"]


def curved_backtrack(dM: float, q: float) -> float:
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


def energy_function(asm: Assembly):
    """The line searches' function when no stresses are carried: (energy, energy)."""
    def f(x: np.ndarray) -> tuple[float, float]:
        E = asm.energy(x)
        return E, E
    return f


def merit_function(asm: Assembly, x0: np.ndarray, opts: NewtonOptions, recent_E):
    """(merit, energy) of a trial point of a mixed Newton step from ``x0``.

    Without ``opts.mixed_merit`` the merit is the energy. With it, a trial point whose energy
    exceeds the highest recent energy by more than ``opts.merit_energy_cap`` of its size is
    refused (merit +inf): the merit forgives the stretch of the stiff rods along a straight
    step, not a step that tears the structure apart (measured: without the cap a curved step
    accepted a state of energy 1.8e5 N mm from 12).
    """
    if not opts.mixed_merit:
        return energy_function(asm)
    E_top = max(recent_E)
    cap = E_top + opts.merit_energy_cap * abs(E_top)

    def f(x: np.ndarray) -> tuple[float, float]:
        m, E = asm.merit(x0, x - x0)
        return (m if np.isfinite(E) and E <= cap else np.inf), E
    return f


def line_search(asm: Assembly, x_fixed, u, d, v, g, M0, Hs, merit,
                M_ref: float | None = None) -> tuple:
    """Backtracking on x(a) = u + a^2 d + a v (or u + a d when v is None); expand along v.

    ``merit(x)`` returns (merit, energy) of a trial point; ``M0`` is the current merit and
    ``M_ref`` the one a Newton step must beat (the highest recent one: non-monotone).
    Returns (x, energy, step length a, curved) with x None when no step lowers the merit.
    Near convergence the merit change of a Newton step falls below its roundoff; then the step
    is accepted when it lowers max|g| instead (the merit cannot tell).
    """
    if v is None:
        return _straight_search(asm, x_fixed, u, d, g, M0, merit, M_ref)
    return _curved_search(asm, x_fixed, u, d, v, g, M0, Hs, merit)


def _straight_search(asm: Assembly, x_fixed, u, d, g, M0, merit, M_ref) -> tuple:
    """Armijo backtracking on u + a d against ``M_ref`` (non-monotone), from a = 1."""
    slope = float(g @ d)
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


def _curved_search(asm: Assembly, x_fixed, u, d, v, g, M0, Hs, merit) -> tuple:
    """Backtracking on u + a^2 d + a v (shortened by :func:`curved_backtrack`), then, from
    a = 1, expansion by 2 while the merit keeps falling (escape from the saddle in one go)."""
    slope = float(g @ d)
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
        a *= curved_backtrack(M - M0, 1e4 * model(a))
    if best is None:
        return None, M0, 0.0, False
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
