"""Batched release (undulate.solve.batch) against the same runs one by one, with a yardstick.

    python benchmarks/bench_batch_release.py                        # 4 single rods, h = 0.2 .. 0.8
    python benchmarks/bench_batch_release.py --h 0.2 0.3 0.5 0.8 1.2 1.6 --json out.json

The runs are the single-rod benchmark cases (bench_engine.py: the default case, one rod of
thickness h on the default sheet), which share one mesh. Each way is run twice in this
process and the second, warm, time is reported (the first also traces and compiles the
kernels: the batched ones are other programs). Checks that every run ends in the same state
(n, l, Newton iterations) both ways, and reports the wall times as ratios to the yardstick
(``../shared/yardstick.py``) measured before and after, the number of rendezvous and the time
the batched kernel calls took.

On a CPU the batched path is not meant to be faster (a kernel over B runs costs about B
single calls); it is the structure a GPU needs, where one call over the batch costs about one.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_engine import cases, yardstick  # noqa: E402

from undulate import api  # noqa: E402
from undulate.mechanics import batched  # noqa: E402
from undulate.solve.batch import release_batch  # noqa: E402


def _timed_batch_kernels() -> dict:
    """Wrap RunBatch's kernel calls to add up their time (results forced to the host)."""
    spent = {"s": 0.0, "calls": 0}
    orig = batched.RunBatch.run

    def run(self, *a, **k):
        t0 = time.perf_counter()
        out = orig(self, *a, **k)
        for o in out:
            for leaf in (o if isinstance(o, tuple) else (o,)):
                leaf.block_until_ready()
        spent["s"] += time.perf_counter() - t0
        spent["calls"] += 1
        return out

    batched.RunBatch.run = run
    return spent


def state(res) -> dict:
    m = api.analyse(res)["rods"][0]
    return dict(n=m["n"], l=m["l"], its=res.stats["newton_iterations"])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--h", type=float, nargs="+", default=[0.2, 0.3, 0.5, 0.8])
    ap.add_argument("--json", type=Path)
    args = ap.parse_args()
    all_cases = cases()
    chosen = [api.case_from_dict(all_cases[f"single-{h:g}"]) if f"single-{h:g}" in all_cases
              else api.case_from_dict({"name": f"single-{h:g}", "rods": {"h": h}})
              for h in args.h]
    spent = _timed_batch_kernels()
    ys0 = yardstick()
    out: dict = {"h": args.h}
    for attempt in ("first", "warm"):
        t0 = time.perf_counter()
        single = [api.simulate(c) for c in chosen]
        t_single = time.perf_counter() - t0
        spent.update(s=0.0, calls=0)
        stats: dict = {}
        t0 = time.perf_counter()
        batch = release_batch(chosen, stats=stats)
        t_batch = time.perf_counter() - t0
        out[attempt] = dict(single_s=t_single, batch_s=t_batch, kernel_s=spent["s"],
                            kernel_calls=spent["calls"], **stats)
        print(f"{attempt}: one by one {t_single:.1f} s, batched {t_batch:.1f} s "
              f"(batched kernels {spent['s']:.1f} s in {spent['calls']} calls, "
              f"{stats['rendezvous']} rendezvous)", flush=True)
    ys1 = yardstick()
    rows = []
    for h, a, b in zip(args.h, single, batch, strict=True):
        if isinstance(b, BaseException):
            rows.append(dict(h=h, batch_error=str(b)))
            continue
        sa, sb = state(a), state(b)
        rows.append(dict(h=h, single=sa, batch=sb,
                         same=sa["n"] == sb["n"] and abs(sa["l"] - sb["l"]) <= 0.01 * sa["l"]))
    out.update(rows=rows, yardstick_before_s=ys0, yardstick_after_s=ys1,
               machine=f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores")
    ys = 0.5 * (ys0 + ys1)
    w = out["warm"]
    print(f"yardstick {ys0:.2f} / {ys1:.2f} s; warm: one by one {w['single_s']:.1f} s "
          f"({w['single_s'] / ys:.1f} x), batched {w['batch_s']:.1f} s "
          f"({w['batch_s'] / ys:.1f} x)")
    for r in rows:
        print(r)
    if args.json:
        args.json.write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
