"""``DIR/report.md``: figures plus the numbers that compare a study with the analytical model.

Sections (each only when the data support it): run counts; slope of l vs h in the linear regime
(runs with n >= 7, 5 or 3, thinner than the first rod that ends in one half-wave) against
eq. (1)'s slope; the eps0
exponent of l (log-log fit) against -1/2; the fraction of runs where circular arcs fit better
than a sine (``r2_arcs_mean > r2_sine_mean``); the bundling ratios h*_n(s_min)/h*_n(s_max) for
the transitions 3->1, 5->3, 7->5 (h*_n = smallest h with n <= n_target) against N^(1/3);
the cost (sum, median and max of the run times, the span of the records, the hosts).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import pandas as pd

from .derived import (
    arcs_beat_sines,
    fit_eps0_exponents,
    fit_l_slope,
    hstar_ratios,
    onset_summary,
    theory,
    up_down_radii,
)
from .figures import make_figures
from .named_setups import describe_setup
from .storage import collect, read_study

__all__ = ["build_report", "write_report"]


def _f(x: Any, fmt: str = ".4g") -> str:
    try:
        xf = float(x)
    except (TypeError, ValueError):
        return str(x)
    return "n/a" if not math.isfinite(xf) else format(xf, fmt)


def build_report(
    study_dir: str | Path,
    df: pd.DataFrame | None = None,
    figures: dict[str, list[Path]] | None = None,
) -> str:
    """The markdown text of the report (figures must already exist to be linked)."""
    study_dir = Path(study_dir)
    if df is None:
        df = collect(study_dir)
    meta = read_study(study_dir) or {}
    figures = figures or {}
    n_total = int(meta.get("n_runs", len(df)))
    st = df["status"].value_counts() if "status" in df else pd.Series(dtype=int)
    n_ok, n_failed = int(st.get("ok", 0)), int(st.get("failed", 0))
    lines = [
        f"# Study report: {meta.get('name', study_dir.name)}",
        "",
        f"- kind: {meta.get('kind', '?')}{' (quick)' if meta.get('quick') else ''}",
        f"- set-up: {describe_setup((meta.get('definition') or {}).get('setup'))}",
        f"- runs: {n_total} expected, {n_ok} ok, {n_failed} failed, "
        f"{max(n_total - n_ok - n_failed, 0)} pending",
        f"- analytical formulas from: {theory()['source']}",
        "",
    ]
    if figures:
        lines += ["## Figures", ""]
        for name, paths in figures.items():
            png = next((p for p in paths if p.suffix == ".png"), paths[0])
            pdf = next((p for p in paths if p.suffix == ".pdf"), None)
            rel = png.relative_to(study_dir)
            extra = f" ([pdf]({pdf.relative_to(study_dir)}))" if pdf else ""
            lines += [f"### {name.replace('_', ' ')}{extra}", "", f"![{name}]({rel})", ""]

    lines += ["## Comparison with the analytical model", ""]
    fit = fit_l_slope(df)
    if fit:
        rel_err = fit["slope"] / fit["slope_eq1"] - 1.0
        lines += [
            f"**l vs h, linear regime** (runs with n >= {fit['n_min']} and h below the first "
            f"n = 1 run at {_f(fit['h_below'])} mm, {fit['n_points']} points, "
            f"eps0 = {_f(fit['eps0'])}):",
            "",
            "| quantity | value |",
            "|---|---|",
            f"| fitted slope dl/dh (with intercept) | {_f(fit['slope'])} |",
            f"| fitted intercept [mm] | {_f(fit['intercept'])} |",
            f"| fitted slope through the origin | {_f(fit['slope_origin'])} |",
            f"| eq. (1) slope | {_f(fit['slope_eq1'])} |",
            f"| fitted / eq. (1) - 1 | {_f(100 * rel_err, '.1f')} % |",
            "",
        ]
    exps = fit_eps0_exponents(df)
    for exp in exps:
        lines += [
            f"**l vs eps0** (log-log fit, h = {_f(exp['h'])} mm, {exp['n_points']} points): "
            f"exponent {_f(exp['exponent'], '.3f')} (eq. (1): -0.5).",
            "",
        ]
    arcs = arcs_beat_sines(df)
    if arcs:
        lines += [
            f"**Arcs vs sines**: circular arcs fit better (R² higher) in {arcs['wins']} of "
            f"{arcs['n']} runs ({_f(100 * arcs['fraction'], '.1f')} %).",
            "",
        ]
    ons = onset_summary(df)
    if ons:
        lines += [
            f"**Onset of buckling** (release strain where the rods first stand out of their "
            f"printed level by their thickness h; {ons['n']} runs): min {_f(ons['min'], '.4f')}, "
            f"median {_f(ons['median'], '.4f')}, max {_f(ons['max'], '.4f')}."
            + (f" An outer rod went first (no later than every inner one) in "
               f"{ons['outer_first']} of {ons['n_multi']} runs of three or more rods."
               if "n_multi" in ons else ""),
            "",
        ]
    ud = up_down_radii(df)
    if ud:
        lines += [
            f"**Up vs down arcs** (interior arcs, runs with n >= {ud['n_min']}, {ud['n']} runs): "
            f"R_up / R_down on the rods' centre line median {_f(ud['centre_median'], '.3f')} "
            f"({_f(ud['centre_min'], '.3f')}-{_f(ud['centre_max'], '.3f')}, below 1 in "
            f"{ud['centre_below_1']}); on the fabric under the rods (the bond line, d = "
            f"(t + h) / 2 below the centre line: R_up - d, R_down + d) median "
            f"{_f(ud['fabric_median'], '.3f')} ({_f(ud['fabric_min'], '.3f')}-"
            f"{_f(ud['fabric_max'], '.3f')}, below 1, crests more curved, in "
            f"{ud['fabric_below_1']}).",
            "",
        ]
    ratios = hstar_ratios(df, meta.get("definition", {}).get("N_nominal"))
    if ratios:
        r0 = ratios[0]
        lines += [
            f"**Bundling**: h*_n(s = {_f(r0['s_min'])}) / h*_n(s = {_f(r0['s_max'])}) "
            f"vs N^(1/3) = {_f(r0['bundling'], '.3f')} (N = {r0['N']}); "
            "h*_n = smallest h whose median n over seeds is <= n_target, so each h* is known "
            "only to the sweep's step in h. Eq. (1) with the close rods taken as one rod N "
            "times as wide (h -> h N^(1/3)) puts the bundle's transitions at thicknesses N^(1/3) "
            "times smaller: h*(s_max) / h*(s_min) = N^(1/3), i.e. h*(s_min) / h*(s_max) = "
            f"N^(-1/3) = {_f(1 / r0['bundling'], '.3f')}.",
            "",
            "| transition | h*(s_min) [mm] | h*(s_max) [mm] | h*(s_min) / h*(s_max) "
            "| h*(s_max) / h*(s_min) | N^(1/3) |",
            "|---|---|---|---|---|---|",
        ]
        for r in ratios:
            inv = 1 / r["ratio"] if r["ratio"] and math.isfinite(r["ratio"]) else float("nan")
            lines.append(
                f"| {r['transition']} | {_f(r['hstar_s_min'])} | {_f(r['hstar_s_max'])} | "
                f"{_f(r['ratio'], '.3f')} | {_f(inv, '.3f')} | {_f(r['bundling'], '.3f')} |"
            )
        lines.append("")
    if not (fit or exps or arcs or ons or ud or ratios):
        lines += ["No comparison possible with the data present.", ""]
    lines += _cost_lines(df)
    if n_failed and "error" in df:
        lines += ["## Failures", ""]
        errs = df.loc[df["status"] == "failed", "error"].fillna("?").astype(str)
        firsts = errs.map(lambda e: (e.splitlines() or ["?"])[0])
        for msg, count in firsts.value_counts().head(10).items():
            lines.append(f"- {count} x `{msg[:200]}`")
        lines.append("")
    return "\n".join(lines)


def _cost_lines(df: pd.DataFrame) -> list[str]:
    """Compute time and machine(s): sums of the per-run times, the span of the records."""
    if "elapsed_s" not in df or df.empty:
        return []
    el = pd.to_numeric(df["elapsed_s"], errors="coerce").dropna()
    if el.empty:
        return []
    out = ["## Cost", "", "| quantity | value |", "|---|---|",
           f"| runs timed | {len(el)} |",
           f"| sum of run times [min] | {_f(el.sum() / 60.0, '.1f')} |",
           f"| median / max run time [s] | {_f(el.median(), '.1f')} / {_f(el.max(), '.1f')} |"]
    if "cpu_s" in df:
        # CPU time of the runs' processes: what a run costs, whatever else shared the machine
        cpu = pd.to_numeric(df["cpu_s"], errors="coerce").dropna()
        if not cpu.empty:
            out += [f"| runs with CPU time recorded | {len(cpu)} |",
                    f"| sum of CPU times [h] | {_f(cpu.sum() / 3600.0, '.2f')} |",
                    f"| median / max CPU time per run [s] | {_f(cpu.median(), '.1f')} / "
                    f"{_f(cpu.max(), '.1f')} |"]
    if "started" in df and "finished" in df:
        t0 = pd.to_datetime(df["started"], errors="coerce", utc=True).min()
        t1 = pd.to_datetime(df["finished"], errors="coerce", utc=True).max()
        if pd.notna(t0) and pd.notna(t1):
            out.append(f"| first start -> last finish (UTC) | {t0:%Y-%m-%d %H:%M} -> "
                       f"{t1:%Y-%m-%d %H:%M} |")
        busy = _busy_hours(df)
        if busy > 0:
            n_ok = int((df["status"] == "ok").sum()) if "status" in df else len(el)
            out += [f"| time with runs in progress [h] (sittings joined, gaps left out) | "
                    f"{_f(busy, '.2f')} |",
                    f"| ok runs per hour of it | {_f(n_ok / busy, '.1f')} |"]
    if "newton_iterations" in df:
        it = pd.to_numeric(df["newton_iterations"], errors="coerce").dropna()
        if not it.empty:
            out.append(f"| median / max Newton iterations (ok runs) | {_f(it.median(), '.0f')}"
                       f" / {_f(it.max(), '.0f')} |")
    if "host" in df:
        hosts = sorted(str(h) for h in df["host"].dropna().unique())
        if hosts:
            out.append(f"| host(s) | {', '.join(hosts)} |")
    if "cpus" in df:
        cpus = pd.to_numeric(df["cpus"], errors="coerce").dropna().astype(int).value_counts()
        if not cpus.empty:
            out.append("| usable cores of the machine (cores: runs) | "
                       + ", ".join(f"{k}: {v}" for k, v in sorted(cpus.items())) + " |")
    if "engine" in df:
        eng = df["engine"].fillna("(not recorded)").astype(str).value_counts()
        if not eng.empty:
            out.append("| engine(s) (source digest: runs) | "
                       + ", ".join(f"{k}: {v}" for k, v in eng.items()) + " |")
    return out + [""]


def _busy_hours(df: pd.DataFrame) -> float:
    """Hours during which at least one of the study's runs was in progress: the union of the
    runs' [started, finished] intervals, so that the gaps between sittings do not count and
    runs in parallel count once. 0 without times."""
    t0 = pd.to_datetime(df["started"], errors="coerce", utc=True)
    t1 = pd.to_datetime(df["finished"], errors="coerce", utc=True)
    spans = sorted((a, b) for a, b in zip(t0, t1, strict=True)
                   if pd.notna(a) and pd.notna(b) and b >= a)
    total = 0.0
    cur_a = cur_b = None
    for a, b in spans:
        if cur_b is None or a > cur_b:
            if cur_b is not None:
                total += (cur_b - cur_a).total_seconds()
            cur_a, cur_b = a, b
        else:
            cur_b = max(cur_b, b)
    if cur_b is not None:
        total += (cur_b - cur_a).total_seconds()
    return total / 3600.0


def write_report(study_dir: str | Path) -> Path:
    """Make the figures and write ``DIR/report.md``; return its path."""
    study_dir = Path(study_dir)
    df = collect(study_dir)
    figs = make_figures(study_dir, df)
    path = study_dir / "report.md"
    path.write_text(build_report(study_dir, df, figs))
    return path
