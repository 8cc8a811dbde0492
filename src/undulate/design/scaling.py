"""Carrying the simulated atlases to other rod lengths and pre-stretches: one scaling variable.

The atlases were simulated at one rod length and one pre-stretch (L = 100 mm, eps0 = 0.5 on the
reference set-up). For a lone rod, the simulated number of half-waves collapses on one
variable,

    x = L / (h (eps0 / eps0_ref)^(-p)),

the number of wave lengths eq. (1) would fit on the rod (l proportional to h) with the
pre-stretch entering more weakly than eq. (1)'s eps0^(-1/2): the simulated l changes with
eps0 far less than eq. (1) says (docs/studies/reproduction.md). The exponent p is fitted on
the single-rod tables (:func:`fit_exponent`: the thickness sweep at eps0_ref gives n(x), the
pre-stretch sweep chooses the p whose n(x) predicts its runs best) and shipped in
``data/scaling.json``, remade by::

    python -m undulate.design.scaling docs/studies/single-rod-h/table.csv \\
        docs/studies/single-rod-eps0/table.csv --out src/undulate/design/data/scaling.json

A case of length L and pre-stretch eps0 is then read off the atlas at the equivalent
thickness h' = h (L_ref / L) (eps0 / eps0_ref)^(-p) (:func:`equivalent`), the same x; its
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

__all__ = ["SCALING_FILE", "Scaling", "equivalent", "fit_exponent", "load_scaling"]

#: the fitted exponent shipped in the package
SCALING_FILE = Path(__file__).with_name("data") / "scaling.json"


@dataclass(frozen=True)
class Scaling:
    """The fitted exponent ``p`` and where it came from (``fitted_on``, ``hits``, ``runs``)."""

    p: float
    hits: int
    runs: int
    fitted_on: list[str]


def _x(h: np.ndarray, L: np.ndarray, eps0: np.ndarray, p: float, eps0_ref: float) -> np.ndarray:
    return np.asarray(L, float) / (np.asarray(h, float) * (np.asarray(eps0, float) / eps0_ref)
                                   ** (-p))


def _ok(table: pd.DataFrame) -> pd.DataFrame:
    t = table[table["status"] == "ok"] if "status" in table else table
    return t.dropna(subset=["h", "L", "eps0", "n"])


def fit_exponent(h_table: pd.DataFrame, eps0_table: pd.DataFrame,
                 grid: np.ndarray | None = None) -> tuple[float, int, int]:
    """The exponent p that best predicts the pre-stretch sweep's n from the thickness sweep's
    n(x) (nearest x, in log), on a grid of p (default 0..1 by 0.01); ties: the middle of the
    best band. Returns (p, runs predicted right, runs)."""
    h_t, e_t = _ok(h_table), _ok(eps0_table)
    if h_t.empty or e_t.empty:
        raise ValueError("fit_exponent: a table without finished runs")
    eps0_ref = float(np.median(h_t["eps0"]))
    grid = np.round(np.arange(0.0, 1.001, 0.01), 2) if grid is None else grid
    hits = []
    for p in grid:
        xr = np.log(_x(h_t["h"], h_t["L"], h_t["eps0"], p, eps0_ref))
        xe = np.log(_x(e_t["h"], e_t["L"], e_t["eps0"], p, eps0_ref))
        nearest = np.abs(xe[:, None] - xr[None, :]).argmin(axis=1)
        hits.append(int(np.sum(h_t["n"].to_numpy()[nearest] == e_t["n"].to_numpy())))
    best = max(hits)
    band = [p for p, k in zip(grid, hits, strict=True) if k == best]
    return float(band[len(band) // 2]), best, len(e_t)


@functools.cache
def load_scaling(path: Path = SCALING_FILE) -> Scaling:
    """The shipped exponent (read once per process)."""
    d = json.loads(Path(path).read_text())
    return Scaling(float(d["p"]), int(d["hits"]), int(d["runs"]), list(d["fitted_on"]))


def equivalent(h: float, L: float, eps0: float, *, L_ref: float, eps0_ref: float,
               p: float) -> tuple[float, float]:
    """(h', k): the thickness that has at (L_ref, eps0_ref) the x of (h, L, eps0), and the
    factor L / L_ref by which the case's lengths are those of the reference."""
    h_eq = h * (L_ref / L) * (eps0 / eps0_ref) ** (-p)
    return float(h_eq), float(L / L_ref)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description="Fit the atlases' scaling exponent p.")
    ap.add_argument("h_table", type=Path, help="single-rod-h table.csv")
    ap.add_argument("eps0_table", type=Path, help="single-rod-eps0 table.csv")
    ap.add_argument("--out", type=Path, default=SCALING_FILE)
    a = ap.parse_args(argv)
    p, hits, runs = fit_exponent(pd.read_csv(a.h_table), pd.read_csv(a.eps0_table))
    a.out.write_text(json.dumps({"p": p, "hits": hits, "runs": runs,
                                 "fitted_on": [a.h_table.as_posix(), a.eps0_table.as_posix()]},
                                indent=1) + "\n")
    print(f"p = {p:g}: {hits} of {runs} runs of the pre-stretch sweep predicted right; "
          f"wrote {a.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
