"""The simulated phase diagram shipped with undulate: where a design sits among simulated runs.

The closed forms of :mod:`undulate.theory` cannot know the quantization's end effects or the
shape families; the study preset ``parallel-phase-diagram`` simulates them over (h, s) for
five rods. :func:`build_atlas` reduces its table to one row per simulated (h, s) point (the
family and n most of its seeds gave, their means of l, lam, a), written as a small CSV with
the set-up in its header; the package ships the reference one as ``data/phase_diagram.csv``
(remade by ``undulate study atlas DIR``). :func:`locate` places a design on it: the nearest
simulated point, whether its neighbours on the grid agree (else "near a transition: coherent
n = 3 or bends n = 1"), and whether the design is inside the simulated box at all (the same N,
L, eps0 and moduli; h and s within the swept ranges). Units: mm, MPa.
"""

from __future__ import annotations

import functools
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

__all__ = ["ATLAS_FILE", "Atlas", "Location", "build_atlas", "load_atlas", "locate",
           "shipped_atlas"]

#: the reference phase diagram shipped in the package
ATLAS_FILE = Path(__file__).with_name("data") / "phase_diagram.csv"
#: the case values a design must share with the atlas to be inside it (relative tolerance)
_FIXED = ("N", "L", "eps0", "E_B", "E", "t", "b")
_REL_TOL = 0.02


@dataclass(frozen=True)
class Atlas:
    """Simulated points (one row per (h, s)) and what was held fixed (``meta``)."""

    points: pd.DataFrame
    meta: dict[str, Any]

    def to_dict(self) -> dict[str, Any]:
        cols = ["h", "s", "family", "n", "l", "lam", "a", "runs"]
        rows = self.points[cols].to_dict(orient="records")
        return {"meta": self.meta, "points": [
            {k: (None if isinstance(v, float) and not math.isfinite(v) else v)
             for k, v in r.items()} for r in rows]}


@dataclass(frozen=True)
class Location:
    """Where a design sits on the atlas (:func:`locate`)."""

    inside: bool
    reason: str  # why not inside ("" when inside)
    h: float  # the nearest simulated point
    s: float
    family: str
    n: int
    alternatives: list[tuple[str, int]]  # other (family, n) among the grid neighbours
    distance: float  # to the nearest point, in grid steps
    l: float = math.nan  # the nearest point's mean l, lam, a [mm]
    lam: float = math.nan
    a: float = math.nan

    @property
    def confidence(self) -> str:
        """'simulated' (the neighbours agree), 'near a transition' or 'outside'."""
        if not self.inside:
            return "outside"
        return "near a transition" if self.alternatives else "simulated"

    def summary(self) -> str:
        """One line for a person: what was simulated nearest, and how sure it is."""
        here = f"{self.family} n = {self.n} at h = {self.h:g} mm, s = {self.s:g} mm"
        if not self.inside:
            return f"outside the simulated diagram ({self.reason}); nearest: {here}"
        if self.alternatives:
            alt = " or ".join(f"{f} n = {n}" for f, n in self.alternatives)
            return f"near a transition: {self.family} n = {self.n} or {alt} (nearest: {here})"
        if self.distance < 1e-9:
            return f"simulated here: {here}"
        return f"between simulated points that agree: {here} (nearest)"

    def to_dict(self) -> dict[str, Any]:
        return {"inside": self.inside, "reason": self.reason, "h": self.h, "s": self.s,
                "family": self.family, "n": self.n,
                "alternatives": [{"family": f, "n": n} for f, n in self.alternatives],
                "distance": self.distance, "confidence": self.confidence,
                "summary": self.summary()}


def build_atlas(table: pd.DataFrame, setup: dict[str, Any] | None = None) -> Atlas:
    """Reduce a ``parallel-phase-diagram`` table (one row per run) to one row per (h, s).

    Per point: the family and n that most of its successful runs gave (ties: the first
    seed's), the mean l, lam and a of those runs, and how many runs there were. ``meta``
    holds the values that were the same for every run (N of the five-rod runs, L, eps0, the
    moduli, b, t), the swept ranges, and ``setup``.
    """
    d = table[table["status"] == "ok"].copy()
    if d.empty:
        raise ValueError("atlas: the table has no successful run")
    d["n_int"] = pd.to_numeric(d["n_mode"] if "n_mode" in d else d["n"],
                               errors="coerce").round().astype("Int64")
    rows = []
    for (h, s), g in d.sort_values("seed").groupby(["h", "s"], sort=True):
        votes = g.groupby(["family", "n_int"], sort=False).size()
        family, n = votes.idxmax()
        pick = g[(g["family"] == family) & (g["n_int"] == n)]
        rows.append({"h": float(h), "s": float(s), "family": str(family), "n": int(n),
                     "l": float(pick["l_mean"].mean()), "lam": float(pick["lam_mean"].mean()),
                     "a": float(pick["a_mean"].mean()), "runs": int(len(g))})
    points = pd.DataFrame(rows)
    meta: dict[str, Any] = {}
    for k in _FIXED:
        col = d[k] if k in d else None
        if k in ("N", "b") and col is not None:
            col = col[d["s"] > 0]  # s = 0 is one rod N times as wide
        if col is not None and len(col) and col.nunique() == 1:
            v = col.iloc[0]
            meta[k] = int(v) if k == "N" else float(v)
    meta["h_range"] = [float(points["h"].min()), float(points["h"].max())]
    meta["s_range"] = [float(points["s"].min()), float(points["s"].max())]
    meta["h_step"] = _step(points["h"])
    meta["s_step"] = _step(points["s"])
    meta["points"] = int(len(points))
    meta["runs"] = int(len(d))
    if setup is not None:
        meta["setup"] = setup
    return Atlas(points, meta)


