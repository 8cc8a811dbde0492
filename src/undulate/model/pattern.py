"""Line patterns: lines drawn on the stretched fabric, read from SVG or DXF, and checked.

A pattern is a list of :class:`Line`: polylines in the **print frame** (the fabric clamped
stretched, x along the stretch, y across it, mm). Curves from a drawing (Bezier segments,
arcs, splines) are sampled into polylines of points at most ``resolution`` mm apart.

>>> from undulate.model.pattern import read_svg, check_lines
>>> lines = read_svg(open("lines.svg").read())        # doctest: +SKIP
>>> check_lines(lines, b=1.0)                          # doctest: +SKIP

Units of a drawing: an SVG's own size (``width="300mm"`` with a ``viewBox``; plain user
units count as CSS pixels, 96 per inch), a DXF's ``$INSUNITS`` (unitless: mm); ``scale``
multiplies the coordinates after that. SVG's y axis points down: it is flipped, so that the
drawing looks the same as the fabric seen from above. Coordinates are then centred on the
pattern's bounding box, the origin of the fabric in a case.
"""

from __future__ import annotations

import io
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .validators import number_problem

__all__ = ["Line", "PatternError", "read_svg", "read_dxf", "read_pattern", "check_lines",
           "centred", "line_from_points"]

#: most points a pattern may hold (sampling of curves included), to keep a page responsive
MAX_POINTS = 200_000


class PatternError(ValueError):
    """A pattern or drawing cannot be used; the message names the line (id or index)."""


@dataclass(frozen=True)
class Line:
    """One line of a pattern: a polyline ``points`` (k x 2, mm, print frame), an ``id`` (from
    the drawing, or its index) and optional per-line thickness ``h`` and width ``b`` [mm]."""

    id: str
    points: np.ndarray
    h: float | None = None
    b: float | None = None
    meta: dict[str, Any] = field(default_factory=dict, compare=False)

    @property
    def length(self) -> float:
        """Arc length of the polyline [mm]."""
        return float(np.sum(np.linalg.norm(np.diff(self.points, axis=0), axis=1)))

    @property
    def chord(self) -> np.ndarray:
        """Vector from the first to the last point [mm]."""
        return self.points[-1] - self.points[0]

    @property
    def angle_deg(self) -> float:
        """Angle of the chord to the stretch direction x, folded into (-90, 90] degrees."""
        dx, dy = self.chord
        ang = math.degrees(math.atan2(dy, dx))
        if ang > 90.0:
            ang -= 180.0
        elif ang <= -90.0:
            ang += 180.0
        return ang

    @property
    def deviation(self) -> float:
        """Largest distance of a point from the chord [mm] (0 for a straight line)."""
        c = self.chord
        norm = float(np.hypot(*c))
        if norm == 0.0:
            return float(np.max(np.linalg.norm(self.points - self.points[0], axis=1)))
        rel = self.points - self.points[0]
        return float(np.max(np.abs(rel[:, 0] * c[1] - rel[:, 1] * c[0])) / norm)

    def is_straight(self, tol: float = 1e-3) -> bool:
        """Whether every point lies within ``tol`` x length of the chord."""
        return self.deviation <= tol * max(self.length, 1e-12)

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"id": self.id, "points": self.points.round(6).tolist()}
        if self.h is not None:
            out["h"] = self.h
        if self.b is not None:
            out["b"] = self.b
        return out


def line_from_points(points: Any, index: int, *, id: str | None = None,
                     h: float | None = None, b: float | None = None) -> Line:
    """A :class:`Line` from a list of ``[x, y]`` pairs, checked (clear error naming it)."""
    name = id if id else str(index)
    try:
        pts = np.asarray(points, dtype=float)
    except (TypeError, ValueError):
        raise PatternError(f"line {name}: points must be a list of [x, y] numbers") from None
    if pts.ndim != 2 or pts.shape[1] != 2 or len(pts) < 2:
        raise PatternError(f"line {name}: points must be a list of at least two [x, y] pairs")
    if not np.isfinite(pts).all():
        raise PatternError(f"line {name}: points must be finite numbers")
    for key, val in (("h", h), ("b", b)):
        if val is not None and not (isinstance(val, int | float) and math.isfinite(val)
                                    and 0 < val <= 50):
            raise PatternError(f"line {name}: {key} must be a number in (0, 50] mm, got {val!r}")
    # drop repeated points (a drawing's zero-length segments)
    keep = np.ones(len(pts), bool)
    keep[1:] = np.linalg.norm(np.diff(pts, axis=0), axis=1) > 1e-9
    pts = pts[keep]
    if len(pts) < 2:
        raise PatternError(f"line {name}: has zero length (all its points coincide)")
    return Line(id=name, points=pts, h=None if h is None else float(h),
                b=None if b is None else float(b))


