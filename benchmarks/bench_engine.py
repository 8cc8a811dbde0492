"""Time the engine on the paper-scale cases, with a yardstick measured in the same run.

    python benchmarks/bench_engine.py                       # demo + all robustness cases
    python benchmarks/bench_engine.py --only demo single-0.3 five-0.5-10
    python benchmarks/bench_engine.py --json out.json --markdown out.md
    python benchmarks/bench_engine.py --no-fast     # as without the `fast` extra (no PARDISO)
    python benchmarks/bench_engine.py --setup bare  # on the engine's defaults (E_B = 3000 MPa)

Cases (on the studies' reference set-up ``study-2022``, rod modulus E_B = 1000 MPa, unless
``--setup`` names another; default settings unless named; passes up to the eighteenth in
docs/benchmarks.md ran on the engine's bare defaults, E_B = 3000 MPa):
* ``demo``: the case of ``undulate demo``.
* ``single-<h>``: one rod of thickness h (the default case otherwise), for
  h in 0.08, 0.1, 0.14, 0.2, 0.3, 0.5, 0.8, 1.2, 1.6, 2.0.
* ``five-<h>-<s>``: N = 5 rods at gap s (s = 0: one rod 5 b wide), the corners of the study's
  (h, s) plane and one inner point.

For each case: converged or not (a ConvergenceError is recorded, not raised), wall time, the
same as a ratio to the yardstick (``../shared/yardstick.py``: SuperLU on a 400 x 400 Laplacian,
about 1.1 s on an idle 2-core machine) measured before and after the cases, Newton iterations
(total, median per release step), unknowns, where the time goes, and the final n and l of the
middle rod. Then the projected wall time of the 97-run single-rod sweep and of the 420-run
phase diagram on 2 cores (two runs at a time), from these figures.

Run it twice on a new machine: the first run also compiles the JAX kernels (cached on disk).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import time
from pathlib import Path

import numpy as np

from undulate import api
from undulate.study.named_setups import REFERENCE, named_setup
from undulate.study.spec import merge_case

SINGLE_H = [0.08, 0.1, 0.14, 0.2, 0.3, 0.5, 0.8, 1.2, 1.6, 2.0]
FIVE = [(0.1, 0.0), (0.1, 50.0), (2.0, 0.0), (2.0, 50.0), (0.5, 10.0)]


def cases(setup: str = REFERENCE) -> dict[str, dict]:
    """The benchmark's cases (nested dicts as in a case file) on the set-up ``setup``."""
    out: dict[str, dict] = {"demo": api.DEMO}
    for h in SINGLE_H:
        out[f"single-{h:g}"] = {"name": f"single-{h:g}", "rods": {"h": h}}
    for h, s in FIVE:
        rods = {"h": h, "N": 1, "b": 5.0} if s == 0 else {"h": h, "N": 5, "s": s}
        out[f"five-{h:g}-{s:g}"] = {"name": f"five-{h:g}-{s:g}", "rods": rods}
    over = named_setup(setup)
    return {k: merge_case(v, over) for k, v in out.items()}


def yardstick() -> float:
    here = Path(__file__).resolve()
    for cand in (here.parents[1] / "shared", here.parents[2] / "shared"):
        if (cand / "yardstick.py").is_file():
            sys.path.insert(0, str(cand))
            from yardstick import yardstick as ys  # type: ignore[import-not-found]

            return float(ys())
    # the same measurement, inline (SuperLU factor + solve of a 400 x 400 grid Laplacian)
    import scipy.sparse as sp
    import scipy.sparse.linalg as la

    n = 400
    t = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], shape=(n, n))
    a = (sp.kron(sp.identity(n), t) + sp.kron(t, sp.identity(n))).tocsc()
    best = float("inf")
    for _ in range(3):
        t0 = time.perf_counter()
        la.splu(a).solve(np.ones(n * n))
        best = min(best, time.perf_counter() - t0)
    return best


