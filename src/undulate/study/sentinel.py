"""The sentinel: a dozen runs that judge a modelling set-up against the study in minutes.

Running the three full studies (587 runs) takes hours; a candidate set-up (a release protocol,
a stiffness ratio, which edges the frame holds...) can be judged first on a few places of the
parameter space where the study says what happens. The sentinel is those places:

* single rods (N = 1, L = 100 mm, eps0 = 0.5) across h: thin (h = 0.1, 0.2: many half-waves),
  the demo's rod (0.3), n ~ 3 (0.5) and the n = 1 region (1.0, 2.0);
* five rods in each corner of the (h, s) plane and its middle: low h / large s (independent
  waves), low h / small s, mid h at small and large s (coherent), large h / small s (rolls),
  large h / large s (bends).

For each case the study's statement is written next to it (``expect``): the family, the
number of half-waves (for single rods: eq. (1)'s odd n, as a range +-2 since the study's own
runs scatter around it; for rolls and bends n = 1), and, over all cases, the onset ("one
critical strain, the same for all h") and the up/down asymmetry ("segments above the fabric
plane slightly more curved": R_up / R_down < 1). :func:`judge` compares a study directory's
table with them; ``undulate study sentinel`` runs the cases and prints that table.

Judgement rules (our choices, stated so a candidate is judged the same way each time):

* family: MATCH when the run's family is one of the expected ones;
* n: MATCH when the run's n lies in the expected range;
* onset: the single rods' onset release strains (where the rods first stand out of their
  printed level by h) are "the same for all h" when max / min <= :data:`ONSET_SPREAD_MAX`;
* up/down: MATCH when R_up / R_down < 1 (computed over runs with n >= 3, where both signs
  have full segments).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import pandas as pd

from ..theory import model as theory_model
from .derived import n_values

__all__ = [
    "SENTINEL_CASES",
    "ONSET_SPREAD_MAX",
    "SentinelCase",
    "expected_n",
    "judge",
    "summary",
    "markdown",
    "compare_markdown",
]

#: "the same onset for all h": largest max / min of the single rods' onset release strains
ONSET_SPREAD_MAX = 1.5


@dataclass(frozen=True)
class SentinelCase:
    """One place of the parameter space and what the study says happens there."""

    label: str
    h: float
    N: int
    s: float
    families: tuple[str, ...]
    where: str

    def params(self) -> dict[str, Any]:
        """The case's swept parameters (dotted paths)."""
        out: dict[str, Any] = {"rods.h": self.h, "rods.N": self.N}
        if self.N > 1:
            out["rods.s"] = self.s
        return out


_N1 = ("rolls", "bends")  # one half-wave: rolls (lambda < 2a) or bends (lambda > 2a)
SENTINEL_CASES: tuple[SentinelCase, ...] = (
    SentinelCase("single-0.1", 0.1, 1, 0.0, ("waves",), "thin rod: many short arcs"),
    SentinelCase("single-0.2", 0.2, 1, 0.0, ("waves",), "thin rod: n ~ 7-9"),
    SentinelCase("single-0.3", 0.3, 1, 0.0, ("waves",), "the demo's rod"),
    SentinelCase("single-0.5", 0.5, 1, 0.0, ("waves",), "n ~ 3"),
    SentinelCase("single-1", 1.0, 1, 0.0, _N1, "n = 1 region"),
    SentinelCase("single-2", 2.0, 1, 0.0, _N1, "n = 1 region, stiffest rod"),
    SentinelCase("five-0.1-50", 0.1, 5, 50.0, ("independent",), "very low h, large s"),
    SentinelCase("five-0.1-5", 0.1, 5, 5.0, ("coherent",), "low h, small s"),
    SentinelCase("five-0.5-10", 0.5, 5, 10.0, ("coherent",), "mid h"),
    SentinelCase("five-0.5-40", 0.5, 5, 40.0, ("coherent",), "mid h, large s"),
    SentinelCase("five-1.6-2.5", 1.6, 5, 2.5, ("rolls",), "large h, small s"),
    SentinelCase("five-1.6-50", 1.6, 5, 50.0, ("bends",), "large h, large s"),
)