def _step(v: pd.Series) -> float:
    u = np.unique(np.round(v.to_numpy(dtype=float), 9))
    return round(float(np.min(np.diff(u))), 9) if len(u) > 1 else 0.0


def write_atlas(atlas: Atlas, path: str | Path) -> Path:
    """The atlas as CSV, its ``meta`` as one JSON comment line on top (``# {...}``)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    text = "# " + json.dumps(atlas.meta, sort_keys=True) + "\n" + atlas.points.to_csv(
        index=False, float_format="%.6g")
    path.write_text(text)
    return path


def load_atlas(path: str | Path | None = None) -> Atlas:
    """Read an atlas written by :func:`write_atlas` (default: the shipped one)."""
    path = Path(path) if path is not None else ATLAS_FILE
    with path.open() as f:
        first = f.readline()
        if not first.startswith("# "):
            raise ValueError(f"{path}: not an atlas (no '# {{meta}}' first line)")
        meta = json.loads(first[2:])
        points = pd.read_csv(f)
    return Atlas(points, meta)


@functools.cache
def shipped_atlas(path: Path = ATLAS_FILE) -> Atlas:
    """A shipped atlas, read once per process (the web page asks on every prediction)."""
    return load_atlas(path)


def _bracket(values: pd.Series, v: float) -> list[float]:
    """The simulated values on either side of v (v itself where it was simulated; the end
    value outside the range)."""
    u = np.unique(values.to_numpy(dtype=float))
    if np.any(np.isclose(u, v, rtol=0.0, atol=1e-9)):
        return [float(u[np.argmin(np.abs(u - v))])]
    lo, hi = u[u < v], u[u > v]
    return [float(x) for x in ((lo.max(),) if lo.size else ()) + ((hi.min(),) if hi.size else ())]


#: how far below its thinnest rods an atlas still answers, as the relative change of the
#: half-wave length l0 = c0 + c1 h (:mod:`undulate.design.scaling`): thin rods' n goes as
#: 1 / l0, so half an h step of a coarse diagram (0.1 -> 0.05 mm: l0 -34 %, n 11 -> ~17)
#: would read another n
THIN_END_L0_SLACK = 0.05


def _thin_end_slack(h_min: float) -> float:
    """The h below ``h_min`` over which l0 shrinks by :data:`THIN_END_L0_SLACK`."""
    from .scaling import load_scaling

    sc = load_scaling()
    return THIN_END_L0_SLACK * (sc.c0 + sc.c1 * h_min) / sc.c1


def _end_slack(values: pd.Series) -> tuple[float, float]:
    """Half the simulated step at each end of an axis (how far past its ends a design still
    counts as inside)."""
    u = np.unique(values.to_numpy(dtype=float))
    if u.size < 2:
        return 0.5, 0.5
    return 0.5 * float(u[1] - u[0]), 0.5 * float(u[-1] - u[-2])


def locate(atlas: Atlas, *, h: float, s: float, **case: float) -> Location:
    """Where a design (h, s and the values in ``case``: N, L, eps0, E_B, E, t, b) sits.

    Inside means: every value of ``case`` the atlas held fixed within 2 %, and (h, s) within
    the swept ranges (half the end step of slack). The nearest point is on the simulated
    thickness nearest h, at the gap nearest s among that thickness's points (n follows h far
    more than s; a refined diagram has rows with fewer gaps); its alternatives are the
    other (family, n) at the corners of the grid cell that holds the design (none where the
    design is a simulated point itself).
    """
    m = atlas.meta
    reasons = []
    for k, v in case.items():
        if k in m and v is not None:
            ref = float(m[k])
            if k in ("N", "b") and s == 0:
                continue  # s = 0: one rod N times as wide, whatever N and b
            if abs(float(v) - ref) > _REL_TOL * max(abs(ref), 1e-12):
                reasons.append(f"{k} = {v:g}, the diagram's {k} = {ref:g}")
    p = atlas.points
    for name, v, (lo, hi) in (("h", h, m["h_range"]), ("s", s, m["s_range"])):
        below, above = _end_slack(p[name])
        if name == "h":
            below = min(below, _thin_end_slack(lo))
        if v < lo - below or v > hi + above:
            reasons.append(f"{name} = {v:g} mm, simulated {lo:g}..{hi:g} mm")
    hs, ss = m.get("h_step") or 1.0, m.get("s_step") or 1.0
    rows = np.unique(p["h"].to_numpy(dtype=float))
    row = p[np.isclose(p["h"], rows[np.argmin(np.abs(rows - h))], rtol=0.0, atol=1e-12)]
    k = int(np.argmin(np.abs(row["s"].to_numpy(dtype=float) - s)))
    near = row.iloc[k]
    distance = float(np.hypot((near["h"] - h) / hs, (near["s"] - s) / ss))
    # the cell around the design: the simulated h on either side, then the simulated s on
    # either side among those (a grid still being filled need not have every s at every h)
    col = p[p["h"].isin(_bracket(p["h"], h))]
    ring = col[col["s"].isin(_bracket(col["s"], s))]
    here = (str(near["family"]), int(near["n"]))
    alts = sorted({(str(f), int(n)) for f, n in zip(ring["family"], ring["n"], strict=True)}
                  - {here})
    return Location(inside=not reasons, reason="; ".join(reasons), h=float(near["h"]),
                    s=float(near["s"]), family=here[0], n=here[1], alternatives=alts,
                    distance=distance, l=float(near["l"]), lam=float(near["lam"]),
                    a=float(near["a"]))
