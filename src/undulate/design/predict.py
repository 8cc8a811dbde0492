"""Instant predictions for a case, from simulated results where there are some, else theory.

:func:`predict_case` answers what ``undulate run`` would give for a case file without running
it: the family and, per rod, n, l, lam, a. Its data are the atlases that ship with undulate
(:mod:`undulate.design.atlas`): the single-rod thickness sweep (one rod, L = 100 mm,
eps0 = 0.5, on the reference set-up) and the five-rod phase diagram. Inside an atlas's box
(the same N, L, eps0 and moduli; h and s within the sweep) the answer is the nearest
simulated point's, with ``confidence`` "simulated" or "near a transition" (then the other
outcomes seen around the design are listed); outside, eq. (1) and the phase map of
:mod:`undulate.theory` answer, with ``source`` "theory" and a warning saying why. Units: mm.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from .. import theory as T
from ..model.families import decide_family
from .atlas import ATLAS_FILE, Atlas, locate, shipped_atlas

__all__ = ["SINGLE_ROD_FILE", "predict_case"]

#: the single-rod atlas shipped in the package (from the single-rod-h study)
SINGLE_ROD_FILE = Path(__file__).with_name("data") / "single_rod.csv"
SOURCES = ("auto", "simulation", "theory")


def _atlases() -> list[Atlas]:
    out = []
    for path in (SINGLE_ROD_FILE, ATLAS_FILE):
        try:
            out.append(shipped_atlas(path))
        except (OSError, ValueError):
            continue
    return out


def _theory(case: Any) -> dict[str, Any]:
    r, e0 = case.rods, case.release.eps0
    mat = {"b": r.b, "E_B": r.E_B, "E": case.fabric.E, "t": case.fabric.t}
    p = T.predictions(r.h, e0, L=r.L, N=r.N, s=r.s if r.N > 1 else None, **mat)
    n = int(p["n"])
    fam = str(p.get("family") or decide_family(
        n, lam=r.L / (1 + e0), a=arch_rise(r.L, e0) if n == 1 else None))
    if r.N > 1 and fam in ("coherent", "independent"):  # bundled rods buckle as one
        pm = T.phase_map(r.h, r.s, eps0=e0, L=r.L, N=r.N, **mat)
        n = int(pm["n"].item())
    l_val = float(p["l_n"]) if n > 1 else r.L
    # each arc's chord shortened as the fabric under it: lam = 2 l / (1 + eps0) (n = 1: the
    # span L / (1 + eps0))
    lam = (2.0 if n > 1 else 1.0) * l_val / (1 + e0)
    return {"family": fam, "n": n, "l": l_val, "lam": lam,
            "a": float(p["a_formula"]) if n > 1 else arch_rise(r.L, e0)}


def arch_rise(length: float, eps0: float) -> float:
    """Rise of one circular arc of ``length`` whose chord is ``length / (1 + eps0)``: the
    single half-wave's height (the amplitude formula of eq. (1) is for many arcs)."""
    from scipy.optimize import brentq

    target = 1.0 / (1.0 + eps0)  # sin(x) / x with x half the arc's turning angle
    x = brentq(lambda x: math.sin(x) / x - target, 1e-9, math.pi - 1e-12)
    return length / (2.0 * x) * (1.0 - math.cos(x))


def predict_case(case: Any, source: str = "auto") -> dict[str, Any]:
    """Family and per-rod n, l, lam, a of a case (a :class:`undulate.model.Case`).

    ``source``: "auto" (simulated data where the case is inside an atlas, else theory),
    "simulation" (the nearest simulated point even outside, with the reason in
    ``warnings``) or "theory" (eq. (1) and the phase map). Returns a JSON-ready dict with
    ``source``, ``family``, ``confidence``, ``summary``, ``warnings`` and ``rods`` (one entry
    per rod, in the order of a run's metrics.json: by y).
    """
    if source not in SOURCES:
        raise ValueError(f"source: must be one of {', '.join(SOURCES)} (got {source!r})")
    r = case.rods
    n_rods = 1 if r.s == 0 else r.N
    warnings: list[str] = []
    if case.pattern is not None:
        warnings.append("a pattern of lines: the simulated data cover parallel straight rods "
                        "only; theory for the case's [rods] values")
        source = "theory"
    best = None
    if source != "theory":
        fixed = {"L": r.L, "eps0": case.release.eps0, "E_B": r.E_B, "E": case.fabric.E,
                 "t": case.fabric.t, "b": r.b}
        for atlas in _atlases():
            single = atlas.meta.get("N") == 1
            if single != (r.N == 1):
                continue
            s = float(atlas.points["s"].iloc[0]) if single else r.s
            loc = locate(atlas, h=r.h, s=s, N=r.N, **fixed)
            if best is None or (loc.inside and not best.inside):
                best = loc
    if best is not None and (best.inside or source == "simulation"):
        loc = best
        if not loc.inside:
            warnings.append(f"outside the simulated data ({loc.reason}): the nearest point")
        rod = {"n": loc.n, "l": loc.l, "lam": loc.lam, "a": loc.a}
        return {"source": "simulation", "family": loc.family, "confidence": loc.confidence,
                "summary": loc.summary(), "alternatives": [
                    {"family": f, "n": n} for f, n in loc.alternatives],
                "warnings": warnings,
                "rods": [{"index": k, **rod} for k in range(n_rods)]}
    if best is not None and source == "auto":
        warnings.append(f"outside the simulated data ({best.reason}): eq. (1) and the "
                        "phase map of the analytical model, which do not know the end "
                        "effects of a finite rod or the families")
    th = _theory(case)
    rod = {k: th[k] for k in ("n", "l", "lam", "a")}
    return {"source": "theory", "family": th["family"], "confidence": "theory",
            "summary": f"theory: {th['family']} n = {th['n']}", "alternatives": [],
            "warnings": warnings, "rods": [{"index": k, **rod} for k in range(n_rods)]}
