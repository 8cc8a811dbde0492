"""Run every pattern of this folder and refresh the gallery's pictures and table.

    python examples/patterns/gallery.py                 # all patterns -> runs/gallery/<name>
    python examples/patterns/gallery.py arcs spiral     # some of them

For each pattern it runs the same job as ``undulate run examples/patterns/<name>.toml``,
copies the run's ``top_view.png`` and ``view_3d.png`` to ``examples/patterns/images/`` and
prints a Markdown table (per line: n and l; wall time, also as a ratio to the yardstick
``../shared/yardstick.py`` when it is there) for ``examples/patterns/README.md``.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]


def yardstick() -> float | None:
    """Seconds of the shared yardstick script, or None where it is not available."""
    script = ROOT.parent / "shared" / "yardstick.py"
    if not script.is_file():
        return None
    t = time.perf_counter()
    subprocess.run([sys.executable, str(script)], check=True, capture_output=True)
    return time.perf_counter() - t


def main(names: list[str]) -> None:
    from undulate import api
    from undulate.model import load_case

    cases = sorted(HERE.glob("*.toml"))
    if names:
        cases = [c for c in cases if c.stem in names]
    (HERE / "images").mkdir(exist_ok=True)
    ys0 = yardstick()
    rows = []
    for path in cases:
        out = ROOT / "runs" / "gallery" / path.stem
        t = time.perf_counter()
        rec = api.run_case(load_case(path), out, overwrite=True)
        wall = time.perf_counter() - t
        for pic in ("top_view", "view_3d"):
            shutil.copyfile(out / f"{pic}.png", HERE / "images" / f"{path.stem}_{pic}.png")
        import json

        m = json.loads((out / "metrics.json").read_text())
        per_line = ", ".join(
            f"{r['id']}: n = {r['n']}, l = {r['l']:.1f}" if r.get("l") is not None
            else f"{r['id']}: n = {r['n']}" for r in m["rods"])
        rows.append((path.stem, rec["n_unknowns"], rec["newton_iterations"], wall, per_line))
        print(f"{path.stem}: {wall:.1f} s, {per_line}", flush=True)
    ys1 = yardstick()
    ys = None if ys0 is None or ys1 is None else 0.5 * (ys0 + ys1)
    print(f"\nyardstick {ys0 and round(ys0, 2)} s before, {ys1 and round(ys1, 2)} s after\n")
    print("| pattern | unknowns | Newton its | wall [s] | / yardstick | per line |")
    print("|---|---|---|---|---|---|")
    for name, nu, its, wall, per_line in rows:
        ratio = f"{wall / ys:.1f}" if ys else "-"
        print(f"| {name} | {nu} | {its} | {wall:.1f} | {ratio} | {per_line} |")


if __name__ == "__main__":
    main(sys.argv[1:])
