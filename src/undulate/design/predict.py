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

import functools
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .. import theory as T
from ..model.families import decide_family
from .atlas import _REL_TOL, ATLAS_FILE, Atlas, Location, locate, shipped_atlas
from .scaling import equivalent, load_scaling
from .waves import GROUP_GAP, N_MIN, WavesFit, load_waves, waves_n

__all__ = ["SINGLE_ROD_FILE", "Placement", "atlas_distance", "atlas_named", "place",
           "predict_case", "scaled_location"]

#: the single-rod atlas shipped in the package (from the single-rod-h study)
SINGLE_ROD_FILE = Path(__file__).with_name("data") / "single_rod.csv"
SOURCES = ("auto", "simulation", "theory")


def _atlases() -> list[tuple[str, Atlas]]:
    """The shipped atlases with their names (the file's path in the data folder, without
    ``.csv``): the single-rod sweep, the five-rod diagram, then every further atlas CSV in
    the data folder and its sub-folders (the diagram at another rod length, single rods over
    L and eps0). The folder is listed once per process."""
    return list(_atlases_of(SINGLE_ROD_FILE, ATLAS_FILE))


@functools.cache
def _atlases_of(single: Path, diagram: Path) -> tuple[tuple[str, Atlas], ...]:
    data = single.parent
    more = sorted(p for p in data.rglob("*.csv") if p not in (single, diagram))
    out = []
    for path in (single, diagram, *more):
        try:
            out.append((path.relative_to(data).with_suffix("").as_posix(), shipped_atlas(path)))
        except (OSError, ValueError):
            continue
    return tuple(out)


def atlas_named(name: str) -> Atlas:
    """A shipped atlas by its name (as in :class:`Placement`); KeyError lists the names."""
    found = dict(_atlases())
    if name not in found:
        raise KeyError(f"atlas: no shipped atlas {name!r} (there are: {', '.join(found)})")
    return found[name]


@dataclass(frozen=True)
class Placement:
    """A design placed on one shipped atlas: where it sits (``loc``), the atlas's ``name``,
    and, when it was carried there by the scaling, ``scaled`` (h', s', the length factor, p,
    the atlas's L and eps0)."""

    name: str
    atlas: Atlas
    loc: Location
    scaled: dict[str, Any] | None = None

    @property
    def confidence(self) -> str:
        """The location's confidence; "scaled" for a scaled one whose neighbours agree."""
        c = self.loc.confidence
        return "scaled" if self.scaled is not None and c == "simulated" else c

    def summary(self) -> str:
        """The location's summary line, saying where a scaled design was carried from."""
        sc = self.scaled
        if sc is None:
            return self.loc.summary()
        where = f"h' = {sc['h']:.3g} mm" + (f", s' = {sc['s']:.3g} mm" if sc["s"] is not None
                                             else "")
        return (f"scaled from the simulated L = {sc['L']:g} mm, eps0 = {sc['eps0']:g} "
                f"({where}): {self.loc.summary()}")


def atlas_distance(L: float, eps0: float, meta: dict[str, Any]) -> float:
    """How far the scaling carries a case at (L, eps0) to an atlas simulated at its L and
    eps0: the distance in (log L, p log eps0), p the scaling's exponent of eps0 (the number
    of half-waves on a rod goes as L eps0^p, so a factor 2 in eps0 moves it as a factor
    2^p in L does)."""
    p = load_scaling().p
    return math.hypot(math.log(L / float(meta["L"])), p * math.log(eps0 / float(meta["eps0"])))


def place(*, h: float, s: float, N: int, L: float, eps0: float,
          atlases: list[tuple[str, Atlas]] | None = None,
          **moduli: float) -> tuple[Placement | None, Placement | None]:
    """A design on the atlases of its kind (one rod or several): (the best direct
    placement: inside an atlas if one holds it, else the nearest point of the first;
    the design carried by the scaling onto the atlas simulated nearest its (L, eps0) in
    the sense of :func:`atlas_distance`, or None). ``atlases``: (name, atlas) pairs,
    default the shipped ones; ``moduli``: E_B, E, t, b, which must be an atlas's."""
    best: Placement | None = None
    scaled: list[tuple[float, Placement]] = []
    for name, atlas in _atlases() if atlases is None else atlases:
        single = atlas.meta.get("N") == 1
        if _bundle_of(atlas, N, moduli.get("b")):
            s_at = 0.0  # one rod as wide as the atlas's N rods: their s = 0 column
        elif single != (N == 1):
            continue
        else:
            s_at = float(atlas.points["s"].iloc[0]) if single else s
        loc = locate(atlas, h=h, s=s_at, N=N, L=L, eps0=eps0, **moduli)
        if best is None or (loc.inside and not best.loc.inside):
            best = Placement(name, atlas, loc)
        carried = None if loc.inside else scaled_location(atlas, h, s_at, L, eps0, single,
                                                           N=N, **moduli)
        if carried is not None:
            scaled.append((atlas_distance(L, eps0, atlas.meta),
                           Placement(name, atlas, *carried)))
    return best, (min(scaled, key=lambda c: c[0])[1] if scaled else None)


