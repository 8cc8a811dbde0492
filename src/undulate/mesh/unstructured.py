"""Unstructured, graded, rod-conforming triangle mesh of the fabric (Shewchuk's Triangle).

The mesh lives in the fabric's *reference* (unstretched) configuration. Rods are straight lines
given in the *printed* (pre-stretched) configuration (:class:`RodLine`: start, unit direction,
length) and mapped to the reference by the homogeneous part of the pre-stretch,
X = x / (1 + eps0), Y = y / lam_y, as in :mod:`undulate.mesh.grid`.

Every rod gets m = ceil(L / dx_rod) + 1 equally spaced centre nodes (row ``p``) and two side rows
at +-b/2 along the in-plane normal n = (-d_y, d_x) (``qp`` at +n, ``qm`` at -n), all placed in
printed coordinates and then mapped. For a rod along +x these are exactly the stations of the
structured grid. The footprint (3 rows x m columns) is meshed here as a structured strip of
triangles with alternating diagonals; the rest of the sheet is meshed by Triangle as a planar
straight-line graph: the outer rectangle plus every footprint outline (all its boundary nodes)
as constrained segments that may not be split, the footprints as holes. Strip triangles are then
added, so every strip edge is a mesh edge.

Element size grows with the distance d (reference) to the nearest footprint::

    h(d) = min(h_far, h_near + (grading - 1) d)

(the continuous analogue of the structured grid's geometric growth ``grading`` per element),
with h_near ~ the rods' node spacing and ``h_far``, both mapped to the reference like
lengths along x. It is imposed with Triangle's per-triangle area constraints (target area of an
equilateral triangle of side h at each centroid, a few refinement passes) under a minimum angle
``min_angle``. Nodes on the outer edges are placed from the same size function.

Geometry code is direction-agnostic: rods may point in any in-plane direction.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .grid import FabricMesh, RodChain

__all__ = [
    "RodLine",
    "rod_lines_from_segments",
    "build_unstructured_mesh",
    "UNSTRUCTURED_HINGE_FACTOR",
]

UNSTRUCTURED_HINGE_FACTOR = 0.44
"""Hinge-bending factor for these meshes (see mechanics/fabric.py).

