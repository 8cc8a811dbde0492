"""What the Newton minimiser takes and gives: its options, its result, and the error a
release raises when no stable equilibrium is found."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["ConvergenceError", "NewtonOptions", "NewtonResult"]


class ConvergenceError(RuntimeError):
    """The solver did not reach a stable equilibrium. ``step`` and ``residual`` say where."""

    def __init__(self, message: str, *, step: int | None = None,
                 residual: float | None = None, release_strain: float | None = None) -> None:
        super().__init__(message)
        self.step = step
        self.residual = residual
        self.release_strain = release_strain


@dataclass
class NewtonOptions:
    rtol: float = 1e-6
    force_scale: float = 1.0
    max_iter: int = 300
    negative_curvature: bool = True
    require_stable: bool = True
    linear_solver: str = "auto"
    #: an equilibrium counts as stable when the lowest eigenvalue of (H, |diag H|) is above
    #: -marginal (a relative curvature; -1e-7 means 1e-7 of each unknown's own stiffness)
    marginal: float = 1e-7
    #: mixed Newton: carry the stresses of the strain-form (stiff rod) groups as unknowns of
    #: the iteration instead of recomputing them from the displacements
    mixed: bool = True
    #: Newton steps (positive definite Hessian) are accepted against the highest energy of
    #: the last ``nonmonotone`` iterates (0: monotone Armijo)
    nonmonotone: int = 5
    #: how many of the lowest negative-curvature modes one curved step follows at most
    modes: int = 1
    #: with ``mixed``, line searches judge a step by the mixed merit (:meth:`Assembly.merit`:
    #: the second-order stretch of stiff rods along a straight step is not charged to it)
    #: instead of the energy, as long as the energy itself stays below the highest recent one
    #: plus ``merit_energy_cap`` times its size
    mixed_merit: bool = True
    merit_energy_cap: float = 0.1
    #: give up (not converged) after this many iterations once a step along negative curvature
    #: of the ``watch`` unknowns has been taken (0: never): the release loop's budget for a
    #: grown step in which the rods' pattern changes (``release.snap_iterations``)
    curved_budget: int = 0
    #: give up (not converged, ``NewtonResult.stalled``) once this many curved steps along
    #: the ``watch`` unknowns have been taken (0: never): the release loop's limit for a step
    #: that can still be halved (``release.stall_curved_steps``)
    curved_limit: int = 0
    #: give up at once (``NewtonResult.unstable_start``) when the start's Hessian is not
    #: positive definite:
    #: the release loop's rule for a grown step (``release.GROWN_STEP_DEFINITE_START``)
    definite_start: bool = False


@dataclass
class NewtonResult:
    u: np.ndarray
    converged: bool
    iterations: int
    residual: float
    energy: float
    n_negative: int
    negative_steps: int = 0
    times: dict = field(default_factory=dict)
    message: str = ""
    #: per iteration: (max|g|, negative pivots, kind of step, step length, energy, share of a
    #: curved step's direction on the ``watch`` unknowns (nan otherwise))
    trace: list = field(default_factory=list)
    #: curved steps with at least WATCH_SHARE of their direction on the ``watch`` unknowns
    watched_steps: int = 0
    #: stopped by ``opts.curved_budget`` (a change of pattern), not by max_iter or a failure
    over_budget: bool = False
    #: stopped at once by ``opts.definite_start`` (the start's Hessian is not positive definite)
    unstable_start: bool = False
    #: stopped by ``opts.curved_limit`` (the rods wander from one negative curvature to the
    #: next without settling)
    stalled: bool = False