def _bundle_of(atlas: Atlas, N: int, b: float | None) -> bool:
    """Whether one rod of width ``b`` is the N rods of a several-rod atlas printed with no
    gap (s = 0: they act as one rod N times as wide), which that atlas simulated."""
    m = atlas.meta
    if N != 1 or b is None or int(m.get("N", 1)) < 2 or "b" not in m:
        return False
    wide = int(m["N"]) * float(m["b"])
    return (abs(b - wide) <= 0.02 * wide
            and bool(np.isclose(atlas.points["s"], 0.0, rtol=0.0, atol=1e-9).any()))


def _theory(case: Any) -> dict[str, Any]:
    r, e0 = case.rods, case.release.eps0
    mat = {"b": r.b, "E_B": r.E_B, "E": case.fabric.E, "t": case.fabric.t}
    p = T.predictions(r.h, e0, L=r.L, N=r.N, s=r.s if r.N > 1 else None, **mat)
    n = int(p["n"])
    fam = str(p.get("family") or decide_family(
        n, lam=r.L / (1 + e0), a=arch_rise(r.L, e0) if n == 1 else None))
    if r.N > 1:  # the group's n (bundled rods buckle as one), the n its family is of
        pm = T.phase_map(r.h, r.s, eps0=e0, L=r.L, N=r.N, **mat)
        n = int(pm["n"].item())
    l_val = r.L / n
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


