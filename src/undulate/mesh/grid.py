"""Graded, rod-conforming triangle mesh of the fabric.

The mesh is a tensor-product grid in the fabric's *reference* (unstretched) configuration, split
into triangles with alternating diagonals. Grid lines are placed so that, after the homogeneous
part of the pre-stretch, every rod lies on a row of nodes (its centre line) with two further rows
at +-b/2 (the edges of its footprint); rods start and end on grid columns. Spacing is fine along
and beside the rods (``dx_rod`` along x, b/2 across) and grows geometrically (``grading``) to
``dx_far`` / ``dy_far`` away from them.

Reference <-> printed mapping used for placing lines: X = x / (1 + eps0), Y = y / lam_y, where
lam_y is the lateral stretch of the fabric under uniaxial tension eps0 (computed for the same
hyperelastic law). Near the clamps the true pre-stretched state differs from this homogeneous
map; the rods are printed wherever their grid rows actually lie after the pre-stretch solve, so
printing is exactly stress-free, and the actual printed positions are reported.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = [
    "FabricMesh",
    "RodChain",
    "graded_coordinates",
    "build_structured_mesh",
    "STRUCTURED_HINGE_FACTOR",
]

STRUCTURED_HINGE_FACTOR = 0.57
"""Hinge-bending factor of this grid (alternating diagonals), see mechanics/fabric.py."""


@dataclass(frozen=True)
class RodChain:
    """Node indices of one rod: centre row ``p`` and footprint edge rows ``qm``, ``qp``.

    ``qp`` lies at +b/2 along the rod's in-plane normal (the direction turned by +90 degrees:
    +y for a rod along +x), ``qm`` at -b/2.
    """

    p: np.ndarray
    qm: np.ndarray
    qp: np.ndarray

    @property
    def n_nodes(self) -> int:
        return int(self.p.size)


@dataclass(frozen=True)
class FabricMesh:
    """Triangle mesh of the fabric in its reference configuration (z = 0)."""

    X: np.ndarray  # (n_nodes, 2) reference coordinates [mm]
    tris: np.ndarray  # (n_tris, 3) node indices, counter-clockwise
    rods: list[RodChain]
    left: np.ndarray  # nodes on the clamped edge x = xmin, sorted by y
    right: np.ndarray  # nodes on the clamped edge x = xmax, sorted by y
    xs: np.ndarray | None = None  # grid x coordinates (reference); None when unstructured
    ys: np.ndarray | None = None  # grid y coordinates (reference); None when unstructured
    # named boundary node sets: "left", "right" (sorted by y), "bottom", "top" (sorted by x)
    node_sets: dict[str, np.ndarray] = field(default_factory=dict)
    # factor of the hinge bending energy that suits this kind of mesh (mechanics/fabric.py)
    hinge_factor: float = STRUCTURED_HINGE_FACTOR
    kind: str = "structured"

    @property
    def n_nodes(self) -> int:
        return int(self.X.shape[0])

    def node(self, i: int, j: int) -> int:
        """Index of the grid node in column i (x) and row j (y) (structured meshes only)."""
        if self.xs is None:
            raise ValueError("mesh.node(i, j): only a structured mesh has grid columns and rows")
        return int(j * self.xs.size + i)

    def hinges(self) -> np.ndarray:
        """Interior edges with their two opposite vertices: (n_hinges, 4) = (e0, e1, o0, o1)."""
        tris = self.tris
        edges = np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]])
        opp = np.concatenate([tris[:, 2], tris[:, 0], tris[:, 1]])
        key = np.sort(edges, axis=1)
        order = np.lexsort((key[:, 1], key[:, 0]))
        key, edges, opp = key[order], edges[order], opp[order]
        same = np.all(key[1:] == key[:-1], axis=1)
        i = np.nonzero(same)[0]
        return np.stack([edges[i, 0], edges[i, 1], opp[i], opp[i + 1]], axis=1)


def graded_coordinates(
    fixed: list[float], lo: float, hi: float, fine: dict[tuple[float, float], float],
    coarse: float, grading: float,
) -> np.ndarray:
    """1D grid through all ``fixed`` points in [lo, hi].

    ``fine`` maps intervals (a, b) to a uniform spacing used inside them; elsewhere the spacing
    grows geometrically by ``grading`` away from the nearest fixed point, capped at ``coarse``.
    """
    pts = sorted({float(lo), float(hi), *[float(f) for f in fixed if lo <= f <= hi]})
    out: list[float] = [pts[0]]
    for a, b in zip(pts[:-1], pts[1:], strict=True):
        if b - a < 1e-12:
            continue
        h_fine = None
        for (fa, fb), hf in fine.items():
            if fa - 1e-9 <= a and b <= fb + 1e-9:
                h_fine = hf if h_fine is None else min(h_fine, hf)
        if h_fine is not None:
            m = max(1, int(np.ceil((b - a) / h_fine - 1e-9)))
            out.extend(np.linspace(a, b, m + 1)[1:].tolist())
            continue
        # graded from both ends: the first spacing equals the fine spacing at each end
        h_a = _spacing_at(a, fine, coarse)
        h_b = _spacing_at(b, fine, coarse)
        out.extend(_graded_interval(a, b, h_a, h_b, coarse, grading)[1:].tolist())
    return np.asarray(out)


def _spacing_at(x: float, fine: dict[tuple[float, float], float], coarse: float) -> float:
    hs = [hf for (fa, fb), hf in fine.items() if fa - 1e-9 <= x <= fb + 1e-9]
    return min(hs) if hs else coarse


def _graded_interval(
    a: float, b: float, h_a: float, h_b: float, coarse: float, g: float
) -> np.ndarray:
    """Points from a to b: spacing starts near h_a, ends near h_b, grows by g, caps at coarse."""
    left = [a]
    right = [b]
    ha, hb = h_a * g, h_b * g
    while True:
        gap = right[-1] - left[-1]
        step_a, step_b = min(ha, coarse), min(hb, coarse)
        if gap <= step_a + step_b:
            break
        if step_a <= step_b:
            left.append(left[-1] + step_a)
            ha *= g
        else:
            right.append(right[-1] - step_b)
            hb *= g
    gap = right[-1] - left[-1]
    if gap > 1.5 * max(min(ha, coarse), min(hb, coarse)):
        left.append(left[-1] + gap / 2)
    return np.asarray(left + right[::-1])


def build_structured_mesh(
    segments: list[tuple[float, float, float]],
    b: float,
    extent: tuple[float, float, float, float],
    *,
    eps0: float,
    lam_y: float,
    dx_rod: float,
    dx_far: float,
    dy_far: float,
    grading: float,
) -> FabricMesh:
    """Build the reference mesh for rods given in the printed configuration.

    ``segments`` are (x_start, y_centre, length) in printed coordinates, ``extent`` the printed
    fabric box. Returns the mesh with the rods' node chains.
    """
    sx = 1.0 + eps0
    sy = lam_y
    xmin, xmax, ymin, ymax = (extent[0] / sx, extent[1] / sx, extent[2] / sy, extent[3] / sy)
    # --- x lines: rod ends; fine spacing over each rod's span
    x_fixed: list[float] = []
    x_fine: dict[tuple[float, float], float] = {}
    for x0, _, length in segments:
        a, c = x0 / sx, (x0 + length) / sx
        x_fixed += [a, c]
        x_fine[(a, c)] = dx_rod / sx
    xs = graded_coordinates(x_fixed, xmin, xmax, x_fine, dx_far / sx, grading)
    # --- y lines: rod centre and footprint edges, fine inside the footprint
    y_fixed: list[float] = []
    y_fine: dict[tuple[float, float], float] = {}
    for _, yc, _ in segments:
        lo, mid, hi = (yc - b / 2) / sy, yc / sy, (yc + b / 2) / sy
        y_fixed += [lo, mid, hi]
        y_fine[(lo, hi)] = (b / 2) / sy
    ys = graded_coordinates(y_fixed, ymin, ymax, y_fine, dy_far / sy, grading)

    nx, ny = xs.size, ys.size
    XX, YY = np.meshgrid(xs, ys)  # row j = y index
    X = np.stack([XX.ravel(), YY.ravel()], axis=1)
    tris = []
    for j in range(ny - 1):
        for i in range(nx - 1):
            n00 = j * nx + i
            n10, n01, n11 = n00 + 1, n00 + nx, n00 + nx + 1
            if (i + j) % 2 == 0:
                tris += [(n00, n10, n11), (n00, n11, n01)]
            else:
                tris += [(n00, n10, n01), (n10, n11, n01)]
    tris_a = np.asarray(tris, dtype=np.int64)

    rods = []
    for x0, yc, length in segments:
        i0 = int(np.argmin(np.abs(xs - x0 / sx)))
        i1 = int(np.argmin(np.abs(xs - (x0 + length) / sx)))
        jc = int(np.argmin(np.abs(ys - yc / sy)))
        cols = np.arange(i0, i1 + 1)
        rods.append(
            RodChain(
                p=jc * nx + cols,
                qm=(jc - 1) * nx + cols,
                qp=(jc + 1) * nx + cols,
            )
        )
    left = np.arange(ny) * nx
    right = np.arange(ny) * nx + nx - 1
    node_sets = {"left": left, "right": right, "bottom": np.arange(nx),
                 "top": (ny - 1) * nx + np.arange(nx)}
    return FabricMesh(X=X, tris=tris_a, xs=xs, ys=ys, rods=rods, left=left, right=right,
                      node_sets=node_sets)
