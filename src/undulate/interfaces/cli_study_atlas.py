"""`undulate study atlas`: studies' results as an atlas for designs (undulate.design.atlas),
the data `undulate predict` answers from."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any, NoReturn

import typer

from .common import fail


def _fail(msg: str) -> NoReturn:
    raise fail(msg)


#: what a SWEEP.toml study may sweep to make an atlas (one row per h, s) ...
_ATLAS_SWEEP = frozenset({"rods.h", "rods.s", "imperfection.seed"})
#: ... and what it may sweep besides to make one atlas per combination of their values
_ATLAS_GROUPS = {"rods.L": "L", "release.eps0": "eps0"}


def atlas_cmd(
    directories: Annotated[list[Path], typer.Argument(
        help="study directories (parallel-phase-diagram, single-rod-h, or sweeps over "
             "rods.h and rods.s, and maybe rods.L and release.eps0), or their table.csv; "
             "several are pooled (e.g. a diagram and its refinement)")],
    out: Annotated[Path, typer.Option(
        "--out", help="atlas CSV to write; a folder when a study sweeps rods.L or "
                      "release.eps0 (one CSV per combination, named L<L>_eps0-<eps0>.csv)")],
) -> None:
    """Studies' results as an atlas for designs (one row per (h, s): family, n, l, lam, a).

    The package ships several (undulate.design.atlas, undulate predict): remake them with
    undulate study atlas DIR [REFINEMENT_DIR] --out src/undulate/design/data/phase_diagram.csv
    (the diagram) and undulate study atlas docs/studies/single-rod-h/table.csv --out
    src/undulate/design/data/single_rod.csv. A SWEEP.toml study that sweeps rods.h and
    rods.s (and the seed) only, e.g. the diagram at another rod length, makes one too; one
    that also sweeps rods.L or release.eps0 makes one atlas per (L, eps0) in the folder
    --out. predict reads every atlas CSV in that data folder and its sub-folders.
    """
    import pandas as pd

    from undulate.design.atlas import build_atlas, write_atlas

    tables, setups, swept = [], [], set()
    for directory in directories:
        table, setup, keys = _atlas_table(directory)
        tables.append(table)
        setups.append(setup)
        swept |= keys
    known = [x for x in setups if x is not None]  # (a table.csv does not say)
    if any(x != known[0] for x in known[1:]):
        _fail(f"{' '.join(map(str, directories))}: the studies were run on different "
              f"set-ups ({'; '.join(map(str, setups))}): pool only studies of one set-up")
    table = pd.concat(tables, ignore_index=True)
    if not swept & set(_ATLAS_GROUPS):
        groups = [("", table)]
    elif out.suffix == ".csv":
        _fail(f"--out: {out} is a file, but the study sweeps "
              f"{', '.join(sorted(swept & set(_ATLAS_GROUPS)))}: give a folder (one atlas "
              "per combination)")
    else:
        groups = [(f"L{L:g}_eps0-{e:g}", g) for (L, e), g in table.groupby(["L", "eps0"])]
    for label, part in groups:
        try:
            atlas = build_atlas(part, setup=(known[0] or None) if known else None)
        except (ValueError, KeyError) as err:
            _fail(f"{' '.join(map(str, directories))}: {err}")
        path = write_atlas(atlas, out / f"{label}.csv" if label else out)
        typer.echo(f"{path}: {atlas.meta['points']} points from {atlas.meta['runs']} runs")


def _atlas_table(directory: Path) -> tuple[Any, Any, set[str]]:
    """One study's table for an atlas, its set-up and what it swept; a study that cannot
    make an atlas stops with one line naming what it sweeps."""
    import pandas as pd

    from undulate.study.storage import collect, read_study

    if directory.is_file() and directory.suffix == ".csv":
        return pd.read_csv(directory), None, set()
    if not (directory / "runs").is_dir():
        _fail(f"{directory}: not a study directory (no runs/) nor a table .csv")
    meta = read_study(directory) or {}
    swept = set((meta.get("definition") or {}).get("sweep") or {})
    allowed = _ATLAS_SWEEP | set(_ATLAS_GROUPS)
    atlas_sweep = meta.get("kind") == "sweep" and swept and swept <= allowed
    if meta.get("name") not in ("parallel-phase-diagram", "single-rod-h") and not atlas_sweep:
        _fail(f"{directory}: an atlas is made from a parallel-phase-diagram or "
              f"single-rod-h study, or a sweep over {', '.join(sorted(allowed))} "
              f"only (this one is {meta.get('name')!r}"
              + (f", sweeping {', '.join(sorted(swept))})" if swept else ")"))
    # (a study run without --setup is on the bare defaults: {} here, not "unknown")
    return collect(directory), meta.get("definition", {}).get("setup") or {}, swept