def predict_case(case: Any, source: str = "auto",
                 atlases: list[tuple[str, Atlas]] | None = None,
                 waves: WavesFit | None = None) -> dict[str, Any]:
    """Family and per-rod n, l, lam, a of a case (a :class:`undulate.model.Case`).

    ``source``: "auto" (simulated data where the case is inside an atlas, or carried there
    by the scaling of :mod:`undulate.design.scaling` when only L and eps0 differ; else
    theory), "simulation" (the nearest simulated point even outside, with the reason in
    ``warnings``) or "theory" (eq. (1) and the phase map). Returns a JSON-ready dict with
    ``source``, ``family``, ``confidence`` ("simulated", "scaled", "near a transition",
    "fitted", "lone rods", "outside" or "theory"), ``summary``, ``warnings`` and ``rods``
    (one entry per rod, in the order of a run's metrics.json: by y); a scaled answer also
    has ``scaled`` (the equivalent h and s on the atlas, the length factor and the
    exponent). A simulated answer of many half-waves (>= 5, lone rods or groups >= 5 mm
    apart) takes its n from the fit over all simulated rods (:mod:`undulate.design.waves`)
    where that differs from the atlas's point: ``confidence`` "fitted". ``atlases``: (name,
    atlas) pairs to answer from instead of the shipped ones; ``waves``: that fit instead of
    the shipped one (both for a cross-check).
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
    mat = {"E_B": r.E_B, "E": case.fabric.E, "t": case.fabric.t, "b": r.b}
    best, scaled = (place(h=r.h, s=r.s, N=r.N, L=r.L, eps0=case.release.eps0,
                          atlases=atlases, **mat)
                    if source != "theory" else (None, None))
    if best is not None and (best.loc.inside or source == "simulation"):
        if not best.loc.inside:
            warnings.append(f"outside the simulated data ({best.loc.reason}): the nearest "
                            "point")
        return _many_waves(_simulated(best, warnings, n_rods), case, waves)
    if scaled is not None:
        return _many_waves(_scaled_answer(scaled, case, warnings, n_rods), case, waves)
    if source == "auto" and best is not None and r.N > 1 and r.s >= LONE_ROD_GAP:
        lone = _lone_rod_answer(case, atlases, warnings, n_rods, best.loc.reason)
        if lone is not None:
            return _many_waves(lone, case, waves)
    if best is not None and source == "auto":
        warnings.append(f"outside the simulated data ({best.loc.reason}): eq. (1) and the "
                        "phase map of the analytical model, which do not know the end "
                        "effects of a finite rod or the families")
    th = _theory(case)
    rod = {k: th[k] for k in ("n", "l", "lam", "a")}
    return {"source": "theory", "family": th["family"], "confidence": "theory",
            "summary": f"theory: {th['family']} n = {th['n']}", "alternatives": [],
            "warnings": warnings, "rods": [{"index": k, **rod} for k in range(n_rods)]}


#: the gap [mm] from which the rods of a group have a lone rod's n: on the simulated five-rod
#: diagrams (L = 50, 75, 100 mm) rods of h <= 0.3 mm at s >= 5 mm had the n that predict
#: gives one rod of the same h, L, eps0 in 100 of 146 runs (most others have two more); at
#: s = 2.5 mm they share fewer, longer waves (docs/design.md, "Groups beyond the diagrams")
LONE_ROD_GAP = GROUP_GAP  # one threshold: the many-half-waves fit takes groups from it too


def _lone_rod_answer(case: Any, atlases: list[tuple[str, Atlas]] | None,
                     warnings: list[str], n_rods: int, reason: str) -> dict[str, Any] | None:
    """A group of rods that no several-rod atlas holds, even scaled: each rod's n, l, lam, a
    from the simulated lone rods of the same h, L and eps0; the family of one arch from them,
    of several half-waves from :func:`_thin_group_family`; None where no lone-rod atlas
    holds it."""
    r, e0 = case.rods, case.release.eps0
    mat = {"E_B": r.E_B, "E": case.fabric.E, "t": case.fabric.t, "b": r.b}
    best, scaled = place(h=r.h, s=0.0, N=1, L=r.L, eps0=e0, atlases=atlases, **mat)
    pl = best if best is not None and best.loc.inside else scaled
    if pl is None:
        return None
    lone = (_simulated(pl, [], 1) if pl.scaled is None
            else _scaled_answer(pl, case, [], 1))
    rod = lone["rods"][0]
    if rod["n"] == 1:  # bends or rolls, as the lone rod
        family, said = lone["family"], ""
    else:
        family, said = _thin_group_family(case, atlases, **mat)
    warnings.append(f"outside the simulated groups of rods ({reason}): each rod's n, l, lam, "
                    f"a are those of a lone rod ({lone['summary']}), which rods {r.s:g} mm "
                    "apart mostly share" + said)
    return {"source": "simulation", "atlas": pl.name, "family": family,
            "confidence": "lone rods",
            "summary": f"as lone rods: {family} n = {rod['n']} (rods from {lone['summary']})",
            "alternatives": list(lone["alternatives"]), "warnings": warnings,
            "rods": [{"index": k, **{q: rod[q] for q in ("n", "l", "lam", "a")}}
                     for k in range(n_rods)]}


def _thin_group_family(case: Any, atlases: list[tuple[str, Atlas]] | None,
                       **mat: float) -> tuple[str, str]:
    """(family, what the warning says of it) of a group of rods thinner than every group
    diagram holds: the family most runs of the thinnest simulated rods (with several
    half-waves, s > 0) have on the group diagram nearest in (L, eps0) (coherent or
    independent at these rods scatters from gap to gap); else the analytical phase map's."""
    r, e0 = case.rods, case.release.eps0
    near = [(atlas_distance(r.L, e0, a.meta), name, a)
            for name, a in (_atlases() if atlases is None else atlases)
            if int(a.meta.get("N", 1)) == r.N and all(
                k not in a.meta or abs(float(a.meta[k]) - v) <= _REL_TOL * abs(v)
                for k, v in mat.items())]
    for _, name, a in sorted(near, key=lambda t: t[0]):
        pts, h_min = a.points, float(a.points["h"].min())
        row = pts[np.isclose(pts["h"], h_min) & (pts["s"] > 0) & (pts["n"] > 1)]
        if not row.empty:
            counts = row["family"].value_counts()
            fam = str(counts.index[0])
            return fam, (f"; the family {fam} is what {counts.iloc[0]} of the {len(row)} "
                         f"groups of the thinnest simulated rods of {name} (h = {h_min:g} "
                         "mm) have")
    fam = _theory(case)["family"]
    return fam, f"; the family {fam} is the analytical phase map's"


