"""3D models of a finished run for design tools: binary glTF (.glb), OBJ and STL.

A designer continues in Rhino, Blender, Grasshopper or a browser viewer; they need the
simulated shape as a mesh, not as ParaView's VTU. :func:`run_scene` reads a run folder (the
files :func:`undulate.pipeline.output.write_result` leaves) and builds one scene:

``fabric``
    the deformed fabric mid-surface, the triangles of the simulation mesh with vertex
    normals. It is a surface, not a solid: the glTF material is double-sided, so both faces
    render.
``rod_0``, ``rod_1``, ...
    each rod as a solid: its real cross-section, b wide and h thick, swept along the deformed
    centre line and closed by an end cap at each end (watertight, outward normals). The
    section's thickness direction is the fabric's normal under the rod (the rod is bonded
    on top), made perpendicular to the centre line.

Coordinates are the simulation's, in **mm** (glTF readers assume metres: scale by 0.001 on
import where a tool does not ask). :func:`export_run` writes the scene with `trimesh`_: a
.glb keeps one named node per part, an .obj one named object per part, an .stl one named
solid per part (ASCII STL, which keeps the names; a binary STL cannot).

.. _trimesh: https://trimesh.org
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["FORMATS", "ExportError", "run_scene", "export_run", "rod_solid"]

#: the formats :func:`export_run` writes (the file suffix without the dot)
FORMATS: tuple[str, ...] = ("glb", "obj", "stl")


class ExportError(ValueError):
    """The run folder or the requested output cannot be used; the message is one line."""


def _tangents(c: np.ndarray) -> np.ndarray:
    """Unit tangents at the nodes of a polyline (central differences, second-order one-sided
    ones at the ends)."""
    d = np.gradient(c, axis=0, edge_order=2 if len(c) > 2 else 1)
    return d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-300)


def rod_solid(c: np.ndarray, up: np.ndarray, b: float, h: float) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and triangles of a b x h rectangle swept along the centre line ``c`` (m, 3).

    ``up`` (m, 3) points, at each node, to the rod's thickness direction (it is made
    perpendicular to the centre line here). Four corners per node; the side faces join
    consecutive sections and two caps close the ends, all wound so that normals point out.
    """
    c = np.asarray(c, dtype=float)
    if c.ndim != 2 or c.shape[1] != 3 or c.shape[0] < 2:
        raise ExportError(f"rod centre line: need at least 2 points of (x, y, z), got shape "
                          f"{c.shape}")
    t = _tangents(c)
    u = up - np.sum(up * t, axis=1, keepdims=True) * t
    u /= np.maximum(np.linalg.norm(u, axis=1, keepdims=True), 1e-300)
    w = np.cross(u, t)  # in-plane width direction; (w, u, t) right-handed
    corners = [(-0.5 * b, -0.5 * h), (0.5 * b, -0.5 * h), (0.5 * b, 0.5 * h), (-0.5 * b, 0.5 * h)]
    verts = np.stack([c + cw * w + cu * u for cw, cu in corners], axis=1).reshape(-1, 3)
    m = c.shape[0]
    faces = []
    for i in range(m - 1):
        a0, a1 = 4 * i, 4 * (i + 1)
        for k in range(4):
            k1 = (k + 1) % 4
            # the section's corners go counter-clockwise seen from +t: outward is
            # (corner k -> k+1) x t
            faces.append((a0 + k, a0 + k1, a1 + k1))
            faces.append((a0 + k, a1 + k1, a1 + k))
    last = 4 * (m - 1)
    faces += [(0, 2, 1), (0, 3, 2)]  # start cap faces -t
    faces += [(last, last + 1, last + 2), (last, last + 2, last + 3)]  # end cap faces +t
    return verts, np.asarray(faces, dtype=np.int64)


