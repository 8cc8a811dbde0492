"""Per-rod shape metrics, phase coherence between rods and the family of a run.

Metric names (same in code, JSON and tables); lengths in mm, curvatures in 1/mm:

==============  ===========================================================================
``n``           number of half-waves = fitted arcs, not counting straight end pieces
                (0 for a flat rod)
``l``           mean arclength of one *interior* arc (all arcs when n <= 2); ``l_segments``
                lists the arclength of every counted arc, in order along the rod
``lam``         projected x-length of two half-waves: 2 x mean projected length of the
                interior arcs; for n = 1 the projected span of the single arc (= ``span``)
``a``           half the peak-to-trough height: mean over interior arcs of each arc's height
                above/below the chord joining its ends (for a periodic chain this is exactly
                half the peak-to-trough height); for n = 1 the rise (= ``rise``)
``R``           mean radius 1/|kappa| of the interior arcs
``R_up``        mean radius of up arcs (crests, bulging to +z, fitted kappa < 0); interior
                arcs if some are up, else all arcs; ``R_down`` likewise for troughs
``kappa_up``    mean |kappa| of the same up arcs (a positive number); ``kappa_down`` likewise
``flat_ends``   [left, right] arclengths of straight end pieces (turning angle below
                max(0.1 rad, 0.2 x median arc turning)); [0, 0] when none
``rise/span``   only for n = 1 (None otherwise)
``r2_arcs``     R^2 on z of the arc-chain fit (1 - sum d^2 / sum (z - mean z)^2, d the normal
                distance); ``r2_sine`` same for the sine fit; ``rms_arcs``/``rms_sine`` RMS of d
``quality``     "flat", "short", "noisy", "end_dominated" or "ok" (first that applies, see
                :func:`rod_metrics`)
==============  ===========================================================================

Undefined values are ``None`` (JSON ``null``), never NaN: a flat rod has ``n = 0``,
``a`` = its half z-range, ``flat_ends = [0, 0]`` and ``None`` for every length/radius/fit.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from ..model.families import COHERENT_THRESHOLD, FAMILIES, decide_family
from .fit import ArcChainFit, fit_arcs, fit_sine, prepare

__all__ = [
    "FLAT_REL",
    "FLAT_ABS",
    "SHORT_POINTS",
    "NOISY_R2",
    "END_DOMINATED_FRACTION",
    "COHERENT_THRESHOLD",
    "FAMILIES",
    "rod_metrics",
    "coherence",
    "classify",
    "analyse_run",
    "unrolled",
]

FLAT_REL = 1e-3
"""A rod is flat when its z-range is below ``FLAT_REL * L`` ..."""
FLAT_ABS = 1e-6
"""... or below ``FLAT_ABS`` mm (guards L ~ 0)."""
SHORT_POINTS = 6
"""Quality "short": fewer than 20 points, or fewer than this many points per half-wave."""
NOISY_R2 = 0.95
"""Quality "noisy": the arc-chain fit explains less than this fraction of the z variance."""
END_DOMINATED_FRACTION = 0.25
"""Quality "end_dominated": straight end pieces cover more than this fraction of the rod."""


def _f(v: Any) -> float | None:
    """Plain float, or None for None/NaN/inf."""
    if v is None:
        return None
    v = float(v)
    return v if np.isfinite(v) else None


def _mean(vals: list[float]) -> float | None:
    return float(np.mean(vals)) if vals else None


def _empty(cl_len: float, L: float | None, npts: int, half_range: float) -> dict[str, Any]:
    return {
        "n": 0, "l": None, "l_segments": [], "lam": None, "a": half_range, "R": None,
        "R_up": None, "R_down": None, "kappa_up": None, "kappa_down": None,
        "flat_ends": [0.0, 0.0], "rise": None, "span": None, "r2_arcs": None,
        "r2_sine": None, "rms_arcs": None, "rms_sine": None, "quality": "flat",
        "length": cl_len, "L_measured": cl_len, "L_nominal": L, "n_points": npts,
        "sine": None, "arcs": [],
    }


def _split_flat_ends(arcs: list[dict[str, Any]]) -> tuple[list[dict[str, Any]], list[float]]:
    """Remove straight end pieces; return the counted arcs and [left, right] flat lengths."""
    turning = [p["turning"] for p in arcs]
    ref = float(np.median(turning)) if turning else 0.0
    thr = max(0.1, 0.2 * ref)
    left = right = 0.0
    arcs = list(arcs)
    while len(arcs) > 1 and arcs[0]["turning"] < thr:
        left += arcs.pop(0)["length"]
    while len(arcs) > 1 and arcs[-1]["turning"] < thr:
        right += arcs.pop()["length"]
    arcs = [p for p in arcs if p["length"] > 1e-9]
    return arcs, [left, right]


def rod_metrics(xyz: ArrayLike, *, L: float | None = None) -> dict[str, Any]:
    """Shape metrics of one buckled rod (names and conventions: module docstring).

    ``xyz`` is the ``(M, 3)`` centre line ordered along the rod (or ``(M, 2)`` ``(x, z)``);
    ``L`` is the nominal (printed) rod length, used for the flatness threshold (default: the
    measured polyline length). Both are returned, named: ``L_nominal`` (``L`` or None) and
    ``L_measured`` (the polyline length, also ``length``); neither replaces the other.
    Quality flags, the first that applies: **"flat"** (z-range below
    ``max(FLAT_REL * L, FLAT_ABS)``), **"short"** (fewer than 20 points or fewer than
    ``SHORT_POINTS`` per half-wave), **"noisy"** (``r2_arcs < NOISY_R2``),
    **"end_dominated"** (straight end pieces longer than ``END_DOMINATED_FRACTION`` of the rod),
    else **"ok"**. Returns a JSON-serialisable dict (plain floats/ints/lists/None).
    Raises ValueError (naming the problem) for NaN/inf, a wrong shape or < 5 points.
    """
    cl = prepare(xyz)
    L_ref = float(L) if L is not None else cl.length
    zr = float(np.ptp(cl.z))
    L_nom = float(L) if L is not None else None
    if zr < max(FLAT_REL * L_ref, FLAT_ABS):
        return _empty(cl.length, L_nom, len(cl.z), 0.5 * zr)
    arc_fit: ArcChainFit = fit_arcs(xyz)
    try:
        sine = fit_sine(xyz)
        sine_d: dict[str, float] | None = sine.to_dict()
    except (ValueError, np.linalg.LinAlgError):  # pragma: no cover - defensive
        sine, sine_d = None, None
    pieces = arc_fit.arcs()
    arcs, flat = _split_flat_ends(pieces)
    n = len(arcs)
    interior = arcs[1:-1] if n >= 3 else arcs
    l_val = _mean([p["length"] for p in interior])
    R_val = _mean([p["R"] for p in interior if p["R"] is not None])

    def side(up: bool) -> list[dict[str, Any]]:
        sel = [p for p in interior if p["up"] == up and p["R"] is not None]
        return sel or [p for p in arcs if p["up"] == up and p["R"] is not None]

    ups, downs = side(True), side(False)
    R_up = _mean([p["R"] for p in ups])
    R_down = _mean([p["R"] for p in downs])
    k_up = _mean([abs(p["kappa"]) for p in ups])
    k_down = _mean([abs(p["kappa"]) for p in downs])
    a_val = _mean([p["height"] for p in interior])
    if n == 1:
        lam = arcs[0]["dx"]
        rise, span = a_val, lam
    else:
        lam = 2.0 * float(np.mean([p["dx"] for p in interior]))
        rise = span = None
    r2_arcs, rms_arcs = arc_fit.r2, arc_fit.rms
    if len(cl.z) < 20 or len(cl.z) < SHORT_POINTS * max(n, 1):
        quality = "short"
    elif r2_arcs < NOISY_R2:
        quality = "noisy"
    elif sum(flat) > END_DOMINATED_FRACTION * float(arc_fit.bounds[-1] - arc_fit.bounds[0]):
        quality = "end_dominated"
    else:
        quality = "ok"
    return {
        "n": int(n),
        "l": _f(l_val),
        "l_segments": [float(p["length"]) for p in arcs],
        "lam": _f(lam),
        "a": _f(a_val),
        "R": _f(R_val),
        "R_up": _f(R_up),
        "R_down": _f(R_down),
        "kappa_up": _f(k_up),
        "kappa_down": _f(k_down),
        "flat_ends": [float(flat[0]), float(flat[1])],
        "rise": _f(rise),
        "span": _f(span),
        "r2_arcs": _f(r2_arcs),
        "r2_sine": _f(sine.r2) if sine else None,
        "rms_arcs": _f(rms_arcs),
        "rms_sine": _f(sine.rms) if sine else None,
        "quality": quality,
        "length": float(cl.length),
        "L_measured": float(cl.length),
        "L_nominal": L_nom,
        "n_points": int(len(cl.z)),
        "sine": {k: _f(v) for k, v in sine_d.items()} if sine_d else None,
        "arcs": [
            {k: (_f(v) if isinstance(v, float) else v) for k, v in p.items()} for p in pieces
        ],
        "arc_chain": {
            "x0": arc_fit.x0, "z0": arc_fit.z0, "psi0": arc_fit.psi0,
            "kappa": [float(k) for k in arc_fit.kappa],
            "bounds": [float(b) for b in arc_fit.bounds],
        },
    }


def coherence(xyz_a: ArrayLike, xyz_b: ArrayLike, *, n_grid: int = 512) -> float:
    """Phase coherence of two neighbouring rods, in [-1, 1].

    Normalised cross-correlation at zero lag of their profiles ``z(x)`` (each minus its mean),
    resampled by linear interpolation on a common uniform grid over the overlap of their x
    ranges: ``sum(za zb) / sqrt(sum(za^2) sum(zb^2))``. +1: identical phase (coherent waves),
    -1: opposite phase, ~0: unrelated. Returns 0.0 when either profile has no variance
    (flat) or the x ranges overlap by less than 10 % of the shorter rod.
    """
    ca, cb = prepare(xyz_a), prepare(xyz_b)
    oa, ob = np.argsort(ca.x, kind="stable"), np.argsort(cb.x, kind="stable")
    xa, za, xb, zb = ca.x[oa], ca.z[oa], cb.x[ob], cb.z[ob]
    lo, hi = max(xa[0], xb[0]), min(xa[-1], xb[-1])
    if hi - lo < 0.1 * min(xa[-1] - xa[0], xb[-1] - xb[0]):
        return 0.0
    g = np.linspace(lo, hi, n_grid)
    pa = np.interp(g, xa, za)
    pb = np.interp(g, xb, zb)
    pa -= pa.mean()
    pb -= pb.mean()
    den = float(np.sqrt(np.sum(pa**2) * np.sum(pb**2)))
    scale = max(float(np.ptp(za)), float(np.ptp(zb)), 1e-300)
    if den <= (1e-12 * scale) ** 2 * n_grid:
        return 0.0
    return float(np.clip(np.sum(pa * pb) / den, -1.0, 1.0))


def _family(rods: list[dict[str, Any]], coh: list[float]) -> str:
    """Family from per-rod metrics and neighbour coherences (the rule:
    :func:`undulate.model.families.decide_family`)."""
    live = [i for i, r in enumerate(rods) if r["n"] > 0]
    if not live:
        return decide_family(0)
    ones = [rods[i] for i in live if rods[i]["n"] == 1]
    if 2 * len(ones) >= len(live):
        return decide_family(1, lam=float(np.median([r["lam"] for r in ones])),
                             a=float(np.median([r["a"] for r in ones])))
    pairs = [c for k, c in enumerate(coh) if rods[k]["n"] > 0 and rods[k + 1]["n"] > 0]
    coherent = (float(np.median(pairs)) >= COHERENT_THRESHOLD
                if len(rods) > 1 and pairs else None)
    return decide_family(2, coherent=coherent)


def classify(rods_xyz: list[ArrayLike], *, L: float | None = None) -> str:
    """Family of a run of parallel rods (ordered by y), one of :data:`FAMILIES`.

    Rules, in order: all rods flat -> **"flat"**; at least half of the non-flat rods have a
    single half-wave (n = 1) -> **"rolls"** if the median ``lam < 2 x`` median ``a`` (the
    arc turns more than a semicircle) else **"bends"** (this also applies to a single rod);
    a single rod with n >= 2 -> **"waves"**; otherwise the median coherence of neighbouring
    non-flat pairs ``>= COHERENT_THRESHOLD`` (0.5) -> **"coherent"**, else **"independent"**.
    """
    return analyse_run(list(rods_xyz), L=L)["family"]


def unrolled(xyz: ArrayLike) -> np.ndarray:
    """``(M, 2)`` array ``(s, z)`` of a curved rod's centre line ``(M, 3)``: ``s`` its in-plane
    arc length (of the ``(x, y)`` path), so that a line drawn as an arc or a spiral is
    measured along itself, as a straight rod is along x."""
    arr = np.asarray(xyz, dtype=float)
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ValueError(f"centre line: expected an (M, 3) array to unroll; got shape "
                         f"{arr.shape}")
    ds = np.linalg.norm(np.diff(arr[:, :2], axis=0), axis=1)
    return np.c_[np.concatenate([[0.0], np.cumsum(ds)]), arr[:, 2]]


def analyse_run(
    centerlines: list[ArrayLike], *, L: float | Sequence[float | None] | None = None,
    along: Sequence[str] | None = None,
) -> dict[str, Any]:
    """Analyse all rods of one run.

    ``L``: the nominal (printed) length of every rod, or one per rod, or None (see
    :func:`rod_metrics`). ``along``: per rod, ``"principal"`` (default: the abscissa is the
    principal in-plane direction of its points, right for straight lines) or
    ``"arclength"`` (curved lines: measured along their own in-plane arc length,
    :func:`unrolled`); coherence then compares neighbours along the same abscissas.

    Returns ``{"rods": [rod_metrics(...) + {"index": k}], "coherence": [coherence(rod k,
    rod k+1)], "family": str, "summary": {...}}``; the summary holds mean/std over the
    non-flat rods of ``l``, ``lam``, ``a``, ``R``, ``R_up``, ``R_down`` and of the fits'
    ``r2_arcs``/``r2_sine``, and the median ``n``. JSON-serialisable.
    """
    if len(centerlines) == 0:
        raise ValueError("analyse_run: no centre lines given")
    if L is None or isinstance(L, int | float):
        Ls: list[float | None] = [L] * len(centerlines)
    else:
        Ls = list(L)
        if len(Ls) != len(centerlines):
            raise ValueError(f"analyse_run: {len(Ls)} lengths L for {len(centerlines)} rods")
    if along is not None:
        if len(along) != len(centerlines):
            raise ValueError(f"analyse_run: {len(along)} 'along' entries for "
                             f"{len(centerlines)} rods")
        bad = sorted(set(along) - {"principal", "arclength"})
        if bad:
            raise ValueError(f"analyse_run: along must be 'principal' or 'arclength', got {bad}")
        centerlines = [unrolled(c) if a == "arclength" else c
                       for c, a in zip(centerlines, along, strict=True)]
    rods = []
    for k, c in enumerate(centerlines):
        try:
            m = rod_metrics(c, L=Ls[k])
        except ValueError as exc:
            raise ValueError(f"rod {k}: {exc}") from exc
        rods.append({"index": k, **m})
    coh = [coherence(centerlines[k], centerlines[k + 1]) for k in range(len(centerlines) - 1)]
    summary: dict[str, Any] = {}
    live = [r for r in rods if r["n"] > 0]
    for key in ("l", "lam", "a", "R", "R_up", "R_down", "r2_arcs", "r2_sine"):
        vals = [r[key] for r in live if r.get(key) is not None]
        summary[f"{key}_mean"] = float(np.mean(vals)) if vals else None
        summary[f"{key}_std"] = float(np.std(vals)) if vals else None
    summary["n_median"] = float(np.median([r["n"] for r in rods]))
    return {"rods": rods, "coherence": coh, "family": _family(rods, coh), "summary": summary}