def expected_n(c: SentinelCase, *, L: float, eps0: float, b: float, E_B: float, E: float,
               t: float) -> tuple[int, int]:
    """The study's n for a case as an inclusive range.

    Rolls and bends: exactly 1. Single rods: eq. (1)'s odd n +-2 (at least 1). Parallel rods
    in waves: any odd n from 3 up to the lone rod's eq. (1) n + 2 (the bundle's is smaller).
    """
    if set(c.families) <= set(_N1):
        return 1, 1
    n_eq1 = int(theory_model.n(c.h, eps0, L, b=b, E_B=E_B, E=E, t=t))
    if c.N == 1:
        return max(1, n_eq1 - 2), n_eq1 + 2
    return 3, n_eq1 + 2


def _num(row: pd.Series, col: str) -> float:
    try:
        v = float(row.get(col))
    except (TypeError, ValueError):
        return math.nan
    return v


def _find(df: pd.DataFrame, c: SentinelCase) -> pd.Series | None:
    """The table row of a case (matched on h, N, s; s = 0 for single rods)."""
    if df.empty:
        return None
    h = pd.to_numeric(df.get("h"), errors="coerce")
    n_rods = pd.to_numeric(df.get("N"), errors="coerce")
    mask = (h - c.h).abs() < 1e-9
    mask &= n_rods == c.N
    if c.N > 1 and "s" in df:
        mask &= (pd.to_numeric(df["s"], errors="coerce") - c.s).abs() < 1e-9
    rows = df[mask]
    return None if rows.empty else rows.iloc[0]


def judge(df: pd.DataFrame) -> list[dict[str, Any]]:
    """One dict per sentinel case: the run's n, family, onset and R_up/R_down beside the
    study's expectation, with ``family_ok`` / ``n_ok`` / ``updown_ok`` (None: not judged)."""
    out: list[dict[str, Any]] = []
    df = df.assign(_n=n_values(df)) if not df.empty else df
    for c in SENTINEL_CASES:
        row = _find(df, c)
        rec: dict[str, Any] = {"case": c.label, "h": c.h, "N": c.N, "s": c.s if c.N > 1 else None,
                               "where": c.where, "expect_family": "/".join(c.families),
                               "status": "missing"}
        if row is None:
            out.append(rec)
            continue
        mat = {k: _num(row, k) for k in ("L", "eps0", "b", "E_B", "E", "t")}
        lo, hi = expected_n(c, L=mat["L"], eps0=mat["eps0"], b=mat["b"], E_B=mat["E_B"], E=mat["E"],
                            t=mat["t"])
        rec.update(status=str(row.get("status")), expect_n=(lo, hi))
        if rec["status"] != "ok":
            rec["error"] = str(row.get("error") or "?").splitlines()[0][:120]
            out.append(rec)
            continue
        n = _num(row, "_n")
        r_up, r_down = _num(row, "R_up_mean"), _num(row, "R_down_mean")
        ratio = r_up / r_down if r_down and math.isfinite(r_up / r_down) else math.nan
        family = str(row.get("family"))
        rec.update(
            n=None if math.isnan(n) else int(n),
            family=family,
            onset=_num(row, "onset_release_strain"),
            l=_num(row, "l_mean"),
            R_up_over_down=ratio,
            family_ok=family in c.families,
            n_ok=(not math.isnan(n)) and lo <= n <= hi,
            updown_ok=(ratio < 1.0) if (math.isfinite(ratio) and not math.isnan(n) and n >= 3)
            else None,
            newton_iterations=_num(row, "newton_iterations"),
            elapsed_s=_num(row, "elapsed_s"),
        )
        out.append(rec)
    return out


