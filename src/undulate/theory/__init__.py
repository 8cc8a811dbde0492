"""Analytical model of rods buckled on a released pre-stretched fabric (docs/theory.md).

Everything here is closed-form and vectorised over numpy arrays (scalars in, floats out).
See :mod:`undulate.theory.model` for the formulas and their assumptions, and ``docs/theory.md``.
"""

from .model import (
    DEFAULTS,
    FAMILIES,
    I_B,
    R,
    a,
    h_bundled,
    h_effective,
    h_star_ratio,
    l,
    l_n,
    n,
    phase_map,
    predictions,
    s_hat,
    sagitta,
    single_arc,
)

__all__ = [
    "DEFAULTS",
    "FAMILIES",
    "I_B",
    "R",
    "a",
    "h_bundled",
    "h_effective",
    "h_star_ratio",
    "l",
    "l_n",
    "n",
    "phase_map",
    "predictions",
    "s_hat",
    "sagitta",
    "single_arc",
]
