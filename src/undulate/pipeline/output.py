"""Files a simulation leaves behind: VTU for ParaView, metrics.json, side-view PNGs, centre lines.

Directory layout written by :func:`write_result`::

    DIR/final.vtu          fabric surface (triangles) + rod centre lines (lines), final state;
                           point data: displacement (from the printed state), position at
                           printing; cell data: membrane strain energy density [N mm / mm^2]
    DIR/printed.vtu        the same at printing (pre-stretched, flat)
    DIR/centerlines.npz    rod0, rod1, ...: final centre lines (m, 3) [mm], rods ordered by y
    DIR/metrics.json       inputs, solver statistics, history, seed, version, per-rod results
    DIR/rod_<k>_side.png   z along x of each rod's centre line
    DIR/rod_<k>_fits.png   the sine and arc-chain fits (written by pipeline.run_case)
    DIR/top_view.png       the sheet near the rods from above, coloured by height
    DIR/view_3d.png        the final shape near the rods in 3D, coloured by height

The folder is written whole or not at all (:class:`undulate.fileio.StagedDir`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .. import __version__
from ..fileio import atomic_write_json, jsonable

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


def _plot_side(path: Path, cl: np.ndarray, cl0: np.ndarray, offset: float, k: int | str,
               title: str, along_arc: bool = False) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..analysis.metrics import unrolled

    fig, ax = plt.subplots(figsize=(8, 2.8))
    xs = unrolled(cl)[:, 0] if along_arc else cl[:, 0]
    ax.plot(xs, cl[:, 2] - offset, "-", lw=2, label="rod centre line (final)")
    ax.axhline(0.0, color="0.6", lw=0.8, label="printed level")
    ax.set_xlabel("arc length along the line [mm]" if along_arc else "x [mm]")
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
    offs = [sk.offset for sk in result.sections]
    cls = result.centerlines
    paths = result.case.rod_paths()
    rods = []
    for k, (c, pth) in enumerate(zip(cls, paths, strict=True)):
        chord = pth.points[-1] - pth.points[0]
        rods.append(dict(index=k, id=pth.id, x_start=float(pth.points[0, 0]),
                         y=float(pth.points[0, 1]), length=pth.length, h=pth.h, b=pth.b,
                         angle_deg=float(np.degrees(np.arctan2(chord[1], chord[0]))),
                         straight=pth.straight,
                         y_printed=float(np.mean(result.centerlines_printed[k][:, 1])),
                         **rod_summary(c, offs[k])))
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
        for k, cl in enumerate(cls):
            title = (f"h = {paths[k].h:g} mm, eps0 = {c.release.eps0}, "
                     f"seed = {c.imperfection.seed}")
            _plot_side(out / f"rod_{k}_side.png", cl, result.centerlines_printed[k], offs[k],
                       paths[k].id if c.pattern is not None else k, title,
                       along_arc=not paths[k].straight)
        plot_top_view(out / "top_view.png", result)
        plot_3d(out / "view_3d.png", result)
    return metrics


def _height_limits(result) -> tuple[float, float]:
    z = result.x_final[:, 2]
    lim = max(float(np.max(np.abs(z))), 1e-6)
    return -lim, lim


def _near_rods(result) -> tuple[np.ndarray, np.ndarray, bool]:
    """Corners (lo, hi) of the lines' box padded by 15 % of its size (at least 10 mm), clipped
    to the sheet, and whether that crops the sheet."""
    x = result.x_final
    cls = np.concatenate(result.centerlines)
    pad = max(0.15 * max(float(np.ptp(cls[:, 0])), float(np.ptp(cls[:, 1]))), 10.0)
    lo = np.maximum(cls[:, :2].min(axis=0) - pad, x[:, :2].min(axis=0))
    hi = np.minimum(cls[:, :2].max(axis=0) + pad, x[:, :2].max(axis=0))
    cropped = bool(np.any(lo > x[:, :2].min(axis=0)) or np.any(hi < x[:, :2].max(axis=0)))
    return lo, hi, cropped


def plot_top_view(path: Path, result) -> None:
    """Top view of the final shape near the lines: the fabric coloured by height z [mm]
    (diverging map, 0 = the print bed), each rod's centre line drawn and named at its start;
    the title says when the sheet reaches beyond the picture."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.tri import Triangulation

    x = result.x_final
    lo, hi = _height_limits(result)
    fig, ax = plt.subplots(figsize=(7.5, 6.0))
    tri = Triangulation(x[:, 0], x[:, 1], result.mesh.tris)
    pc = ax.tripcolor(tri, x[:, 2], shading="gouraud", cmap="RdBu_r", vmin=lo, vmax=hi)
    paths = result.case.rod_paths()
    for k, cl in enumerate(result.centerlines):
        ax.plot(cl[:, 0], cl[:, 1], "-", color="k", lw=1.2)
        ax.annotate(paths[k].id, cl[0, :2], fontsize=7, xytext=(-4, 3),
                    textcoords="offset points", ha="right")
    fig.colorbar(pc, ax=ax, label="height z [mm]", shrink=0.85)
    lo_xy, hi_xy, cropped = _near_rods(result)
    ax.set_xlim(lo_xy[0], hi_xy[0])
    ax.set_ylim(lo_xy[1], hi_xy[1])
    ax.set_aspect("equal")
    d = result.case.release.direction
    ax.set_xlabel("x [mm]" + (" (stretch direction)" if d == 0 else f" (stretch at {d:g} deg)"))
    ax.set_ylabel("y [mm]")
    ax.set_title(f"{result.case.name}: top view after release (fabric coloured by height"
                 + ("; the sheet goes on beyond" if cropped else "") + ")", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_3d(path: Path, result) -> None:
    """3D rendering of the final shape near the rods (the far fabric cropped), coloured by
    height, with the rods' centre lines in black. Vertical scale exaggerated where the
    shape is flat, and said so in the title."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    x = result.x_final
    lo_xy, hi_xy, _ = _near_rods(result)
    tris = result.mesh.tris
    cen = x[tris].mean(axis=1)
    keep = np.all((cen[:, :2] >= lo_xy) & (cen[:, :2] <= hi_xy), axis=1)
    lo, hi = _height_limits(result)
    span = float(np.max(hi_xy - lo_xy))
    z_range = max(hi - lo, 1e-9)
    exag = max(1.0, 0.15 * span / z_range)
    fig = plt.figure(figsize=(8.0, 5.5))
    ax = fig.add_subplot(projection="3d")
    ax.plot_trisurf(x[:, 0], x[:, 1], x[:, 2] * exag, triangles=tris[keep], cmap="RdBu_r",
                    vmin=lo * exag, vmax=hi * exag, linewidth=0.0, antialiased=False,
                    alpha=0.9)
    for cl in result.centerlines:
        ax.plot(cl[:, 0], cl[:, 1], cl[:, 2] * exag, "-", color="k", lw=1.2, zorder=10)
    ax.set_xlim(lo_xy[0], hi_xy[0])
    ax.set_ylim(lo_xy[1], hi_xy[1])
    ax.set_box_aspect((hi_xy[0] - lo_xy[0], hi_xy[1] - lo_xy[1],
                       max(z_range * exag, 0.05 * span)))
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("y [mm]")
    ax.set_zlabel("z [mm]" if exag == 1.0 else f"z x {exag:.3g}")
    ax.view_init(elev=35, azim=-60)
    ttl = f"{result.case.name}: final shape"
    if exag > 1.0:
        ttl += f" (heights x {exag:.3g})"
    ax.set_title(ttl, fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
