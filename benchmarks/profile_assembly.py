"""Where one Newton iteration's assembly time goes, group by group (default single rod).

    python benchmarks/profile_assembly.py

For each element group: the JAX kernel (gradient + element Hessians) and the host-side
post-processing (concatenation, dropping padding, selecting the upper triangle); then the whole
``Assembly.gradient_hessian`` and one energy evaluation, and one LDL^T numeric refactorization
of the same Hessian for comparison. Times are means over 5 calls after a warm-up.
"""

from __future__ import annotations

import time

import jax
import numpy as np

from undulate import api
from undulate.mechanics.assemble import Assembly
from undulate.solve.linear import make_solver
from undulate.solve.newton import NewtonOptions
from undulate.solve.release import _clamped, prepare, prestretch
from undulate.solve.terms import TermState, groups


def _mean(fn, n: int = 5) -> float:
    fn()
    t = time.perf_counter()
    for _ in range(n):
        fn()
    return (time.perf_counter() - t) / n


def main() -> None:
    sim = prepare(api.demo_case())
    x_print, _ = prestretch(sim, NewtonOptions(force_scale=sim.force_scale))
    fixed = np.zeros((sim.mesh.n_nodes, 3), bool)
    fixed[_clamped(sim)] = True
    printed = groups(sim, ("print",), TermState(x_print, ~fixed.all(axis=1)))
    asm = Assembly(sim.mesh.n_nodes, sim.fabric + printed, fixed)
    x = x_print.copy()
    x[:, 2] += 1e-3 * np.random.default_rng(0).standard_normal(len(x))
    print(f"nodes {sim.mesh.n_nodes}, unknowns {asm.n_free}, Hessian nnz (upper) {asm.nnz}")
    print(f"{'group':16s} {'elements':>8s} {'chunk':>6s} {'kernel ms':>10s} {'host ms':>8s}")
    for g, keep in zip(asm.groups, asm._keep, strict=True):
        outs = g.run("grad_hess", x)

        def kern(g=g):
            jax.block_until_ready(g.run("grad_hess", x))

        def host(outs=outs, g=g, keep=keep):
            np.concatenate([np.asarray(o[0]) for o in outs])[: g.n_el]
            He = np.concatenate([np.asarray(o[1]) for o in outs])[: g.n_el]
            He.ravel()[keep]

        print(f"{g.name:16s} {g.n_el:8d} {g.chunk:6d} {1e3 * _mean(kern):10.2f} "
              f"{1e3 * _mean(host):8.2f}")
    t_gh = _mean(lambda: asm.gradient_hessian(x))
    t_e = _mean(lambda: asm.energy(x))
    _, H = asm.gradient_hessian(x)
    K = H.copy()
    K.data[asm.diag_pos] += 1e-2 * np.abs(H.diagonal())  # keep it definite for the timing
    solver = make_solver()
    t_f = _mean(lambda: solver.factor(K))
    print(f"gradient_hessian {1e3 * t_gh:.1f} ms, energy {1e3 * t_e:.1f} ms, "
          f"LDL^T refactorization ({solver.name}) {1e3 * t_f:.1f} ms")


if __name__ == "__main__":
    main()
