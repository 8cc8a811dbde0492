"""Inertial release: implicit Euler dynamics written as a minimisation (incremental potential).

Each time step solves

    x_{n+1} = argmin_x  E(x) + sum_i m_i / (2 dt^2) |x_i - x_hat_i|^2,
    x_hat   = x_n + dt v_n / (1 + c dt),         v_{n+1} = (x_{n+1} - x_n) / dt

with lumped masses m_i (fabric rho t A / 3 per triangle corner, rod rho_B b h per unit length;
the same masses carry the weight when ``case.gravity`` is on, :func:`gravity_group`)
and mass-proportional damping c. The inertia term is just another element group, so the same
Newton solver (and its negative-curvature handling) is reused. Clamps move linearly from eps0
to 0 over ``release_time``; then the structure settles for ``settle_time``. Implicit Euler is
dissipative at large steps: with the default dt the motion is overdamped except where a snap
happens, which is where the dynamics decides which buckled state is reached.
"""

from __future__ import annotations

import numpy as np

from ..mechanics.assemble import Assembly, ElementGroup
from ..mechanics.fabric import inertia
from .boundary import clamp_positions
from .linear import make_solver
from .newton import ConvergenceError, NewtonOptions, minimize
from .simulation import rod_heights
from .terms import gravity_group, lumped_masses

__all__ = ["lumped_masses", "gravity_group", "release_inertial"]


def release_inertial(sim, asm: Assembly, x: np.ndarray, opts: NewtonOptions, progress):
    dyn = sim.case.dynamics
    eps0 = sim.case.release.eps0
    dt = dyn.dt
    n_rel = max(1, int(round(dyn.release_time / dt)))
    n_set = int(round(dyn.settle_time / dt))
    mass = lumped_masses(sim)
    free_nodes = np.nonzero(~asm.fixed.all(axis=1))[0]
    grp = ElementGroup("inertia", inertia, free_nodes[:, None],
                       (mass[free_nodes] / dt**2, x[free_nodes]))
    dyn_asm = Assembly(asm.n_nodes, asm.groups + [grp], asm.fixed)
    solver = make_solver(opts.linear_solver)
    rng = np.random.default_rng(sim.case.imperfection.seed + 1)
    v = np.zeros_like(x)
    history: list[dict] = []
    totals = dict(newton_iterations=0, negative_curvature_steps=0, time_steps=0)
    n_total = n_rel + n_set
    for k in range(1, n_total + 1):
        e = sim.case.release.final_strain + (eps0 - sim.case.release.final_strain) * max(
            0.0, 1.0 - k / n_rel)
        x_hat = x + dt * v / (1.0 + dyn.damping * dt)
        grp.set_params(mass[free_nodes] / dt**2, x_hat[free_nodes])
        x0 = clamp_positions(sim, e, x_hat)
        res = minimize(dyn_asm, x0, dyn_asm.free(x0), opts, solver=solver, rng=rng)
        totals["newton_iterations"] += res.iterations
        totals["negative_curvature_steps"] += res.negative_steps
        if not res.converged:
            raise ConvergenceError(
                f"inertial step {k} (t = {k * dt:.4g} s, release strain {eps0 - e:.4g}): "
                f"{res.message}", step=k, residual=res.residual, release_strain=eps0 - e)
        x_new = dyn_asm.full(res.u, x0)
        v = (x_new - x) / dt
        x = x_new
        rec = dict(step=k, time=k * dt, release_strain=eps0 - e, clamp_strain=e,
                   energy=asm.energy(x), kinetic=float(0.5 * np.sum(mass[:, None] * v**2)),
                   **rod_heights(sim, x), newton_iterations=res.iterations,
                   negative_steps=res.negative_steps, residual=res.residual)
        history.append(rec)
        if progress is not None:
            progress(k / n_total, rec)
    totals["time_steps"] = n_total
    # the settled state must be a static equilibrium: finish with a static solve
    res = minimize(asm, x, asm.free(x), opts, solver=solver, rng=rng)
    if not res.converged:
        raise ConvergenceError(f"after settling: {res.message}", step=n_total,
                               residual=res.residual, release_strain=eps0)
    x = asm.full(res.u, x)
    totals.update(converged=True, final_residual=res.residual,
                  final_static_iterations=res.iterations)
    return x, history, totals