def centred(lines: list[Line]) -> list[Line]:
    """The lines shifted so that their bounding box is centred on the origin."""
    allp = np.vstack([ln.points for ln in lines])
    mid = 0.5 * (allp.min(axis=0) + allp.max(axis=0))
    return [Line(ln.id, ln.points - mid, ln.h, ln.b, ln.meta) for ln in lines]


def _sample(seglen: float, resolution: float) -> int:
    return max(2, int(math.ceil(seglen / resolution)) + 1)


def read_svg(text: str | bytes, *, scale: float = 1.0, resolution: float = 0.5,
             centre: bool = True) -> list[Line]:
    """Lines of an SVG drawing (``path``, ``line``, ``polyline``; transforms applied).

    Each sub-path is one line; curved pieces are sampled every ``resolution`` mm or finer.
    Closed shapes (``rect``, ``circle``, ``polygon``, a path ending in ``Z``) are refused:
    a closed loop is not a line. Raises :class:`PatternError` naming the element.
    """
    import svgelements as S

    if (msg := number_problem("scale", scale)) is not None:
        raise PatternError(msg)
    if isinstance(text, bytes):
        text = text.decode("utf-8", errors="replace")
    try:
        doc = S.SVG.parse(io.StringIO(text))
    except Exception as err:  # noqa: BLE001 - any parse failure is the same user error
        raise PatternError(f"svg: not a readable SVG document ({type(err).__name__}: {err})"
                           ) from None
    px_mm = 25.4 / 96.0 * scale
    lines: list[Line] = []
    count = 0
    for el in doc.elements():
        if isinstance(el, S.Text | S.Image):  # drawn, but not as lines: never dropped silently
            kind = "text" if isinstance(el, S.Text) else "image"
            what = f" {el.id!r}" if getattr(el, "id", None) else ""
            raise PatternError(f"svg: a {kind} element{what} is not a line (only path, line and "
                               f"polyline are); remove it, or convert it to paths")
        if not isinstance(el, S.Shape):
            continue
        tag = type(el).__name__.replace("Simple", "").lower()
        name = el.id or f"{tag}#{count}"
        count += 1
        if isinstance(el, S.Rect | S.Circle | S.Ellipse | S.Polygon):
            raise PatternError(f"line {name}: a closed {tag} is not a line (draw open paths, "
                               "lines or polylines)")
        path = S.Path(el)
        path.reify()
        for k, sub in enumerate(path.as_subpaths()):
            sub = S.Path(sub)
            segs = [sg for sg in sub if not isinstance(sg, S.Move)]
            if not segs:
                continue
            lid = name if k == 0 else f"{name}.{k}"
            if any(isinstance(sg, S.Close) for sg in segs):
                raise PatternError(f"line {lid}: a closed path (ends in Z) is not a line")
            pts: list[tuple[float, float]] = [tuple(segs[0].start)]
            for sg in segs:
                if isinstance(sg, S.Line):
                    pts.append(tuple(sg.end))
                else:
                    m = _sample(sg.length() * px_mm, resolution)
                    t = np.linspace(0.0, 1.0, m)[1:]
                    pts.extend(map(tuple, np.asarray(sg.npoint(t))))
                if len(pts) > MAX_POINTS:
                    raise PatternError(f"svg: more than {MAX_POINTS} points after sampling; "
                                       "use a coarser resolution or a simpler drawing")
            arr = np.asarray(pts, float) * px_mm
            arr[:, 1] *= -1.0
            lines.append(line_from_points(arr, len(lines), id=lid))
    if not lines:
        raise PatternError("svg: holds no lines (path, line or polyline elements)")
    return centred(lines) if centre else lines


_DXF_UNITS_MM = {0: 1.0, 1: 25.4, 2: 304.8, 4: 1.0, 5: 10.0, 6: 1000.0}