def summary(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Scores over the judged cases: families, n, up/down matched, and the onset spread."""
    done = [r for r in rows if r.get("status") == "ok"]
    singles = [r for r in done if r["N"] == 1 and math.isfinite(r.get("onset", math.nan))]
    onsets = [r["onset"] for r in singles if r["onset"] > 0]
    spread = max(onsets) / min(onsets) if len(onsets) >= 2 else math.nan
    ud = [r["updown_ok"] for r in done if r.get("updown_ok") is not None]
    return {
        "cases": len(rows),
        "ok": len(done),
        "family_match": sum(bool(r["family_ok"]) for r in done),
        "n_match": sum(bool(r["n_ok"]) for r in done),
        "updown_match": sum(bool(v) for v in ud),
        "updown_judged": len(ud),
        "onset_min": min(onsets) if onsets else math.nan,
        "onset_max": max(onsets) if onsets else math.nan,
        "onset_spread": spread,
        "onset_ok": (spread <= ONSET_SPREAD_MAX) if math.isfinite(spread) else None,
        "elapsed_s": sum(r.get("elapsed_s", 0.0) or 0.0 for r in done
                         if math.isfinite(r.get("elapsed_s", math.nan))),
    }


def _mark(ok: bool | None) -> str:
    return "" if ok is None else ("MATCH" if ok else "MISMATCH")


def _g(x: Any, fmt: str) -> str:
    try:
        xf = float(x)
    except (TypeError, ValueError):
        return "-"
    return "-" if not math.isfinite(xf) else format(xf, fmt)


def markdown(rows: list[dict[str, Any]], setup: dict[str, Any] | None = None) -> str:
    """The sentinel's table and scores as markdown."""
    s = summary(rows)
    lines = [
        "## Sentinel: this set-up against the study",
        "",
        f"set-up (changes from the defaults): `{setup or {}}`",
        "",
        "| case | where | family (study) | family | n (study) | n | onset | l [mm] "
        "| R_up/R_down | verdict |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        if r.get("status") != "ok":
            lines.append(f"| {r['case']} | {r['where']} | {r['expect_family']} | "
                         f"{r.get('status')} | | | | | | {r.get('error', '')} |")
            continue
        lo, hi = r["expect_n"]
        verdict = ", ".join(v for v in (
            f"family {_mark(r['family_ok'])}", f"n {_mark(r['n_ok'])}",
            f"up/down {_mark(r['updown_ok'])}" if r["updown_ok"] is not None else "") if v)
        lines.append(
            f"| {r['case']} | {r['where']} | {r['expect_family']} | {r['family']} | "
            f"{lo if lo == hi else f'{lo}-{hi}'} | {r['n']} | {_g(r['onset'], '.4f')} | "
            f"{_g(r['l'], '.3g')} | {_g(r['R_up_over_down'], '.3f')} | {verdict} |")
    lines += [
        "",
        f"- families: {s['family_match']} of {s['ok']} MATCH; n: {s['n_match']} of {s['ok']}; "
        f"up more curved than down (R_up/R_down < 1, runs with n >= 3): {s['updown_match']} of "
        f"{s['updown_judged']}",
        f"- onset (single rods, release strain where a rod stands out by h): "
        f"{_g(s['onset_min'], '.4f')} to {_g(s['onset_max'], '.4f')}, max/min "
        f"{_g(s['onset_spread'], '.2f')} (the study: one critical strain for all h; MATCH "
        f"when <= {ONSET_SPREAD_MAX:g}): {_mark(s['onset_ok'])}",
        f"- {s['ok']} of {s['cases']} runs ok; their run times add up to "
        f"{_g(s['elapsed_s'], '.0f')} s",
        "",
    ]
    return "\n".join(lines)


def compare_markdown(entries: list[tuple[str, dict[str, Any] | None, list[dict[str, Any]]]]
                     ) -> str:
    """Candidate set-ups side by side: one row per candidate (``entries``: label, set-up,
    :func:`judge` rows), its scores, then each case's family and n (``*`` where it differs
    from the study)."""
    labels = [c.label for c in SENTINEL_CASES]
    head = ("| candidate | set-up | families | n | up/down | onset min-max (max/min) | "
            + " | ".join(labels) + " |")
    lines = ["## Sentinel: candidate set-ups against the study", "",
             "Each case: family initial and n (w waves, c coherent, i independent, r rolls, "
             "b bends; * where the family or n differs from the study).", "", head,
             "|" + "---|" * (5 + len(labels))]
    study = " | ".join("/".join(f[0] for f in c.families) for c in SENTINEL_CASES)
    lines.append(f"| the study | | | | R_up < R_down | one strain | {study} |")
    for label, setup, rows in entries:
        s = summary(rows)
        cells = []
        for r in rows:
            if r.get("status") != "ok":
                cells.append(str(r.get("status")))
                continue
            star = "" if (r["family_ok"] and r["n_ok"]) else "*"
            cells.append(f"{(r['family'] or '?')[0]}{r['n']}{star}")
        onset = (f"{_g(s['onset_min'], '.3f')}-{_g(s['onset_max'], '.3f')} "
                 f"({_g(s['onset_spread'], '.2f')})")
        lines.append(
            f"| {label} | `{setup or {}}` | {s['family_match']}/{s['ok']} | "
            f"{s['n_match']}/{s['ok']} | {s['updown_match']}/{s['updown_judged']} | {onset} | "
            + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"