def scaled_location(atlas: Atlas, h: float, s: float, L: float, eps0: float, single: bool,
                    **fixed: float) -> tuple[Location, dict[str, Any]] | None:
    """A design read off ``atlas`` at the thickness (and gap) with the same scaling variable
    (:func:`undulate.design.scaling.equivalent`): (its location there, and ``scaled``: h', s',
    the length factor, p, the atlas's L and eps0); None if that is outside the atlas too.
    ``fixed``: N and the moduli, which must be the atlas's."""
    m = atlas.meta
    if "L" not in m or "eps0" not in m:
        return None
    sc = load_scaling()
    h_eq, k = equivalent(h, L, eps0, L_ref=float(m["L"]), eps0_ref=float(m["eps0"]), p=sc.p,
                         c0=sc.c0, c1=sc.c1)
    if not math.isfinite(h_eq):
        return None
    s_eq = s if single else s / k
    loc = locate(atlas, h=h_eq, s=s_eq, L=float(m["L"]), eps0=float(m["eps0"]), **fixed)
    if not loc.inside:
        return None
    return loc, {"h": h_eq, "s": None if single else s_eq, "length_factor": k, "p": sc.p,
                 "L": float(m["L"]), "eps0": float(m["eps0"])}


def _many_waves(out: dict[str, Any], case: Any, waves: WavesFit | None) -> dict[str, Any]:
    """A simulated answer of many half-waves with the n of the fit over all simulated rods
    (:func:`undulate.design.waves.waves_n`) where it differs: each rod's l, lam, a shortened
    as the waves are more (same arc length), ``confidence`` "fitted", the atlas's point
    among the alternatives. Unchanged for fewer than :data:`~undulate.design.waves.N_MIN`
    half-waves, rods closer than 5 mm, and widths the fit did not see."""
    fit = load_waves() if waves is None else waves
    r, rod = case.rods, out["rods"][0]
    group = r.N > 1
    if (rod["n"] < N_MIN or (group and r.s < GROUP_GAP)
            or abs(r.b - fit.b) > _REL_TOL * fit.b):
        return out
    n = waves_n(fit, r.h, r.L, case.release.eps0, group)
    if n == rod["n"]:
        return out
    k = rod["n"] / n
    new = {"n": n, "l": rod["l"] * k, "lam": rod["lam"] * k, "a": rod["a"] * k}
    alts = [a for a in out["alternatives"] if (a["family"], a["n"]) != (out["family"], n)]
    if all((a["family"], a["n"]) != (out["family"], rod["n"]) for a in alts):
        alts.insert(0, {"family": out["family"], "n": rod["n"]})
    return {**out, "confidence": "fitted", "alternatives": alts,
            "summary": (f"many half-waves: {out['family']} n = {n} from the fit over all "
                        f"simulated rods with >= {N_MIN} (the atlas: {out['summary']})"),
            "rods": [{"index": j, **new} for j in range(len(out["rods"]))]}


def _simulated(pl: Placement, warnings: list[str], n_rods: int) -> dict[str, Any]:
    loc = pl.loc
    rod = {"n": loc.n, "l": loc.l, "lam": loc.lam, "a": loc.a}
    return {"source": "simulation", "atlas": pl.name, "family": loc.family,
            "confidence": loc.confidence,
            "summary": loc.summary(), "alternatives": [
                {"family": f, "n": n} for f, n in loc.alternatives],
            "warnings": warnings, "rods": [{"index": k, **rod} for k in range(n_rods)]}


def _scaled_answer(pl: Placement, case: Any, warnings: list[str],
                   n_rods: int) -> dict[str, Any]:
    """A located point's answer carried back to the case: lengths by the length factor, lam
    also by the chord's shortening, the family of one arch decided on the carried shape."""
    loc, sc = pl.loc, pl.scaled
    assert sc is not None
    k, eps0 = sc["length_factor"], case.release.eps0
    lam = loc.lam * k * (1.0 + sc["eps0"]) / (1.0 + eps0)
    rod = {"n": loc.n, "l": loc.l * k, "lam": lam, "a": loc.a * k}
    family = decide_family(1, lam=lam, a=rod["a"]) if loc.n == 1 else loc.family
    out = _simulated(pl, warnings, n_rods)
    out.update(family=family, rods=[{"index": j, **rod} for j in range(n_rods)],
               confidence=pl.confidence, summary=pl.summary(), scaled=sc)
    return out