def read_dxf(path: str | Path, *, scale: float = 1.0, resolution: float = 0.5,
             centre: bool = True) -> list[Line]:
    """Lines of a DXF drawing's model space: LINE, LWPOLYLINE, POLYLINE, ARC, SPLINE.

    Units from ``$INSUNITS`` (unitless, mm, cm, m, inch, foot); closed polylines, circles,
    ellipses and every other entity (text, blocks, hatches, ...) are refused, named, never
    dropped.
    """
    import ezdxf
    from ezdxf import path as dxfpath

    if (msg := number_problem("scale", scale)) is not None:
        raise PatternError(msg)
    try:
        doc = ezdxf.readfile(str(path))
    except (OSError, ezdxf.DXFStructureError) as err:
        raise PatternError(f"dxf: cannot read {path}: {err}") from None
    units = int(doc.header.get("$INSUNITS", 0))
    if units not in _DXF_UNITS_MM:
        raise PatternError(f"dxf: $INSUNITS = {units} is not one of unitless, mm, cm, m, inch,"
                           " foot")
    f = _DXF_UNITS_MM[units] * scale
    lines: list[Line] = []
    for k, e in enumerate(doc.modelspace()):
        kind = e.dxftype()
        name = f"{kind}#{e.dxf.handle}"
        if kind in ("CIRCLE", "ELLIPSE") or (kind in ("LWPOLYLINE", "POLYLINE")
                                             and e.is_closed):
            raise PatternError(f"line {name}: a closed {kind.lower()} is not a line")
        if kind not in ("LINE", "LWPOLYLINE", "POLYLINE", "ARC", "SPLINE"):
            raise PatternError(
                f"dxf: a {kind} entity ({name}, layer {e.dxf.get('layer', '0')}) is not a line "
                "(only LINE, LWPOLYLINE, POLYLINE, ARC and SPLINE are); delete it from the "
                "model space, or explode it into lines")
        p = dxfpath.make_path(e)
        pts = np.array([(v.x, v.y) for v in p.flattening(distance=resolution / (4 * f),
                                                         segments=4)], float) * f
        lines.append(line_from_points(pts, len(lines), id=name))
        del k
    if not lines:
        raise PatternError("dxf: holds no lines (LINE, LWPOLYLINE, POLYLINE, ARC, SPLINE)")
    return centred(lines) if centre else lines


def read_pattern(path: str | Path, *, scale: float = 1.0, resolution: float = 0.5
                 ) -> list[Line]:
    """Lines of an ``.svg`` or ``.dxf`` file (by its suffix)."""
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix == ".svg":
        try:
            text = p.read_text(encoding="utf-8", errors="replace")
        except OSError as err:
            raise PatternError(f"svg: cannot read {p}: {err.strerror}") from None
        return read_svg(text, scale=scale, resolution=resolution)
    if suffix == ".dxf":
        return read_dxf(p, scale=scale, resolution=resolution)
    raise PatternError(f"pattern: {p.name}: unknown kind {suffix or '(none)'}; use .svg or .dxf")


# ---- checks --------------------------------------------------------------------------------
def _segments(ln: Line) -> tuple[np.ndarray, np.ndarray]:
    return ln.points[:-1], ln.points[1:]


