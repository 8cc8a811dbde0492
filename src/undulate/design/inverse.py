"""The analytical inverse: targets (l, lam, a, n, family) -> printable h, s, eps0.

The forward model is that of :mod:`undulate.theory`, with one relation added for the
wavelength:

* ``h_eff``: the thickness one rod of a group acts with (:func:`undulate.theory.h_effective`:
  ``h N**(1/3)`` for touching rods, ``h`` from the gap ``s_hat`` on; ``h`` for a lone rod);
* ``l = l(h_eff, eps0)`` (eq. (1)), ``n`` = the odd integer nearest ``L / l``;
* ``a = a(h_eff, eps0)`` (the amplitude formula, = the arc radius R);
* ``lam = 2 l / (1 + eps0)``: two half-waves of printed length ``l`` on fabric that shrinks
  by ``1 + eps0`` (an inextensible rod that follows the fabric under it). On the default rod
  the simulation gives lam / l = 1.43 against this 1.33 (docs/design.md);
* for ``n = 1`` the rod is one arc of length L and radius R(h): ``lam`` its span and ``a`` its
  rise (:func:`undulate.theory.single_arc`).

Unknowns: ``h`` always; ``eps0`` when a range is allowed (two targets fix it); the gap ``s``
of a group of rods from the wanted family (coherent: half of s_hat, the middle of the band
where the model has the rods coupled; independent: 1.5 s_hat) unless it is given. The
thickness found is rounded to the printer's step and the metrics are given again for the
rounded value, with how far they move for the printer's thickness tolerance.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
from scipy.optimize import brentq

from .. import theory as th
from ..model.config import MATERIAL_DEFAULTS, number_problem

__all__ = ["TARGET_KEYS", "Constraints", "Design", "DesignError", "forward", "inverse",
           "parse_targets"]

#: the metrics a target may name, and what each is
TARGET_KEYS: dict[str, str] = {
    "l": "arc length of one half-wave [mm]",
    "lam": "wavelength, projected length of two half-waves [mm]",
    "a": "amplitude [mm]",
    "n": "number of half-waves over the line length L (odd)",
}
#: the families a design may ask of a group of rods
WANTED_FAMILIES = ("coherent", "independent")
#: where the gap is put for a wanted family, as a fraction of s_hat
COHERENT_GAP = 0.5
INDEPENDENT_GAP = 1.5
#: points of the scan of the allowed eps0 range that brackets the second target
EPS0_SCAN = 64


class DesignError(ValueError):
    """A design request is invalid or has no solution (the message names the field)."""


@dataclass(frozen=True)
class Constraints:
    """What can be printed and stretched. Units: mm."""

    L: float = 100.0
    N: int = 1
    b: float = MATERIAL_DEFAULTS["b"]
    h_min: float = 0.08
    h_max: float = 2.0
    h_step: float = 0.02
    h_tol: float = 0.02
    eps0: float = 0.5
    eps0_min: float | None = None
    eps0_max: float | None = None
    s: float | None = None
    s_min: float = 0.0
    s_max: float = 50.0
    family: str | None = None
    E_B: float = MATERIAL_DEFAULTS["E_B"]
    E: float = MATERIAL_DEFAULTS["E"]
    t: float = MATERIAL_DEFAULTS["t"]

    def check(self) -> None:
        """Raise DesignError naming the first invalid field."""
        pos = {"L": self.L, "b": self.b, "h_min": self.h_min, "h_max": self.h_max,
               "h_step": self.h_step, "eps0": self.eps0, "E_B": self.E_B, "E": self.E,
               "t": self.t}
        for k, v in pos.items():
            if (msg := number_problem(k, v)) is not None:
                raise DesignError(msg)
        if self.h_tol < 0:
            raise DesignError(f"h_tol: must be >= 0 (got {self.h_tol!r})")
        if self.h_max < self.h_min:
            raise DesignError(f"h_max: must be >= h_min = {self.h_min:g} (got {self.h_max:g})")
        if not (isinstance(self.N, int) and 1 <= self.N <= 1000):
            raise DesignError(f"N: must be a whole number from 1 to 1000 (got {self.N!r})")
        if self.eps0 > 3.0:
            raise DesignError(f"eps0: must be <= 3 (got {self.eps0:g})")
        lo, hi = self.eps0_min, self.eps0_max
        if (lo is None) != (hi is None):
            raise DesignError("eps0_min, eps0_max: give both (an allowed range) or neither")
        if lo is not None and hi is not None and not (0 < lo < hi <= 3.0):
            raise DesignError(f"eps0_min, eps0_max: need 0 < eps0_min < eps0_max <= 3 "
                              f"(got {lo:g}, {hi:g})")
        if not (0 <= self.s_min <= self.s_max):
            raise DesignError(f"s_min, s_max: need 0 <= s_min <= s_max (got {self.s_min:g}, "
                              f"{self.s_max:g})")
        if self.s is not None and self.s < 0:
            raise DesignError(f"s: must be >= 0 (got {self.s:g})")
        if self.family is not None and self.family not in WANTED_FAMILIES:
            raise DesignError(f"family: must be one of {', '.join(WANTED_FAMILIES)} (got "
                              f"{self.family!r})")
        if self.family is not None and self.N < 2:
            raise DesignError("family: needs N >= 2 rods (a lone rod has no neighbour)")


@dataclass
class Design:
    """A printable design and what the model predicts for it."""

    h: float
    h_exact: float
    s: float | None
    eps0: float
    b: float
    L: float
    N: int
    targets: dict[str, float | str]
    predicted: dict[str, Any]
    predicted_exact: dict[str, Any]
    sensitivity: dict[str, dict[str, float]]
    notes: list[str] = field(default_factory=list)
    model: str = "analytical (undulate.theory)"
    h_step: float = 0.02

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready."""
        return asdict(self)


