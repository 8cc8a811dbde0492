"""Quantities derived from a study table (shared by figures and report), and the theory curves
(the functions of :mod:`undulate.theory`, see :func:`theory`).
"""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np
import pandas as pd

from ..model.config import MATERIAL_DEFAULTS

__all__ = [
    "theory",
    "up_down_radii",
    "ok_rows",
    "n_values",
    "is_swept",
    "material",
    "per_point",
    "hstar",
    "fit_l_slope",
    "fit_eps0_exponents",
    "arcs_beat_sines",
    "hstar_ratios",
    "onset_summary",
    "outer_rod_first",
]


def theory() -> dict[str, Any]:
    """``{"l", "a", "s_hat", "R", "n", "source"}``: the closed-form functions (docs/theory.md) of
    :mod:`undulate.theory` (eq. (1), amplitude, s_hat, R = l/sqrt(24 eps0), odd n nearest L/l)."""
    from undulate import theory as th

    return {"l": th.l, "a": th.a, "s_hat": th.s_hat, "R": th.R, "n": th.n,
            "source": "undulate.theory"}


def ok_rows(df: pd.DataFrame) -> pd.DataFrame:
    """Rows of successful runs (with ``r2_*_mean`` filled from the per-rod lists if absent)."""
    if "status" not in df:
        return df.iloc[0:0]
    d = df[df["status"] == "ok"].copy()
    for key in ("r2_arcs", "r2_sine"):
        if f"rods_{key}" in d:
            filled = d[f"rods_{key}"].map(_json_mean)
            d[f"{key}_mean"] = (pd.to_numeric(d[f"{key}_mean"], errors="coerce")
                                .fillna(filled) if f"{key}_mean" in d else filled)
    return d


def _json_mean(text: object) -> float:
    """Mean of the numbers in a JSON list (tables written before the summary held it)."""
    try:
        vals = [float(v) for v in json.loads(str(text)) if v is not None]
    except (TypeError, ValueError):
        return float("nan")
    return float(np.mean(vals)) if vals else float("nan")


def n_values(df: pd.DataFrame) -> pd.Series:
    """Number of half-waves per row: ``n_mode`` if present else ``round(n_mean)``."""
    if "n_mode" in df:
        return pd.to_numeric(df["n_mode"], errors="coerce")
    if "n_mean" in df:
        return pd.to_numeric(df["n_mean"], errors="coerce").round()
    return pd.Series(np.nan, index=df.index)


def is_swept(df: pd.DataFrame, col: str) -> bool:
    """Whether a column takes more than one value."""
    return col in df and df[col].nunique(dropna=True) > 1


def material(df: pd.DataFrame) -> dict[str, float]:
    """b, E_B, E, t of the study (medians; they are constants in the presets)."""
    out = {}
    for k, default in MATERIAL_DEFAULTS.items():
        out[k] = float(df[k].median()) if k in df and df[k].notna().any() else default
    return out


def per_point(df: pd.DataFrame, keys: list[str], cols: list[str]) -> pd.DataFrame:
    """Mean and std over seeds of ``cols`` for each combination of ``keys``."""
    cols = [c for c in cols if c in df]
    num = df[keys + cols].copy()
    for c in cols:
        num[c] = pd.to_numeric(num[c], errors="coerce")
    g = num.groupby(keys, sort=True)
    mean = g.mean()
    std = g.std(ddof=0).add_suffix("_sd")
    count = g.size().rename("count")
    return pd.concat([mean, std, count], axis=1).reset_index()


def hstar(df: pd.DataFrame, n_target: int = 1, by: str = "s") -> pd.Series:
    """h*_n per value of ``by``: the smallest h whose (median over seeds) n is <= ``n_target``.

    Without a swept ``by`` column (single-rod study) the result has one element, indexed by
    the constant value of ``by`` (0.0 when absent). NaN where no run reaches ``n <= n_target``.
    """
    d = ok_rows(df)
    if d.empty or "h" not in d:
        return pd.Series(dtype=float)
    d = d.assign(_n=n_values(d))
    if by not in d or d[by].nunique() <= 1:
        d = d.assign(**{by: d[by].iloc[0] if by in d else 0.0})
    med = d.groupby([by, "h"])["_n"].median().reset_index()
    out = {}
    for key, grp in med.groupby(by):
        hit = grp[grp["_n"] <= n_target]
        out[key] = float(hit["h"].min()) if not hit.empty else float("nan")
    return pd.Series(out, name=f"hstar_{n_target}").sort_index()


