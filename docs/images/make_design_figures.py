"""Figures of docs/design.md: what `undulate predict` answers, and from which data.

    python docs/images/make_design_figures.py            # writes docs/images/predict-*.png

* ``predict-atlas.png``: the simulated phase diagram shipped with undulate (five rods, the
  reference set-up), each simulated (h, s) point coloured by its family and labelled with its
  n, and four designs placed on it with what ``undulate predict`` says of them (family, n,
  confidence);
* ``predict-single.png``: a lone rod's n against h, simulated (the shipped single-rod atlas)
  and from eq. (1) alone, where the two part;
* ``predict-grid.png``: a lone rod's simulated n against h at every rod length and
  pre-stretch of the shipped single-rod grid (the atlases a case is scaled from).

No simulation is run: the figures read the package's atlases (``undulate study atlas`` makes
them from the study tables) and call the predictor as the command line does. Seconds.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from undulate import theory as T  # noqa: E402
from undulate.design.atlas import ATLAS_FILE, load_atlas  # noqa: E402
from undulate.design.predict import predict_case  # noqa: E402
from undulate.model import case_from_dict  # noqa: E402

COLOURS = {"coherent": "#3465a4", "independent": "#73d216", "rolls": "#cc0000",
           "bends": "#f57900", "waves": "#75507b", "flat": "#888a85"}
#: designs placed on the five-rod diagram: (h, s) of five 100 mm rods, E_B = 1000 MPa
DESIGNS = [(0.3, 10.0), (0.55, 12.0), (1.2, 20.0), (0.1, 40.0)]


def _five(h: float, s: float) -> dict:
    return {"rods": {"N": 5, "h": h, "s": s, "L": 100.0, "E_B": 1000.0},
            "release": {"eps0": 0.5}}


def _gaps(values) -> dict[float, float]:
    """Per simulated value, the gap to its nearest simulated neighbour."""
    u = np.unique(np.asarray(values, dtype=float))
    if u.size < 2:
        return {float(v): 1.0 for v in u}
    d = np.diff(u)
    near = np.minimum(np.r_[np.inf, d], np.r_[d, np.inf])
    return {float(v): float(g) for v, g in zip(u, near, strict=True)}


def atlas_figure(out: Path) -> Path:
    atlas = load_atlas(ATLAS_FILE)
    pts = atlas.points
    fig, ax = plt.subplots(figsize=(8.0, 5.6))
    # each point a cell as large as the gaps to its simulated neighbours (the thin end has
    # refined rows)
    h_gap = {s: _gaps(d["h"]) for s, d in pts.groupby("s")}  # along each column
    s_gap = {h: _gaps(d["s"]) for h, d in pts.groupby("h")}  # along each row
    seen = set()
    for _, r in pts.iterrows():
        w = 0.85 * min(s_gap[r["h"]][r["s"]], atlas.meta["s_step"])
        t = 0.85 * h_gap[r["s"]][r["h"]]
        fam = str(r["family"])
        ax.add_patch(plt.Rectangle((r["s"] - w / 2, r["h"] - t / 2), w, t, lw=0,
                                   color=COLOURS.get(fam, "k"), alpha=0.55,
                                   label=None if fam in seen else f"{fam} (simulated)"))
        seen.add(fam)
        ax.text(r["s"], r["h"], str(int(r["n"])), ha="center", va="center",
                fontsize=6 if t >= 0.05 else 4)
    ax.autoscale_view()
    for h, s in DESIGNS:
        p = predict_case(case_from_dict(_five(h, s)))
        n = p["rods"][len(p["rods"]) // 2]["n"]
        ax.plot(s, h, marker="*", ms=16, color="k", mec="w", zorder=5)
        ax.annotate(f"h = {h:g}, s = {s:g}: {p['family']} n = {n}\n({p['confidence']})",
                    (s, h), xytext=(10, 8), textcoords="offset points", fontsize=7.5,
                    bbox=dict(boxstyle="round,pad=0.25", fc="w", ec="0.6", alpha=0.9),
                    zorder=6)
    meta = atlas.meta
    ax.set_xlabel("gap s between the rods [mm]")
    ax.set_ylabel("rod thickness h [mm]")
    ax.set_title(f"undulate predict on the shipped phase diagram: {meta.get('N')} rods, "
                 f"L = {meta.get('L'):g} mm, eps0 = {meta.get('eps0')}, E_B = "
                 f"{meta.get('E_B'):g} MPa ({meta.get('points')} simulated points; "
                 "number: n)", fontsize=9)
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), framealpha=0.9)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return out


def single_figure(out: Path) -> Path:
    atlas = load_atlas(ATLAS_FILE.with_name("single_rod.csv"))
    pts = atlas.points.sort_values("h")
    meta = atlas.meta
    hh = np.linspace(float(pts["h"].min()), float(pts["h"].max()), 400)
    mat = {"b": meta.get("b", 1.0), "E_B": meta["E_B"], "E": meta["E"], "t": meta["t"]}
    n_th = np.asarray(T.n(hh, meta["eps0"], meta["L"], **mat))
    fig, ax = plt.subplots(figsize=(7.5, 4.2))
    ax.step(hh, n_th, where="mid", color="0.5", lw=1.2, label="eq. (1) alone (theory)")
    for fam, d in pts.groupby("family"):
        ax.plot(d["h"], d["n"], "o", ms=4, color=COLOURS.get(fam, "k"),
                label=f"simulated: {fam}")
    ax.set_xlabel("rod thickness h [mm]")
    ax.set_ylabel("half-waves n")
    ax.set_title(f"A lone rod, L = {meta['L']:g} mm, eps0 = {meta['eps0']}, E_B = "
                 f"{meta['E_B']:g} MPa: what predict answers (simulated) and eq. (1)",
                 fontsize=9)
    ax.legend(fontsize=8)
    fig.savefig(out, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return out


def grid_figure(out: Path) -> Path:
    """n against h per (L, eps0) of the shipped single-rod grid, one panel per L."""
    from undulate.design.predict import _atlases

    grid = [a for name, a in _atlases() if name.startswith("single_rod_grid/")]
    lengths = sorted({float(a.meta["L"]) for a in grid})
    if not lengths:
        raise SystemExit("no single-rod grid shipped (src/undulate/design/data/single_rod_grid)")
    fig, axes = plt.subplots(1, len(lengths), figsize=(2.6 * len(lengths), 3.4), sharey=True)
    axes = np.atleast_1d(axes)
    eps = sorted({float(a.meta["eps0"]) for a in grid})
    shades = dict(zip(eps, plt.cm.viridis(np.linspace(0.0, 0.85, len(eps))), strict=True))
    for ax, L in zip(axes, lengths, strict=True):
        for a in sorted((a for a in grid if float(a.meta["L"]) == L),
                        key=lambda a: a.meta["eps0"]):
            pts = a.points.sort_values("h")
            e = float(a.meta["eps0"])
            ax.plot(pts["h"], pts["n"], "-", color=shades[e], lw=1.0, label=f"eps0 = {e:g}")
            for fam, d in pts.groupby("family"):
                ax.plot(d["h"], d["n"], "o", ms=3.2, color=COLOURS.get(fam, "k"), mec="none")
        ax.set_xscale("log")
        ax.set_title(f"L = {L:g} mm", fontsize=9)
        ax.set_xlabel("h [mm]")
    axes[0].set_ylabel("half-waves n (simulated)")
    axes[0].legend(fontsize=7)
    fig.suptitle("A lone rod over length and pre-stretch (reference set-up; dots coloured by "
                 "family: grey-violet waves, orange bends, red rolls)", fontsize=9)
    fig.savefig(out, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path(__file__).parent)
    a = ap.parse_args()
    for p in (atlas_figure(a.out / "predict-atlas.png"),
              single_figure(a.out / "predict-single.png"),
              grid_figure(a.out / "predict-grid.png")):
        print(f"wrote {p}")


if __name__ == "__main__":
    main()
