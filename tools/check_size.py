"""Size limits that keep the engine readable, checked by .ci/run.

    python tools/check_size.py            # exit 1 and one line per breach

* no function or method in solve/ and mechanics/ over 60 lines (its whole ``def``, docstring
  and comments included);
* no module in the package over 500 lines unless its first 40 lines hold a comment
  ``# size: <why>`` saying why it stays whole.

Complexity (at most 15 per function in solve/ and mechanics/) is ruff's C901, also run by
.ci/run.
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1] / "src" / "undulate"
FUNCTION_LINES = 60
MODULE_LINES = 500
ENGINE = ("solve", "mechanics")


def breaches() -> list[str]:
    out = []
    for path in sorted(ROOT.rglob("*.py")):
        text = path.read_text()
        rel = path.relative_to(ROOT.parent)
        n = text.count("\n")
        if n > MODULE_LINES and "# size:" not in "\n".join(text.splitlines()[:40]):
            out.append(f"{rel}: {n} lines (> {MODULE_LINES}); split it or say why in a "
                       "'# size:' comment near the top")
        if path.relative_to(ROOT).parts[0] not in ENGINE:
            continue
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                first = min([node.lineno] + [d.lineno for d in node.decorator_list])
                length = node.end_lineno - first + 1
                if length > FUNCTION_LINES:
                    out.append(f"{rel}:{node.lineno}: {node.name} is {length} lines "
                               f"(> {FUNCTION_LINES})")
    return out


def main() -> int:
    found = breaches()
    for line in found:
        print(line)
    return 1 if found else 0


if __name__ == "__main__":
    sys.exit(main())
