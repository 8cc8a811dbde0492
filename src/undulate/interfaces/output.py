"""Files a simulation leaves behind: VTU for ParaView, metrics.json, side-view PNGs, centre lines.

Directory layout written by :func:`write_result`::

    DIR/final.vtu          fabric surface (triangles) + rod centre lines (lines), final state;
                           point data: displacement (from the printed state), position at
                           printing; cell data: membrane strain energy density [N mm / mm^2]
    DIR/printed.vtu        the same at printing (pre-stretched, flat)
    DIR/centerlines.npz    rod0, rod1, ...: final centre lines (m, 3) [mm], rods ordered by y
    DIR/metrics.json       inputs, solver statistics, history, seed, version, per-rod results
    DIR/rod_<k>_side.png   z along x of each rod's centre line
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .. import __version__
from ..study.storage import atomic_write_json, jsonable

__all__ = ["write_result", "rod_summary"]


def rod_summary(cl: np.ndarray, offset: float) -> dict:
    """Raw per-rod results: height above the printed level, sign changes of z, span."""
    z = cl[:, 2] - offset
    zs = z[np.abs(z) > 1e-3 * max(np.max(np.abs(z)), 1e-12)]
    return dict(
        max_height=float(np.max(z)),
        min_height=float(np.min(z)),
        sign_changes=int(np.count_nonzero(np.diff(np.sign(zs)) != 0)) if zs.size else 0,
        span=float(cl[-1, 0] - cl[0, 0]),
        n_nodes=int(cl.shape[0]),
    )


def _write_vtu(path: Path, result, x: np.ndarray, cls: list[np.ndarray]) -> None:
    import meshio

    mesh = result.mesh
    n = mesh.n_nodes
    pts = [x]
    lines = []
    off = n
    for c in cls:
        pts.append(c)
        m = c.shape[0]
        lines.append(np.stack([np.arange(off, off + m - 1), np.arange(off + 1, off + m)], 1))
        off += m
    P = np.concatenate(pts)
    disp = np.concatenate([x - result.x_printed] + [c - c0 for c, c0 in
                                                     zip(cls, result.centerlines_printed,
                                                         strict=True)]) \
        if x is not result.x_printed else np.zeros_like(P)
    is_rod = np.r_[np.zeros(n), np.ones(P.shape[0] - n)]
    cells = [("triangle", mesh.tris)]
    if lines:
        cells.append(("line", np.concatenate(lines)))
    X = result.x_reference
    tri = mesh.tris
    A0 = 0.5 * np.abs(np.cross(X[tri[:, 1]] - X[tri[:, 0]], X[tri[:, 2]] - X[tri[:, 0]])[:, 2])
    if x is result.x_final and "fabric_membrane" in result.element_energy:
        sed = result.element_energy["fabric_membrane"] / A0
    else:
        sed = np.zeros(tri.shape[0])
    cell_data = {"strain_energy_density": [sed] + ([np.zeros(len(np.concatenate(lines)))]
                                                   if lines else [])}
    meshio.write(
        str(path),
        meshio.Mesh(P, cells, point_data={"displacement": disp, "is_rod": is_rod},
                    cell_data=cell_data),
    )


def _plot_side(path: Path, cl: np.ndarray, cl0: np.ndarray, offset: float, k: int,
               title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 2.8))
    ax.plot(cl[:, 0], cl[:, 2] - offset, "-", lw=2, label="rod centre line (final)")
    ax.axhline(0.0, color="0.6", lw=0.8, label="printed level")
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("z [mm]")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_title(f"rod {k}: {title}", fontsize=9)
    ax.legend(fontsize=7, loc="upper right")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def write_result(result, out: Path, *, extra: dict | None = None, plots: bool = True,
                 vtu: bool = True) -> dict:
    """Write all output files of ``result`` into ``out``; return the metrics dict written."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    off = result.section.offset
    cls = result.centerlines
    rods = []
    for k, (c, (x0, y0, length)) in enumerate(zip(cls, result.case.segments(), strict=True)):
        rods.append(dict(index=k, x_start=x0, y=y0, length=length,
                         y_printed=float(np.mean(result.centerlines_printed[k][:, 1])),
                         **rod_summary(c, off)))
    metrics = {
        "undulate_version": __version__,
        "units": "mm, MPa, N, s",
        "case": result.case.model_dump(mode="json"),
        "seed": result.case.imperfection.seed,
        "release_path": {"mode": result.case.mode, "steps": result.case.release.steps,
                         "adaptive": result.case.release.adaptive},
        "solver": result.stats,
        "energies": result.energies,
        "history": result.history,
        "rods": rods,
    }
    if extra:
        metrics.update(extra)
    np.savez(out / "centerlines.npz", **{f"rod{k}": c for k, c in enumerate(cls)})
    atomic_write_json(out / "metrics.json", jsonable(metrics))
    if vtu:
        _write_vtu(out / "final.vtu", result, result.x_final, cls)
        _write_vtu(out / "printed.vtu", result, result.x_printed, result.centerlines_printed)
    if plots:
        c = result.case
        title = f"h = {c.rods.h} mm, eps0 = {c.release.eps0}, seed = {c.imperfection.seed}"
        for k, cl in enumerate(cls):
            _plot_side(out / f"rod_{k}_side.png", cl, result.centerlines_printed[k], off, k,
                       title)
    return metrics
