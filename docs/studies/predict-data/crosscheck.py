"""Cross-check of `undulate predict` on simulated data it did not see: leave one atlas out.

    python docs/studies/predict-data/crosscheck.py STUDY [STUDY ...]  # folders or table.csv

Each study (a sweep over rods.h and maybe rods.L, release.eps0, e.g. single-rod-grid.toml) is
cut into one atlas per (L, eps0), as `undulate study atlas` does. Then each of these atlases
in turn is held out: its runs are predicted from the shipped atlases of their kind plus the
other atlases of the studies (the held-out one and any shipped atlas at the same L and eps0
removed), and the predicted n and family are compared with the simulated ones. Printed per
rule of choosing an atlas:

- "nearest (L, eps0)": what predict does (the atlas nearest in log L and log eps0);
- "L = 100, eps0 = 0.5 only": the shipped single-rod sweep alone (the rule before the grid);
- "theory": eq. (1) and the phase map.

Held-out points are farther from the atlases that answer them than a new case is from the
full set (the grid's step is doubled where one is removed), so the rates are pessimistic.
"""

from __future__ import annotations

import functools
import sys
from collections import defaultdict
from pathlib import Path

import pandas as pd

from undulate.design.atlas import build_atlas
from undulate.design.predict import _atlases, predict_case
from undulate.design.waves import fit_waves, load_waves
from undulate.model import case_from_dict
from undulate.study import collect

_SAME = 0.02  # relative tolerance of "the same L, eps0"


def _case(row: pd.Series) -> object:
    return case_from_dict({
        "rods": {"h": float(row["h"]), "L": float(row["L"]), "N": int(row["N"]),
                 "s": float(row["s"]), "b": float(row["b"]), "E_B": float(row["E_B"])},
        "release": {"eps0": float(row["eps0"])},
        "fabric": {"E": float(row["E"]), "t": float(row["t"])}})


def _same(meta: dict, L: float, eps0: float) -> bool:
    return (abs(float(meta["L"]) - L) <= _SAME * L
            and abs(float(meta["eps0"]) - eps0) <= _SAME * eps0)


@functools.cache
def _fit_tables(names: tuple[str, ...]) -> tuple[pd.DataFrame, ...]:
    """The tables the shipped fit was made on, read once."""
    root = Path(__file__).resolve().parents[3]
    return tuple(pd.read_csv(root / name) for name in names)


def _waves_without(L: float, eps0: float) -> object:
    """The many-half-waves fit (undulate.design.waves) remade on its tables without the runs
    at (L, eps0), so that the held-out atlas's runs do not answer themselves."""
    shipped = load_waves()
    tables = []
    for t in _fit_tables(shipped.fitted_on):
        here = (abs(t["L"] - L) <= _SAME * L) & (abs(t["eps0"] - eps0) <= _SAME * eps0)
        tables.append(t[~here])
    return fit_waves(tables, shipped.c0, shipped.c1)


def main(dirs: list[str]) -> int:
    table = pd.concat([pd.read_csv(d) if d.endswith(".csv") else collect(d) for d in dirs],
                      ignore_index=True)
    table = table[table["status"] == "ok"]
    groups = {(float(L), float(e)): g for (L, e), g in table.groupby(["L", "eps0"])}
    own = [(f"L{L:g}_eps0-{e:g}", build_atlas(g)) for (L, e), g in groups.items()]
    shipped = _atlases()
    rules = ("nearest (L, eps0)", "L = 100, eps0 = 0.5 only", "theory")
    hits: dict[str, list[int]] = defaultdict(lambda: [0, 0, 0])  # rule -> cases, n, family
    by_h: dict[tuple[str, str], list[int]] = defaultdict(lambda: [0, 0, 0])
    for (L, e), g in groups.items():
        others = [(n, a) for n, a in own + shipped if not _same(a.meta, L, e)]
        base = [(n, a) for n, a in shipped
                if _same(a.meta, 100.0, 0.5) and not _same(a.meta, L, e)]
        waves = _waves_without(L, e)
        for _, row in g.iterrows():
            case = _case(row)
            sim_n = int(row["n_mode"] if "n_mode" in row else row["n"])
            sim_f = str(row["family"])
            answers = {rules[0]: predict_case(case, atlases=others, waves=waves),
                       rules[1]: predict_case(case, atlases=base, waves=waves),
                       rules[2]: predict_case(case, "theory")}
            band = f"L = {L:g}, eps0 = {e:g}"
            for rule, p in answers.items():
                for key in (rule, (rule, band)):
                    tally = hits[key] if isinstance(key, str) else by_h[key]
                    tally[0] += 1
                    tally[1] += int(p["rods"][0]["n"] == sim_n)
                    tally[2] += int(p["family"] == sim_f)
    print(f"{len(table)} runs in {len(groups)} atlases (L, eps0), each held out in turn")
    print("| rule | runs | n right | family right |")
    print("|---|---|---|---|")
    for rule in rules:
        c, n, f = hits[rule]
        print(f"| {rule} | {c} | {n} ({100 * n / c:.0f} %) | {f} ({100 * f / c:.0f} %) |")
    print("\nby held-out atlas (rule: runs, n right, family right):")
    for band in sorted({b for _, b in by_h}):
        print(f"  {band}: " + "; ".join(
            f"{rule} {by_h[rule, band][0]}, {by_h[rule, band][1]}, {by_h[rule, band][2]}"
            for rule in rules))
    return 0


if __name__ == "__main__":
    if len(sys.argv) < 2:
        raise SystemExit(__doc__)
    raise SystemExit(main(sys.argv[1:]))
