"""Draw undulate's map: its stages as layers, and which stage imports which.

    python tools/layers.py                       # docs/images/layers.png + a table on stdout
    python tools/layers.py --out map.png

The layers are those of the import-linter contract in pyproject.toml (the top one may import
every one below it, never one above; stages on one layer do not import each other), read from
there so the picture is the contract. The arrows are the imports that exist today, counted by
grimp (import-linter's import graph), module to module, type-checking-only imports left out.
"""

from __future__ import annotations

import argparse
import tomllib
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def layers() -> list[list[str]]:
    """The stages, top layer first, as the contract in pyproject.toml lists them."""
    cfg = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["importlinter"]
    contract = next(c for c in cfg["contracts"] if c["type"] == "layers")
    return [[s.strip().removeprefix("undulate.") for s in row.split("|")]
            for row in contract["layers"]]


def stage_imports(stages: list[str]) -> Counter:
    """(importer stage, imported stage) -> number of module-level imports between them."""
    import grimp

    graph = grimp.build_graph("undulate", exclude_type_checking_imports=True)

    def stage(module: str) -> str | None:
        parts = module.split(".")
        return parts[1] if len(parts) > 1 and parts[1] in stages else None

    out: Counter = Counter()
    for mod in graph.modules:
        a = stage(mod)
        for dep in graph.find_modules_directly_imported_by(mod):
            b = stage(dep)
            if a and b and a != b:
                out[(a, b)] += 1
    return out


def draw(out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = layers()
    stages = [s for row in rows for s in row]
    edges = stage_imports(stages)
    pos = {}
    for i, row in enumerate(rows):
        for j, s in enumerate(row):
            # a stage alone on its layer steps aside, left and right in turn, so the arrows
            # that pass it do not run through it
            x = (j + 1) / (len(row) + 1) if len(row) > 1 else 0.5 + 0.14 * (-1) ** i
            pos[s] = (x, 1.0 - i / max(len(rows) - 1, 1))
    fig, ax = plt.subplots(figsize=(8.0, 9.0))
    for (a, b), n in sorted(edges.items()):
        (xa, ya), (xb, yb) = pos[a], pos[b]
        ax.annotate("", xy=(xb, yb + 0.03), xytext=(xa, ya - 0.03),
                    arrowprops=dict(arrowstyle="->", color="0.55", lw=0.5 + 0.25 * min(n, 8),
                                    shrinkA=6, shrinkB=6, connectionstyle="arc3,rad=0.08"))
    for s, (x, y) in pos.items():
        ax.text(x, y, s, ha="center", va="center", fontsize=11,
                bbox=dict(boxstyle="round,pad=0.4", fc="#e8f0fb", ec="#3465a4"))
    ax.set_xlim(0, 1)
    ax.set_ylim(-0.08, 1.08)
    ax.axis("off")
    ax.set_title("undulate: stages import only the stages below them\n"
                 "(arrow: imports, width ~ how many; tools/layers.py)", fontsize=10)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110, bbox_inches="tight")
    plt.close(fig)
    for (a, b), n in sorted(edges.items(), key=lambda e: (stages.index(e[0][0]), -e[1])):
        print(f"{a:>12} -> {b:<12} {n:3d} imports")
    print(f"wrote {out}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "images" / "layers.png")
    draw(ap.parse_args().out)


if __name__ == "__main__":
    main()