def _read_run(run_dir: Path) -> tuple[np.ndarray, np.ndarray, list[np.ndarray], list[dict]]:
    """Fabric points and triangles, rod centre lines and rod entries of a run folder."""
    import meshio

    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise ExportError(f"RUN_DIR: {run_dir} is not a folder (give the --out of an "
                          "'undulate run' or 'undulate demo')")
    missing = [n for n in ("final.vtu", "centerlines.npz", "metrics.json")
               if not (run_dir / n).is_file()]
    if missing:
        raise ExportError(f"RUN_DIR: {run_dir} has no {', '.join(missing)} (not a finished "
                          "run folder)")
    try:
        mesh = meshio.read(run_dir / "final.vtu")
        meta = json.loads((run_dir / "metrics.json").read_text())
        with np.load(run_dir / "centerlines.npz") as z:
            cls = [np.asarray(z[f"rod{k}"], dtype=float) for k in range(len(z.files))]
    except (OSError, ValueError, KeyError) as err:
        raise ExportError(f"RUN_DIR: cannot read {run_dir} ({type(err).__name__}: "
                          f"{str(err).splitlines()[0] if str(err) else ''})") from None
    tris = np.asarray(mesh.cells_dict.get("triangle", np.zeros((0, 3))), dtype=np.int64)
    is_rod = np.asarray(mesh.point_data.get("is_rod", np.zeros(len(mesh.points))))
    n_fabric = int(np.count_nonzero(is_rod == 0))
    rods = list(meta.get("rods") or [])
    if not tris.size or len(rods) != len(cls):
        raise ExportError(f"RUN_DIR: {run_dir} does not hold a fabric mesh with "
                          f"{len(cls)} rod(s) described in metrics.json")
    return np.asarray(mesh.points[:n_fabric], dtype=float), tris, cls, rods


def run_scene(run_dir: str | Path) -> Any:
    """The run's final state as a :class:`trimesh.Scene`: ``fabric`` and ``rod_<k>`` nodes."""
    import trimesh
    from scipy.spatial import cKDTree

    pts, tris, cls, rods = _read_run(Path(run_dir))
    fabric = trimesh.Trimesh(pts, tris, process=False)
    normals = np.asarray(fabric.vertex_normals)
    # the rods sit on top of the fabric: orient the normals so that most rods are above
    tree = cKDTree(pts)
    scene = trimesh.Scene()
    fabric.visual = trimesh.visual.TextureVisuals(material=trimesh.visual.material.PBRMaterial(
        name="fabric", baseColorFactor=[200, 200, 210, 255], doubleSided=True,
        roughnessFactor=0.9, metallicFactor=0.0))
    scene.add_geometry(fabric, node_name="fabric", geom_name="fabric")
    for k, (c, rod) in enumerate(zip(cls, rods, strict=True)):
        _, near = tree.query(c)
        up = normals[near]
        # bonded on top: the normal points from the fabric towards the rod's centre line
        side = np.sum((c - pts[near]) * up, axis=1)
        up = up * np.where(side < 0.0, -1.0, 1.0)[:, None]
        v, f = rod_solid(c, up, float(rod["b"]), float(rod["h"]))
        solid = trimesh.Trimesh(v, f, process=False)
        solid.visual = trimesh.visual.TextureVisuals(
            material=trimesh.visual.material.PBRMaterial(
                name=f"rod_{k}", baseColorFactor=[230, 110, 40, 255], roughnessFactor=0.6,
                metallicFactor=0.0))
        scene.add_geometry(solid, node_name=f"rod_{k}", geom_name=f"rod_{k}")
    return scene


def _stl_ascii(scene: Any) -> str:
    """One ``solid NAME`` block per part of the scene (ASCII STL keeps the names)."""
    out = []
    for name, g in scene.geometry.items():
        n = np.asarray(g.face_normals)
        tri = np.asarray(g.triangles)
        out.append(f"solid {name}")
        for nk, (a, b, c) in zip(n, tri, strict=True):
            out.append(f"  facet normal {nk[0]:.6e} {nk[1]:.6e} {nk[2]:.6e}\n    outer loop")
            out.extend(f"      vertex {p[0]:.6e} {p[1]:.6e} {p[2]:.6e}" for p in (a, b, c))
            out.append("    endloop\n  endfacet")
        out.append(f"endsolid {name}")
    return "\n".join(out) + "\n"


def export_run(run_dir: str | Path, out: str | Path, fmt: str | None = None) -> Path:
    """Write the run's final state as a 3D model; the format from ``fmt`` or ``out``'s suffix.

    Returns the path written. Raises :class:`ExportError` (one line) for a folder that is not
    a finished run, an unknown format or an output that cannot be written.
    """
    out = Path(out)
    fmt = (fmt or out.suffix.lstrip(".")).lower()
    if fmt not in FORMATS:
        raise ExportError(f"format: must be one of {', '.join(FORMATS)} (or an --out ending "
                          f"in one of them), got {fmt!r}")
    scene = run_scene(run_dir)
    if fmt == "glb":
        data: bytes | str = scene.export(file_type="glb")
    elif fmt == "obj":
        data = scene.export(file_type="obj", include_normals=True, include_texture=False)
    else:
        data = _stl_ascii(scene)
    try:
        if out.parent and not out.parent.exists():
            out.parent.mkdir(parents=True)
        if isinstance(data, str):
            out.write_text(data)
        else:
            out.write_bytes(data)
    except OSError as err:
        raise ExportError(f"--out: cannot write {out} ({err.strerror or err})") from None
    return out
