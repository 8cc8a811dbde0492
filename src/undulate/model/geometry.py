"""Geometry derived from a case: every rod as printed, the straight rods as segments, and
the fabric's extent. Printed (stretched) configuration, mm."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from .lines import PrintedRod

if TYPE_CHECKING:
    from .case import Case

__all__ = ["fabric_extent", "rod_paths", "rod_sections", "segments"]


def _section(item: Any, case: Case) -> tuple[float, float]:
    """(h, b) of one pattern line or array: its own, else the case's [rods] values."""
    r = case.rods
    return (item.h if item.h is not None else r.h, item.b if item.b is not None else r.b)


def rod_sections(case: Case) -> list[tuple[float, float]]:
    """(h, b) of every rod: [rods], or each line and array of the pattern (its own values,
    else [rods]'s). Needs no polylines, so it works before the pattern is checked."""
    if case.pattern is None:
        return [(case.rods.h, case.rods.b)]
    items = [*case.pattern.lines, *case.pattern.arrays]
    return [_section(it, case) for it in items] or [(case.rods.h, case.rods.b)]


def rod_paths(case: Case) -> list[PrintedRod]:
    """Every rod as printed (polyline, id, h, b): the pattern's lines in their order, or
    the rods of [rods] (parallel or segments) sorted by y as :func:`segments`."""
    r = case.rods
    if case.pattern is None:
        return [PrintedRod(str(k), np.array([[x0, y], [x0 + length, y]], dtype=float),
                           r.h, r.b) for k, (x0, y, length) in enumerate(segments(case))]
    out = [PrintedRod(ln.id or str(k), ln.polyline(case.pattern.resolution),
                      *_section(ln, case)) for k, ln in enumerate(case.pattern.lines)]
    for j, arr in enumerate(case.pattern.arrays):
        out.extend(PrintedRod(name, pts, *_section(arr, case)) for name, pts in arr.lines(j))
    return out

def segments(case: Case) -> list[tuple[float, float, float]]:
    """Rods as (x_start, y_centre, length) in the printed configuration, sorted by y (rods
    along +x; a case with a pattern has no segments: use :func:`rod_paths`)."""
    if case.pattern is not None:
        raise ValueError("case: a pattern's lines are not segments along x; use rod_paths()")
    r = case.rods
    if r.segments is not None:
        out = [(s.start[0], s.start[1], s.length) for s in r.segments]
    else:
        pitch = r.b + r.s
        ys = [(k - (r.N - 1) / 2.0) * pitch for k in range(r.N)]
        out = [(-r.L / 2.0, y, r.L) for y in ys]
    return sorted(out, key=lambda s: (s[1], s[0]))

def fabric_extent(case: Case) -> tuple[float, float, float, float]:
    """(xmin, xmax, ymin, ymax) of the fabric in the printed (stretched) configuration, in
    the stretch frame (x along the stretch; the drawing's frame for direction 0): the rods'
    footprints plus ``margin_x`` beyond them along the stretch and ``margin_y`` across."""
    from ..mesh import stretch_rotation

    rot = stretch_rotation(case.release.direction)
    paths = rod_paths(case)
    pts = [p.points @ rot for p in paths]  # in the stretch frame
    bs = [p.b for p in paths]
    lo = np.min([q.min(axis=0) - b / 2 for q, b in zip(pts, bs, strict=True)], axis=0)
    hi = np.max([q.max(axis=0) + b / 2 for q, b in zip(pts, bs, strict=True)], axis=0)
    if case.pattern is None and case.release.direction == 0.0:
        # rods along the stretch end exactly at their ends
        lo[0] = min(float(q[0, 0]) for q in pts)
        hi[0] = max(float(q[-1, 0]) for q in pts)
    if case.fabric.size is not None:
        a, c = case.fabric.size
        return -0.5 * a, 0.5 * a, -0.5 * c, 0.5 * c
    xmin = float(lo[0]) - case.fabric.margin_x
    xmax = float(hi[0]) + case.fabric.margin_x
    ymin = float(lo[1]) - case.fabric.margin_y
    ymax = float(hi[1]) + case.fabric.margin_y
    # symmetric about the origin in x so the clamps move symmetrically
    half = max(abs(xmin), abs(xmax))
    return -half, half, ymin, ymax