def bench(name: str, data: dict) -> dict:
    case = api.case_from_dict(data)
    t0 = time.perf_counter()
    try:
        r = api.simulate(case)
    except api.ConvergenceError as err:
        return dict(case=name, converged=False, wall_s=time.perf_counter() - t0,
                    error=str(err).splitlines()[0])
    wall = time.perf_counter() - t0
    s = r.stats
    per_step = [h["newton_iterations"] for h in r.history[1:]]
    m = api.analyse(r)
    mid = m["rods"][len(m["rods"]) // 2]
    return dict(
        case=name, converged=True, wall_s=wall, setup_s=s["setup_time_s"],
        unknowns=s["n_unknowns"], newton_iterations=s["newton_iterations"],
        release_steps=s["release_steps"], step_cuts=s["step_cuts"], snap_cuts=s.get("snap_cuts"),
        median_its_per_step=statistics.median(per_step) if per_step else 0,
        max_its_per_step=max(per_step) if per_step else 0,
        assembly_s=s["assembly_time_s"], factor_s=s["factor_time_s"], eig_s=s["eig_time_s"],
        line_search_s=s["line_search_time_s"], linear_solver=s["linear_solver"],
        n=mid.get("n"), l=mid.get("l"), family=m.get("family"),
    )


def projection(rows: list[dict], ys: float) -> dict:
    """Projected sweep times on 2 cores (2 runs at a time) from the measured cases."""
    ok = {r["case"]: r for r in rows if r.get("converged")}
    single = [ok[k]["wall_s"] for k in ok if k.startswith("single-")]
    five = [ok[k]["wall_s"] for k in ok if k.startswith("five-")]
    out = {}
    if single:
        out["single_rod_h_97_runs_h"] = 97 * statistics.mean(single) / 2 / 3600
    if five:
        out["phase_diagram_420_runs_h"] = 420 * statistics.mean(five) / 2 / 3600
    return out


def markdown(rows: list[dict], ys0: float, ys1: float, proj: dict,
             setup: str = REFERENCE) -> str:
    ys = 0.5 * (ys0 + ys1)
    lines = [
        f"machine: {platform.processor() or platform.machine()}, python "
        f"{platform.python_version()}, {os.cpu_count()} cores; yardstick {ys0:.2f} s before, "
        f"{ys1:.2f} s after; set-up {setup}",
        "",
        "| case | converged | wall [s] | wall / yardstick | unknowns | Newton its "
        "| median its/step | max its/step | factor [s] | assembly [s] | solver | n | l [mm] |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        if not r.get("converged"):
            lines.append(f"| {r['case']} | **no**: {r.get('error', '')} | {r['wall_s']:.1f} | "
                         f"{r['wall_s'] / ys:.1f} | | | | | | | | | |")
            continue
        lines.append(
            f"| {r['case']} | yes | {r['wall_s']:.1f} | {r['wall_s'] / ys:.1f} | "
            f"{r['unknowns']} | {r['newton_iterations']} | {r['median_its_per_step']:g} | "
            f"{r['max_its_per_step']} | {r['factor_s']:.1f} | {r['assembly_s']:.1f} | "
            f"{r['linear_solver']} | {r['n']} | {r['l']:.2f} |")
    meds = [r["median_its_per_step"] for r in rows if r.get("converged")]
    if meds:
        lines += ["", f"median over cases of the median Newton iterations per release step: "
                      f"{statistics.median(meds):g}"]
    for k, v in proj.items():
        lines.append(f"projected {k.replace('_', ' ')}: {v:.2f}")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--only", nargs="*", help="case names (default: all)")
    ap.add_argument("--json")
    ap.add_argument("--markdown")
    ap.add_argument("--no-fast", action="store_true",
                    help="choose linear solvers as an install without the `fast` extra would")
    ap.add_argument("--setup", default=REFERENCE,
                    help=f"a shipped set-up the cases run on (default {REFERENCE}; bare: the "
                         "engine's defaults)")
    a = ap.parse_args()
    if a.no_fast:
        from undulate.solve import linear

        linear.pardiso_available = lambda: False  # what `auto` consults
    all_cases = cases(a.setup)
    names = a.only or list(all_cases)
    unknown = [n for n in names if n not in all_cases]
    if unknown:
        ap.error(f"unknown case(s) {unknown}; choose from {list(all_cases)}")
    ys0 = yardstick()
    rows = []
    for n in names:
        r = bench(n, all_cases[n])
        rows.append(r)
        print(json.dumps({k: (round(v, 3) if isinstance(v, float) else v)
                          for k, v in r.items()}), flush=True)
    ys1 = yardstick()
    proj = projection(rows, 0.5 * (ys0 + ys1))
    md = markdown(rows, ys0, ys1, proj, a.setup)
    print(md)
    if a.json:
        Path(a.json).write_text(json.dumps(dict(yardstick=[ys0, ys1], setup=a.setup, rows=rows,
                                                projection=proj), indent=1))
    if a.markdown:
        Path(a.markdown).write_text(md + "\n")


if __name__ == "__main__":
    main()
