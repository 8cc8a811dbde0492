"""Inverse design: what to print (h, s, eps0, b, line length) to get a wanted wave.

:func:`inverse` inverts the closed-form model of :mod:`undulate.theory` (eq. (1), the
amplitude formula, the odd-n rule, s_hat and bundling) under printing constraints;
:func:`refine` corrects the thickness with a few simulations. See docs/design.md.
"""

from .inverse import TARGET_KEYS, Constraints, Design, DesignError, inverse, parse_targets
from .refine import Refined, refine

__all__ = ["TARGET_KEYS", "Constraints", "Design", "DesignError", "Refined", "inverse",
           "parse_targets", "refine"]
