"""Lines of any shape on the fabric: table ``[pattern]`` of a case file (lines, arcs,
splines, arrays of parallel lines) and :class:`PrintedRod`, one rod as printed."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Annotated, Any

import numpy as np
from pydantic import (
    Field,
    Strict,
    StrictFloat,
    field_validator,
    model_validator,
)

from .validators import PosFloat, _Strict


class Arc(_Strict):
    """A circular arc: centre, radius, start and end angles in degrees from +x.

    Angles run counter-clockwise; ``end < start`` draws the arc clockwise."""

    centre: tuple[StrictFloat, StrictFloat] = Field(strict=False, description="(x, y) [mm]")
    radius: float = Field(gt=0.0, le=1e4, description="radius [mm]")
    start: float = Field(ge=-720.0, le=720.0, description="start angle [degrees]")
    end: float = Field(ge=-720.0, le=720.0, description="end angle [degrees]")

    @model_validator(mode="after")
    def _span(self) -> Arc:
        if not 0.0 < abs(self.end - self.start) < 360.0:
            raise ValueError("end: must differ from start by more than 0 and less than 360 "
                             f"degrees (a line, not a closed circle); got {self.start} -> "
                             f"{self.end}")
        return self

    def points(self, resolution: float) -> np.ndarray:
        """(k, 2) points along the arc, at most ``resolution`` mm apart."""
        span = math.radians(self.end - self.start)
        k = max(2, int(math.ceil(abs(span) * self.radius / resolution)) + 1)
        th = math.radians(self.start) + np.linspace(0.0, span, k)
        return np.c_[self.centre[0] + self.radius * np.cos(th),
                     self.centre[1] + self.radius * np.sin(th)]


Point2 = Annotated[tuple[StrictFloat, StrictFloat], Strict(False)]


def spline_points(through: np.ndarray, resolution: float) -> np.ndarray:
    """(k, 2) points, at most ``resolution`` mm apart, on the smooth curve through the given
    points: a natural cubic spline of each coordinate against the chord length."""
    from scipy.interpolate import CubicSpline

    d = np.linalg.norm(np.diff(through, axis=0), axis=1)
    if np.any(d <= 0.0):
        k = int(np.argmin(d))
        raise ValueError(f"spline: points {k} and {k + 1} coincide")
    t = np.r_[0.0, np.cumsum(d)]
    if len(through) == 2:
        f = np.linspace(0.0, 1.0, max(2, int(math.ceil(t[-1] / resolution)) + 1))
        return through[0] + f[:, None] * (through[1] - through[0])
    cs = CubicSpline(t, through, bc_type="natural")
    out = [through[:1]]
    for t0, t1 in zip(t[:-1], t[1:], strict=True):
        # between two given points: samples equally spaced in arc length (the chord-length
        # parameter is not quite that), so the curve keeps every given point
        tf = np.linspace(t0, t1, 257)
        arc = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(cs(tf), axis=0), axis=1))]
        k = max(1, int(math.ceil(arc[-1] / (0.99 * resolution))))
        out.append(cs(np.interp(np.linspace(0.0, arc[-1], k + 1)[1:], arc, tf)))
    return np.concatenate(out)


class PatternLine(_Strict):
    """One line of a pattern: a polyline `points`, an `arc` or a `spline`, optionally its own
    `h`, `b`.

    Lines without their own ``h`` or ``b`` take those of [rods]."""

    id: str | None = Field(None, min_length=1, max_length=100,
                           description="name of the line (default: its index)")
    points: list[Point2] | None = Field(
        None, description="polyline [[x, y], ...] in the printed frame [mm]",
        json_schema_extra={"allowed": "two or more [x, y] points"},
    )
    arc: Arc | None = Field(None, description="a circular arc instead of points")
    spline: list[Point2] | None = Field(
        None, description="a smooth curve through these [[x, y], ...] instead of points "
        "(natural cubic spline against chord length) [mm]",
        json_schema_extra={"allowed": "two or more [x, y] points, no two in a row equal"},
    )
    h: float | None = Field(None, gt=0.0, le=20.0, description="thickness of this line [mm]")
    b: float | None = Field(None, gt=0.0, le=50.0, description="width of this line [mm]")

    @model_validator(mode="after")
    def _one_shape(self) -> PatternLine:
        if sum(v is not None for v in (self.points, self.arc, self.spline)) != 1:
            raise ValueError("give exactly one of points (a polyline), arc or spline")
        for name in ("points", "spline"):
            v = getattr(self, name)
            if v is not None and len(v) < 2:
                raise ValueError(f"{name}: a line needs at least two [x, y] points")
        if self.spline is not None:
            pts = np.asarray(self.spline, dtype=float)
            d = np.linalg.norm(np.diff(pts, axis=0), axis=1)
            if np.any(d <= 0.0):
                k = int(np.argmin(d))
                raise ValueError(f"spline: points {k} and {k + 1} coincide")
        return self

    def polyline(self, resolution: float) -> np.ndarray:
        """(k, 2) points of the line [mm] (arcs and splines sampled every ``resolution``)."""
        if self.points is not None:
            return np.asarray(self.points, dtype=float)
        if self.arc is not None:
            return self.arc.points(resolution)
        return spline_points(np.asarray(self.spline, dtype=float), resolution)


class LineArray(_Strict):
    """Parallel straight lines side by side: equal or graded spacing, one length or a length
    per line. Line k is centred at ``centre`` moved across the lines (to the left of
    ``angle``) by the sum of the first k spacings."""

    id: str | None = Field(None, min_length=1, max_length=100,
                           description="prefix of the lines' names (lines <id>0, <id>1, ...; "
                           "default f<index>.)")
    centre: tuple[StrictFloat, StrictFloat] = Field(
        (0.0, 0.0), strict=False, description="(x, y) centre of the first line [mm]")
    angle: float = Field(0.0, ge=-180.0, le=180.0,
                         description="direction of the lines, degrees from +x")
    length: PosFloat | list[PosFloat] = Field(
        description="length of every line, or one length per line [mm]",
        json_schema_extra={"allowed": "> 0, <= 1e5 (each)"})
    count: int | None = Field(None, ge=1, le=1000,
                              description="number of lines (with spacing)")
    spacing: float | None = Field(None, gt=0.0, le=1e4,
                                  description="centre-to-centre distance of the lines [mm]")
    gaps: list[PosFloat] | None = Field(
        None, description="centre-to-centre distances of consecutive lines, one fewer than "
        "the lines (graded spacing; instead of count and spacing) [mm]",
        json_schema_extra={"allowed": "each > 0"})
    h: float | None = Field(None, gt=0.0, le=20.0, description="thickness of the lines [mm]")
    b: float | None = Field(None, gt=0.0, le=50.0, description="width of the lines [mm]")

    @field_validator("length", mode="before")
    @classmethod
    def _lengths(cls, v: Any) -> Any:
        vals = v if isinstance(v, list) else [v]
        ok = vals and all(isinstance(x, int | float) and not isinstance(x, bool)
                          and math.isfinite(x) and 0 < x <= 1e5 for x in vals)
        if not ok:
            raise ValueError(f"must be a length > 0 and <= 1e5 mm, or a list of them, one per "
                             f"line; got {v!r}")
        return [float(x) for x in v] if isinstance(v, list) else float(v)

    @model_validator(mode="after")
    def _layout(self) -> LineArray:
        if self.gaps is not None:
            if self.count is not None or self.spacing is not None:
                raise ValueError("gaps: give either gaps or count and spacing, not both")
            n = len(self.gaps) + 1
        elif self.count is not None:
            if self.count > 1 and self.spacing is None:
                raise ValueError("spacing: count > 1 needs the spacing of the lines")
            n = self.count
        else:
            raise ValueError("count: give count (and spacing) or gaps")
        if isinstance(self.length, list) and len(self.length) != n:
            raise ValueError(f"length: {len(self.length)} lengths for {n} lines")
        return self

    def offsets(self) -> np.ndarray:
        """Distance of each line from the first, across the lines [mm]."""
        if self.gaps is not None:
            return np.r_[0.0, np.cumsum(self.gaps)]
        return np.arange(self.count) * (self.spacing or 0.0)

    def lines(self, index: int) -> list[tuple[str, np.ndarray]]:
        """(id, 2 x 2 end points) of each line; ``index`` names the array by default."""
        off = self.offsets()
        lengths = (np.asarray(self.length, dtype=float) if isinstance(self.length, list)
                   else np.full(len(off), float(self.length)))
        a = math.radians(self.angle)
        d = np.array([math.cos(a), math.sin(a)])
        nrm = np.array([-d[1], d[0]])
        c0 = np.asarray(self.centre, dtype=float)
        prefix = self.id if self.id is not None else f"f{index}."
        return [(f"{prefix}{k}", np.stack([c0 + o * nrm - 0.5 * ln * d,
                                           c0 + o * nrm + 0.5 * ln * d]))
                for k, (o, ln) in enumerate(zip(off, lengths, strict=True))]


class Pattern(_Strict):
    """Lines of any direction and shape drawn on the stretched fabric (docs/patterns.md).

    In a case file, ``file = "lines.svg"`` (SVG or DXF, relative to the case file) adds the
    lines of a drawing, ``scale`` multiplies its coordinates."""

    lines: list[PatternLine] = Field(
        default_factory=list, description="the lines (at least one, with those of a file "
        "and the arrays)"
    )
    arrays: list[LineArray] = Field(
        default_factory=list, description="arrays of parallel straight lines (after the "
        "lines)"
    )
    resolution: float = Field(
        0.5, gt=0.0, le=10.0,
        description="largest spacing of the points sampled on arcs and splines [mm]"
    )
    @model_validator(mode="before")
    @classmethod
    def _renamed(cls, data: Any) -> Any:
        if isinstance(data, dict) and "families" in data:
            if data["families"]:
                raise ValueError("families: renamed arrays: write [[pattern.arrays]] "
                                 "(parallel straight lines side by side)")
            # an empty list: what cases saved before the rename hold (metrics.json, study
            # records); nothing to carry over
            data = {k: v for k, v in data.items() if k != "families"}
        return data

    min_gap: float = Field(
        0.0, ge=0.0, le=1e3,
        description="smallest allowed gap between two lines, edge to edge [mm] (what your "
        "printer can separate; 0: the footprints must just not touch)",
    )


@dataclass(frozen=True)
class PrintedRod:
    """One rod as printed: ``points`` (k x 2 polyline, printed frame, mm), its ``id``,
    thickness ``h`` and width ``b`` [mm]."""

    id: str
    points: np.ndarray
    h: float
    b: float

    @property
    def length(self) -> float:
        """Arc length [mm]."""
        return float(np.sum(np.linalg.norm(np.diff(self.points, axis=0), axis=1)))

    @property
    def straight(self) -> bool:
        """Whether every point lies on the chord (within 1e-9 of the length)."""
        c = self.points[-1] - self.points[0]
        rel = self.points - self.points[0]
        norm = float(np.hypot(*c))
        dev = np.abs(rel[:, 0] * c[1] - rel[:, 1] * c[0]) / max(norm, 1e-300)
        return bool(np.max(dev) <= 1e-9 * max(self.length, 1.0))