def fit_l_slope(df: pd.DataFrame, n_min: int | None = None) -> dict[str, float] | None:
    """Fit ``l_mean = k h + c`` over the linear regime (runs with ``n >= n_min`` and ``h`` below
    the first run that ends with n = 1, ``h_below``).

    Without ``n_min`` the first of 7, 5, 3 that leaves at least 3 distinct h is used (7 keeps
    clear of the quantization plateaus for L = 100 mm; coarse/quick studies need less).
    Returns ``{"slope", "intercept", "slope_origin", "slope_eq1", "n_points", "eps0", "n_min",
    "h_below"}``
    or None when no choice leaves 3 distinct h. ``slope_origin`` fits through the origin as
    eq. (1) does.
    """
    if n_min is None:
        for n_try in (7, 5, 3):
            res = fit_l_slope(df, n_try)
            if res is not None:
                return res
        return None
    d = ok_rows(df)
    if d.empty or "l_mean" not in d or "h" not in d:
        return None
    d = d.assign(_n=n_values(d), _l=pd.to_numeric(d["l_mean"], errors="coerce"))
    if "eps0" in d and d["eps0"].nunique() > 1:  # keep the most common eps0
        d = d[d["eps0"] == d["eps0"].mode().iloc[0]]
    # "below the plateaus": thinner than the first rod that ends in one half-wave (thick rods
    # can come back to n = 3 with l ~ L/2, which is not the linear regime)
    ones = d.loc[d["_n"] == 1, "h"]
    h_one = float(ones.min()) if not ones.empty else float("inf")
    d = d[(d["_n"] >= n_min) & d["_l"].notna() & (d["h"] < h_one)]
    if d["h"].nunique() < 3:
        return None
    h = d["h"].to_numpy(float)
    lv = d["_l"].to_numpy(float)
    k, c = np.polyfit(h, lv, 1)
    k0 = float(np.dot(h, lv) / np.dot(h, h))
    eps0 = float(d["eps0"].iloc[0]) if "eps0" in d else 0.5
    k_eq1 = float(np.asarray(theory()["l"](1.0, eps0, **material(d))))
    return {"slope": float(k), "intercept": float(c), "slope_origin": k0, "slope_eq1": k_eq1,
            "n_points": int(len(d)), "eps0": eps0, "n_min": n_min, "h_below": h_one}


def fit_eps0_exponents(df: pd.DataFrame) -> list[dict[str, float]]:
    """Least-squares slope of ``log l_mean`` vs ``log eps0`` (eq. (1): -1/2), one fit per rod
    thickness h with at least two pre-stretches (seeds enter as separate points); empty
    when eps0 is not swept."""
    d = ok_rows(df)
    if d.empty or "l_mean" not in d or not is_swept(d, "eps0"):
        return []
    d = d.assign(_l=pd.to_numeric(d["l_mean"], errors="coerce"))
    d = d[(d["_l"] > 0) & (d["eps0"] > 0)]
    if "h" not in d:
        d = d.assign(h=float("nan"))
    out = []
    for h, g in d.groupby("h", dropna=False, sort=True):
        if g["eps0"].nunique() < 2:
            continue
        p, c = np.polyfit(np.log(g["eps0"].to_numpy(float)), np.log(g["_l"].to_numpy(float)), 1)
        out.append({"exponent": float(p), "exponent_eq1": -0.5, "prefactor": float(math.exp(c)),
                    "n_points": int(len(g)), "h": float(h)})
    return out


def arcs_beat_sines(df: pd.DataFrame) -> dict[str, float] | None:
    """Fraction of successful runs where ``r2_arcs_mean > r2_sine_mean``."""
    d = ok_rows(df)
    if d.empty or "r2_arcs_mean" not in d or "r2_sine_mean" not in d:
        return None
    ra = pd.to_numeric(d["r2_arcs_mean"], errors="coerce")
    rs = pd.to_numeric(d["r2_sine_mean"], errors="coerce")
    m = ra.notna() & rs.notna()
    if not m.any():
        return None
    wins = int((ra[m] > rs[m]).sum())
    return {"fraction": wins / int(m.sum()), "wins": wins, "n": int(m.sum())}


#: arc-chain fits with a lower R^2 do not resolve the arcs (too few nodes per arc)
ARCS_RESOLVED_R2 = 0.9


