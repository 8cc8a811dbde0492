"""Run finished study runs again on the current code and compare them with their records.

For a change of the solver that must not change results (or must say where it does): each
record's case is simulated again as the study runner does it (PARDISO on one thread per
worker, two workers) and n, family, l and the Newton iterations are set beside the record's.

    python benchmarks/rerun_records.py OUT.jsonl runs/single-rod-grid/runs/*.json
    python benchmarks/rerun_records.py OUT.jsonl --min-iterations 300 runs/*/runs/*.json

One JSON line per run in OUT.jsonl (resumable: runs already there are skipped), one line of
text per run on stdout, and a summary at the end.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

os.environ.setdefault("UNDULATE_PARDISO_THREADS", "1")

KEYS = ("n", "family", "l_mean", "rods_n", "newton_iterations", "step_cuts", "wall_time_s")


def rerun(path: str) -> dict:
    """Simulate the case of the record at ``path`` again; the old and new values side by side."""
    from undulate.pipeline.run import run_case

    d = json.loads(Path(path).read_text())
    t0 = time.perf_counter()
    try:
        new, err = run_case(d["case"], None, artifacts=False), None
    except Exception as e:  # a run that no longer converges is a result too
        new, err = {}, f"{type(e).__name__}: {e}"
    return dict(file=path, study=d["study"], params=d["params"], wall=time.perf_counter() - t0,
                err=err, old={k: d["record"].get(k) for k in KEYS},
                new={k: new.get(k) for k in KEYS})


def summary(rows: list[dict]) -> str:
    same = [r for r in rows if r["old"]["newton_iterations"] == r["new"]["newton_iterations"]
            and r["old"]["l_mean"] == r["new"]["l_mean"]]
    changed = [r for r in rows if (r["old"]["n"], r["old"]["family"])
               != (r["new"]["n"], r["new"]["family"])]
    its = [sum(r[k]["newton_iterations"] or 0 for r in rows) for k in ("old", "new")]
    lines = [f"{len(rows)} runs: {len(same)} identical, {len(rows) - len(same) - len(changed)} "
             f"same n and family, {len(changed)} changed; Newton iterations {its[0]} -> {its[1]}"]
    lines += [f"  changed: {r['study']} {r['params']}: {r['old']['family']} n = {r['old']['n']} "
              f"-> {r['new']['family']} n = {r['new']['n']}" for r in changed]
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("out", help="JSON lines file (appended to; runs in it are skipped)")
    ap.add_argument("records", nargs="+", help="run records (STUDY/runs/ID.json)")
    ap.add_argument("--min-iterations", type=int, default=0,
                    help="only records that took at least this many Newton iterations")
    ap.add_argument("--workers", type=int, default=2)
    a = ap.parse_args()
    out = Path(a.out)
    done = {json.loads(x)["file"] for x in out.read_text().splitlines()} if out.exists() else set()
    todo = []
    for f in a.records:
        d = json.loads(Path(f).read_text())
        its = (d.get("record") or {}).get("newton_iterations") or 0
        if d.get("status") == "ok" and its >= a.min_iterations and f not in done:
            todo.append(f)
    print(f"{len(todo)} runs to simulate, {len(done)} done before", flush=True)
    import multiprocessing as mp

    with mp.get_context("spawn").Pool(a.workers) as pool, out.open("a") as fh:
        for i, r in enumerate(pool.imap_unordered(rerun, todo), 1):
            fh.write(json.dumps(r) + "\n")
            fh.flush()
            o, n = r["old"], r["new"]
            print(f"{i}/{len(todo)} {r['study']} {r['params']}: n {o['n']} -> {n['n']}, "
                  f"{o['family']} -> {n['family']}, iterations {o['newton_iterations']} -> "
                  f"{n['newton_iterations']}, {r['wall']:.0f} s {r['err'] or ''}", flush=True)
    rows = [json.loads(x) for x in out.read_text().splitlines()]
    print(summary(rows))


if __name__ == "__main__":
    main()
