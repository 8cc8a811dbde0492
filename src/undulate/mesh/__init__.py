"""Mesh stage: the graded, rod-conforming triangle mesh of the fabric and the rods' node chains.

Two kinds: ``"unstructured"`` (:mod:`.unstructured`, Triangle; fine only near the rods, rods in
any direction) and ``"structured"`` (:mod:`.grid`, tensor-product grid; rods along x only).
"""

from __future__ import annotations

from typing import Literal

from .grid import (
    STRUCTURED_HINGE_FACTOR,
    FabricMesh,
    RodChain,
    build_structured_mesh,
    graded_coordinates,
)
from .unstructured import (
    UNSTRUCTURED_HINGE_FACTOR,
    RodLine,
    RodPath,
    build_unstructured_mesh,
    rod_lines_from_segments,
    stretch_rotation,
)

__all__ = [
    "FabricMesh",
    "RodChain",
    "RodLine",
    "RodPath",
    "build_mesh",
    "build_structured_mesh",
    "build_unstructured_mesh",
    "graded_coordinates",
    "rod_lines_from_segments",
    "stretch_rotation",
    "STRUCTURED_HINGE_FACTOR",
    "UNSTRUCTURED_HINGE_FACTOR",
]


def build_mesh(
    segments,
    b: float,
    extent: tuple[float, float, float, float],
    *,
    eps0: float,
    lam_y: float,
    dx_rod: float,
    dx_far: float,
    dy_far: float,
    grading: float,
    kind: Literal["unstructured", "structured"] = "structured",
    h_far: float | None = None,
    direction: float = 0.0,
) -> FabricMesh:
    """Mesh of the fabric for rods given in printed coordinates, of the requested ``kind``.

    ``segments``: :class:`RodLine` objects or (x_start, y_centre, length) tuples (rods along
    +x); ``extent``: the printed fabric box (xmin, xmax, ymin, ymax). The structured grid takes
    rods along +x only and ignores ``h_far``; the unstructured mesh ignores ``dx_far`` and
    ``dy_far`` unless ``h_far`` (its largest element size) is None, then it uses ``dx_far``.
    """
    if kind == "unstructured":
        return build_unstructured_mesh(
            segments, b, extent, eps0=eps0, lam_y=lam_y, dx_rod=dx_rod,
            h_far=dx_far if h_far is None else h_far, grading=grading, direction=direction,
        )
    if direction != 0.0:
        raise ValueError("mesh: the structured mesh stretches along x only (direction 0); use "
                         "kind = 'unstructured'")
    if kind != "structured":
        raise ValueError(f"mesh kind: must be 'unstructured' or 'structured', got {kind!r}")
    segs = []
    for k, ln in enumerate(rod_lines_from_segments(segments)):
        if isinstance(ln, RodPath):
            raise ValueError(
                f"mesh: rod {ln.id or k} is a polyline; the structured mesh takes straight rods "
                "along +x only (use kind = 'unstructured')"
            )
        if abs(ln.direction[1]) > 1e-12 or ln.direction[0] < 0:
            raise ValueError(
                f"mesh: rod {k} has direction {ln.direction}; the structured mesh takes rods "
                "along +x only (use kind = 'unstructured')"
            )
        segs.append((ln.start[0], ln.start[1], ln.length))
    return build_structured_mesh(
        segs, b, extent, eps0=eps0, lam_y=lam_y, dx_rod=dx_rod, dx_far=dx_far, dy_far=dy_far,
        grading=grading,
    )
