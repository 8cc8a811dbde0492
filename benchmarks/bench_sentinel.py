"""Run the sentinel (12 runs judged against the study) on a set-up, timed in yardsticks.

    python benchmarks/bench_sentinel.py --out runs/sentinel
    python benchmarks/bench_sentinel.py --out runs/sentinel-eb1000 --set rods.E_B=1000
    python benchmarks/bench_sentinel.py --out runs/sentinel -j 2 --markdown sentinel-bench.md

It calls ``undulate study sentinel`` (resumable: finished runs are kept), measures the
yardstick (``../shared/yardstick.py``, about 1.1 s on an idle 2-core machine) before and after,
and prints the wall time beside its ratio to the yardstick and the sentinel's scores. This is
the sentinel's home outside the default test suite: it takes 5-10 minutes on 2 cores.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
from bench_engine import yardstick  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True, type=Path, help="sentinel study directory")
    ap.add_argument("--set", action="append", default=[], dest="settings",
                    help="set-up PATH=VALUE (repeatable), as for undulate study sentinel")
    ap.add_argument("-j", "--workers", type=int, default=2)
    ap.add_argument("--markdown", type=Path, help="also write the timing and table here")
    args = ap.parse_args()
    ys0 = yardstick()
    cmd = ["undulate", "study", "sentinel", "--out", str(args.out), "-j", str(args.workers)]
    for s in args.settings:
        cmd += ["--set", s]
    t0 = time.perf_counter()
    rc = subprocess.run(cmd).returncode
    wall = time.perf_counter() - t0
    ys1 = yardstick()
    ys = 0.5 * (ys0 + ys1)
    line = (f"sentinel {' '.join(args.settings) or '(defaults)'}: wall {wall:.0f} s = "
            f"{wall / ys:.0f} yardsticks (yardstick {ys0:.3f} / {ys1:.3f} s), rc {rc}")
    print(line)
    if args.markdown is not None:
        table = (args.out / "sentinel.md").read_text() if (args.out / "sentinel.md").exists() \
            else ""
        args.markdown.write_text(line + "\n\n" + table)
    return rc


if __name__ == "__main__":
    raise SystemExit(main())
