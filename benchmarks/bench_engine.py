"""Time the engine: default single rod and five parallel rods (CPU).

    python benchmarks/bench_engine.py [--only single|five] [--json OUT.json]

Reports total wall time, Newton iterations, time per iteration, and where the time goes
(assembly = energies/gradients/Hessians + sparse scatter, factorization, eigen-directions,
line search). Run it twice: the first run on a machine also compiles the JAX kernels (cached).
"""

from __future__ import annotations

import argparse
import json
import platform
import time

from undulate import api

CASES = {
    "single": api.DEMO,
    "five": {"name": "five", "rods": {"h": 0.4, "N": 5, "s": 10.0, "L": 100.0},
             "release": {"steps": 15}, "mesh": {"dx_rod": 1.0}},
}


def bench(name: str) -> dict:
    case = api.case_from_dict(CASES[name])
    t0 = time.perf_counter()
    r = api.simulate(case)
    wall = time.perf_counter() - t0
    s = r.stats
    it = s["newton_iterations"]
    out = dict(case=name, wall_s=wall, setup_s=s["setup_time_s"], unknowns=s["n_unknowns"],
               newton_iterations=it, release_steps=s["release_steps"],
               per_iteration_s=(wall - s["setup_time_s"]) / max(it, 1),
               assembly_s=s["assembly_time_s"], factor_s=s["factor_time_s"],
               eig_s=s["eig_time_s"], line_search_s=s["line_search_time_s"],
               factor_share=s["factor_time_s"] / max(wall, 1e-9),
               max_height=r.history[-1]["max_height"])
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--only", choices=list(CASES))
    ap.add_argument("--json")
    a = ap.parse_args()
    rows = [bench(n) for n in ([a.only] if a.only else CASES)]
    cpu = platform.processor() or platform.machine()
    print(f"machine: {cpu}, python {platform.python_version()}")
    for r in rows:
        print(" ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}"
                       for k, v in r.items()))
    if a.json:
        with open(a.json, "w") as f:
            json.dump(rows, f, indent=1)


if __name__ == "__main__":
    main()
