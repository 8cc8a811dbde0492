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

Geometry code is direction-agnostic: rods may point in any in-plane direction, and a rod may
be any smooth polyline (:class:`RodPath`): its centre nodes are then equally spaced along its
arc length and the side rows lie at +-b/2 along the local normal (central differences of the
centre nodes), so a curved rod's footprint is a curved strip; each path may carry its own
width b.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .grid import FabricMesh, RodChain

__all__ = [
    "stretch_rotation",
    "RodLine",
    "RodPath",
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


@dataclass(frozen=True)
class RodPath:
    """A rod along a polyline ``points`` (k x 2, printed configuration, mm), of its own width
    ``b`` [mm] (None: the mesh's common width). Straight or curved; it must bend gently
    compared with b and the node spacing (checked by the case, see ``model/config.py``)."""

    points: np.ndarray
    b: float | None = None
    id: str = ""

    def __post_init__(self) -> None:
        pts = np.asarray(self.points, dtype=float)
        if pts.ndim != 2 or pts.shape[1] != 2 or len(pts) < 2 or not np.isfinite(pts).all():
            raise ValueError(f"RodPath: points must be k >= 2 finite (x, y) pairs, got shape "
                             f"{pts.shape}")
        keep = np.ones(len(pts), bool)
        keep[1:] = np.linalg.norm(np.diff(pts, axis=0), axis=1) > 1e-12
        pts = pts[keep]
        if len(pts) < 2:
            raise ValueError("RodPath: has zero length")
        object.__setattr__(self, "points", pts)

    @property
    def length(self) -> float:
        """Arc length [mm]."""
        return float(np.sum(np.linalg.norm(np.diff(self.points, axis=0), axis=1)))

    def stations(self, dx_rod: float) -> np.ndarray:
        """(m, 2) centre nodes equally spaced along the arc length, m = ceil(L / dx_rod) + 1;
        for a straight path the same as :meth:`RodLine.stations`."""
        seg = np.linalg.norm(np.diff(self.points, axis=0), axis=1)
        cum = np.concatenate([[0.0], np.cumsum(seg)])
        n_int = max(1, int(np.ceil(cum[-1] / dx_rod - 1e-9)))
        s = np.linspace(0.0, cum[-1], n_int + 1)
        out = np.stack([np.interp(s, cum, self.points[:, 0]),
                        np.interp(s, cum, self.points[:, 1])], axis=1)
        out[0], out[-1] = self.points[0], self.points[-1]
        return out

    @staticmethod
    def normals(P: np.ndarray) -> np.ndarray:
        """(m, 2) unit in-plane normals (tangent turned by +90 degrees) at the centre nodes
        ``P``: central differences inside, one-sided at the ends."""
        t = np.empty_like(P)
        t[1:-1] = P[2:] - P[:-2]
        t[0] = P[1] - P[0]
        t[-1] = P[-1] - P[-2]
        t /= np.linalg.norm(t, axis=1, keepdims=True)
        return np.stack([-t[:, 1], t[:, 0]], axis=1)


def rod_lines_from_segments(segments) -> list[RodLine | RodPath]:
    """Accept RodLine or RodPath objects or (x_start, y_centre, length) tuples of rods along
    +x."""
    out: list[RodLine | RodPath] = []
    for s in segments:
        if isinstance(s, RodLine | RodPath):
            out.append(s)
        else:
            x0, y0, length = s
            out.append(RodLine((x0, y0), (1.0, 0.0), length))
    return out


def _strip(ln: RodLine | RodPath, dx_rod: float, b: float
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Centre nodes P and side rows Qp (+b/2 along the normal), Qm (printed), each (m, 2)."""
    P = ln.stations(dx_rod)
    nrm = np.broadcast_to(ln.normal, P.shape) if isinstance(ln, RodLine) else RodPath.normals(P)
    half = 0.5 * (ln.b if isinstance(ln, RodPath) and ln.b is not None else b)
    return P, P + half * nrm, P - half * nrm


def _centre_gap(a: np.ndarray, c: np.ndarray, spacing: float) -> tuple[float, np.ndarray]:
    """Smallest distance between two polylines (each (k, 2)), sampled at most ``spacing``
    apart, and the point of ``a`` where it is attained."""
    from scipy.spatial import cKDTree

    def dense(pts: np.ndarray) -> np.ndarray:
        out = [pts[:1]]
        for p0, p1 in zip(pts[:-1], pts[1:], strict=True):
            k = max(1, int(np.ceil(np.linalg.norm(p1 - p0) / spacing)))
            t = np.linspace(0.0, 1.0, k + 1)[1:, None]
            out.append(p0 + t * (p1 - p0))
        return np.concatenate(out)

    da, dc = dense(a), dense(c)
    d, _ = cKDTree(dc).query(da)
    k = int(np.argmin(d))
    return float(d[k]), da[k]


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


def _describe(k: int, line: RodLine | RodPath) -> str:
    if isinstance(line, RodPath):
        p0 = line.points[0]
        name = f"rod {line.id}" if line.id else f"rod {k}"
        return f"{name} (from {p0[0]:g}, {p0[1]:g}; length {line.length:.4g})"
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
    direction: float = 0.0,
) -> FabricMesh:
    """Reference mesh for rods (``RodLine`` or (x0, y, L) tuples) given in printed coordinates.

    ``extent`` is the printed fabric box (xmin, xmax, ymin, ymax) in the stretch frame (x along
    the stretch); ``direction`` [degrees] turns that frame against the drawing's, in which the
    rods are given and the mesh is made (0: the same frame). Returns a :class:`FabricMesh`
    with ``xs = ys = None``, the rods' node chains, the clamped edges ``left``/``right`` (the
    box's ends along the stretch) and the ``node_sets`` "left", "right", "bottom", "top".
    """
    import triangle
    from scipy.spatial import cKDTree

    lines = rod_lines_from_segments(segments)
    if not lines:
        raise ValueError("mesh: the unstructured mesh needs at least one rod")
    sx, sy = 1.0 + eps0, lam_y
    scale = np.array([1.0 / sx, 1.0 / sy])
    # the stretch runs along (cos, sin)(direction): ``extent`` is the fabric box in the
    # stretch frame (u along the stretch, v across); rods and the mesh are in the drawing frame
    rot = stretch_rotation(direction)

    def to_ref(pts: np.ndarray) -> np.ndarray:  # printed (drawing) -> reference (drawing)
        return ((pts @ rot) * scale) @ rot.T

    xmin, xmax, ymin, ymax = (extent[0] / sx, extent[1] / sx, extent[2] / sy, extent[3] / sy)
    tol = 1e-9 * max(xmax - xmin, ymax - ymin)

    # ---- rod strips (printed -> reference) and input checks
    strips = []  # (P, Qp, Qm) reference, each (m, 2)
    corners = []  # printed footprint rectangles (straight rods) or None
    widths = []
    centres = []  # printed centre nodes
    for k, ln in enumerate(lines):
        P, Qp, Qm = _strip(ln, dx_rod, b)
        bk = float(np.linalg.norm(Qp[0] - Qm[0]))
        widths.append(bk)
        centres.append(P)
        corners.append(np.array([Qm[0], Qm[-1], Qp[-1], Qp[0]])
                       if isinstance(ln, RodLine) else None)
        ref = to_ref(np.concatenate([Qp, Qm])) @ rot
        if (ref[:, 0].min() <= xmin + tol or ref[:, 0].max() >= xmax - tol
                or ref[:, 1].min() <= ymin + tol or ref[:, 1].max() >= ymax - tol):
            raise ValueError(
                f"mesh: {_describe(k, ln)}: its footprint (width b = {bk:g} mm) is not strictly "
                f"inside the fabric {tuple(float(v) for v in extent)} (printed, mm)"
            )
        strips.append((to_ref(P), to_ref(Qp), to_ref(Qm)))
    for i in range(len(lines)):
        for j in range(i + 1, len(lines)):
            tol_ij = 1e-6 * max(widths[i], widths[j], dx_rod)
            if corners[i] is not None and corners[j] is not None:
                hit = _rects_overlap(corners[i], corners[j], tol_ij)
            else:
                # rods along polylines: centre lines must stay (b_i + b_j) / 2 apart
                d, _ = _centre_gap(centres[i], centres[j], 0.1 * min(widths[i], widths[j]))
                hit = d < 0.5 * (widths[i] + widths[j]) + tol_ij
            if hit:
                raise ValueError(
                    f"mesh: {_describe(i, lines[i])} and {_describe(j, lines[j])} overlap or "
                    f"touch (footprints of width {widths[i]:g} and {widths[j]:g} mm)"
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
    box = [np.array(c, float) @ rot.T
           for c in ((xmin, ymin), (xmax, ymin), (xmax, ymax), (xmin, ymax))]
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
            direction=direction,
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
    U = Xa @ rot  # stretch frame: the clamped edges are u = xmin and u = xmax
    node_sets = {
        "left": _sorted_set(U, np.abs(U[:, 0] - xmin) <= eps, 1),
        "right": _sorted_set(U, np.abs(U[:, 0] - xmax) <= eps, 1),
        "bottom": _sorted_set(U, np.abs(U[:, 1] - ymin) <= eps, 0),
        "top": _sorted_set(U, np.abs(U[:, 1] - ymax) <= eps, 0),
    }
    return FabricMesh(
        X=Xa, tris=Ta, rods=rods, left=node_sets["left"], right=node_sets["right"],
        node_sets=node_sets, hinge_factor=UNSTRUCTURED_HINGE_FACTOR, kind="unstructured",
    )


def stretch_rotation(direction: float) -> np.ndarray:
    """Rotation (2 x 2) from the stretch frame (u along the stretch, v across) to the
    drawing frame, for a stretch ``direction`` in degrees from the drawing's x axis
    (counter-clockwise). Row vectors: ``x = u @ R.T``, ``u = x @ R``; the identity, exactly,
    for 0."""
    if direction == 0.0:
        return np.eye(2)
    t = math.radians(direction)
    c, s = math.cos(t), math.sin(t)
    return np.array([[c, -s], [s, c]])


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
