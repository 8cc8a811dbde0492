"""Solve stage: Newton minimisation past bifurcations, quasi-static release, inertial release."""

from .linear import LDLSolver, LUSolver, make_solver
from .newton import ConvergenceError, NewtonOptions, NewtonResult, minimize

__all__ = [
    "ConvergenceError",
    "LDLSolver",
    "LUSolver",
    "NewtonOptions",
    "NewtonResult",
    "make_solver",
    "minimize",
]
