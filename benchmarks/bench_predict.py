"""How often `undulate predict` gets the n and the family that a simulation gives.

    python benchmarks/bench_predict.py --out runs/bench-predict                 # 40 cases
    python benchmarks/bench_predict.py --out runs/bench-predict --markdown predict-bench.md
    python benchmarks/bench_predict.py --out runs/bp-smoke --cases 3 --quick    # a smoke run

Draws ``--cases`` random cases with a fixed seed (``--seed``, not used by any fit) over the
documented range on the reference set-up (E_B = 1000 MPa): h log-uniform in 0.08..2 mm,
L in 40..150 mm (5 mm steps), eps0 in 0.2..1.0 (0.05 steps), N = 1 or 5, s in 0..50 mm
(2.5 mm steps) for five rods. Simulates them as one resumable study in ``--out`` (finished
runs are kept; ``-j`` workers) and compares, per case, the simulated n (the rods' most
common) and family with ``undulate predict``'s (``--source auto``) and with eq. (1) and the
phase map alone (``--source theory``). Prints a table per case and the three hit rates.
This is the acceptance benchmark of the simulation-backed prediction: >= 90 % of n and of
families. Each full-size case takes 0.5-10 minutes on 2 cores.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from undulate.design.predict import predict_case
from undulate.model import case_from_dict
from undulate.study import collect, run_study
from undulate.study.named_setups import REFERENCE, named_setup
from undulate.study.presets import QUICK_OVERRIDES
from undulate.study.spec import RunSpec, Study, apply_single_rod_rule, merge_case, run_id

sys.path.insert(0, str(Path(__file__).parent))
from bench_engine import yardstick  # noqa: E402


def draw_cases(k: int, seed: int, quick: bool) -> list[dict]:
    """``k`` random cases (nested dicts as in a case file) on the reference set-up."""
    rng = np.random.default_rng(seed)
    setup = named_setup(REFERENCE)
    cases = []
    for i in range(k):
        n_rods = int(rng.choice([1, 5]))
        case = {
            "name": f"bench-predict-{i}",
            "rods": {"h": round(float(np.exp(rng.uniform(np.log(0.08), np.log(2.0)))), 2),
                     "L": float(5 * rng.integers(8, 31)), "N": n_rods,
                     "s": float(2.5 * rng.integers(0, 21)) if n_rods > 1 else 10.0},
            "release": {"eps0": round(float(0.05 * rng.integers(4, 21)), 2)},
            "imperfection": {"seed": 0},
        }
        case = merge_case(case, setup)
        apply_single_rod_rule(case)  # s = 0: one rod N times as wide, as in the presets
        if quick:
            case = merge_case(case, QUICK_OVERRIDES)
        cases.append(case)
    return cases


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True, type=Path, help="study directory of the cases")
    ap.add_argument("--cases", type=int, default=40)
    ap.add_argument("--seed", type=int, default=2026)
    ap.add_argument("--quick", action="store_true", help="coarse mesh (a smoke run only)")
    ap.add_argument("-j", "--workers", type=int, default=2)
    ap.add_argument("--markdown", type=Path, help="also write the table here")
    args = ap.parse_args()
    cases = draw_cases(args.cases, args.seed, args.quick)
    runs = [RunSpec(id=run_id(c), params={"case": i}, seed=0, case=c)
            for i, c in enumerate(cases)]
    study = Study(name="bench-predict", kind="sweep", quick=args.quick,
                  definition={"seed": args.seed, "cases": args.cases}, runs=runs)
    ys0 = yardstick()
    t0 = time.perf_counter()
    summary = run_study(study, args.out, workers=args.workers, artifacts=False)
    wall = time.perf_counter() - t0
    ys1 = yardstick()
    table = collect(args.out).set_index("run_id")
    lines = ["| case | h | L | eps0 | N | s | simulated | predict | confidence | atlas | theory |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    hits = {"predict_n": 0, "predict_family": 0, "theory_n": 0, "theory_family": 0,
            "predict_n_or_alternative": 0}
    by_confidence: dict[str, list[int]] = {}  # confidence -> [cases, n right, family right]
    by_band: dict[str, list[int]] = {}  # thin (h < 0.2 mm: many half-waves) or not -> the same
    done = 0
    for r, c in zip(runs, cases, strict=True):
        if r.id not in table.index or table.loc[r.id, "status"] != "ok":
            continue
        done += 1
        sim_n, sim_f = int(table.loc[r.id, "n_mode"]), str(table.loc[r.id, "family"])
        case = case_from_dict(c)
        p, t = predict_case(case), predict_case(case, "theory")
        for name, res in (("predict", p), ("theory", t)):
            hits[f"{name}_n"] += int(res["rods"][0]["n"] == sim_n)
            hits[f"{name}_family"] += int(res["family"] == sim_f)
        alternatives = {a["n"] for a in p.get("alternatives", [])}
        hits["predict_n_or_alternative"] += int(sim_n in alternatives | {p["rods"][0]["n"]})
        rods = c["rods"]
        band = "h < 0.2 mm" if rods["h"] < 0.2 else "h >= 0.2 mm"
        for row in (by_confidence.setdefault(p["confidence"], [0, 0, 0]),
                    by_band.setdefault(band, [0, 0, 0])):
            row[0] += 1
            row[1] += int(p["rods"][0]["n"] == sim_n)
            row[2] += int(p["family"] == sim_f)
        lines.append(f"| {r.params['case']} | {rods['h']:g} | {rods['L']:g} | "
                     f"{c['release']['eps0']:g} | {rods['N']} | "
                     f"{rods['s']:g} | {sim_f} n = {sim_n} | {p['family']} n = "
                     f"{p['rods'][0]['n']} | {p['confidence']} | {p.get('atlas', '-')} | "
                     f"{t['family']} n = "
                     f"{t['rods'][0]['n']} |")
    rate = {k: (v / done if done else float("nan")) for k, v in hits.items()}
    ys = 0.5 * (ys0 + ys1)
    lines += ["", f"{done} of {len(runs)} cases simulated ({summary.ran} this time, "
              f"{wall:.0f} s = {wall / ys:.0f} yardsticks of {ys:.2f} s)",
              f"predict: n {100 * rate['predict_n']:.0f} %, family "
              f"{100 * rate['predict_family']:.0f} %; eq. (1) and the phase map: n "
              f"{100 * rate['theory_n']:.0f} %, family {100 * rate['theory_family']:.0f} %",
              f"predict's n or one of its alternatives: "
              f"{100 * rate['predict_n_or_alternative']:.0f} %",
              "by predict's confidence (cases, n right, family right): "
              + "; ".join(f"{k} {v[0]}, {v[1]}, {v[2]}" for k, v in by_confidence.items()),
              "by thickness (cases, n right, family right): "
              + "; ".join(f"{k} {v[0]}, {v[1]}, {v[2]}" for k, v in sorted(by_band.items()))]
    text = "\n".join(lines) + "\n"
    print(text)
    if args.markdown:
        args.markdown.write_text(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
