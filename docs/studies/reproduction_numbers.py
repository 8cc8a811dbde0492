"""The counts that docs/studies/reproduction.md quotes from the reference tables.

    python docs/studies/reproduction_numbers.py

Reads docs/studies/parallel-phase-diagram/table.csv and
docs/studies/single-rod-eps0-long/table.csv (no simulation) and prints: the families of the
five-rod runs, how often an outer rod reaches the onset first, the runs whose rods disagree
on n, the far corner's shallow inner rods, h* (the first h with n = 1) per gap, the master
curve's bands of l below h / h* = 1, lam / 2a of every one-arch rod, and the long rod's
take-up of the release (lam / 2l = 1 / (1 + eps_rod)) with the exponents of l against eps0
and against eps_rod.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd

HERE = Path(__file__).resolve().parent


def _lists(col: pd.Series) -> list[list]:
    return [json.loads(v) for v in col]


def diagram(path: Path = HERE / "parallel-phase-diagram" / "table.csv") -> None:
    t = pd.read_csv(path)
    t = t[t["status"] == "ok"]
    five = t[t["rods.s"] > 0]
    print(f"runs ok {len(t)}; five-rod {len(five)}: {five['family'].value_counts().to_dict()}; "
          f"s = 0: {t[t['rods.s'] == 0]['family'].value_counts().to_dict()}")
    first, late = 0, []
    for (_, r), on in zip(five.iterrows(), _lists(five["rods_onset_release_strain"]),
                          strict=True):
        outer, inner = min(on[0], on[-1]), min(on[1:-1])
        if outer <= inner:
            first += 1
        else:
            late.append((r["rods.h"], r["rods.s"], round(outer / inner - 1, 4)))
    print(f"an outer rod first in {first} of {len(five)}; the others (h, s, lag): {late}")
    ns = _lists(five["rods_n"])
    split = [(h, s, n) for h, s, n in zip(five["rods.h"], five["rods.s"], ns, strict=True)
             if len(set(n)) > 1]
    print(f"rods disagree on n in {len(split)} runs:",
          f"{sum(h == 0.1 for h, _, _ in split)} at h = 0.1,",
          f"{sum(h >= 1.6 for h, _, _ in split)} at h >= 1.6; others:",
          [x for x in split if 0.1 < x[0] < 1.6])
    corner = five[(five["rods.h"] >= 1.6) & pd.Series([3 in n for n in ns], index=five.index)]
    print("far corner (h >= 1.6, some rods n = 3):", corner["family"].value_counts().to_dict(),
          "coherent at", sorted(zip(corner[corner["family"] == "coherent"]["rods.h"],
                                    corner[corner["family"] == "coherent"]["rods.s"],
                                    strict=True))[:3], "...")
    h_star = {s: g[g["n_mode"] == 1]["rods.h"].min() for s, g in t.groupby("rods.s")}
    print("h* per s:", {float(s): float(h) for s, h in h_star.items()})
    x = t["rods.h"] / t["rods.s"].map(h_star)
    below = t[(x < 1) & (t["rods.s"] > 0)].assign(x=x)
    for lo, hi in ((0.1, 0.2), (0.3, 0.45), (0.55, 0.8)):
        g = below[(below["x"] >= lo) & (below["x"] < hi)]
        print(f"master curve, h / h* in [{lo}, {hi}): {len(g)} runs, l "
              f"{g['l_mean'].min():.1f}-{g['l_mean'].max():.1f} mm "
              f"(median {g['l_mean'].median():.1f})")
    rods = zip(_lists(t["rods_n"]), _lists(t["rods_lam"]), _lists(t["rods_a"]), strict=True)
    ratio = [la / (2 * a) for n_, lam_, a_ in rods
             for n, la, a in zip(n_, lam_, a_, strict=True) if n == 1 and la and a]
    print(f"one-arch rods: {len(ratio)}, lam / 2a min {min(ratio):.3f}, "
          f"median {np.median(ratio):.3f}")


def long_rod(path: Path = HERE / "single-rod-eps0-long" / "table.csv") -> None:
    t = pd.read_csv(path).sort_values("eps0")
    eps_rod = 2 * t["l_mean"] / t["lam_mean"] - 1
    print("long rod: eps0, eps_rod / eps0:",
          [(e, round(r / e, 2)) for e, r in zip(t["eps0"], eps_rod, strict=True)])
    print(f"l ~ eps0^{np.polyfit(np.log(t['eps0']), np.log(t['l_mean']), 1)[0]:.2f}, "
          f"l ~ eps_rod^{np.polyfit(np.log(eps_rod), np.log(t['l_mean']), 1)[0]:.2f}")


if __name__ == "__main__":
    diagram()
    long_rod()
