"""Rods with many half-waves: their n from one fit over every simulated rod, not one atlas.

A thin rod carries many half-waves, and its n moves by two (one merge) over a small change of
h, L or eps0. Read off the nearest point of one atlas, a design between two simulated
thicknesses takes that point's n, which is one merge off about every third time at the thin
end (held out: 131 of 169 lone rods, 89 of 144 rods of groups). Over all simulated rods with
at least five half-waves (lone rods of every (L, eps0) of the grid and the sweeps, and the
rods of five-rod groups at least 5 mm apart) n follows one power law,

    log n = k0 + kL log L + ke log eps0 + kl log l0(h) + kg [a rod of a group],

with l0(h) = c0 + c1 h the half-wave length of :mod:`undulate.design.scaling` (on the
reference set-up about n ~ L eps0^0.23 / l0^1.13, and a group's rods about 5 % more
half-waves than a lone rod's). :func:`waves_n` rounds it to the nearest odd n (half-waves
come in odd numbers on a symmetric rod). Held out (each (L, eps0) removed in turn and the
fit made on the rest), it gives the simulated n to 142 of those 169 lone rods and 128 of
the 144 rods of groups.

The fit ships in ``data/waves.json``, remade from the tables by::

    python -m undulate.design.waves docs/studies/single-rod-h/table.csv ... --out \\
        src/undulate/design/data/waves.json

(the command with every table is in docs/studies/predict-data/README.md). Units: mm.
"""

from __future__ import annotations

import argparse
import functools
import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from .scaling import load_scaling

__all__ = ["N_MIN", "WAVES_FILE", "WavesFit", "fit_waves", "load_waves", "waves_n"]

#: the fit shipped in the package
WAVES_FILE = Path(__file__).with_name("data") / "waves.json"
#: the fewest half-waves a rod has for the fit to count it (and to answer for it)
N_MIN = 5
#: the smallest gap [mm] at which a group's rods enter the fit (closer, they share longer
#: waves: docs/design.md, "Groups beyond the diagrams")
GROUP_GAP = 5.0


@dataclass(frozen=True)
class WavesFit:
    """The coefficients (k0, kL, ke, kl, kg) of log n, the half-wave length l0 = c0 + c1 h
    [mm] they use, the rod width ``b`` [mm] and set-up of the runs, how many ``runs`` (lone,
    of groups) and which tables (``fitted_on``)."""

    coef: tuple[float, float, float, float, float]
    c0: float
    c1: float
    b: float
    runs: tuple[int, int]
    fitted_on: tuple[str, ...]


def _features(h: np.ndarray, L: np.ndarray, eps0: np.ndarray, group: np.ndarray,
              c0: float, c1: float) -> np.ndarray:
    h = np.asarray(h, float)
    return np.column_stack([np.ones_like(h), np.log(np.asarray(L, float)),
                            np.log(np.asarray(eps0, float)), np.log(c0 + c1 * h),
                            np.asarray(group, float)])


def _rods(table: pd.DataFrame) -> pd.DataFrame:
    """The runs a fit takes: finished, >= N_MIN half-waves (the rods' most common n), lone
    rods or rods of groups >= GROUP_GAP apart, of the most common rod width (a group's
    s = 0 run is one rod N times as wide: left out)."""
    t = table[table["status"] == "ok"] if "status" in table else table
    n_col = "n_mode" if "n_mode" in t else "n"
    t = t.assign(n_fit=pd.to_numeric(t[n_col], errors="coerce").round(),
                 group=(t["N"] > 1).astype(float))
    t = t.dropna(subset=["h", "L", "eps0", "n_fit"])
    t = t[(t["n_fit"] >= N_MIN) & ((t["group"] == 0) | (t["s"] >= GROUP_GAP))]
    return t[np.isclose(t["b"], t["b"].mode().iloc[0])] if "b" in t else t


def fit_waves(tables: list[pd.DataFrame], c0: float, c1: float,
              fitted_on: tuple[str, ...] = ()) -> WavesFit:
    """Least squares of log n on the features over the runs of ``tables`` (study tables of
    lone rods and of groups, one row per run, as ``undulate study`` writes them) with at
    least :data:`N_MIN` half-waves. Raises ValueError when they do not span L, eps0, h and
    both kinds (lone, group)."""
    t = _rods(pd.concat(tables, ignore_index=True))
    if t["group"].nunique() < 2 or min(t[k].nunique() for k in ("h", "L", "eps0")) < 2:
        raise ValueError("fit_waves: the runs with many half-waves must span h, L, eps0 and "
                         "hold both lone rods and groups")
    b = t["b"].unique() if "b" in t else np.array([1.0])
    x = _features(t["h"], t["L"], t["eps0"], t["group"], c0, c1)
    k, *_ = np.linalg.lstsq(x, np.log(t["n_fit"].to_numpy(float)), rcond=None)
    lone = int((t["group"] == 0).sum())
    return WavesFit(coef=tuple(round(float(v), 5) for v in k),  # type: ignore[arg-type]
                    c0=c0, c1=c1, b=float(b[0]), runs=(lone, len(t) - lone),
                    fitted_on=tuple(fitted_on))


def waves_n(fit: WavesFit, h: float, L: float, eps0: float, group: bool) -> int:
    """The odd n nearest the fit's for a rod of thickness ``h`` and length ``L`` [mm] at
    pre-stretch ``eps0``, alone or in a group (never below :data:`N_MIN`: the fit knows
    only rods with that many)."""
    x = _features(np.array([h]), np.array([L]), np.array([eps0]), np.array([float(group)]),
                  fit.c0, fit.c1)
    n = math.exp(float(x[0] @ np.asarray(fit.coef)))
    return max(N_MIN, 2 * round((n - 1.0) / 2.0) + 1)


@functools.cache
def load_waves(path: Path = WAVES_FILE) -> WavesFit:
    """The shipped fit (read once per process)."""
    d = json.loads(Path(path).read_text())
    return WavesFit(coef=tuple(d["coef"]), c0=float(d["c0"]), c1=float(d["c1"]),
                    b=float(d["b"]), runs=tuple(d["runs"]), fitted_on=tuple(d["fitted_on"]))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description="Fit n of the rods with many half-waves.")
    ap.add_argument("tables", nargs="+", type=Path, help="study table.csv files")
    ap.add_argument("--out", type=Path, default=WAVES_FILE)
    a = ap.parse_args(argv)
    sc = load_scaling()
    fit = fit_waves([pd.read_csv(p) for p in a.tables], sc.c0, sc.c1,
                    tuple(p.as_posix() for p in a.tables))
    a.out.write_text(json.dumps({"coef": list(fit.coef), "c0": fit.c0, "c1": fit.c1,
                                 "b": fit.b, "runs": list(fit.runs),
                                 "fitted_on": list(fit.fitted_on)}, indent=1) + "\n")
    k = fit.coef
    print(f"log n = {k[0]:.4g} + {k[1]:.4g} log L + {k[2]:.4g} log eps0 + {k[3]:.4g} log l0 "
          f"+ {k[4]:.4g} [group], on {fit.runs[0]} runs of lone rods and {fit.runs[1]} of "
          f"groups; wrote {a.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
