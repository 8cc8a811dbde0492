r"""Closed-form predictions for rods printed on a pre-stretched fabric (docs/theory.md).

Derivation in one paragraph
---------------------------
A rod of bending stiffness :math:`E_B I_B` is bonded on a fabric (modulus ``E``, thickness ``t``)
stretched by ``eps0``. On release the fabric wants to shorten, the rod does not: it buckles.
The model assumes

* an **inextensible rod** (its arclength is the printed length),
* a **planar buckled state** (the rod stays in its vertical x-z plane),
* **identical circular segments** (the buckled rod is a chain of circular arcs of the same
  length ``l`` joined tangentially, alternating up/down),
* **zero mean transverse tension** in the fabric (no y-stress averaged over a period),
* the **fabric tensioned only under each half-wave** (it relaxes between contact points, over
  a width that sets the interaction distance ``s_hat`` between neighbouring rods).

Balancing the rod's bending energy of one arc against the fabric's stretching energy released
over that arc gives eq. (1) ``l = (24 sqrt(6) E_B I_B / (E t))**(1/3) * eps0**(-1/2)``. The
geometry of one arc follows from the chord shortening: to the model's small-angle order
``theta**2 / 24 = eps0`` (``theta = l / R`` is the angle the arc turns), i.e.
``R = l / sqrt(24 eps0)``.

Three amplitudes, do not mix them up
------------------------------------
* :func:`a` -- the **formula amplitude** (docs/theory.md),
  ``(1/(2 eps0)) ((E_B b)/(3 E t))**(1/3) h``. Algebraically it is *identical* to :func:`R`.
* :func:`sagitta` -- the **exact geometric** height of a circular arc of length ``l`` and
  radius ``R``: ``R (1 - cos(theta/2))`` with ``theta = l / R = sqrt(24 eps0)``. At eps0 = 0.5,
  ``theta = 3.46 rad`` (a bit more than a semicircle), so the sagitta is ~1.16 R.
* the **measured** amplitude ``a`` of :func:`undulate.analysis.rod_metrics`: half the
  peak-to-trough height of the simulated (or scanned) centre line.

Units: mm, MPa. All functions broadcast over numpy arrays and return floats for scalar input.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..model.config import MATERIAL_DEFAULTS
from ..model.families import FAMILIES as ALL_FAMILIES
from ..model.families import decide_family
from ..model.numerics import eq1_arc_length

__all__ = [
    "DEFAULTS",
    "FAMILIES",
    "I_B",
    "l",
    "a",
    "R",
    "sagitta",
    "s_hat",
    "h_bundled",
    "h_star_ratio",
    "h_effective",
    "n",
    "l_n",
    "single_arc",
    "phase_map",
    "predictions",
]

#: Defaults (those of the case file, docs/config.md) used by every function here: rod width
#: b [mm], rod modulus E_B [MPa], fabric modulus E [MPa], fabric thickness t [mm].
DEFAULTS: dict[str, float] = dict(MATERIAL_DEFAULTS)

#: Shape families predicted by :func:`phase_map`, in the order of their integer ``code`` (the
#: first four of :data:`undulate.model.families.FAMILIES`, same codes)
FAMILIES: tuple[str, ...] = ALL_FAMILIES[:4]


def _ret(x: NDArray[Any]) -> Any:
    """Return a Python scalar for 0-d results, the array otherwise."""
    x = np.asarray(x)
    return x.item() if x.ndim == 0 else x


#: the family rule on arrays; any n but one half-wave (also an undefined n) counts as many
_decide = np.vectorize(
    lambda n_, lam_, a_, coh_: decide_family(1 if n_ == 1 else 2, lam=float(lam_),
                                             a=float(a_), coherent=bool(coh_)),
    otypes=[object])


def _arr(x: ArrayLike) -> NDArray[np.float64]:
    return np.asarray(x, dtype=float)


def I_B(h: ArrayLike, b: ArrayLike = DEFAULTS["b"]) -> Any:
    """Second moment of area of the rod's rectangular section for out-of-plane bending [mm^4].

    ``I_B = h**3 * b / 12`` with ``h`` the thickness (out of plane) and ``b`` the width.
    """
    return _ret(_arr(h) ** 3 * _arr(b) / 12.0)


def l(  # noqa: E743 - the usual name of the arc length
    h: ArrayLike,
    eps0: ArrayLike,
    *,
    b: ArrayLike = DEFAULTS["b"],
    E_B: ArrayLike = DEFAULTS["E_B"],
    E: ArrayLike = DEFAULTS["E"],
    t: ArrayLike = DEFAULTS["t"],
) -> Any:
    """Arc length of one circular segment, eq. (1) of docs/theory.md [mm].

    ``l = (24 sqrt(6) E_B I_B / (E t))**(1/3) * eps0**(-1/2)``: linear in ``h``, proportional
    to ``(E_B b / (E t))**(1/3)`` and to ``eps0**(-1/2)`` (more pre-stretch, shorter arcs).
    Assumptions: see the module docstring (inextensible planar rod, identical circular
    segments, zero mean transverse tension, fabric tensioned only under each half-wave).
    """
    return _ret(eq1_arc_length(h, eps0, b=b, E_B=E_B, E=E, t=t))


def a(
    h: ArrayLike,
    eps0: ArrayLike,
    *,
    b: ArrayLike = DEFAULTS["b"],
    E_B: ArrayLike = DEFAULTS["E_B"],
    E: ArrayLike = DEFAULTS["E"],
    t: ArrayLike = DEFAULTS["t"],
) -> Any:
    """The **formula** amplitude (docs/theory.md) [mm].

    ``a = (1 / (2 eps0)) * ((E_B b) / (3 E t))**(1/3) * h``. It is algebraically equal to
    :func:`R` (the arc radius), not to the exact sagitta of the arc (:func:`sagitta`) nor to
    the measured half peak-to-trough height (:func:`undulate.analysis.rod_metrics`).
    """
    return _ret(
        (1.0 / (2.0 * _arr(eps0))) * np.cbrt(_arr(E_B) * _arr(b) / (3.0 * _arr(E) * _arr(t)))
        * _arr(h)
    )


def R(
    h: ArrayLike,
    eps0: ArrayLike,
    *,
    b: ArrayLike = DEFAULTS["b"],
    E_B: ArrayLike = DEFAULTS["E_B"],
    E: ArrayLike = DEFAULTS["E"],
    t: ArrayLike = DEFAULTS["t"],
) -> Any:
    """Radius of one circular segment [mm]: ``R = l / sqrt(24 eps0)``.

    From the small-angle chord shortening of an arc turning ``theta = l / R``:
    ``1 - sin(theta/2) / (theta/2) ~ theta**2 / 24 = eps0``.
    """
    return _ret(_arr(l(h, eps0, b=b, E_B=E_B, E=E, t=t)) / np.sqrt(24.0 * _arr(eps0)))


def sagitta(
    h: ArrayLike,
    eps0: ArrayLike,
    *,
    b: ArrayLike = DEFAULTS["b"],
    E_B: ArrayLike = DEFAULTS["E_B"],
    E: ArrayLike = DEFAULTS["E"],
    t: ArrayLike = DEFAULTS["t"],
) -> Any:
    """**Exact** height of a circular arc of length :func:`l` and radius :func:`R` [mm].

    ``R * (1 - cos(theta / 2))`` with ``theta = l / R = sqrt(24 eps0)``: the distance from the
    chord to the apex. Exceeds ``R`` when the arc turns more than a semicircle (eps0 > pi^2/24,
    i.e. eps0 > 0.411).
    """
    rr = _arr(R(h, eps0, b=b, E_B=E_B, E=E, t=t))
    theta = np.sqrt(24.0 * _arr(eps0))
    return _ret(rr * (1.0 - np.cos(theta / 2.0)))


def s_hat(
    h: ArrayLike,
    eps0: ArrayLike,
    *,
    b: ArrayLike = DEFAULTS["b"],
    E_B: ArrayLike = DEFAULTS["E_B"],
    E: ArrayLike = DEFAULTS["E"],
    t: ArrayLike = DEFAULTS["t"],
) -> Any:
    """Spacing over which the fabric tension relaxes between rods [mm]: ``2 a (1 + eps0)``.

    ``a`` is the formula amplitude :func:`a`; ``(1 + eps0)`` maps it to the printed (stretched)
    configuration in which the gap ``s`` is measured. For ``s > s_hat`` rods act alone.
    """
    return _ret(2.0 * _arr(a(h, eps0, b=b, E_B=E_B, E=E, t=t)) * (1.0 + _arr(eps0)))


def h_bundled(h: ArrayLike, N: ArrayLike) -> Any:
    """Thickness of one rod equivalent to ``N`` touching rods (s -> 0): ``h * N**(1/3)``.

    ``N`` rods side by side are one rod ``N b`` wide; since ``l ~ (b h**3)**(1/3)`` this is the
    same as a rod of width ``b`` and thickness ``h N**(1/3)`` in eq. (1).
    """
    return _ret(_arr(h) * np.cbrt(_arr(N)))


def h_star_ratio(N: ArrayLike) -> Any:
    """Predicted ``h*(s = 0) / h*(s large)`` = ``N**(1/3)`` (1.71 for N = 5)."""
    return _ret(np.cbrt(_arr(N)))


def h_effective(h: ArrayLike, s: ArrayLike, s_hat_: ArrayLike, N: ArrayLike) -> Any:
    """Effective single-rod thickness of one of ``N`` rods at gap ``s`` (a documented heuristic).

    Linear interpolation in ``s`` between the bundled thickness ``h N**(1/3)`` at ``s = 0`` and
    the lone-rod thickness ``h`` for ``s >= s_hat``::

        h_eff = h * (1 + (N**(1/3) - 1) * clip(1 - s / s_hat, 0, 1))
    """
    w = np.clip(1.0 - _arr(s) / _arr(s_hat_), 0.0, 1.0)
    return _ret(_arr(h) * (1.0 + (np.cbrt(_arr(N)) - 1.0) * w))


def n(
    h: ArrayLike,
    eps0: ArrayLike,
    L: ArrayLike,
    *,
    b: ArrayLike = DEFAULTS["b"],
    E_B: ArrayLike = DEFAULTS["E_B"],
    E: ArrayLike = DEFAULTS["E"],
    t: ArrayLike = DEFAULTS["t"],
) -> Any:
    """Predicted number of half-waves on a rod of length ``L``: the odd integer nearest ``L/l``.

    Computed as ``2 * round((L/l - 1) / 2) + 1``, at least 1 (numpy rounds halves to even, so
    ``L/l = 2`` gives 1 and ``L/l = 4`` gives 5). Returns ints (an int array for array input).
    """
    ratio = _arr(L) / _arr(l(h, eps0, b=b, E_B=E_B, E=E, t=t))
    odd = 2 * np.round((ratio - 1.0) / 2.0) + 1
    return _ret(np.maximum(odd, 1).astype(int))


def l_n(L: ArrayLike, n_: ArrayLike) -> Any:
    """Quantized arc length ``L / n`` [mm] when ``n`` half-waves share the rod length ``L``."""
    return _ret(_arr(L) / _arr(n_))


def single_arc(L: ArrayLike, radius: ArrayLike) -> tuple[Any, Any]:
    """Projected span and rise of ONE circular arc of length ``L`` and radius ``radius``.

    The arc turns ``theta = min(L / radius, 2 pi)``; span (chord, = ``lam`` for n = 1) is
    ``2 radius sin(theta/2)`` and rise (= ``a`` for n = 1) is ``radius (1 - cos(theta/2))``.
    ``span < 2 rise`` exactly when the arc turns more than a semicircle.
    """
    rad = _arr(radius)
    theta = np.minimum(_arr(L) / rad, 2.0 * np.pi)
    return _ret(2.0 * rad * np.sin(theta / 2.0)), _ret(rad * (1.0 - np.cos(theta / 2.0)))


def phase_map(
    h: ArrayLike,
    s: ArrayLike,
    *,
    eps0: float = 0.5,
    L: float = 100.0,
    N: int = 5,
    b: float = DEFAULTS["b"],
    E_B: float = DEFAULTS["E_B"],
    E: float = DEFAULTS["E"],
    t: float = DEFAULTS["t"],
) -> dict[str, NDArray[Any]]:
    """Predicted shape family of ``N`` parallel rods at each ``(h, s)`` point.

    ``h`` and ``s`` broadcast together (pass ``np.meshgrid(h, s)`` for a plane). The rule:

    1. ``s_hat = s_hat(h, eps0)`` (the lone rod's relaxation distance) and the effective
       thickness ``h_eff = h_effective(h, s, s_hat, N)`` (bundled ``h N**(1/3)`` at ``s = 0``,
       plain ``h`` for ``s >= s_hat``, linear in between).
    2. ``n_eff = n(h_eff, eps0, L)``. If ``n_eff > 1``: **"independent"** where ``s > s_hat``,
       **"coherent"** where ``s <= s_hat``.
    3. If ``n_eff == 1`` the rods form one half-wave of arclength ``L`` whose curvature is each
       rod's own natural curvature ``1 / R(h, eps0)`` (bundling sets how many half-waves fit, not
       how much each rod bends). With :func:`single_arc` giving ``lam`` (span) and ``a`` (rise):
       **"rolls"** if ``lam < 2 a`` (the arc turns more than a semicircle) else **"bends"**.

    The rolls/bends split of this heuristic is the lone-rod criterion ``L / R(h) > pi``; it does
    not depend on ``s`` except through whether ``n_eff == 1``, so bundling (small ``s``) makes
    rolls appear at smaller ``h``. Compare with simulated phase diagrams before trusting it.

    Returns a dict of arrays of the broadcast shape: ``h``, ``s``, ``family`` (str),
    ``code`` (index into :data:`FAMILIES`, for ``pcolormesh``), ``n`` (predicted ``n_eff``),
    ``h_eff``, ``s_hat``, ``l`` (eq. (1) at ``h_eff``), ``lam`` and ``a`` (single-arc geometry;
    meaningful where ``n == 1``).
    """
    hh, ss = np.broadcast_arrays(_arr(h), _arr(s))
    hh = hh.astype(float)
    ss = ss.astype(float)
    if np.any(hh <= 0) or np.any(ss < 0):
        raise ValueError("phase_map: h must be > 0 and s >= 0")
    mat = {"b": b, "E_B": E_B, "E": E, "t": t}
    sh = _arr(s_hat(hh, eps0, **mat))
    heff = _arr(h_effective(hh, ss, sh, N))
    n_eff = np.asarray(n(heff, eps0, L, **mat))
    lam1, a1 = single_arc(L, R(hh, eps0, **mat))
    lam1 = _arr(lam1)
    a1 = _arr(a1)
    decided = _decide(n_eff, lam1, a1, ss <= sh)  # one rule: model.families.decide_family
    code = np.asarray(np.vectorize(FAMILIES.index, otypes=[int])(decided))
    family = np.asarray(FAMILIES)[code]
    return {
        "h": hh,
        "s": ss,
        "family": family,
        "code": code.astype(int),
        "n": n_eff.astype(int),
        "h_eff": heff,
        "s_hat": sh,
        "l": _arr(l(heff, eps0, **mat)),
        "lam": lam1 * np.ones_like(hh),
        "a": a1 * np.ones_like(hh),
    }


def predictions(
    h: float,
    eps0: float,
    *,
    L: float = 100.0,
    N: int = 5,
    s: float | None = None,
    b: float = DEFAULTS["b"],
    E_B: float = DEFAULTS["E_B"],
    E: float = DEFAULTS["E"],
    t: float = DEFAULTS["t"],
) -> dict[str, float | int | str]:
    """All scalar predictions for one design, as a JSON-ready dict (used by the CLI).

    Keys: ``I_B``, ``l``, ``a_formula``, ``R``, ``sagitta``, ``s_hat``, ``n``, ``l_n``,
    ``h_bundled`` and, when ``s`` is given, the ``family`` of :func:`phase_map`.
    """
    mat = {"b": b, "E_B": E_B, "E": E, "t": t}
    n_pred = int(n(h, eps0, L, **mat))
    out: dict[str, float | int | str] = {
        "I_B": float(I_B(h, b)),
        "l": float(l(h, eps0, **mat)),
        "a_formula": float(a(h, eps0, **mat)),
        "R": float(R(h, eps0, **mat)),
        "sagitta": float(sagitta(h, eps0, **mat)),
        "s_hat": float(s_hat(h, eps0, **mat)),
        "n": n_pred,
        "l_n": float(l_n(L, n_pred)),
        "h_bundled": float(h_bundled(h, N)),
    }
    if s is not None:
        pm = phase_map(h, s, eps0=eps0, L=L, N=N, **mat)
        out["family"] = str(pm["family"].item())
    return out
