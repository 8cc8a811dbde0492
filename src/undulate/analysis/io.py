"""Analysis of a simulation output directory, and the per-rod fit figures.

Directory format (written by the engine)::

    DIR/centerlines.npz   arrays rod0, rod1, ... each (M, 3): final centre line [mm],
                          rods ordered by y
    DIR/metrics.json      {"case": {..., "rods": {"L": ..., "h": ...}}, "rods": [{"index": 0,
                          ...}, ...], ...}

:func:`analyse_dir` adds to metrics.json (keeping every existing key): a top-level
``analysis`` (the full :func:`~undulate.analysis.analyse_run` result), a top-level ``family``
and, in each entry of ``rods`` (matched by ``index``, else by position), the keys
``l, lam, a, R, n, r2_arcs, r2_sine`` (plus ``quality``, ``L_nominal``, ``L_measured``).
It draws ``DIR/rod_<k>_fits.png``.
"""

from __future__ import annotations

import json
import re
import zipfile
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .fit import prepare
from .geometry import chain_points
from .metrics import analyse_run

__all__ = ["load_centerlines", "analyse_dir", "plot_fits", "ROD_KEYS"]

ROD_KEYS: tuple[str, ...] = (
    "l", "lam", "a", "R", "n", "r2_arcs", "r2_sine", "quality", "L_nominal", "L_measured"
)
"""Per-rod keys merged into each entry of ``metrics.json["rods"]``."""


def load_centerlines(path: str | Path) -> list[np.ndarray]:
    """Read ``centerlines.npz`` (a file, or a directory containing it): arrays ``rod<k>``
    in order of ``k``. Raises FileNotFoundError / ValueError with the path in the message."""
    p = Path(path)
    f = p / "centerlines.npz" if p.is_dir() else p
    if not f.is_file():
        raise FileNotFoundError(f"{f}: no centerlines.npz (expected arrays rod0, rod1, ...)")
    unreadable = f"{f}: not a readable centre-line file (truncated, or not written by undulate)"
    try:
        data = np.load(f, allow_pickle=False)
    except (zipfile.BadZipFile, EOFError, ValueError, OSError) as exc:
        raise ValueError(unreadable) from exc
    if not isinstance(data, np.lib.npyio.NpzFile):  # a bare .npy array
        raise ValueError(f"{f}: a single array, expected an .npz archive of rod0, rod1, ...")
    try:
        with data:
            keys = sorted(
                (k for k in data.files if re.fullmatch(r"rod\d+", k)), key=lambda k: int(k[3:])
            )
            if not keys:
                raise ValueError(f"{f}: no arrays named rod0, rod1, ... (found {data.files})")
            out = [np.asarray(data[k], dtype=float) for k in keys]
    except ValueError as exc:
        if str(exc).startswith(str(f)):
            raise
        raise ValueError(unreadable) from exc
    except (zipfile.BadZipFile, EOFError, OSError, KeyError) as exc:
        raise ValueError(unreadable) from exc
    for k, a in zip(keys, out, strict=True):
        if a.ndim != 2 or a.shape[1] not in (2, 3):
            raise ValueError(f"{f}: array {k} has shape {a.shape}, expected (M, 3)")
    return out


def _positive(v: Any) -> float | None:
    return float(v) if isinstance(v, int | float) and not isinstance(v, bool) and v > 0 else None


def _rod_lengths(meta: dict[str, Any], n: int) -> list[float | None] | None:
    """Nominal (printed) length of each rod: ``rods[k].length`` as the engine wrote it, else
    ``case.rods.L`` for parallel rods; None where unknown."""
    rods = meta.get("rods")
    if isinstance(rods, list) and len(rods) == n and all(isinstance(e, dict) for e in rods):
        Ls = [_positive(e.get("length")) for e in rods]
        if all(v is not None for v in Ls):
            return Ls
    try:
        r = meta["case"]["rods"]
        if r.get("segments") is None:
            return [_positive(r.get("L"))] * n
    except (KeyError, TypeError, AttributeError):
        pass
    return None