def parse_targets(items: list[str]) -> dict[str, float]:
    """``["l=20", "n=5"]`` -> ``{"l": 20.0, "n": 5.0}``; one clear DesignError per bad item."""
    out: dict[str, float] = {}
    for item in items:
        key, sep, val = item.partition("=")
        key = key.strip()
        if not sep:
            raise DesignError(f"--target {item!r}: write KEY=VALUE, e.g. l=20")
        if key not in TARGET_KEYS:
            raise DesignError(f"--target {item!r}: unknown key {key!r}; valid keys: "
                              f"{', '.join(TARGET_KEYS)}")
        try:
            v = float(val)
        except ValueError:
            raise DesignError(f"--target {item!r}: {key} must be a number") from None
        if not (math.isfinite(v) and v > 0):
            raise DesignError(f"--target {item!r}: {key} must be > 0")
        if key in out:
            raise DesignError(f"--target {item!r}: {key} is given twice")
        out[key] = v
    return out


def _gap(h: float, eps0: float, c: Constraints) -> float | None:
    if c.N < 2:
        return None
    if c.s is not None:
        return c.s
    sh = float(th.s_hat(h, eps0, b=c.b, E_B=c.E_B, E=c.E, t=c.t))
    frac = INDEPENDENT_GAP if c.family == "independent" else COHERENT_GAP
    return frac * sh


def forward(h: float, eps0: float, c: Constraints, s: float | None = None) -> dict[str, Any]:
    """The model's metrics for thickness ``h`` and pre-stretch ``eps0`` under ``c`` (the gap
    from the wanted family unless ``s`` is given)."""
    mat = {"b": c.b, "E_B": c.E_B, "E": c.E, "t": c.t}
    s = _gap(h, eps0, c) if s is None else s
    sh = float(th.s_hat(h, eps0, **mat))
    h_eff = h if c.N < 2 or s is None else float(th.h_effective(h, s, sh, c.N))
    l_ = float(th.l(h_eff, eps0, **mat))
    n_ = int(th.n(h_eff, eps0, c.L, **mat))
    if n_ == 1:
        lam, a_ = (float(v) for v in th.single_arc(c.L, th.R(h, eps0, **mat)))
        family = "rolls" if lam < 2.0 * a_ else "bends"
    else:
        lam = 2.0 * l_ / (1.0 + eps0)
        a_ = float(th.a(h_eff, eps0, **mat))
        family = ("independent" if s is not None and s > sh else "coherent") if c.N > 1 \
            else "waves"
    return {"l": l_, "lam": lam, "a": a_, "R": float(th.R(h_eff, eps0, **mat)), "n": n_,
            "l_n": c.L / n_, "family": family, "s": s, "s_hat": sh, "h_eff": h_eff}


