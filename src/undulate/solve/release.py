"""The experiment, step by step: stretch, print, perturb, release (quasi-static or inertial).

1. **Pre-stretch.** The fabric (reference = unstretched mesh) is stretched along x by clamping
   its short edges at x = X (1 + eps0) (y and z held at their reference values, as in a frame);
   the long edges are free unless ``release.clamps`` holds them too (straight, at their
   printed y, moving with the stretch along x). With ``release.direction`` the same happens
   in a frame turned by that angle against the drawing's (x along the stretch). The
   in-plane equilibrium is solved with z = 0 (the fabric is flat on the print bed).
2. **Print.** The groups of the energy terms that act from printing on
   (:mod:`undulate.solve.terms`: the rods, the weight) are built from the pre-stretched
   positions, so the rods are stress-free there.
3. **Imperfection.** A smooth random out-of-plane displacement (RMS ``amplitude``, correlation
   length ``correlation``, from ``seed``) is added under the rods.
4. **Release.** The clamp strain goes from eps0 to ``release.final_strain`` (0: all the
   way). Quasi-static: nominal increments,
   growing on the smooth buckled branch and cut in half (when ``adaptive``) on failure,
   when a grown step starts from an unstable prediction, or when it holds a change of the
   rods' pattern (``snap_iterations``), each solved to
   a *stable* equilibrium by :func:`undulate.solve.newton.minimize` from a predictor.
   Inertial: implicit damped dynamics
   (see :mod:`undulate.solve.dynamics`) with the clamps moving over ``release_time``, then
   ``settle_time`` of settling.
5. **Hang** (``[hang]``, optional). The fabric is held by the chosen edges only, and the
   other clamps' forces are taken down to zero in steps (:func:`hang`).

Every step records the release strain, energy, max rod height, Newton iterations.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from ..mechanics.assemble import Assembly, ElementGroup
from ..mechanics.build import rod_centrelines
from ..mechanics.fabric import dead_load
from ..model import Case
from .boundary import (
    Boundary,
    clamp_positions,
    clamped_nodes,
    edge_nodes,
    make_boundary,
    prestretch,
)
from .linear import SingularMatrixError, make_solver, single_threaded_blas
from .newton import ConvergenceError, NewtonOptions, minimize
from .simulation import (  # re-exported: a release's inputs and result, by their old address
    ProgressFn,
    SimResult,
    Simulation,
    imperfection_field,
    prepare,
    printed_lateral_stretch,
    rod_heights,
)
from .terms import TermState, groups

__all__ = ["ProgressFn", "Simulation", "SimResult", "prepare", "prestretch", "run_release",
           "imperfection_field", "printed_lateral_stretch", "clamp_positions", "edge_nodes"]

#: the frame's nodes during the pre-stretch (kept under its old name for the tests and benchmarks)
_clamped = clamped_nodes


def run_release(case: Case, progress: ProgressFn | None = None, *,
                assembly: Callable[[Assembly], Assembly] | None = None) -> SimResult:
    """Run the whole experiment for ``case`` and return the final rest state.

    ``assembly``: a wrapper of the release's assembly (the batched runner of
    :mod:`undulate.solve.batch` passes one that evaluates many runs together). Dense linear
    algebra runs on one thread meanwhile (:func:`undulate.solve.linear.single_threaded_blas`).
    """
    with single_threaded_blas():
        return _run_release(case, progress, assembly)


def _run_release(case: Case, progress: ProgressFn | None,
                 assembly: Callable[[Assembly], Assembly] | None) -> SimResult:
    t_start = time.perf_counter()
    sim = prepare(case)
    so = case.solver
    opts = NewtonOptions(rtol=so.rtol, force_scale=sim.force_scale, max_iter=so.max_iter,
                         negative_curvature=so.negative_curvature,
                         linear_solver=so.linear_solver, modes=so.modes)
    x_print, pre = prestretch(sim, opts)
    boundary = make_boundary(sim, x_print)
    fixed = boundary.fixed
    rng = np.random.default_rng(case.imperfection.seed)
    x = x_print.copy()
    imp = case.imperfection
    for ch in sim.mesh.rods:
        dz = imperfection_field(ch.n_nodes, case.mesh.dx_rod, imp.amplitude, imp.correlation, rng)
        for idx in (ch.p, ch.qp, ch.qm):
            x[idx, 2] += dz
    # the rods, printed stress-free (flat, or with the noise in their shape), and the weight,
    # from the start of the release on
    rest = x if imp.kind == "printed" else x_print
    printed = groups(sim, ("print",), TermState(rest, ~fixed.all(axis=1)))
    asm = Assembly(sim.mesh.n_nodes, sim.fabric + printed + boundary.groups(), fixed)
    if assembly is not None:
        asm = assembly(asm)
    t_setup = time.perf_counter() - t_start
    if case.mode == "inertial":
        from .dynamics import release_inertial

        x, history, stats = release_inertial(sim, asm, x, opts, progress)
    else:
        x, history, stats = _release_quasistatic(sim, asm, x, opts, progress, boundary)
    if case.hang is not None:
        asm, x = hang(sim, rest, x, opts, history, stats, progress)
    stats.update(
        prestretch_iterations=pre["iterations"],
        setup_time_s=t_setup,
        wall_time_s=time.perf_counter() - t_start,
        n_nodes=sim.mesh.n_nodes,
        n_unknowns=asm.n_free,
        hessian_nnz=asm.nnz,
        mode=case.mode,
        seed=imp.seed,
    )
    return SimResult(
        case=case, mesh=sim.mesh, sections=sim.sections, x_reference=sim.X3, x_printed=x_print,
        x_final=x, centerlines=rod_centrelines(sim.mesh.rods, x, sim.sections),
        centerlines_printed=rod_centrelines(sim.mesh.rods, x_print, sim.sections),
        history=history, stats=stats, energies=asm.energy_by_group(x),
        element_energy={
            "fabric_membrane": asm.element_energies(x, "fabric_membrane"),
        },
    )


def hang(sim: Simulation, x_rest: np.ndarray, x: np.ndarray, opts: NewtonOptions,
         history: list[dict], stats: dict, progress: ProgressFn | None = None
         ) -> tuple[Assembly, np.ndarray]:
    """After the release: hold the fabric by ``case.hang.edges`` only (where they are now) and
    let go of the other clamps gradually (``x_rest``: the positions the rods were printed
    at).

    The force each let-go clamp exerts on its nodes at the end of the release becomes a dead
    load, taken down to zero in ``hang.steps`` equal steps, each solved to a stable
    equilibrium (so the sheet, e.g., swings down under its weight gradually instead of in one
    jump). Appends one record per step to ``history`` (``stage = "hang"``) and the totals to
    ``stats``; returns the final assembly (held edges fixed, weight on every other node) and
    state (its groups from :mod:`undulate.solve.terms`)."""
    hg = sim.case.hang
    held = edge_nodes(sim.mesh, hg.edges)
    let_go = _clamped(sim) & ~held
    fixed = np.zeros((sim.mesh.n_nodes, 3), dtype=bool)
    fixed[held] = True
    base = sim.fabric + groups(sim, ("print",), TermState(x_rest, ~held))
    nodes = np.nonzero(let_go)[0]
    # the clamps' forces on the let-go nodes: what keeps them in equilibrium now
    final = Assembly(sim.mesh.n_nodes, base, fixed)
    if nodes.size == 0:  # every clamp is among the held edges: nothing to let go
        stats.update(hang_steps=0, hang_newton_iterations=0)
        return final, x
    w0 = final.gradient_full(x)[nodes]
    clamp = ElementGroup("clamp_force", dead_load, nodes[:, None], (w0,))
    asm = Assembly(sim.mesh.n_nodes, base + [clamp], fixed)
    solver = make_solver(opts.linear_solver)
    rng = np.random.default_rng(sim.case.imperfection.seed + 2)
    last = history[-1] if history else {}
    step0 = int(last.get("step", len(history) - 1)) + 1
    its = negs = 0
    for k in range(1, hg.steps + 1):
        clamp.set_params(w0 * (1.0 - k / hg.steps))
        res = minimize(asm, x, asm.free(x), opts, solver=solver, rng=rng)
        its += res.iterations
        negs += res.negative_steps
        if not res.converged:
            raise ConvergenceError(
                f"letting go of the clamps, step {k} of {hg.steps} (clamp forces at "
                f"{1.0 - k / hg.steps:.3g} of their value): {res.message}",
                step=step0 + k - 1, residual=res.residual)
        x = asm.full(res.u, x)
        rec = dict(step=step0 + k - 1, stage="hang", let_go=k / hg.steps,
                   release_strain=last.get("release_strain"),
                   clamp_strain=last.get("clamp_strain"), energy=res.energy,
                   **rod_heights(sim, x), newton_iterations=res.iterations,
                   negative_steps=res.negative_steps, residual=res.residual)
        history.append(rec)
        if progress is not None:
            progress(1.0, rec)
    stats["newton_iterations"] = stats.get("newton_iterations", 0) + its
    stats["negative_curvature_steps"] = stats.get("negative_curvature_steps", 0) + negs
    stats.update(hang_steps=hg.steps, hang_newton_iterations=its,
                 final_residual=history[-1]["residual"])
    return final, x  # energies are reported without the (now zero) clamp forces


def _affine_predictor(x: np.ndarray, e_old: float, e_new: float, on_rod: np.ndarray,
                      rod_nodes: list[np.ndarray], rot: np.ndarray | None = None
                      ) -> np.ndarray:
    """Fabric scaled along the stretch with the clamps; each rod moved rigidly with its
    centroid. ``rot``: stretch frame -> drawing frame (None: the same)."""
    x_pred = x.copy() if rot is None else x @ rot
    scale = (1.0 + e_new) / (1.0 + e_old)
    x_pred[~on_rod, 0] *= scale  # rod nodes untouched: their centroids are read below
    for ch_nodes in rod_nodes:
        xc = x_pred[ch_nodes, 0].mean()
        x_pred[ch_nodes, 0] += xc * (scale - 1.0)
    return x_pred if rot is None else x_pred @ rot.T


#: chord steps of the predictor (each one gradient, one solve, one energy; no factorization).
#: Measured on nine benchmark cases (demo, single rods h = 0.08, 0.1, 0.3, 2, five rods at
#: (0.1, 0), (0.1, 50), (2, 50), (0.5, 10)): 2,536 Newton iterations with one, 2,391 with two
#: (single-0.08 318 -> 279, single-2 229 -> 198, five-0.1-50 470 -> 409: fewer cut steps);
#: on the six small cases 1,525 with one, 1,449 with two, 1,455 with three; same final states.
CHORD_STEPS = 2


def _chord_correction(asm: Assembly, solver, x_pred: np.ndarray,
                      steps: int = CHORD_STEPS) -> np.ndarray:
    """The predicted start moved by chord steps, ``u -= H^-1 g`` with the Hessian H of the last
    equilibrium (its factorization is still in ``solver``: no new one is made), each kept
    only when it lowers the energy (the first that does not ends the correction).

    The affine and secant predictors leave the fabric next to the rods' ends, and the slack
    far field at the end of the release, compressed: the start then has tens to hundreds of
    negative pivots (wrinkles), each followed by its own curved Newton step before the rods
    move at all. Linear corrections from the last equilibrium's stiffness remove most of
    that (measured on the demo: 252 -> 220 Newton iterations with one, same final state; a
    second one: :data:`CHORD_STEPS`).
    """
    E = asm.energy(x_pred)
    for _ in range(steps):
        g = asm.gradient(x_pred)
        try:
            du = solver.solve(-g)  # may make a deferred LDL^T (linear.factor_lazily)
        except SingularMatrixError:
            break
        if not np.all(np.isfinite(du)):
            break
        x_try = asm.full(asm.free(x_pred) + du, x_pred)
        E_try = asm.energy(x_try)
        if not E_try < E:
            break
        x_pred, E = x_try, E_try
    return x_pred


#: a grown step (longer than ``snap_resolution`` x nominal) whose predicted start is not
#: positive definite is taken again in halves at once, before any Newton iteration: a start
#: with negative pivots means the step jumps past a loss of stability (of the rods' pattern or
#: of the slack fabric), which the snap budget would otherwise find only after following the
#: fabric's wrinkles for tens of iterations. Measured (`benchmarks/bench_engine.py`, same
#: states in every case): demo 225 -> 175 Newton iterations, five-0.5-10 169 -> 116,
#: five-0.1-0 267 -> 236, single-0.3 241 -> 220; single-0.08, five-0.1-50 unchanged;
#: five-2-50 364 -> 377.
GROWN_STEP_DEFINITE_START = True

#: a release step that converged in at most this many Newton iterations, none of them along
#: negative curvature, lets the next increment grow
EASY_STEP_ITERATIONS = 5
#: deflection (in rod thicknesses) above which the rods count as buckled without a bifurcation
BUCKLED_DEFLECTION = 2.0


def _next_increment(de: float, de_nom: float, max_factor: float, buckled: bool, res,
                    onset_substeps: int = 1) -> float:
    """The next release increment after a converged step of size ``de``.

    Before the rods have buckled (``buckled``: decided by the release loop) the increment is
    ``de_nom / onset_substeps`` (a cut increment doubles back to it), which sets how finely
    the onset is resolved. After every step that needed negative curvature or more than
    :data:`EASY_STEP_ITERATIONS` iterations, the increment goes back towards the nominal one:
    the changes of pattern are taken at the nominal resolution. On the smooth post-buckling
    branch an easy step doubles the increment, up to ``max_factor`` x nominal.
    """
    if not buckled:
        return min(2.0 * de, de_nom / onset_substeps)
    easy = res.negative_steps == 0 and res.iterations <= EASY_STEP_ITERATIONS
    return min(2.0 * de, (max_factor if easy else 1.0) * de_nom)


@dataclass
class _Walk:
    """Where the quasi-static release stands between two steps."""

    x: np.ndarray  # the last equilibrium
    e: float  # its clamp strain
    de: float  # the next increment
    steps: list  # (e_old, e_new) steps queued (halves of a cut step)
    x_prev: np.ndarray | None = None  # the equilibrium before (secant predictor)
    e_prev: float | None = None
    chord_ready: bool = False  # the solver holds the last equilibrium's factorization
    buckled: bool = False
    history: list = field(default_factory=list)
    totals: dict = field(default_factory=lambda: dict(
        newton_iterations=0, negative_curvature_steps=0, step_cuts=0, snap_cuts=0,
        unstable_start_cuts=0, stall_cuts=0, assembly_time_s=0.0, factor_time_s=0.0,
        eig_time_s=0.0, line_search_time_s=0.0))

    def next_step(self, eps0: float, e_end: float) -> tuple[float, float]:
        if self.steps:
            return self.steps.pop()
        # equal increments add up to eps0 only to roundoff: a remainder of 1e-17 would
        # otherwise make an extra, empty step
        e, de = self.e, self.de
        return e, (e - de if e - de > e_end + 1e-9 * eps0 else e_end)

    def count(self, res) -> None:
        tot = self.totals
        tot["newton_iterations"] += res.iterations
        tot["negative_curvature_steps"] += res.negative_steps
        for key in ("assembly", "factor", "eig", "line_search"):
            tot[f"{key}_time_s"] += res.times.get(key, 0.0)


def _rod_masks(sim: Simulation, asm: Assembly) -> tuple[np.ndarray, list, np.ndarray]:
    """(nodes on a rod, each rod's nodes, the free unknowns on rods: minimize's ``watch``)."""
    rod_nodes = [np.concatenate([ch.p, ch.qp, ch.qm]) for ch in sim.mesh.rods]
    on_rod = np.zeros(sim.mesh.n_nodes, dtype=bool)
    for rn in rod_nodes:
        on_rod[rn] = True
    return on_rod, rod_nodes, np.repeat(on_rod, 3)[asm.free_dofs]


def _predict(sim: Simulation, asm: Assembly, bd: Boundary, w: _Walk, e_old: float,
             e_new: float, on_rod: np.ndarray, rod_nodes: list, solver) -> np.ndarray:
    """The start of the step from ``e_old`` to ``e_new``.

    The secant of the last two equilibria when there are two (it follows the buckled branch;
    measured on the default rod: 146 Newton iterations against 226 for the affine predictor
    alone, same final state) unless its energy is more than twice that of the affine one
    (fabric follows the clamps in x while the nearly inextensible rods keep their shape and
    move with their centroid): right after a change of mode the secant extrapolates the jump
    (measured on a thin rod: energy 219 N mm against 18.5 before). A plain "lower energy" test
    picks the affine start too often (its energy is lower but it is farther from the branch:
    311 against 270 iterations). Then the chord correction (:func:`_chord_correction`).
    """
    rel = sim.case.release
    x = w.x
    x_pred = _affine_predictor(x, e_old, e_new, on_rod, rod_nodes,
                               sim.rotation if rel.direction else None)
    x_pred = bd.place(e_new, x_pred)
    if w.x_prev is not None and w.e_prev is not None and w.e_prev != e_old and e_old != e_new:
        x_sec = x + (x - w.x_prev) * ((e_old - e_new) / (w.e_prev - e_old))
        x_sec = bd.place(e_new, x_sec)
        if asm.energy(x_sec) < 2.0 * asm.energy(x_pred):
            x_pred = x_sec
    if w.chord_ready:
        x_pred = _chord_correction(asm, solver, x_pred)
    return x_pred


def _halvable(rel, e_old: float, e_new: float, de_min: float) -> bool:
    """Whether the step from ``e_old`` to ``e_new`` may be taken again in halves."""
    return rel.adaptive and (e_old - e_new) / 2 >= de_min and e_old != e_new


def _cut(w: _Walk, res, e_old: float, e_new: float, halvable: bool, eps0: float) -> None:
    """Queue the two halves of a step that did not converge (``halvable``: see
    :func:`_halvable`), or raise ConvergenceError."""
    if halvable:
        w.de = (e_old - e_new) / 2
        w.totals["step_cuts"] += 1
        w.totals["snap_cuts"] += int(res.over_budget)
        w.totals["unstable_start_cuts"] += int(res.unstable_start)
        w.totals["stall_cuts"] += int(res.stalled)
        w.steps.append((e_old, e_old - w.de))
        return
    n = len(w.history)
    raise ConvergenceError(f"release step {n} (release strain {eps0 - e_new:.4g}): "
                           f"{res.message}", step=n, residual=res.residual,
                           release_strain=eps0 - e_new)


def _release_quasistatic(sim: Simulation, asm: Assembly, x: np.ndarray, opts: NewtonOptions,
                         progress: ProgressFn | None, bd: Boundary
                         ) -> tuple[np.ndarray, list[dict], dict]:
    rel = sim.case.release
    eps0, e_end = rel.eps0, rel.final_strain  # the clamps stop at e_end (0: a full release)
    de_nom = (eps0 - e_end) / rel.steps
    de_min = de_nom * rel.min_step_fraction
    solver = make_solver(opts.linear_solver)
    rng = np.random.default_rng(sim.case.imperfection.seed + 1)
    snap_opts = replace(opts, curved_budget=rel.snap_iterations,
                        definite_start=GROWN_STEP_DEFINITE_START)
    snap_opts_last = replace(snap_opts, definite_start=False)
    on_rod, rod_nodes, watch = _rod_masks(sim, asm)
    # equilibrium with the imperfection at the start (clamps still at eps0)
    w = _Walk(x, eps0, de_nom / rel.onset_substeps, [(eps0, eps0)])
    while True:
        e_old, e_new = w.next_step(eps0, e_end)
        x_pred = _predict(sim, asm, bd, w, e_old, e_new, on_rod, rod_nodes, solver)
        # a long step gets a budget of Newton iterations once it has followed negative
        # curvature: one that needs more holds a change of the rods' pattern and is taken
        # again in halves (below), so the change starts from just past the strain where the
        # old pattern ends, not from wherever a long jump lands; the unstable-start rule
        # only where the step can still be halved
        long_step = rel.adaptive and (e_old - e_new) > rel.snap_resolution * de_nom * (1 + 1e-9)
        halvable = _halvable(rel, e_old, e_new, de_min)
        step_opts = opts if not long_step else (snap_opts if halvable else snap_opts_last)
        if halvable and rel.stall_curved_steps:
            step_opts = replace(step_opts, curved_limit=rel.stall_curved_steps)
        res = minimize(asm, x_pred, asm.free(x_pred), step_opts,
                       solver=solver, rng=rng, x_ref=w.x, watch=watch)
        w.count(res)
        # the solver now holds the factorization of this attempt's last Hessian: that of the
        # new equilibrium when it converged
        w.chord_ready = res.converged
        if not res.converged:
            _cut(w, res, e_old, e_new, halvable, eps0)
            continue
        w.x_prev, w.e_prev = w.x, e_old
        w.x, w.e = asm.full(res.u, x_pred), e_new
        rec = _record(sim, bd, w, res, eps0)
        if progress is not None:
            progress((eps0 - w.e) / (eps0 - e_end), rec)
        if w.e <= e_end:
            break
        w.buckled = _buckled(w.buckled, res, rec, sim)
        w.de = _next_increment(w.de, de_nom, rel.max_step_factor, w.buckled, res,
                               rel.onset_substeps)
    w.totals.update(release_steps=len(w.history) - 1, converged=True,
                    linear_solver=solver.name, final_residual=w.history[-1]["residual"])
    return w.x, w.history, w.totals


def _record(sim: Simulation, bd: Boundary, w: _Walk, res, eps0: float) -> dict:
    """The history entry of the equilibrium just reached (appended to ``w.history``)."""
    e_measured = bd.strain(w.e, w.x)
    rec = dict(step=len(w.history), release_strain=eps0 - e_measured, clamp_strain=e_measured,
               energy=res.energy, **rod_heights(sim, w.x),
               newton_iterations=res.iterations, negative_steps=res.negative_steps,
               rod_negative_steps=res.watched_steps, residual=res.residual)
    w.history.append(rec)
    return rec


def _buckled(already: bool, res, rec: dict, sim: Simulation) -> bool:
    """Buckled: a step needed negative curvature (a bifurcation), or the rods stand out of
    the plane by more than twice their thickness (an imperfect, smooth onset; the curl of
    the bilayer before buckling is a fraction of h)."""
    return (already or res.negative_steps > 0
            or any(dk > BUCKLED_DEFLECTION * sk.h for dk, sk in
                   zip(rec["rod_max_deflection"], sim.sections, strict=True)))
