"""The rods' collective state after the release: its names and the one rule that decides it.

A **family** is what a run of rods (or a theory's prediction of one) looks like as a whole:

* ``"flat"``: no rod left its printed level;
* ``"rolls"`` / ``"bends"``: the rods form one half-wave each (n = 1), an arc that turns more
  than a semicircle (``lam < 2 a``: it rolls over) or less;
* ``"waves"``: a lone rod (or rods whose neighbours cannot be compared) with n >= 2;
* ``"coherent"`` / ``"independent"``: several rods with n >= 2 whose neighbours move in step
  or not.

The analysis (:func:`undulate.analysis.classify`, from measured centre lines) and the theory
(:func:`undulate.theory.phase_map`, from eq. (1) and the relaxation distance) both decide it
through :func:`decide_family`, so the word means one thing everywhere.
"""

from __future__ import annotations

__all__ = ["COHERENT_THRESHOLD", "FAMILIES", "decide_family", "one_arc_family"]

FAMILIES: tuple[str, ...] = ("coherent", "independent", "rolls", "bends", "waves", "flat")
"""Every family, in the order of the integer codes of phase maps."""

COHERENT_THRESHOLD = 0.5
"""Rods are "coherent" when the median coherence of neighbouring pairs is at least this."""


def one_arc_family(lam: float, a: float) -> str:
    """``"rolls"`` for one half-wave of span ``lam`` and rise ``a`` with ``lam < 2 a`` (its
    arc turns more than a semicircle), else ``"bends"``."""
    return "rolls" if float(lam) < 2.0 * float(a) else "bends"


def decide_family(n: int, *, lam: float | None = None, a: float | None = None,
                  coherent: bool | None = None) -> str:
    """The family of rods whose representative half-wave count is ``n``.

    ``n``: 0 for flat rods, 1 when (at least half of the buckled) rods form one half-wave,
    else their count of half-waves. ``lam``, ``a``: span and rise of that one half-wave
    (needed when ``n == 1``). ``coherent``: whether neighbouring rods move in step (None for
    a lone rod, or when no neighbours can be compared).
    """
    if n <= 0:
        return "flat"
    if n == 1:
        if lam is None or a is None:
            raise ValueError("decide_family: one half-wave needs its span lam and rise a")
        return one_arc_family(lam, a)
    if coherent is None:
        return "waves"
    return "coherent" if coherent else "independent"