def plot_fits(xyz: ArrayLike, metrics: dict[str, Any], out: str | Path, *, title: str = "") -> Path:
    """Figure of ``z(x)`` with the sine and arc-chain fits of :func:`rod_metrics` overlaid."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cl = prepare(xyz)
    fig, ax = plt.subplots(figsize=(8, 3))
    ax.plot(cl.x, cl.z, ".", ms=3, color="0.3", label="centre line")
    ch = metrics.get("arc_chain")
    if ch:
        ss = np.linspace(ch["bounds"][0], ch["bounds"][-1], 800)
        x, z, _ = chain_points(ch["x0"], ch["z0"], ch["psi0"], ch["kappa"], ch["bounds"][1:-1], ss)
        ax.plot(x, z, "-", color="C3", label=f"arcs (R²={metrics['r2_arcs']:.4f})")
        xk, zk, _ = chain_points(
            ch["x0"], ch["z0"], ch["psi0"], ch["kappa"], ch["bounds"][1:-1], ch["bounds"]
        )
        ax.plot(xk, zk, "o", mfc="none", color="C3", ms=5, label="junctions")
    sine = metrics.get("sine")
    if sine:
        xs = np.linspace(cl.x.min(), cl.x.max(), 800)
        zs = sine["A"] * np.sin(2 * np.pi * xs / sine["lam"] + sine["phi"]) + sine["c"]
        ax.plot(xs, zs, "--", color="C0", label=f"sine (R²={metrics['r2_sine']:.4f})")
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("z [mm]")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_title(title or f"n = {metrics['n']}, quality = {metrics['quality']}", fontsize=9)
    ax.legend(fontsize=7, loc="best")
    fig.tight_layout()
    out = Path(out)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out


def analyse_dir(path: str | Path, *, plots: bool = True) -> dict[str, Any]:
    """Analyse a simulation output directory in place (format: module docstring).

    Uses the nominal rod lengths from metrics.json when present (``rods[k].length``, else
    ``case.rods.L``); the result keeps them as ``L_nominal`` beside the measured
    ``L_measured``. A folder still being written (``.NAME.incomplete-XXXX``) is refused. Writes the
    merged ``metrics.json`` and, if ``plots``, ``rod_<k>_fits.png``. Returns the
    :func:`analyse_run` dict plus ``"figures"`` (paths as strings).
    """
    from ..fileio import atomic_write_json, jsonable

    d = Path(path)
    if not d.is_dir():
        raise FileNotFoundError(f"{d}: not a directory")
    if ".incomplete-" in d.resolve().name:
        raise ValueError(f"{d}: an interrupted or unfinished run (its files are incomplete)")
    lines = load_centerlines(d)
    mfile = d / "metrics.json"
    meta: dict[str, Any] = {}
    if mfile.is_file():
        try:
            meta = json.loads(mfile.read_text(encoding="utf-8"))
        except (ValueError, UnicodeDecodeError) as exc:
            raise ValueError(f"{mfile}: not valid JSON (truncated or damaged?): {exc}") from None
        if not isinstance(meta, dict):
            raise ValueError(f"{mfile}: expected a JSON object")
    result = analyse_run(lines, L=_rod_lengths(meta, len(lines)))
    rods = meta.get("rods")
    if not isinstance(rods, list):
        rods = []
    by_index = {
        e.get("index", i): e for i, e in enumerate(rods) if isinstance(e, dict)
    }
    for r in result["rods"]:
        entry = by_index.get(r["index"])
        if entry is None:
            entry = {"index": r["index"]}
            rods.append(entry)
        entry.update({k: r[k] for k in ROD_KEYS})
    meta["rods"] = rods
    meta["analysis"] = result
    meta["family"] = result["family"]
    atomic_write_json(mfile, jsonable(meta))
    figures = []
    if plots:
        for k, (xyz, r) in enumerate(zip(lines, result["rods"], strict=True)):
            figures.append(str(plot_fits(xyz, r, d / f"rod_{k}_fits.png", title=f"rod {k}")))
    return {**result, "figures": figures}