On an equilateral mesh the hinge energy D * f * |e|^2 / (A_a + A_b) * theta^2 equals
(D/2) * integral kappa^2 dA for a cylinder of any orientation with f = 1 exactly; on Triangle's
quality meshes the irregular hinges add energy, and f = 1 overestimates by a factor 1.95-2.46
(mean 2.28; cylinders along x, y and +-45 degrees, uniform and graded meshes, dx_rod 0.5-1),
hence f = 1 / 2.28 = 0.44 (``tests/test_mesh_unstructured.py``).
"""


@dataclass(frozen=True)
class RodLine:
    """A straight rod in the printed configuration: start point, unit direction, length [mm]."""

    start: tuple[float, float]
    direction: tuple[float, float]
    length: float

    def __post_init__(self) -> None:
        dx, dy = (float(v) for v in self.direction)
        norm = math.hypot(dx, dy)
        if not norm > 0.0 or not math.isfinite(norm):
            raise ValueError(f"RodLine: direction must be a non-zero vector, got {self.direction}")
        if not self.length > 0.0:
            raise ValueError(f"RodLine: length must be > 0, got {self.length}")
        object.__setattr__(self, "direction", (dx / norm, dy / norm))
        object.__setattr__(self, "start", (float(self.start[0]), float(self.start[1])))
        object.__setattr__(self, "length", float(self.length))

    @property
    def normal(self) -> np.ndarray:
        """In-plane unit normal (+90 degrees from the direction): +y for a rod along +x."""
        return np.array([-self.direction[1], self.direction[0]])

    def stations(self, dx_rod: float) -> np.ndarray:
        """(m, 2) centre-node positions, m = ceil(L / dx_rod) + 1, equally spaced (printed)."""
        n_int = max(1, int(np.ceil(self.length / dx_rod - 1e-9)))
        s = np.linspace(0.0, self.length, n_int + 1)
        return np.asarray(self.start) + s[:, None] * np.asarray(self.direction)


def rod_lines_from_segments(segments) -> list[RodLine]:
    """Accept RodLine objects or (x_start, y_centre, length) tuples of rods along +x."""
    out = []
    for s in segments:
        if isinstance(s, RodLine):
            out.append(s)
        else:
            x0, y0, length = s
            out.append(RodLine((x0, y0), (1.0, 0.0), length))
    return out


BOUNDARY_SPACING = 0.8
"""Nodes on the outer edges are spaced by this fraction of the size function there: slightly
denser than the interior, so that Triangle meets the minimum angle next to them."""

NEAR_SIZE_FACTOR = 1.2
"""h_near = this * the longest footprint outline edge (reference). With h_near equal to the
outline spacing, Triangle now and then inserts points that encroach on the fixed footprint
outlines and has to split them (2 of 72 cases at q28); with 1.2 none of 108 cases did
(N = 1 and 5, s = 1 and 2.5 mm, margins 20-200 mm, h_far 4-15 mm, dx_rod 0.5 and 1 mm;
all had min angle >= 28 degrees outside the footprints). Should it still happen, the mesh is
made again with every boundary segment kept whole (Triangle's -Y)."""


def _size(d: np.ndarray, h_near: float, h_far: float, grading: float) -> np.ndarray:
    return np.minimum(h_far, h_near + (grading - 1.0) * np.maximum(d, 0.0))


def _edge_points(a: np.ndarray, c: np.ndarray, size_at) -> np.ndarray:
    """Points from a to c (both included) spaced by the size function along the edge."""
    length = float(np.linalg.norm(c - a))
    s = np.linspace(0.0, length, max(200, int(length / 0.05)) + 1)
    pts = a + (s / length)[:, None] * (c - a)
    inv_h = 1.0 / (BOUNDARY_SPACING * size_at(pts))
    cum = np.concatenate([[0.0], np.cumsum(0.5 * (inv_h[1:] + inv_h[:-1]) * np.diff(s))])
    n = max(1, int(np.ceil(cum[-1] - 0.2)))
    si = np.interp(np.linspace(0.0, cum[-1], n + 1), cum, s)
    si[0], si[-1] = 0.0, length
    out = a + (si / length)[:, None] * (c - a)
    out[0], out[-1] = a, c  # exact corners
    return out


def _rects_overlap(ca: np.ndarray, cb: np.ndarray, tol: float) -> bool:
    """Do two convex polygons (k, 2) overlap or come closer than ``tol`` (separating axes)?"""
    for poly in (ca, cb):
        e = np.roll(poly, -1, axis=0) - poly
        normals = np.stack([-e[:, 1], e[:, 0]], axis=1)
        normals /= np.linalg.norm(normals, axis=1, keepdims=True)
        for nrm in normals:
            pa, pb = ca @ nrm, cb @ nrm
            if pa.max() + tol <= pb.min() or pb.max() + tol <= pa.min():
                return False
    return True


def _describe(k: int, line: RodLine) -> str:
    return (f"rod {k} (start {line.start[0]:g}, {line.start[1]:g}; direction "
            f"{line.direction[0]:.4g}, {line.direction[1]:.4g}; length {line.length:g})")


def build_unstructured_mesh(
    segments,
    b: float,
    extent: tuple[float, float, float, float],
    *,
    eps0: float,
    lam_y: float,
    dx_rod: float,
    h_far: float,
    grading: float,
    min_angle: float = 28.0,
    max_passes: int = 12,
    protect_boundary: bool = False,
) -> FabricMesh:
    """Reference mesh for rods (``RodLine`` or (x0, y, L) tuples) given in printed coordinates.

    ``extent`` is the printed fabric box (xmin, xmax, ymin, ymax). Returns a :class:`FabricMesh`
    with ``xs = ys = None``, the rods' node chains, the clamped edges ``left``/``right`` and the
    ``node_sets`` "left", "right", "bottom", "top".
    """
    import triangle
    from scipy.spatial import cKDTree

    lines = rod_lines_from_segments(segments)
    if not lines:
        raise ValueError("mesh: the unstructured mesh needs at least one rod")
    sx, sy = 1.0 + eps0, lam_y
    scale = np.array([1.0 / sx, 1.0 / sy])
    xmin, xmax, ymin, ymax = (extent[0] / sx, extent[1] / sx, extent[2] / sy, extent[3] / sy)
    tol = 1e-9 * max(xmax - xmin, ymax - ymin)

    # ---- rod strips (printed -> reference) and input checks
    strips = []  # (P, Qp, Qm) reference, each (m, 2)
    corners = []  # printed footprint rectangles
    for k, ln in enumerate(lines):
        P = ln.stations(dx_rod)
        nrm = ln.normal * (b / 2.0)
        Qp, Qm = P + nrm, P - nrm
        rect = np.array([Qm[0], Qm[-1], Qp[-1], Qp[0]])
        corners.append(rect)
        ref = rect * scale
        if (ref[:, 0].min() <= xmin + tol or ref[:, 0].max() >= xmax - tol
                or ref[:, 1].min() <= ymin + tol or ref[:, 1].max() >= ymax - tol):
            raise ValueError(
                f"mesh: {_describe(k, ln)}: its footprint (width b = {b:g} mm) is not strictly "
                f"inside the fabric {tuple(float(v) for v in extent)} (printed, mm)"
            )
        strips.append((P * scale, Qp * scale, Qm * scale))
    for i in range(len(lines)):
        for j in range(i + 1, len(lines)):
            if _rects_overlap(corners[i], corners[j], 1e-6 * max(b, dx_rod)):
                raise ValueError(
                    f"mesh: {_describe(i, lines[i])} and {_describe(j, lines[j])} overlap or "
                    f"touch (footprints of width b = {b:g} mm)"
                )

    # ---- size function (reference lengths)
    # the footprint's longest edges (along the rod, or b/2 across it at its ends) set h_near
    h_near = NEAR_SIZE_FACTOR * min(
        max(float(np.linalg.norm(P[1] - P[0])), float(np.linalg.norm(Qp[0] - P[0])))
        for P, Qp, _ in strips)
    h_big = max(h_far / sx, h_near)
    outline_dense = []
    for _, Qp, Qm in strips:
        ring = np.concatenate([Qm, Qp[::-1], Qm[:1]])
        t = np.linspace(0.0, 1.0, 5)[:-1]
        outline_dense.append((ring[:-1, None] + t[None, :, None] * np.diff(ring, axis=0)[:, None])
                             .reshape(-1, 2))
    tree = cKDTree(np.concatenate(outline_dense))

    def size_at(pts: np.ndarray) -> np.ndarray:
        d, _ = tree.query(pts)
        return _size(d, h_near, h_big, grading)

    # ---- PSLG: footprint outlines first (their indices are kept by Triangle), then the box
    verts: list[np.ndarray] = []
    segs: list[np.ndarray] = []
    holes = []
    outline_ids = []  # per rod: (ids of Qm, ids of P ends, ids of Qp) in the PSLG numbering
    off = 0
    for P, Qp, Qm in strips:
        m = P.shape[0]
        ring = np.concatenate([Qm, P[-1:], Qp[::-1], P[:1]])  # 2m + 2 nodes, closed loop
        ids = off + np.arange(ring.shape[0])
        verts.append(ring)
        segs.append(np.stack([ids, np.roll(ids, -1)], axis=1))
        qm_ids = ids[:m]
        p_end = ids[m]
        qp_ids = ids[m + 1 : 2 * m + 1][::-1]
        p_start = ids[2 * m + 1]
        outline_ids.append((qm_ids, p_start, p_end, qp_ids))
        holes.append((P[0] + P[1] + Qp[0]) / 3.0)
        off += ring.shape[0]
    box = [np.array(c, float) for c in ((xmin, ymin), (xmax, ymin), (xmax, ymax), (xmin, ymax))]
    ring = np.concatenate([_edge_points(box[i], box[(i + 1) % 4], size_at)[:-1]
                           for i in range(4)])
    ids = off + np.arange(ring.shape[0])
    verts.append(ring)
    segs.append(np.stack([ids, np.roll(ids, -1)], axis=1))
    V_in = np.concatenate(verts)
    S_in = np.concatenate(segs)
    n_outline = off

    pslg = {"vertices": V_in, "segments": S_in, "holes": np.asarray(holes)}
    area_far = math.sqrt(3.0) / 4.0 * h_big**2
    opts = f"pq{min_angle:g}" + ("Y" if protect_boundary else "")
    t = triangle.triangulate(pslg, opts + f"a{area_far:.12g}")
    for _ in range(max_passes):
        V, T = t["vertices"], t["triangles"]
        cen = V[T].mean(axis=1)
        target = math.sqrt(3.0) / 4.0 * size_at(cen) ** 2
        area = 0.5 * np.abs(_cross(V[T[:, 1]] - V[T[:, 0]], V[T[:, 2]] - V[T[:, 0]]))
        if np.all(area <= 1.25 * target):
            break
        t = triangle.triangulate(
            {"vertices": V, "triangles": T, "segments": t["segments"],
             "triangle_max_area": target, "holes": np.asarray(holes)},
            "r" + opts + "a",
        )
    V, T = t["vertices"], np.asarray(t["triangles"], dtype=np.int64)
    if not np.array_equal(V[:n_outline], V_in[:n_outline]):
        raise RuntimeError("mesh: Triangle moved or renumbered the footprint outline nodes")
    if not _has_edges(T, S_in[:n_outline]):
        # Triangle split a footprint outline segment (encroached): mesh again with every
        # boundary segment kept whole (quality near the outer edges may then be a bit lower)
        if protect_boundary:
            raise RuntimeError("mesh: Triangle split a footprint outline segment")
        return build_unstructured_mesh(
            segments, b, extent, eps0=eps0, lam_y=lam_y, dx_rod=dx_rod, h_far=h_far,
            grading=grading, min_angle=min_angle, max_passes=max_passes, protect_boundary=True,
        )

    # ---- strips: interior centre nodes appended, structured triangles added
    X = [V]
    n = V.shape[0]
    tris = [T]
    rods = []
    for (P, _, _), (qm_ids, p_start, p_end, qp_ids) in zip(strips, outline_ids, strict=True):
        m = P.shape[0]
        p_ids = np.concatenate([[p_start], n + np.arange(m - 2), [p_end]]).astype(np.int64)
        X.append(P[1:-1])
        n += m - 2
        rows = [qm_ids, p_ids, qp_ids]
        st = []
        for j in range(2):
            lo, hi = rows[j], rows[j + 1]
            for i in range(m - 1):
                if (i + j) % 2 == 0:
                    st += [(lo[i], lo[i + 1], hi[i + 1]), (lo[i], hi[i + 1], hi[i])]
                else:
                    st += [(lo[i], lo[i + 1], hi[i]), (lo[i + 1], hi[i + 1], hi[i])]
        tris.append(np.asarray(st, dtype=np.int64))
        rods.append(RodChain(p=p_ids, qm=np.asarray(qm_ids, np.int64),
                             qp=np.asarray(qp_ids, np.int64)))
    Xa = np.concatenate(X)
    Ta = np.concatenate(tris)
    det = _cross(Xa[Ta[:, 1]] - Xa[Ta[:, 0]], Xa[Ta[:, 2]] - Xa[Ta[:, 0]])
    flip = det < 0
    Ta[flip] = Ta[flip][:, [0, 2, 1]]

    eps = 1e-9 * max(xmax - xmin, ymax - ymin)
    node_sets = {
        "left": _sorted_set(Xa, np.abs(Xa[:, 0] - xmin) <= eps, 1),
        "right": _sorted_set(Xa, np.abs(Xa[:, 0] - xmax) <= eps, 1),
        "bottom": _sorted_set(Xa, np.abs(Xa[:, 1] - ymin) <= eps, 0),
        "top": _sorted_set(Xa, np.abs(Xa[:, 1] - ymax) <= eps, 0),
    }
    return FabricMesh(
        X=Xa, tris=Ta, rods=rods, left=node_sets["left"], right=node_sets["right"],
        node_sets=node_sets, hinge_factor=UNSTRUCTURED_HINGE_FACTOR, kind="unstructured",
    )


def _has_edges(T: np.ndarray, edges: np.ndarray) -> bool:
    """Are all ``edges`` (k, 2) edges of the triangles ``T``?"""
    te = np.sort(np.concatenate([T[:, [0, 1]], T[:, [1, 2]], T[:, [2, 0]]]), axis=1)
    have = set(map(tuple, te.tolist()))
    return all(tuple(e) in have for e in np.sort(edges, axis=1).tolist())


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]


def _sorted_set(X: np.ndarray, mask: np.ndarray, axis: int) -> np.ndarray:
    idx = np.nonzero(mask)[0]
    return idx[np.argsort(X[idx, axis], kind="stable")].astype(np.int64)