def _size_target(targets: dict[str, float], c: Constraints, eps0: float) -> tuple[str, float]:
    """The target that sets the scale, as (metric, value): n becomes l = L / n."""
    if "n" in targets:
        return "l", c.L / targets["n"]
    for k in ("l", "lam", "a"):
        if k in targets:
            return k, targets[k]
    raise AssertionError("no size target")


def _solve_h(metric: str, value: float, eps0: float, c: Constraints) -> float:
    def f(h: float) -> float:
        return _metric_for_inverse(metric, h, eps0, c) - value

    lo, hi = f(c.h_min), f(c.h_max)
    if lo * hi > 0:
        m_lo = _metric_for_inverse(metric, c.h_min, eps0, c)
        m_hi = _metric_for_inverse(metric, c.h_max, eps0, c)
        raise DesignError(
            f"target {metric} = {value:g}: out of reach for h in [{c.h_min:g}, {c.h_max:g}] mm "
            f"at eps0 = {eps0:.4g} (the model gives {metric} = {m_lo:.4g} .. {m_hi:.4g})")
    if lo == 0:
        return c.h_min
    if hi == 0:
        return c.h_max
    return float(brentq(f, c.h_min, c.h_max, xtol=1e-12, rtol=1e-12))


def _metric_for_inverse(metric: str, h: float, eps0: float, c: Constraints) -> float:
    """The wave branch of the model (no n = 1 switch): what the continuous inverse solves."""
    m = forward(h, eps0, c)
    if metric == "l":
        return m["l"]
    if metric == "lam":
        return 2.0 * m["l"] / (1.0 + eps0)
    return float(th.a(m["h_eff"], eps0, b=c.b, E_B=c.E_B, E=c.E, t=c.t))


def inverse(targets: dict[str, float], constraints: Constraints | None = None, *,
            family: str | None = None) -> Design:
    """Printable parameters that give ``targets`` (keys of :data:`TARGET_KEYS`).

    One size target (l, lam, a or n) with a fixed eps0 sets h. Two size targets need an eps0
    range (``eps0_min``/``eps0_max``): the second sets eps0. ``n`` is met at the middle of its
    plateau, l = L / n. Raises :class:`DesignError` (one line naming the field) for bad input
    or a target out of reach.
    """
    c = constraints or Constraints()
    if family is not None:
        c = Constraints(**{**asdict(c), "family": family})
    c.check()
    bad = set(targets) - set(TARGET_KEYS)
    if bad:
        raise DesignError(f"targets: unknown {', '.join(sorted(bad))}; valid keys: "
                          f"{', '.join(TARGET_KEYS)}")
    if not targets:
        raise DesignError(f"targets: give at least one of {', '.join(TARGET_KEYS)}")
    if "n" in targets:
        nv = targets["n"]
        if nv != int(nv) or int(nv) % 2 == 0:
            raise DesignError(f"target n = {nv:g}: must be an odd whole number (the model's "
                              "rods buckle into an odd number of half-waves)")
    free_eps = c.eps0_min is not None and c.eps0_max is not None
    if len(targets) > 2:
        raise DesignError(f"targets: at most two of {', '.join(TARGET_KEYS)} (the model has "
                          "two unknowns, h and eps0); got " + ", ".join(targets))
    if len(targets) == 2 and not free_eps:
        raise DesignError("targets: two targets need eps0 free: give an allowed range "
                          "(--eps0-min and --eps0-max)")
    if len(targets) == 2 and set(targets) == {"l", "n"}:
        raise DesignError("targets: l and n both set the arc length (n means l = L / n); "
                          "give one of them with lam or a")
    notes: list[str] = []
    if len(targets) == 1 and free_eps:
        eps0 = c.eps0
        if not (c.eps0_min <= eps0 <= c.eps0_max):  # type: ignore[operator]
            eps0 = 0.5 * (c.eps0_min + c.eps0_max)  # type: ignore[operator]
        notes.append(f"one target: eps0 kept at {eps0:g} (an eps0 range is used only with "
                     "two targets)")
    elif len(targets) == 1:
        eps0 = c.eps0
    else:
        eps0 = _solve_eps0(targets, c)
    metric, value = _size_target(targets, c, eps0)
    h_exact = _solve_h(metric, value, eps0, c)
    h = min(max(round(h_exact / c.h_step) * c.h_step, c.h_min), c.h_max)
    h = float(f"{h:.10g}")
    if abs(h - h_exact) > 1e-12:
        notes.append(f"h rounded to the printer's step {c.h_step:g} mm: {h_exact:.4g} -> {h:g}")
    pred_exact = forward(h_exact, eps0, c)
    pred = forward(h, eps0, c)
    if "n" in targets and pred["n"] != int(targets["n"]):
        notes.append(f"after rounding h the model gives n = {pred['n']}, not "
                     f"{int(targets['n'])}: choose a finer h_step")
    if pred["n"] == 1:
        notes.append("n = 1: the rod is one arc over its whole length; l, lam and a are those "
                     "of that arc, not of eq. (1)")
    if c.N > 1 and c.s is None and not (c.s_min <= pred["s"] <= c.s_max):
        raise DesignError(f"family {c.family or 'coherent'}: the gap it needs, s = "
                          f"{pred['s']:.4g} mm, is outside [s_min, s_max] = [{c.s_min:g}, "
                          f"{c.s_max:g}]")
    sens = _sensitivity(h, eps0, c)
    return Design(h=h, h_exact=h_exact, s=pred["s"], eps0=eps0, b=c.b, L=c.L, N=c.N,
                  targets={**targets, **({"family": c.family} if c.family else {})},
                  predicted=pred, predicted_exact=pred_exact, sensitivity=sens, notes=notes,
                  h_step=c.h_step)


