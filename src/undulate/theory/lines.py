"""The analytical model applied to a drawn pattern: one prediction per line, with warnings.

The closed forms of :mod:`undulate.theory.model` are derived for straight rods along the
stretch. For a drawn pattern each line gets

* its own length ``L`` (arc length of the polyline) and pre-stretch along it, ``eps_line``:
  a segment of the stretched fabric at angle ``theta`` to x shortens on release by the factor
  ``sqrt(cos^2 theta / lx^2 + sin^2 theta / ly^2)``, with ``lx = 1 + eps0`` and the lateral
  stretch of the clamped sheet ``ly = (1 + eps0)^(-nu)`` (free long edges), so
  ``eps_line = 1 / factor - 1``: ``eps0`` along x, negative across (such a line is pulled, not
  compressed, and stays flat);
* its group: lines of about the same direction (within 10 degrees) closer than the
  relaxation distance ``s_hat`` edge to edge interact; a group of N lines at a median gap s is
  given the family of the (h, s) phase map for N rods (bundling included);
* warnings where the model is stretched beyond what it was derived for (curved or inclined
  lines, one half-wave, strains outside the study's range).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..model.config import MATERIAL_DEFAULTS
from ..model.families import decide_family
from ..model.pattern import Line, line_gap
from . import model as T

__all__ = ["eps_along", "predict_lines"]

#: lines whose directions differ by less than this are one family (degrees)
PARALLEL_DEG = 10.0


def eps_along(angle_deg: float, eps0: float, nu: float) -> float:
    """Pre-stretch along a line at ``angle_deg`` to the stretch direction (see module doc)."""
    th = math.radians(angle_deg)
    lx = 1.0 + eps0
    ly = (1.0 + eps0) ** (-nu)
    factor = math.sqrt(math.cos(th) ** 2 / lx**2 + math.sin(th) ** 2 / ly**2)
    return 1.0 / factor - 1.0


def _groups(lines: list[Line], b: float, reach: list[float]
            ) -> tuple[list[list[int]], dict[tuple[int, int], float]]:
    """Connected sets of near-parallel lines closer than their reach, edge to edge, and the
    edge-to-edge gap of every near-parallel pair (i < j)."""
    parent = list(range(len(lines)))

    def find(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    gaps: dict[tuple[int, int], float] = {}
    for i in range(len(lines)):
        for j in range(i + 1, len(lines)):
            da = abs(lines[i].angle_deg - lines[j].angle_deg)
            if min(da, 180.0 - da) > PARALLEL_DEG:
                continue
            d, _ = line_gap(lines[i], lines[j])
            gap = d - 0.5 * ((lines[i].b or b) + (lines[j].b or b))
            gaps[(i, j)] = gap
            if gap <= max(reach[i], reach[j]):
                parent[find(i)] = find(j)
    out: dict[int, list[int]] = {}
    for i in range(len(lines)):
        out.setdefault(find(i), []).append(i)
    return list(out.values()), gaps


def predict_lines(lines: list[Line], *, h: float, eps0: float, b: float = MATERIAL_DEFAULTS["b"],
                  E_B: float = MATERIAL_DEFAULTS["E_B"], E: float = MATERIAL_DEFAULTS["E"],
                  t: float = MATERIAL_DEFAULTS["t"], nu: float = 0.3) -> dict[str, Any]:
    """Per-line and per-group predictions for a pattern (JSON-ready).

    Returns ``{"lines": [...], "groups": [...], "warnings": [...]}``; each line has ``id``,
    ``L``, ``angle_deg``, ``eps_line``, ``h``, ``b``, ``n`` and ``l`` (those of its group:
    bundling at small gaps makes N rods buckle as one of thickness ``h_eff``), ``n_alone`` and
    ``l_alone`` (the line by itself), ``l_n``, ``a`` (the formula amplitude), ``R``,
    ``s_hat``, ``family`` (that of its group), ``group`` and its own ``warnings``.
    """
    per: list[dict[str, Any]] = []
    reach: list[float] = []
    for ln in lines:
        hh, bb = ln.h or h, ln.b or b
        eps = eps_along(ln.angle_deg, eps0, nu)
        rec: dict[str, Any] = {"id": ln.id, "L": ln.length, "angle_deg": ln.angle_deg,
                               "eps_line": eps, "h": hh, "b": bb, "warnings": []}
        w = rec["warnings"]
        if not ln.is_straight(1e-2):
            w.append(f"curved (strays {ln.deviation:.3g} mm from its chord): treated as a "
                     "straight line of the same length")
        if abs(ln.angle_deg) > 5.0:
            w.append(f"at {ln.angle_deg:.0f} deg to the stretch: pre-stretch along it "
                     f"estimated as {eps:.3g} (the model is derived for lines along x)")
        if eps <= 0.0:
            w.append("stretched, not compressed, on release: it stays flat")
            rec.update(n=0, l=None, l_n=None, a=None, R=None, s_hat=0.0, family=decide_family(0))
            reach.append(0.0)
            per.append(rec)
            continue
        mat = {"b": bb, "E_B": E_B, "E": E, "t": t}
        p = T.predictions(hh, eps, L=ln.length, N=1, **mat)
        rec.update(n=int(p["n"]), l=p["l"], l_n=p["l_n"], a=p["a_formula"], R=p["R"],
                   s_hat=p["s_hat"])
        if eps < 0.05 or eps > 1.0:
            w.append(f"pre-stretch {eps:.3g} is outside 0.05..1, where the model was checked")
        if not 0.08 <= hh <= 2.0:
            w.append(f"h = {hh:g} mm is outside the study's 0.08..2 mm")
        reach.append(float(p["s_hat"]))
        per.append(rec)
    groups, gaps = _groups(lines, b, reach)
    out_groups = []
    for gi, members in enumerate(groups):
        members = sorted(members)
        rec_g: dict[str, Any] = {"index": gi, "lines": [per[i]["id"] for i in members],
                                 "N": len(members)}
        live = [i for i in members if per[i]["n"]]
        if len(members) == 1 or not live:
            i = members[0]
            fam = per[i].get("family") or (decide_family(per[i]["n"]) if per[i]["n"] > 1
                                           else _one_arc_family(per[i]))
            rec_g.update(s=None, family=fam)
        else:
            near = [min(gaps.get((min(i, j), max(i, j)), math.inf) for j in members if j != i)
                    for i in members]
            s = float(np.median([g for g in near if math.isfinite(g)]))
            k = live[0]
            pm = T.phase_map(per[k]["h"], max(s, 0.0), eps0=per[k]["eps_line"],
                             L=float(np.mean([per[i]["L"] for i in live])), N=len(members),
                             b=per[k]["b"], E_B=E_B, E=E, t=t)
            fam = str(pm["family"].item())
            rec_g.update(s=s, family=fam, n_group=int(pm["n"].item()),
                         l_group=float(pm["l"].item()), h_eff=float(pm["h_eff"].item()))
            if np.ptp([per[i]["L"] for i in live]) > 0.05 * max(per[i]["L"] for i in live):
                rec_g["warning"] = ("lines of different lengths side by side: their n differ "
                                    "and the waves may branch where they meet")
        for i in members:
            per[i]["group"] = gi
            per[i]["n_alone"], per[i]["l_alone"] = per[i]["n"], per[i]["l"]
            if "n_group" in rec_g and per[i]["n"]:
                # the group's half-waves: bundled rods (small s) buckle as one thicker rod
                per[i]["n"], per[i]["l"] = rec_g["n_group"], rec_g["l_group"]
            if per[i].get("family") != "flat":
                per[i]["family"] = rec_g["family"]
            if per[i]["n"] == 1:
                per[i]["warnings"].append("one half-wave: eq. (1) does not set its shape; "
                                          "it forms a single arc over the whole line")
        out_groups.append(rec_g)
    warnings = [f"line {r['id']}: {m}" for r in per for m in r["warnings"]]
    warnings += [f"group {g['index']}: {g['warning']}" for g in out_groups if "warning" in g]
    return {"lines": per, "groups": out_groups, "warnings": warnings}


def _one_arc_family(rec: dict[str, Any]) -> str:
    """rolls or bends for a lone line with one half-wave (the one rule of the families)."""
    lam1, a1 = T.single_arc(rec["L"], rec["R"])
    return decide_family(1, lam=float(lam1), a=float(a1))