def up_down_radii(df: pd.DataFrame, n_min: int = 5) -> dict[str, Any] | None:
    """R_up / R_down of the interior arcs, on the rod's centre line and on the fabric under it.

    The centre line sits d = (t + h) / 2 above the fabric's mid-surface (the bond), outside
    the bond line at a crest and inside it at a trough. Circular arcs offset by d stay circular
    with radius R -/+ d, so on the fabric line ``R_up_fabric = R_up - d`` and
    ``R_down_fabric = R_down + d``: even bond-line arcs of equal radius give R_up - R_down =
    t + h on the centre line. Runs with ``n >= n_min`` (two or more interior arcs of each sign;
    for n = 3 one side would be end arcs only), both radii and resolved arcs (arc-chain R^2 at
    least :data:`ARCS_RESOLVED_R2`). None when no run qualifies.
    """
    d = ok_rows(df)
    need = {"R_up_mean", "R_down_mean", "h", "t"}
    if d.empty or not need <= set(d.columns):
        return None
    n = n_values(d)
    up = pd.to_numeric(d["R_up_mean"], errors="coerce")
    down = pd.to_numeric(d["R_down_mean"], errors="coerce")
    m = (n >= n_min) & up.notna() & down.notna()
    if "r2_arcs_mean" in d:  # resolved arcs only (at h = 0.08 mm five nodes span an arc)
        m &= pd.to_numeric(d["r2_arcs_mean"], errors="coerce") >= ARCS_RESOLVED_R2
    if "rods.offset" in d:  # a set-up that moves the centre line: its own offset
        off = pd.to_numeric(d["rods.offset"], errors="coerce")
    else:
        off = pd.Series(float("nan"), index=d.index)
    dd = off.where(off.notna(), (d["t"] + d["h"]) / 2.0)
    if not m.any():
        return None
    centre = (up / down)[m]
    fabric = ((up - dd) / (down + dd))[m]
    return {"n": int(m.sum()), "n_min": n_min,
            "centre_median": float(centre.median()), "centre_min": float(centre.min()),
            "centre_max": float(centre.max()), "centre_below_1": int((centre < 1).sum()),
            "fabric_median": float(fabric.median()), "fabric_min": float(fabric.min()),
            "fabric_max": float(fabric.max()), "fabric_below_1": int((fabric < 1).sum())}


def hstar_ratios(df: pd.DataFrame, n_nominal: int | None = None) -> list[dict[str, Any]]:
    """h*_n(s = min s) / h*_n(s = max s) for the transitions 3->1, 5->3, 7->5 vs N^(1/3)."""
    d = ok_rows(df)
    if d.empty or not is_swept(d, "s") or "h" not in d:
        return []
    if n_nominal is None:
        n_nominal = int(d["N"].max()) if "N" in d else 5
    s_lo, s_hi = float(d["s"].min()), float(d["s"].max())
    out = []
    for n_from, n_to in ((3, 1), (5, 3), (7, 5)):
        hs = hstar(d, n_to)
        lo, hi = hs.get(s_lo, float("nan")), hs.get(s_hi, float("nan"))
        ratio = lo / hi if (np.isfinite(lo) and np.isfinite(hi) and hi > 0) else float("nan")
        out.append({"transition": f"{n_from}->{n_to}", "hstar_s_min": lo, "hstar_s_max": hi,
                    "s_min": s_lo, "s_max": s_hi, "ratio": ratio,
                    "bundling": n_nominal ** (1.0 / 3.0), "N": n_nominal})
    return out


def outer_rod_first(rods_onset: Any) -> bool | None:
    """Whether an outer rod (first or last) reached the onset of buckling no later than every
    inner one, from a run's per-rod onsets (a list, or its JSON text as in the study table).
    None for fewer than three rods, a rod without an onset, or text that is not a list."""
    try:
        rods = json.loads(rods_onset) if isinstance(rods_onset, str) else list(rods_onset)
    except (TypeError, ValueError):
        return None
    if not isinstance(rods, list) or len(rods) < 3 or any(v is None for v in rods):
        return None
    return bool(min(rods[0], rods[-1]) <= min(rods[1:-1]))


def onset_summary(df: pd.DataFrame) -> dict[str, Any] | None:
    """The onset of buckling over a study: ``n``, ``min``, ``median``, ``max`` of
    ``onset_release_strain``, and for runs of three or more rods ``outer_first`` / ``n_multi``:
    in how many of them an outer rod (first or last) reached the onset no later than every
    inner one. None without onset data."""
    d = ok_rows(df)
    if d.empty or "onset_release_strain" not in d:
        return None
    e = pd.to_numeric(d["onset_release_strain"], errors="coerce").dropna()
    if e.empty:
        return None
    out: dict[str, Any] = {"n": int(len(e)), "min": float(e.min()),
                           "median": float(e.median()), "max": float(e.max())}
    outer = multi = 0
    for text in d.get("rods_onset_release_strain", pd.Series(dtype=object)).dropna():
        first = outer_rod_first(text)
        if first is None:
            continue
        multi += 1
        outer += int(first)
    if multi:
        out.update(outer_first=outer, n_multi=multi)
    return out
