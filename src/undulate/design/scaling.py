"""Carrying the simulated atlases to other rod lengths and pre-stretches: one scaling variable.

The atlases were simulated at one rod length and one pre-stretch (L = 100 mm, eps0 = 0.5 on the
reference set-up). For a lone rod, the simulated number of half-waves collapses on one
variable,

    x = L / (l0(h) (eps0 / eps0_ref)^(-p)),     l0(h) = c0 + c1 h,

the number of the rod's own half-wave lengths that fit on it. l0 is the half-wave length of
rods with many waves (n >= 7 in the thickness sweep, where the ends do not set it: l = 1.89 +
41.4 h mm on the reference set-up), and the pre-stretch enters more weakly than eq. (1)'s
eps0^(-1/2): the simulated l changes with eps0 far less than eq. (1) says
(docs/studies/reproduction.md). c0, c1 and p are fitted on the single-rod tables
(:func:`fit_wavelength`; :func:`fit_exponent`: the thickness sweep at eps0_ref gives n(x),
the pre-stretch sweep chooses the p whose n(x) predicts its runs best) and shipped in
``data/scaling.json``, remade by::

    python -m undulate.design.scaling docs/studies/single-rod-h/table.csv \\
        docs/studies/single-rod-eps0/table.csv --out src/undulate/design/data/scaling.json

A case of length L and pre-stretch eps0 is then read off the atlas at the equivalent
thickness h', l0(h') = l0(h) (L_ref / L) (eps0 / eps0_ref)^(-p) (:func:`equivalent`), the
same x; its
lengths (l, a, and the gap s between rods) scale by L / L_ref, and lam also by the chord's
shortening (1 + eps0_ref) / (1 + eps0). What the collapse rests on, and what the
prediction benchmark (benchmarks/bench_predict.py) tests: that L enters only through x (the
end effects scale with the wave length), and that a group of rods scales as a lone rod does.
Units: mm.
"""

from __future__ import annotations

import argparse
import functools
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

__all__ = ["SCALING_FILE", "Scaling", "equivalent", "fit_exponent", "fit_wavelength",
           "load_scaling"]

#: the fitted exponent shipped in the package
SCALING_FILE = Path(__file__).with_name("data") / "scaling.json"


@dataclass(frozen=True)
class Scaling:
    """The fitted exponent ``p``, the half-wave length l0 = c0 + c1 h [mm], and where they
    came from (``fitted_on``; ``hits`` of ``runs`` of the pre-stretch sweep)."""

    p: float
    c0: float
    c1: float
    hits: int
    runs: int
    fitted_on: list[str]


def _x(h: np.ndarray, L: np.ndarray, eps0: np.ndarray, p: float, eps0_ref: float,
       c0: float = 0.0, c1: float = 1.0) -> np.ndarray:
    l0 = c0 + c1 * np.asarray(h, float)
    return np.asarray(L, float) / (l0 * (np.asarray(eps0, float) / eps0_ref) ** (-p))


def _ok(table: pd.DataFrame) -> pd.DataFrame:
    t = table[table["status"] == "ok"] if "status" in table else table
    return t.dropna(subset=["h", "L", "eps0", "n"])


def fit_wavelength(h_table: pd.DataFrame, n_min: int = 7) -> tuple[float, float]:
    """(c0, c1) of the half-wave length l = c0 + c1 h [mm] of the thickness sweep's runs
    with at least ``n_min`` half-waves (least squares): the rod's own length, where the
    rod is long enough that its ends do not set it."""
    t = _ok(h_table).dropna(subset=["l_mean"])
    t = t[t["n"] >= n_min]
    if len(t) < 2 or t["h"].nunique() < 2:
        raise ValueError(f"fit_wavelength: fewer than two thicknesses with n >= {n_min}")
    c1, c0 = np.polyfit(t["h"].to_numpy(float), t["l_mean"].to_numpy(float), 1)
    return float(c0), float(c1)


def fit_exponent(h_table: pd.DataFrame, eps0_table: pd.DataFrame,
                 grid: np.ndarray | None = None, c0: float = 0.0,
                 c1: float = 1.0) -> tuple[float, int, int]:
    """The exponent p that best predicts the pre-stretch sweep's n from the thickness sweep's
    n(x) (nearest x, in log), on a grid of p (default 0..1 by 0.01); ties: the middle of the
    best band. ``c0``, ``c1``: l0 (default: proportional to h). Returns (p, runs predicted
    right, runs)."""
    h_t, e_t = _ok(h_table), _ok(eps0_table)
    if h_t.empty or e_t.empty:
        raise ValueError("fit_exponent: a table without finished runs")
    eps0_ref = float(np.median(h_t["eps0"]))
    grid = np.round(np.arange(0.0, 1.001, 0.01), 2) if grid is None else grid
    hits = []
    for p in grid:
        xr = np.log(_x(h_t["h"], h_t["L"], h_t["eps0"], p, eps0_ref, c0, c1))
        xe = np.log(_x(e_t["h"], e_t["L"], e_t["eps0"], p, eps0_ref, c0, c1))
        nearest = np.abs(xe[:, None] - xr[None, :]).argmin(axis=1)
        hits.append(int(np.sum(h_t["n"].to_numpy()[nearest] == e_t["n"].to_numpy())))
    best = max(hits)
    band = [p for p, k in zip(grid, hits, strict=True) if k == best]
    return float(band[len(band) // 2]), best, len(e_t)


@functools.cache
def load_scaling(path: Path = SCALING_FILE) -> Scaling:
    """The shipped exponent (read once per process)."""
    d = json.loads(Path(path).read_text())
    return Scaling(float(d["p"]), float(d["c0"]), float(d["c1"]), int(d["hits"]),
                   int(d["runs"]), list(d["fitted_on"]))


def equivalent(h: float, L: float, eps0: float, *, L_ref: float, eps0_ref: float,
               p: float, c0: float = 0.0, c1: float = 1.0) -> tuple[float, float]:
    """(h', k): the thickness that has at (L_ref, eps0_ref) the x of (h, L, eps0) (nan when
    no positive one has), and the factor L / L_ref by which the case's lengths are those of
    the reference."""
    l_eq = (c0 + c1 * h) * (L_ref / L) * (eps0 / eps0_ref) ** (-p)
    h_eq = (l_eq - c0) / c1
    return (float(h_eq) if h_eq > 0 else float("nan")), float(L / L_ref)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description="Fit the atlases' scaling exponent p.")
    ap.add_argument("h_table", type=Path, help="single-rod-h table.csv")
    ap.add_argument("eps0_table", type=Path, help="single-rod-eps0 table.csv")
    ap.add_argument("--out", type=Path, default=SCALING_FILE)
    a = ap.parse_args(argv)
    h_table, eps0_table = pd.read_csv(a.h_table), pd.read_csv(a.eps0_table)
    c0, c1 = fit_wavelength(h_table)
    p, hits, runs = fit_exponent(h_table, eps0_table, c0=c0, c1=c1)
    a.out.write_text(json.dumps({"p": p, "c0": round(c0, 4), "c1": round(c1, 4), "hits": hits,
                                 "runs": runs,
                                 "fitted_on": [a.h_table.as_posix(), a.eps0_table.as_posix()]},
                                indent=1) + "\n")
    print(f"l0 = {c0:.3g} + {c1:.4g} h mm; p = {p:g}: {hits} of {runs} runs of the "
          f"pre-stretch sweep predicted right; wrote {a.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
