"""Figures of a study, from its tidy table (PNG + PDF in ``DIR/figures``).

Only the figures whose data exist are made:

1. ``single_rod_h``: l, lambda, a, R, n and fit quality vs h (h swept, s not), eq. (1) drawn;
2. ``l_vs_eps0``: l vs eps0, log-log, with eq. (1) (eps0 swept);
3. ``phase_diagram``: (h, s) coloured by family, s_hat from data (dashed) and formula (solid);
4. ``master_curve``: l (mean +- std over rods) vs h/h*, L/n marks, inset h* vs s;
5. ``quantized_flattening``: a and lambda vs h across the quantization plateaus;
6. ``onset``: onset of buckling vs h (single rods);
7. ``transitions``: the thicknesses h*_n of the transitions n+2 -> n vs s, with eq. (1)'s
   bundling (h and s swept);
8. ``onset_map``: onset of buckling over (h, s), and whether an outer rod went first.

Matplotlib's object API is used (no pyplot), so no display or backend is needed.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from .derived import (
    hstar,
    is_swept,
    material,
    n_values,
    ok_rows,
    outer_rod_first,
    per_point,
    theory,
)
from .storage import collect

__all__ = ["make_figures", "FIGURES"]

FAMILY_COLORS = {
    "coherent": "tab:blue",
    "independent": "tab:green",
    "rolls": "tab:red",
    "bends": "tab:orange",
}


#: thickness figures need at least this many distinct h (the eps0 study's three are a
#: parameter of that figure, not a sweep to plot against)
MIN_H_VALUES = 4


def _save(fig: Figure, outdir: Path, name: str) -> list[Path]:
    outdir.mkdir(parents=True, exist_ok=True)
    paths = []
    for ext in ("png", "pdf"):
        p = outdir / f"{name}.{ext}"
        fig.savefig(p, dpi=130 if ext == "png" else "figure")
        paths.append(p)
    return paths


def _num(df: pd.DataFrame, col: str) -> pd.Series:
    return pd.to_numeric(df[col], errors="coerce") if col in df else pd.Series(np.nan, df.index)


def _ln_marks(ax: Any, L: float, ymax: float, n_max: int = 9, side: str = "right") -> None:
    """Short ticks with labels at L/n (n odd) on one side of an axis."""
    x = 1.0 if side == "right" else 0.0
    for n in range(1, n_max + 1, 2):
        y = L / n
        if y > ymax * 1.05:
            continue
        ax.plot([x - 0.02, x], [y, y], color="k", lw=1.2, transform=ax.get_yaxis_transform(),
                clip_on=False)
        ax.text(x + 0.01, y, f"L/{n}", transform=ax.get_yaxis_transform(), va="center",
                fontsize=7)


def fig_single_rod_h(df: pd.DataFrame, outdir: Path) -> list[Path] | None:
    """l, lambda, a, R, n vs h for single rods (per eps0), with eq. (1) and its companions."""
    d = ok_rows(df)
    if (d.empty or not is_swept(d, "h") or is_swept(d, "s") or "l_mean" not in d
            or d["h"].nunique() < MIN_H_VALUES):
        return None
    d = d.assign(n=n_values(d))
    th = theory()
    mat = material(d)
    L = float(d["L"].median()) if "L" in d else 100.0
    cols = ["l_mean", "lam_mean", "a_mean", "R_mean", "n", "r2_arcs_mean", "r2_sine_mean"]
    pts = per_point(d, ["eps0", "h"], cols)
    fig = Figure(figsize=(12, 7), layout="constrained")
    axes = fig.subplots(2, 3, sharex=True).ravel()
    panels = [("l_mean", "arc length l [mm]", "l"), ("lam_mean", "wavelength λ [mm]", None),
              ("a_mean", "amplitude a [mm]", "a"), ("R_mean", "radius R [mm]", "R"),
              ("n", "half-waves n", None)]
    hh = np.linspace(0.0, float(d["h"].max()) * 1.02, 200)
    for (eps0, g), color in zip(pts.groupby("eps0"), _cycle(), strict=False):
        for ax, (col, label, key) in zip(axes, panels, strict=False):
            if col not in g:
                continue
            ax.errorbar(g["h"], g[col], yerr=g.get(f"{col}_sd"), fmt="o", ms=3, color=color,
                        label=f"simulation, ε0={eps0:g}")
            if key is not None:
                ax.plot(hh, th[key](hh, eps0, **mat), "-", color=color, alpha=0.7,
                        label={"l": "eq. (1)", "a": "a formula", "R": "l/√(24ε0)"}[key]
                        + f", ε0={eps0:g}")
            ax.set_ylabel(label)
        n_pred = th["n"](hh[1:], eps0, L, **mat)  # docs/theory.md: odd integer nearest L/l
        axes[4].step(hh[1:], n_pred, where="mid", color=color, alpha=0.7,
                     label=f"odd n nearest L/l, ε0={eps0:g}")
        if "r2_arcs_mean" in g:
            axes[5].plot(g["h"], g["r2_arcs_mean"], "o-", ms=3, color=color, label="arcs")
        if "r2_sine_mean" in g:
            axes[5].plot(g["h"], g["r2_sine_mean"], "s--", ms=3, color=color, mfc="none",
                         label="sine")
    lmax = float(np.nanmax(_num(d, "l_mean"))) if d["l_mean"].notna().any() else L
    axes[0].set_ylim(0, max(lmax, 1e-9) * 1.15)
    for n in range(1, 10, 2):
        if L / n <= lmax * 1.15:
            axes[0].axhline(L / n, color="0.6", lw=0.7, ls=":")
            axes[0].text(0.01, L / n, f"L/{n}", fontsize=7, va="bottom", color="0.4",
                         transform=axes[0].get_yaxis_transform())
    axes[1].set_ylim(bottom=0)
    nmax = float(np.nanmax(_num(d, "n"))) if d["n"].notna().any() else 1.0
    axes[4].set_ylim(0, max(nmax, 3.0) * 1.15)
    axes[5].set_ylabel("fit R²")
    locs = ["upper left"] * 4 + ["upper right", "lower left"]
    for ax, loc in zip(axes, locs, strict=True):
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc=loc)  # an explicit loc: "best" is slow with many points
    for ax in axes[3:]:
        ax.set_xlabel("rod thickness h [mm]")
    fig.suptitle(f"Single rod, thickness sweep (L = {L:g} mm; theory: {th['source']})")
    return _save(fig, outdir, "single_rod_h")


def fig_onset(df: pd.DataFrame, outdir: Path) -> list[Path] | None:
    """Onset of buckling vs h (single rods, per eps0): the release strain where the rod
    first stands out of its printed level by h (mean +- std over seeds), and the first
    release step that needed negative curvature."""
    d = ok_rows(df)
    if (d.empty or not is_swept(d, "h") or is_swept(d, "s") or "onset_release_strain" not in d
            or d["h"].nunique() < MIN_H_VALUES):
        return None
    cols = ["onset_release_strain", "onset_negative_curvature_release_strain"]
    pts = per_point(d, ["eps0", "h"], cols)
    if pts["onset_release_strain"].notna().sum() == 0:
        return None
    fig = Figure(figsize=(6.5, 4.5), layout="constrained")
    ax = fig.subplots()
    for (eps0, g), color in zip(pts.groupby("eps0"), _cycle(), strict=False):
        ax.errorbar(g["h"], g["onset_release_strain"], yerr=g.get("onset_release_strain_sd"),
                    fmt="o", ms=3, color=color,
                    label=f"deflection > h (interpolated), ε0={eps0:g}")
        if cols[1] in g and g[cols[1]].notna().any():
            ax.plot(g["h"], g[cols[1]], "s", ms=3, mfc="none", color=color, alpha=0.6,
                    label=f"first negative-curvature step, ε0={eps0:g}")
    ax.set_xlabel("rod thickness h [mm]")
    ax.set_ylabel("release strain at the onset [-]")
    ax.set_ylim(bottom=0)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="upper left")
    ax.set_title("Onset of buckling")
    return _save(fig, outdir, "onset")


def _cycle() -> Any:
    import itertools

    return itertools.cycle(["tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple"])


def fig_l_vs_eps0(df: pd.DataFrame, outdir: Path) -> list[Path] | None:
    """l vs eps0 (log-log) with eq. (1), one series per h (at most 5)."""
    d = ok_rows(df)
    if d.empty or not is_swept(d, "eps0") or "l_mean" not in d:
        return None
    th = theory()
    mat = material(d)
    pts = per_point(d, ["h", "eps0"], ["l_mean"])
    fig = Figure(figsize=(6, 4.5), layout="constrained")
    ax = fig.subplots()
    hs = sorted(pts["h"].unique())
    if len(hs) > 5:
        hs = [hs[i] for i in np.linspace(0, len(hs) - 1, 5).round().astype(int)]
    ee = np.geomspace(float(d["eps0"].min()) * 0.9, float(d["eps0"].max()) * 1.1, 100)
    for h, color in zip(hs, _cycle(), strict=False):
        g = pts[pts["h"] == h]
        ax.errorbar(g["eps0"], g["l_mean"], yerr=g["l_mean_sd"], fmt="o", color=color,
                    label=f"simulation, h={h:g} mm")
        ax.plot(ee, th["l"](h, ee, **mat), "-", color=color, label=f"eq. (1), h={h:g} mm")
        if len(g) >= 2 and (g["l_mean"] > 0).all():
            p = np.polyfit(np.log(g["eps0"]), np.log(g["l_mean"]), 1)[0]
            ax.plot([], [], " ", label=f"fitted exponent {p:.3f} (eq. (1): -0.5)")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("pre-stretch ε0 [-]")
    ax.set_ylabel("arc length l [mm]")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7, loc="upper right")
    ax.set_title("Arc length vs pre-stretch")
    return _save(fig, outdir, "l_vs_eps0")


def _family_majority(d: pd.DataFrame) -> pd.DataFrame:
    return (d.groupby(["h", "s"])["family"]
            .agg(lambda x: x.value_counts().index[0] if x.notna().any() else None)
            .reset_index())


def fig_phase_diagram(df: pd.DataFrame, outdir: Path) -> list[Path] | None:
    """(h, s) phase diagram coloured by family, with s_hat (data dashed, formula solid)."""
    d = ok_rows(df)
    if d.empty or not (is_swept(d, "h") and is_swept(d, "s")) or "family" not in d:
        return None
    th = theory()
    mat = material(d)
    mat["b"] = float(d.loc[d["N"] == d["N"].max(), "b"].median()) if "N" in d else mat["b"]
    eps0 = float(d["eps0"].median())
    fam = _family_majority(d)
    fig = Figure(figsize=(7, 5.5), layout="constrained")
    ax = fig.subplots()
    for name, g in fam.groupby("family"):
        ax.scatter(g["h"], g["s"], c=FAMILY_COLORS.get(str(name), "0.5"), s=40, marker="s",
                   label=str(name), edgecolors="none")
    failed = df[(df.get("status") == "failed")] if "status" in df else df.iloc[0:0]
    if not failed.empty and {"h", "s"} <= set(failed):
        ax.scatter(failed["h"], failed["s"], marker="x", c="k", s=30, label="failed")
    hh = np.linspace(0.0, float(d["h"].max()) * 1.02, 200)
    ax.plot(hh, th["s_hat"](hh, eps0, **mat), "k-", lw=1.5, label="ŝ formula 2a(1+ε0)")
    if "a_mean" in d:
        a_h = per_point(d[d["N"] > 1] if "N" in d and (d["N"] > 1).any() else d, ["h"],
                        ["a_mean"])
        ax.plot(a_h["h"], 2 * a_h["a_mean"] * (1 + eps0), "k--", lw=1.5,
                label="ŝ from simulated a")
    ax.set_ylim(float(d["s"].min()) - 2, float(d["s"].max()) + 2)
    ax.set_xlim(0, float(d["h"].max()) * 1.05)
    ax.set_xlabel("rod thickness h [mm]")
    ax.set_ylabel("gap s [mm]")
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    ax.set_title(f"Shape families over (h, s), ε0 = {eps0:g}")
    return _save(fig, outdir, "phase_diagram")


def fig_master_curve(df: pd.DataFrame, outdir: Path) -> list[Path] | None:
    """l (mean +- std over rods) vs h/h*(s), L/n marks at the side, inset h* vs s."""
    d = ok_rows(df)
    if d.empty or not (is_swept(d, "h") and is_swept(d, "s")) or "l_mean" not in d:
        return None
    hs = hstar(d, 1)
    if not np.isfinite(hs.to_numpy(float)).any():
        return None
    L = float(d["L"].median()) if "L" in d else 100.0
    fig = Figure(figsize=(7, 5), layout="constrained")
    ax = fig.subplots()
    import matplotlib as mpl

    cmap = mpl.colormaps["viridis"]
    smin, smax = float(d["s"].min()), float(d["s"].max())
    norm = mpl.colors.Normalize(smin, smax)
    for s, g in d.groupby("s"):
        h_star = hs.get(s, np.nan)
        if not np.isfinite(h_star):
            continue
        ax.errorbar(g["h"] / h_star, _num(g, "l_mean"), yerr=_num(g, "l_std"), fmt="o", ms=3,
                    color=cmap(norm(s)), elinewidth=0.8, alpha=0.85)
    sm = mpl.cm.ScalarMappable(norm=norm, cmap=cmap)
    fig.colorbar(sm, ax=ax, label="gap s [mm]", pad=0.08)
    ymax = float(np.nanmax(_num(d, "l_mean") + _num(d, "l_std").fillna(0)))
    ax.set_ylim(0, max(ymax, L) * 1.08)
    _ln_marks(ax, L, max(ymax, L) * 1.08)
    ax.axvline(1.0, color="0.5", ls=":", lw=1)
    ax.set_xlabel("h / h*  (h*: smallest h with final n = 1)")
    ax.set_ylabel("arc length l [mm] (mean ± std over rods)")
    ax.grid(alpha=0.3)
    ax.set_title("Master curve")
    ins = ax.inset_axes([0.1, 0.5, 0.36, 0.3])
    ins.plot(hs.index, hs.to_numpy(float), "o-", ms=3, color="k")
    ins.set_xlabel("s [mm]", fontsize=7)
    ins.set_ylabel("h* [mm]", fontsize=7)
    ins.tick_params(labelsize=6)
    ins.grid(alpha=0.3)
    return _save(fig, outdir, "master_curve")


def fig_quantized_flattening(df: pd.DataFrame, outdir: Path, n_max: int = 9) -> list[Path] | None:
    """a and lambda vs h across the plateaus n <= n_max (single rods, or the largest s)."""
    d = ok_rows(df)
    if (d.empty or not is_swept(d, "h") or not {"a_mean", "lam_mean"} <= set(d)
            or d["h"].nunique() < MIN_H_VALUES):
        return None
    label = "single rod"
    if is_swept(d, "s"):
        s_use = float(d["s"].max())
        d = d[d["s"] == s_use]
        label = f"s = {s_use:g} mm"
    if is_swept(d, "eps0"):
        e = d["eps0"].mode().iloc[0]
        d = d[d["eps0"] == e]
    d = d.assign(n=n_values(d))
    pts = per_point(d, ["h"], ["a_mean", "lam_mean"])
    n_mode = d.groupby("h")["n"].agg(lambda x: x.mode().iloc[0] if x.notna().any() else np.nan)
    pts["n"] = pts["h"].map(n_mode)
    pts = pts[pts["n"] <= n_max]
    if len(pts) < 3:
        return None
    fig = Figure(figsize=(7, 6), layout="constrained")
    ax_a, ax_l = fig.subplots(2, 1, sharex=True)
    # shade consecutive h with the same n (a plateau)
    nn = pts["n"].round().to_numpy()
    h = pts["h"].to_numpy(float)
    dh = np.diff(h).min() if len(h) > 1 else 0.1
    start = 0
    shades = ["0.93", "0.82"]
    for i in range(1, len(h) + 1):
        if i == len(h) or nn[i] != nn[start]:
            for ax in (ax_a, ax_l):
                ax.axvspan(h[start] - dh / 2, h[i - 1] + dh / 2,
                           color=shades[(len(shades) + int(nn[start]) // 2) % 2], zorder=0)
            if i - start >= 2:
                ax_a.text((h[start] + h[i - 1]) / 2, 1.0, f"n={int(nn[start])}", fontsize=7,
                          transform=ax_a.get_xaxis_transform(), ha="center", va="bottom")
            start = i
    ax_a.errorbar(pts["h"], pts["a_mean"], yerr=pts.get("a_mean_sd"), fmt="o-", ms=3)
    ax_l.errorbar(pts["h"], pts["lam_mean"], yerr=pts.get("lam_mean_sd"), fmt="s-", ms=3,
                  color="tab:red")
    ax_a.set_ylabel("amplitude a [mm]")
    ax_l.set_ylabel("wavelength λ [mm]")
    ax_l.set_xlabel("rod thickness h [mm]")
    for ax in (ax_a, ax_l):
        ax.grid(alpha=0.3)
    fig.suptitle(f"Quantized flattening ({label}): on a plateau a falls and λ rises")
    return _save(fig, outdir, "quantized_flattening")


def fig_transitions(df: pd.DataFrame, outdir: Path) -> list[Path] | None:
    """h*_n(s) for the transitions 3 -> 1, 5 -> 3, 7 -> 5 (the smallest h whose final n is
    <= n), and eq. (1)'s bundling: close rods act as one rod N times as wide, whose h*_n is
    h*_n(s_max) / N^(1/3)."""
    d = ok_rows(df)
    if d.empty or not (is_swept(d, "h") and is_swept(d, "s")):
        return None
    N = int(d["N"].max()) if "N" in d else 5
    fig = Figure(figsize=(6.5, 4.5), layout="constrained")
    ax = fig.subplots()
    drawn = False
    for n_to, color in zip((1, 3, 5), ("tab:orange", "tab:blue", "tab:green"), strict=True):
        hs = hstar(d, n_to)
        if not np.isfinite(hs.to_numpy(float)).any():
            continue
        drawn = True
        ax.plot(hs.index, hs.to_numpy(float), "o-", ms=4, color=color,
                label=f"h* of {n_to + 2} → {n_to}")
        far = float(hs.iloc[-1])
        if np.isfinite(far):
            ax.axhline(far / N ** (1 / 3), color=color, ls="--", lw=1,
                       label=f"{n_to + 2} → {n_to}, bundled: h*(s = {hs.index[-1]:g}) / N^(1/3)")
    if not drawn:
        return None
    dh = float(np.diff(np.sort(d["h"].unique())).min())
    ax.set_xlabel("gap s [mm]")
    ax.set_ylabel("transition thickness h* [mm]")
    ax.set_ylim(bottom=0)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="lower right")
    ax.set_title(f"Transitions vs gap (N = {N}; h* known to the sweep's step, {dh:g} mm)")
    return _save(fig, outdir, "transitions")


def fig_onset_map(df: pd.DataFrame, outdir: Path) -> list[Path] | None:
    """Onset of buckling over (h, s) (release strain, colour), and which rods went first:
    filled where an outer rod reached the onset no later than every inner one, a cross
    where an inner rod went first."""
    d = ok_rows(df)
    if (d.empty or not (is_swept(d, "h") and is_swept(d, "s"))
            or "onset_release_strain" not in d):
        return None
    e = _num(d, "onset_release_strain")
    if e.notna().sum() == 0:
        return None
    first = d.get("rods_onset_release_strain", pd.Series(None, d.index)).map(outer_rod_first)
    fig = Figure(figsize=(7, 5.5), layout="constrained")
    ax = fig.subplots()
    sc = ax.scatter(d["h"], d["s"], c=e, s=40, marker="s", cmap="viridis", edgecolors="none")
    fig.colorbar(sc, ax=ax, label="release strain at the onset [-]")
    inner = first.eq(False).to_numpy()
    if inner.any():
        ax.scatter(d["h"][inner], d["s"][inner], marker="x", c="r", s=25,
                   label="an inner rod went first")
        ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(0.0, -0.12))
    ax.set_xlabel("rod thickness h [mm]")
    ax.set_ylabel("gap s [mm]")
    n_multi = int(first.notna().sum())
    n_outer = int(first.eq(True).sum())
    ax.set_title(f"Onset of buckling (deflection > h); outer rod first in {n_outer} of "
                 f"{n_multi} runs", fontsize=10)
    return _save(fig, outdir, "onset_map")


FIGURES = {
    "single_rod_h": fig_single_rod_h,
    "l_vs_eps0": fig_l_vs_eps0,
    "phase_diagram": fig_phase_diagram,
    "master_curve": fig_master_curve,
    "quantized_flattening": fig_quantized_flattening,
    "onset": fig_onset,
    "transitions": fig_transitions,
    "onset_map": fig_onset_map,
}


def make_figures(study_dir: str | Path, df: pd.DataFrame | None = None) -> dict[str, list[Path]]:
    """Make every figure the study's data supports; return ``{name: [png, pdf]}``."""
    study_dir = Path(study_dir)
    if df is None:
        df = collect(study_dir)
    outdir = study_dir / "figures"
    made: dict[str, list[Path]] = {}
    for name, fn in FIGURES.items():
        paths = fn(df, outdir)
        if paths:
            made[name] = paths
    return made
