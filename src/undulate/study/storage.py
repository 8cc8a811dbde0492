"""On-disk layout of a study directory, atomic records, and the tidy results table.

Layout of ``DIR``::

    DIR/study.json            the study definition and its expected runs (id, params, seed)
    DIR/runs/<id>.json        one record per finished run (status "ok" or "failed")
    DIR/artifacts/<id>/       optional per-run artifacts written by the engine
    DIR/results.parquet       tidy table, one row per run (rewritten by ``run`` and ``status``)
    DIR/figures/*.png|pdf     figures; DIR/report.md the report

Records are written atomically: the JSON goes to a uniquely named ``*.tmp`` file in ``runs/``,
is flushed and fsync'ed, then ``os.replace``'d onto ``<id>.json``. A reader therefore sees either
the previous complete record or the new complete one, never a partial file. Leftover ``*.tmp``
files (a process killed while writing) and files that do not parse as a valid record are
ignored by :func:`scan_runs` and reported; their runs count as pending.
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pandas as pd

from ..fileio import (  # noqa: F401 (re-exported)
    atomic_path,
    atomic_write_json,
    current_umask,
    default_mode,
    jsonable,
)
from ..model.config import MATERIAL_DEFAULTS, Fabric, MeshOptions
from .spec import get_path

__all__ = [
    "RECORD_SCHEMA",
    "ScanResult",
    "jsonable",
    "atomic_write_json",
    "write_record",
    "read_record",
    "scan_runs",
    "read_study",
    "write_study",
    "collect",
    "write_table",
    "write_csv",
    "CSV_COLUMNS",
    "PARAM_ALIASES",
    "default_mode",
]

RECORD_SCHEMA = 1
STATUSES = ("ok", "failed")

#: short column name -> dotted path in the (effective) case, with the Case default
PARAM_ALIASES: dict[str, tuple[str, Any]] = {
    "h": ("rods.h", 0.3),
    "b": ("rods.b", MATERIAL_DEFAULTS["b"]),
    "L": ("rods.L", 100.0),
    "N": ("rods.N", 1),
    "s": ("rods.s", 10.0),
    "E_B": ("rods.E_B", MATERIAL_DEFAULTS["E_B"]),
    "eps0": ("release.eps0", 0.5),
    "E": ("fabric.E", MATERIAL_DEFAULTS["E"]),
    "t": ("fabric.t", MATERIAL_DEFAULTS["t"]),
    # records written before the resolved case was stored used the 20 mm default
    "margin_y": ("fabric.margin_y", 20.0),
    # the sheet and the mesh (defaults: those of the case file)
    "margin_x": ("fabric.margin_x", Fabric.model_fields["margin_x"].default),
    "mesh_kind": ("mesh.kind", MeshOptions.model_fields["kind"].default),
    "dx_rod": ("mesh.dx_rod", MeshOptions.model_fields["dx_rod"].default),
    "dx_far": ("mesh.dx_far", MeshOptions.model_fields["dx_far"].default),
}


def write_record(study_dir: Path, record: dict[str, Any]) -> Path:
    """Atomically write one run record to ``DIR/runs/<id>.json``; return its path."""
    path = Path(study_dir) / "runs" / f"{record['id']}.json"
    atomic_write_json(path, record)
    return path


def read_record(path: Path) -> dict[str, Any] | None:
    """A valid record from ``path``, or None if missing, unparsable or not a valid record."""
    try:
        data = json.loads(Path(path).read_text())
    except (OSError, ValueError, UnicodeDecodeError):
        return None
    if (
        not isinstance(data, dict)
        or data.get("id") != Path(path).stem
        or data.get("status") not in STATUSES
        or not isinstance(data.get("case"), dict)
    ):
        return None
    return data


@dataclass
class ScanResult:
    """Records found in ``DIR/runs``: valid ones by id, plus what was ignored and why."""

    records: dict[str, dict[str, Any]] = field(default_factory=dict)
    invalid: list[Path] = field(default_factory=list)
    tmp: list[Path] = field(default_factory=list)


def scan_runs(study_dir: Path) -> ScanResult:
    """Read every ``DIR/runs/*.json``; ignore (and list) ``*.tmp`` and invalid files."""
    res = ScanResult()
    runs = Path(study_dir) / "runs"
    if not runs.is_dir():
        return res
    for p in sorted(runs.iterdir()):
        if p.name.endswith(".tmp"):
            res.tmp.append(p)
        elif p.suffix == ".json":
            rec = read_record(p)
            if rec is None:
                res.invalid.append(p)
            else:
                res.records[rec["id"]] = rec
    return res


def remove_stale_tmp(study_dir: Path, older_than_s: float = 60.0) -> int:
    """Delete ``runs/*.tmp`` older than ``older_than_s`` (left by killed writers)."""
    n = 0
    now = time.time()
    for p in scan_runs(study_dir).tmp:
        try:
            if now - p.stat().st_mtime > older_than_s:
                p.unlink()
                n += 1
        except OSError:
            pass
    return n


def read_study(study_dir: Path) -> dict[str, Any] | None:
    """The parsed ``DIR/study.json`` or None."""
    p = Path(study_dir) / "study.json"
    try:
        data = json.loads(p.read_text())
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


def write_study(study_dir: Path, meta: dict[str, Any]) -> None:
    """Atomically write ``DIR/study.json``."""
    atomic_write_json(Path(study_dir) / "study.json", jsonable(meta))


def _row(rec: dict[str, Any]) -> dict[str, Any]:
    case = rec.get("case_resolved") or rec.get("case", {})
    row: dict[str, Any] = {
        "run_id": rec["id"],
        "status": rec["status"],
        "seed": rec.get("seed"),
    }
    for path, value in (rec.get("params") or {}).items():
        row[path] = value
    for short, (path, default) in PARAM_ALIASES.items():
        row[short] = get_path(case, path, default)
    for key, value in (rec.get("record") or {}).items():
        col = key if key not in row else f"rec_{key}"
        row[col] = json.dumps(value) if isinstance(value, list | dict) else value
    for key in ("error", "elapsed_s", "cpu_s", "started", "finished", "attempt", "host", "cpus",
                "engine"):
        row[key] = rec.get(key)
    return row


def collect(study_dir: Path, *, only_study: bool = True) -> pd.DataFrame:
    """Tidy table of a study: one row per valid record.

    Columns: ``run_id``, ``status``, ``seed``; the swept parameters by dotted path
    (e.g. ``rods.h``); short aliases of the effective case (``h b L N s E_B eps0 E t margin_y``,
    after the s = 0 single-rod rule); every field of the engine's record (a name that collides
    gets a ``rec_`` prefix; lists/dicts as JSON strings); ``error``, ``elapsed_s``, ``cpu_s``
    (CPU time of the run's process; empty in records written before it was kept), ``started``,
    ``finished``, ``attempt``, ``host``, ``cpus`` (cores the run could use), ``engine`` (digest
    of the engine that ran it, :func:`undulate.study.runner.engine_id`; empty for records
    written before it was kept). With ``only_study`` and a ``study.json`` present, only
    the runs of the current definition are included.
    """
    scan = scan_runs(study_dir)
    recs = list(scan.records.values())
    meta = read_study(study_dir)
    if only_study and meta and isinstance(meta.get("runs"), list):
        order = {r["id"]: i for i, r in enumerate(meta["runs"])}
        recs = sorted((r for r in recs if r["id"] in order), key=lambda r: order[r["id"]])
    df = pd.DataFrame([_row(r) for r in recs])
    if df.empty:
        df = pd.DataFrame(columns=["run_id", "status", "seed", "error", "elapsed_s"])
    return df


def _arrow_safe(df: pd.DataFrame) -> pd.DataFrame:
    """Object columns with mixed value types become strings so that parquet accepts them."""
    out = df.copy()
    for col in out.columns:
        if out[col].dtype == object:
            types = {type(v) for v in out[col] if v is not None and not _isnan(v)}
            if len(types) > 1 and not types <= {int, float}:
                out[col] = [None if v is None or _isnan(v) else str(v) for v in out[col]]
    return out


def _isnan(v: Any) -> bool:
    return isinstance(v, float) and math.isnan(v)


#: the leading columns of a study's CSV table, in this order (per-rod lists as JSON strings);
#: every other column of :func:`collect` follows them
CSV_COLUMNS: tuple[str, ...] = (
    "run_id", "status", "seed", "h", "s", "eps0", "N", "L", "b", "margin_y", "family", "n",
    "l_mean", "l_std", "lam_mean", "a_mean", "R_mean", "R_up_mean", "R_down_mean",
    "r2_arcs_mean", "r2_sine_mean", "onset_release_strain",
    "onset_negative_curvature_release_strain",
    "wall_time_s", "newton_iterations", "rods_n", "rods_l", "rods_a",
    "rods_onset_release_strain",
)


def write_csv(study_dir: Path, path: Path | None = None) -> Path:
    """Write the study's table as CSV (default ``DIR/table.csv``; atomically), one row per run:
    :data:`CSV_COLUMNS` first (empty where a record lacks one, e.g. a failed run), then the
    rest of :func:`collect`'s columns."""
    study_dir = Path(study_dir)
    df = collect(study_dir)
    for col in CSV_COLUMNS:
        if col not in df.columns:
            df[col] = None
    df = df[list(CSV_COLUMNS) + [c for c in df.columns if c not in CSV_COLUMNS]]
    path = Path(path) if path is not None else study_dir / "table.csv"
    with atomic_path(path) as tmp:
        df.to_csv(tmp, index=False)
    return path


def write_table(study_dir: Path, df: pd.DataFrame | None = None) -> Path:
    """Write ``DIR/results.parquet`` (atomically) from :func:`collect`; return its path."""
    study_dir = Path(study_dir)
    if df is None:
        df = collect(study_dir)
    path = study_dir / "results.parquet"
    with atomic_path(path) as tmp:
        _arrow_safe(df).to_parquet(tmp, index=False)
    return path