def _solve_eps0(targets: dict[str, float], c: Constraints) -> float:
    keys = list(targets)
    first = "n" if "n" in keys else ("l" if "l" in keys else keys[0])
    second = next(k for k in keys if k != first)
    sub = {first: targets[first]}

    def resid(e: float) -> float:
        m, v = _size_target(sub, c, e)
        h = _solve_h(m, v, e, c)
        return _metric_for_inverse(second, h, e, c) / targets[second] - 1.0

    lo_e, hi_e = float(c.eps0_min), float(c.eps0_max)  # type: ignore[arg-type]
    # the first target can be out of reach (h range) over part of the eps0 range: scan it,
    # keep where it is reachable, and bracket a sign change of the second target's residual
    grid = np.geomspace(lo_e, hi_e, EPS0_SCAN)
    vals: list[tuple[float, float]] = []
    for e in grid:
        try:
            vals.append((float(e), resid(float(e))))
        except DesignError:
            continue
    if not vals:
        raise DesignError(f"target {first} = {targets[first]:g}: out of reach for h in "
                          f"[{c.h_min:g}, {c.h_max:g}] mm at every eps0 in [{lo_e:g}, {hi_e:g}]")
    for (e0, r0), (e1, r1) in zip(vals, vals[1:], strict=False):
        if r0 == 0.0:
            return e0
        if r0 * r1 < 0:
            return float(brentq(resid, e0, e1, xtol=1e-13, rtol=1e-13))
    if vals[-1][1] == 0.0:
        return vals[-1][0]
    span = [targets[second] * (1 + r) for _, r in vals]
    raise DesignError(f"targets {first} = {targets[first]:g} and {second} = "
                      f"{targets[second]:g}: no eps0 in [{lo_e:g}, {hi_e:g}] gives both "
                      f"({second} would be {min(span):.4g} .. {max(span):.4g})")


def _sensitivity(h: float, eps0: float, c: Constraints) -> dict[str, dict[str, float]]:
    """Each metric at h - h_tol and h + h_tol (within the printable range)."""
    lo = max(h - c.h_tol, 1e-6)
    hi = h + c.h_tol
    m_lo, m_hi = forward(lo, eps0, c), forward(hi, eps0, c)
    return {k: {"h_minus_tol": float(m_lo[k]), "h_plus_tol": float(m_hi[k])}
            for k in ("l", "lam", "a", "n")}