def _seg_seg_distance(a0: np.ndarray, a1: np.ndarray, b0: np.ndarray, b1: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray]:
    """Distance between every segment of A (n) and every segment of B (m), and a point of A
    where it is attained (n x m and n x m x 2); 0 where they cross."""
    def pt_seg(p: np.ndarray, s0: np.ndarray, s1: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        d = s1 - s0
        dd = np.maximum(np.einsum("...i,...i->...", d, d), 1e-300)
        t = np.clip(np.einsum("...i,...i->...", p - s0, d) / dd, 0.0, 1.0)
        q = s0 + t[..., None] * d
        return np.linalg.norm(p - q, axis=-1), q

    A0, A1 = a0[:, None, :], a1[:, None, :]
    B0, B1 = b0[None, :, :], b1[None, :, :]
    cands = []
    for p, s0, s1, on_a in ((A0, B0, B1, False), (A1, B0, B1, False), (B0, A0, A1, True),
                            (B1, A0, A1, True)):
        p = np.broadcast_to(p, np.broadcast_shapes(A0.shape, B0.shape))
        d, q = pt_seg(p, s0, s1)
        cands.append((d, q if on_a else p))
    dist = np.stack([c[0] for c in cands])
    where = np.stack([c[1] for c in cands])
    k = np.argmin(dist, axis=0)
    best = np.take_along_axis(dist, k[None], 0)[0]
    pt = np.take_along_axis(where, k[None, ..., None], 0)[0]

    def orient(p: np.ndarray, q: np.ndarray, r: np.ndarray) -> np.ndarray:
        return (q[..., 0] - p[..., 0]) * (r[..., 1] - p[..., 1]) - (
            q[..., 1] - p[..., 1]) * (r[..., 0] - p[..., 0])

    o1, o2 = orient(A0, A1, B0), orient(A0, A1, B1)
    o3, o4 = orient(B0, B1, A0), orient(B0, B1, A1)
    cross = (o1 * o2 < 0) & (o3 * o4 < 0)
    if cross.any():
        da = A1 - A0
        db = B1 - B0
        den = da[..., 0] * db[..., 1] - da[..., 1] * db[..., 0]
        den = np.where(den == 0, 1.0, den)
        t = ((B0 - A0)[..., 0] * db[..., 1] - (B0 - A0)[..., 1] * db[..., 0]) / den
        xpt = A0 + t[..., None] * da
        best = np.where(cross, 0.0, best)
        pt = np.where(cross[..., None], xpt, pt)
    return best, pt


def line_gap(a: Line, b: Line) -> tuple[float, np.ndarray]:
    """Smallest centre-line distance between two lines [mm] and a point of ``a`` where it is
    attained."""
    d, p = _seg_seg_distance(*_segments(a), *_segments(b))
    k = np.unravel_index(int(np.argmin(d)), d.shape)
    return float(d[k]), p[k]


def _self_intersection(ln: Line) -> np.ndarray | None:
    a0, a1 = _segments(ln)
    n = len(a0)
    if n < 3:
        return None
    d, p = _seg_seg_distance(a0, a1, a0, a1)
    i, j = np.triu_indices(n, k=2)
    hit = d[i, j] < 1e-9 * max(ln.length, 1.0)
    if hit.any():
        k = int(np.argmax(hit))
        return p[i[k], j[k]]
    return None


def check_lines(lines: list[Line], *, b: float = 1.0, min_gap: float = 0.0,
                bounds: tuple[float, float, float, float] | None = None,
                min_radius: float | None = None) -> None:
    """Raise :class:`PatternError` for the first problem found, naming the line(s).

    * a line crossing itself, or two lines that cross or touch (their footprints, ``b`` or the
      line's own width, overlap): the message gives the point;
    * two lines closer than ``min_gap`` edge to edge;
    * a line leaving ``bounds`` = (xmin, xmax, ymin, ymax);
    * a line bending more sharply than ``min_radius`` (a rod of width b cannot follow it).
    """
    if not lines:
        raise PatternError("pattern: holds no lines")
    ids = [ln.id for ln in lines]
    dup = {i for i in ids if ids.count(i) > 1}
    if dup:
        raise PatternError(f"line ids must be unique; repeated: {sorted(dup)} (an array's "
                           "lines are named <id>0, <id>1, ...: give the array another id)")
    for ln in lines:
        p = _self_intersection(ln)
        if p is not None:
            raise PatternError(f"line {ln.id}: crosses itself at ({p[0]:.3g}, {p[1]:.3g}) mm")
        if bounds is not None:
            xmin, xmax, ymin, ymax = bounds
            w = 0.5 * (ln.b or b)
            lo, hi = ln.points.min(axis=0), ln.points.max(axis=0)
            if lo[0] - w < xmin or hi[0] + w > xmax or lo[1] - w < ymin or hi[1] + w > ymax:
                raise PatternError(f"line {ln.id}: leaves the fabric (x in [{xmin:g}, {xmax:g}]"
                                   f", y in [{ymin:g}, {ymax:g}] mm)")
        if min_radius is not None and len(ln.points) >= 3:
            r = _min_radius(ln.points)
            if r < min_radius:
                raise PatternError(f"line {ln.id}: bends with a radius of {r:.3g} mm, below "
                                   f"the smallest allowed {min_radius:g} mm")
    for i in range(len(lines)):
        for j in range(i + 1, len(lines)):
            a, c = lines[i], lines[j]
            d, p = line_gap(a, c)
            need = 0.5 * ((a.b or b) + (c.b or b))
            if d <= need + 1e-9:
                what = "cross" if d < 1e-9 else "touch (their footprints overlap)"
                raise PatternError(f"lines {a.id} and {c.id}: {what} at ({p[0]:.3g}, "
                                   f"{p[1]:.3g}) mm; centre lines {d:.3g} mm apart, need > "
                                   f"{need:g} mm")
            if d - need < min_gap:
                raise PatternError(f"lines {a.id} and {c.id}: {d - need:.3g} mm apart edge to "
                                   f"edge at ({p[0]:.3g}, {p[1]:.3g}) mm, below the minimum "
                                   f"gap {min_gap:g} mm")


def _min_radius(pts: np.ndarray) -> float:
    """Smallest radius of the circle through three consecutive points."""
    a, b, c = pts[:-2], pts[1:-1], pts[2:]
    ab = np.linalg.norm(b - a, axis=1)
    bc = np.linalg.norm(c - b, axis=1)
    ca = np.linalg.norm(a - c, axis=1)
    area2 = np.abs((b - a)[:, 0] * (c - a)[:, 1] - (b - a)[:, 1] * (c - a)[:, 0])
    with np.errstate(divide="ignore", invalid="ignore"):
        r = ab * bc * ca / (2.0 * area2)
    r = np.where(area2 <= 1e-12 * (ab * bc + 1e-300), np.inf, r)
    return float(np.min(r)) if len(r) else math.inf
