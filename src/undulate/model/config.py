"""Validated description of one simulation case.

Units everywhere in undulate: lengths in mm, moduli and stresses in MPa (= N/mm^2), forces in N,
energies in N*mm (= mJ), times in s, densities in t/mm^3 (so that N = t*mm/s^2).

A case is a pre-stretched fabric with rods printed on it. The coordinates of rods are given in
the *printed* configuration, i.e. on the fabric while it is stretched by ``eps0`` along x, with
the origin at the centre of the fabric. Rod lengths ``L`` are printed lengths.

Every model is strict: unknown keys, NaN/inf, out-of-range values and values of the wrong type
(``h = "0.3"``, ``N = true``, ``N = 2.0``, ``adaptive = "yes"``: nothing is converted; an
integer is accepted where a real number is expected) raise a :class:`pydantic.ValidationError`
whose message names the field and the allowed range.
:func:`load_case` turns that into a one-line-per-problem :class:`ConfigError`.
"""

from __future__ import annotations

import math
import re
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    Strict,
    StrictFloat,
    ValidationError,
    field_validator,
    model_validator,
)

__all__ = [
    "Fabric",
    "Rods",
    "Segment",
    "Arc",
    "PatternLine",
    "Family",
    "Pattern",
    "PrintedRod",
    "Release",
    "Imperfection",
    "Gravity",
    "Hang",
    "MeshOptions",
    "SolverOptions",
    "Dynamics",
    "Case",
    "ConfigError",
    "load_case",
    "case_from_dict",
    "allowed_range",
    "check_value",
    "number_problem",
]


class _Strict(BaseModel):
    model_config = ConfigDict(
        extra="forbid", allow_inf_nan=False, validate_assignment=True, strict=True
    )


PosFloat = Annotated[float, Field(gt=0.0)]
#: the fabric's four edges in the stretch frame: left/right are its ends along the stretch
Edge = Literal["left", "right", "bottom", "top"]


class Fabric(_Strict):
    """The knitted textile: an isotropic hyperelastic sheet, or orthotropic with E_y and G.

    Isotropic: compressible neo-Hookean (E, nu). Orthotropic (``E_y`` and ``G`` given): St
    Venant-Kirchhoff with E along the stretch, E_y across it, nu the contraction across
    under a pull along, G the in-plane shear modulus (docs/model.md, "Orthotropic knit")."""

    E: float = Field(0.45, gt=0.0, le=1e4,
                     description="Young's modulus [MPa] (orthotropic: along the stretch)")
    nu: float = Field(0.3, ge=0.0, lt=0.5, description="Poisson ratio [-]")
    E_y: float | None = Field(
        None, gt=0.0, le=1e4,
        description="orthotropic knit: Young's modulus across the stretch [MPa] (not set: "
        "isotropic)")
    G: float | None = Field(
        None, gt=0.0, le=1e4, description="orthotropic knit: in-plane shear modulus [MPa]")
    t: float = Field(0.4, gt=0.0, le=20.0, description="thickness [mm]")
    edge_tension: float = Field(
        0.0, ge=0.0, le=100.0,
        description="extra pull on the edges across the stretch that the frame leaves free "
        "(release.clamps), outwards, from the pre-stretch on [N per mm of unstretched edge] "
        "(0: free edges)",
    )
    bending_factor: float = Field(
        1.0, gt=0.0, le=10.0,
        description="the knit's bending stiffness as a fraction of a continuum sheet's E t^3 "
        "/ (12 (1 - nu^2)) [-]: a knit of loops bends much more easily than a solid sheet of "
        "the same E and t (1: continuum sheet)",
    )
    rho: float = Field(1.2e-9, gt=0.0, description="density [t/mm^3] (inertial mode only)")
    margin_x: float = Field(
        20.0, ge=2.0, le=1e4, description="fabric beyond the rod ends along x, printed state [mm]"
    )
    # With free long edges a narrow strip lifts as a whole with the rod (a ribbon arch, n = 1):
    # from h = 0.28 at 20 mm, from h = 0.5 at 40 mm. At 100 mm the rod h = 0.5 still ends with
    # n = 3 while 200, 300 and 400 mm all give n = 2 (lower energy). 200 mm is the default:
    # doubling it to 400 mm changes neither n nor l by more than 1 % for h = 0.3 and 0.5
    # (docs/model.md, "Fabric width"; tests/test_sheet_width.py); the graded mesh with
    # h_far = 24 makes that far field cheaper than 100 mm with h_far = 12 was.
    margin_y: float = Field(
        200.0, ge=2.0, le=1e4,
        description="fabric beyond the outer rods along y, printed state [mm]",
    )
    size: tuple[PosFloat, PosFloat] | None = Field(
        None, strict=False,
        description="a fabric of this size instead of margins: [along the stretch, across it] "
        "in the printed (stretched) state, centred on the origin [mm]; every line must keep "
        "2 mm of fabric to each edge",
        json_schema_extra={"allowed": "two lengths > 0, each <= 1e5"},
    )

    @model_validator(mode="after")
    def _size_or_margins(self) -> Fabric:
        if self.size is not None:
            given = [k for k in ("margin_x", "margin_y") if k in self.model_fields_set]
            if given:
                raise ValueError(f"size: give either size or {' and '.join(given)} (the "
                                 "margins size the fabric around the lines)")
            if max(self.size) > 1e5:
                raise ValueError(f"size: each length must be <= 1e5 mm; got {self.size}")
        return self


class Segment(_Strict):
    """One straight rod given explicitly (printed configuration, origin at fabric centre)."""

    # strict=False on the tuple only, so that a TOML/JSON array becomes a tuple; its items stay
    # strict numbers
    start: tuple[StrictFloat, StrictFloat] = Field(
        strict=False, description="(x, y) of the rod's first end [mm]"
    )
    direction: tuple[StrictFloat, StrictFloat] = Field(
        (1.0, 0.0), strict=False, description="direction of the rod",
        json_schema_extra={"allowed": "[1, 0] only: rods run along +x, the stretch direction"},
    )
    length: float = Field(gt=0.0, le=1e4, description="printed length [mm]")

    @model_validator(mode="after")
    def _direction_along_x(self) -> Segment:
        dx, dy = self.direction
        norm = math.hypot(dx, dy)
        if norm == 0.0:
            raise ValueError("direction: must be a non-zero vector")
        if abs(dy) > 1e-9 * norm or dx < 0:
            raise ValueError(
                "direction: only rods along +x (the stretch direction), i.e. (1, 0), are "
                f"supported by the structured mesh; got {self.direction}"
            )
        return self


class Rods(_Strict):
    """Straight rods printed along x: N parallel rods at gap ``s``, or explicit ``segments``."""

    h: float = Field(0.3, gt=0.0, le=20.0, description="thickness, out of plane [mm]")
    b: float = Field(1.0, gt=0.0, le=50.0, description="width, in plane [mm]")
    L: float = Field(100.0, gt=0.0, le=1e4, description="printed length [mm]")
    E_B: float = Field(3000.0, gt=0.0, le=1e6, description="rod Young's modulus [MPa]")
    nu_B: float = Field(0.35, ge=0.0, lt=0.5, description="rod Poisson ratio [-]")
    rho_B: float = Field(1.24e-9, gt=0.0, description="rod density [t/mm^3] (inertial mode)")
    offset: float | None = Field(
        None, ge=0.0, le=20.0,
        description="height of the rods' centre line above the fabric's mid-surface [mm] "
        "(not set: (t + h) / 2, the rod lying on the fabric; 0: a control with the centre "
        "line on the mid-surface, no bilayer: the flat state stays exactly flat until it "
        "buckles)",
    )
    N: int = Field(1, ge=1, le=200, description="number of parallel rods")
    s: float = Field(
        10.0, ge=0.0, le=1e4, description="edge-to-edge gap between parallel rods [mm]"
    )
    segments: list[Segment] | None = Field(
        None, description="explicit rods (at least one); N, s and L must then be left out"
    )

    @model_validator(mode="after")
    def _gap_for_parallel(self) -> Rods:
        if self.segments is not None:
            if not self.segments:
                raise ValueError(
                    "segments: give at least one rod, or leave segments out and use N, s, L"
                )
            given = [k for k in ("N", "s", "L") if k in self.model_fields_set]
            if given:
                raise ValueError(
                    f"segments: {', '.join(given)} cannot be given together with segments "
                    "(each segment has its own start and length); remove "
                    f"{'it' if len(given) == 1 else 'them'}"
                )
        if self.segments is None and self.N > 1 and self.s <= 0.0:
            raise ValueError(
                "s: must be > 0 for N > 1 parallel rods (s = 0 means one rod N*b wide: "
                "use N = 1 and b = N*b)"
            )
        return self


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


class Family(_Strict):
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
    def _layout(self) -> Family:
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
        """(id, 2 x 2 end points) of each line; ``index`` names the family by default."""
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
        "and the families)"
    )
    families: list[Family] = Field(
        default_factory=list, description="families of parallel straight lines (after the "
        "lines)"
    )
    resolution: float = Field(
        0.5, gt=0.0, le=10.0,
        description="largest spacing of the points sampled on arcs and splines [mm]"
    )
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


class Release(_Strict):
    """Pre-stretch and the gradual release of the clamps."""

    eps0: float = Field(0.5, gt=0.0, le=3.0, description="pre-stretch engineering strain [-]")
    direction: float = Field(
        0.0, ge=-180.0, le=180.0,
        description="direction of the stretch, degrees from the drawing's x axis "
        "(counter-clockwise); the clamps hold the fabric's two edges across it",
    )
    steps: int = Field(40, ge=1, le=100000, description="number of release increments")
    final_strain: float = Field(
        0.0, ge=0.0, le=3.0,
        description="clamp strain where the release stops (0: a full release; a partial "
        "release leaves the fabric stretched by this much)",
    )
    adaptive: bool = Field(True, description="cut the increment when a step fails to converge")
    min_step_fraction: float = Field(
        1e-3, gt=0.0, le=1.0, description="smallest increment as a fraction of the nominal one"
    )
    max_step_factor: float = Field(
        4.0, ge=1.0, le=100.0,
        description="largest increment as a multiple of the nominal one: once the rods have "
        "buckled, a step that converged in a few Newton iterations without negative "
        "curvature doubles the next increment, up to this (1: equal increments)",
    )
    onset_substeps: int = Field(
        1, ge=1, le=1024,
        description="until the rods have buckled, the release advances by the nominal "
        "increment divided by this, so the onset of buckling is resolved to eps0 / (steps x "
        "onset_substeps); afterwards the increment doubles back to the nominal one",
    )
    snap_iterations: int = Field(
        12, ge=1, le=100000,
        description="Newton iterations a release step longer than snap_resolution x the "
        "nominal increment may take once it has followed negative curvature of the rods; a "
        "step that needs more (a change of the rods' pattern inside it) is taken again in "
        "halves, so the new pattern grows from just past the strain where the old one ends "
        "(with adaptive)",
    )
    snap_resolution: float = Field(
        1.0, gt=0.0, le=100.0,
        description="increment, as a fraction of the nominal one, down to which steps with a "
        "change of pattern are halved (see snap_iterations)",
    )



    control: Literal["displacement", "force"] = Field(
        "displacement",
        description="displacement: the clamps move back and hold the edges to the end; "
        "force: after the pre-stretch the clamps let go and their forces, as loads on the "
        "free edges, are taken down to zero (or to final_strain / eps0 of them), so the "
        "sample ends free, as one cut off its frame (quasi-static only)",
    )
    clamps: list[Edge] = Field(
        default_factory=lambda: ["left", "right"],
        description="edges held by the frame during the pre-stretch and the release: 'left' "
        "and 'right' (the ends along the stretch, which stretch it) and, if you add them, "
        "'bottom' and/or 'top' (held straight at their printed position across the stretch, "
        "moving with the stretch along it)",
    )

    @model_validator(mode="after")
    def _frame(self) -> Release:
        if len(set(self.clamps)) != len(self.clamps):
            raise ValueError(f"clamps: each edge at most once; got {self.clamps}")
        missing = [e for e in ("left", "right") if e not in self.clamps]
        if missing:
            raise ValueError(f"clamps: must hold {' and '.join(repr(m) for m in missing)} (the "
                             f"stretch acts between left and right); got {self.clamps}")
        return self

    @model_validator(mode="after")
    def _stop_below_start(self) -> Release:
        if self.final_strain >= self.eps0:
            raise ValueError(f"final_strain: must be below eps0 = {self.eps0:g} (the clamps "
                             f"move from eps0 down to it); got {self.final_strain:g}")
        return self


class Hang(_Strict):
    """After the release: the fabric is taken off the clamps and held by some edges only, as
    they are at the end of the release (e.g. hung up by its top edge under [gravity])."""

    edges: list[Edge] = Field(
        min_length=1, max_length=4,
        description="edges that keep holding the fabric, where the release left them "
        "(stretch frame: 'left'/'right' are the ends along the stretch, 'bottom'/'top' the "
        "edges across it); the clamps of the others let go",
    )
    steps: int = Field(
        10, ge=1, le=10000,
        description="the let-go clamps' forces are taken down to zero in this many equal steps",
    )

    @model_validator(mode="after")
    def _unique(self) -> Hang:
        if len(set(self.edges)) != len(self.edges):
            raise ValueError(f"edges: each edge at most once; got {self.edges}")
        return self


class Gravity(_Strict):
    """A constant body force on fabric and rods from the start of the release on, also while
    the fabric hangs ([hang]); off by default."""

    g: tuple[StrictFloat, StrictFloat, StrictFloat] = Field(
        (0.0, 0.0, 0.0), strict=False,
        description="acceleration of gravity in the drawing's frame [mm/s^2]: [0, 0, -9810] "
        "for the sheet lying face up, [0, 9810, 0] hanging with the drawing's +y down "
        "(at the bottom), [0, 0, 0] off",
        json_schema_extra={"allowed": "each component within +-1e6"},
    )

    @model_validator(mode="after")
    def _size(self) -> Gravity:
        if any(abs(v) > 1e6 for v in self.g):
            raise ValueError(f"g: each component must be within +-1e6 mm/s^2; got {self.g}")
        return self

    @property
    def on(self) -> bool:
        return any(v != 0.0 for v in self.g)


class Imperfection(_Strict):
    """Small random out-of-plane noise on the rods: a displacement at the start of the release,
    or part of the printed (stress-free) shape."""

    kind: Literal["start", "printed"] = Field(
        "start",
        description="start: the noise displaces the flat, stress-free rods at the start of the "
        "release (where the flat state is stable the first equilibrium takes it out again); "
        "printed: the rods are printed with the noise in their shape, so it stays as a "
        "geometric imperfection",
    )
    amplitude: float = Field(1e-3, ge=0.0, le=10.0, description="RMS of the noise [mm]")
    seed: int = Field(0, ge=0, description="seed of the random generator")
    correlation: float = Field(
        2.0, gt=0.0, le=1e3, description="correlation length of the noise along the rod [mm]"
    )


class MeshOptions(_Strict):
    """Resolution of the graded, rod-conforming triangle mesh (printed configuration).

    ``kind = "unstructured"``: Triangle mesh, fine only near the rods; element size
    h = min(h_far, h_near + (grading - 1) * distance to the nearest rod footprint), h_near about
    1.2 * max(dx_rod, b/2) (see :mod:`undulate.mesh.unstructured`).
    ``kind = "structured"``: tensor-product grid (rods along x only); spacings dx_rod along the
    rods, b/2 across them, growing by ``grading`` per cell to dx_far (x) and dy_far (y).
    """

    kind: Literal["unstructured", "structured"] = Field(
        "unstructured", description="unstructured (Triangle) or structured (tensor grid) mesh"
    )
    dx_rod: float = Field(1.0, gt=0.0, le=20.0, description="node spacing along rods [mm]")
    dx_far: float = Field(
        4.0, gt=0.0, le=100.0, description="structured: spacing in x beyond rod ends [mm]"
    )
    dy_far: float = Field(
        5.0, gt=0.0, le=100.0, description="structured: largest spacing in y [mm]"
    )
    # 24: on the 200 mm sheet l changes by -0.1 % (h = 0.3) and +0.9 % (h = 0.5) against
    # h_far = 12, same n, with 4,836 unknowns instead of 7,038 (docs/model.md, "Fabric width")
    h_far: float = Field(
        24.0, gt=0.0, le=200.0,
        description="unstructured: largest element size [mm] (at least dx_rod)",
    )
    # 1.3: at 1.5 the unstructured far field is coarse enough to shift l by 2 % (margin_y 40)
    # and to change n at margin_y 100 (measured against the structured mesh, docs/model.md)
    grading: float = Field(1.3, ge=1.0, le=3.0, description="growth ratio of spacings [-]")

    @model_validator(mode="after")
    def _order(self) -> MeshOptions:
        if self.dx_far < self.dx_rod:
            raise ValueError(f"dx_far: must be >= dx_rod = {self.dx_rod} mm")
        return self


class SolverOptions(_Strict):
    """Newton energy minimisation."""

    rtol: float = Field(
        1e-6, gt=0.0, lt=1.0, description="residual tolerance relative to the force scale"
    )
    # 300, not 60: just past a bifurcation and at mode changes the equilibrium lies along a very
    # soft direction and Newton needs 150-300 damped iterations (measured: h = 0.08, the
    # buckling step took 184; with 60 the step was cut down to its minimum and the run failed)
    max_iter: int = Field(300, ge=1, le=10000, description="Newton iterations per increment")
    linear_solver: Literal["auto", "qdldl", "splu", "pardiso"] = Field(
        "auto", description="sparse direct solver"
    )
    negative_curvature: bool = Field(
        True, description="follow negative-curvature directions past bifurcations"
    )
    # 8, not 1: where the release leaves the slack fabric with many unstable wrinkle modes at
    # once (the demo's last step starts with 92 negative pivots), following them one per
    # iteration took 48 iterations of tiny steps, and the non-monotone Newton steps after it
    # carried the rod out of its still-stable five-arc state into a three-arc one (239
    # iterations); with 8 modes per step the same step took 42 and stayed on the stable branch
    modes: int = Field(
        8, ge=1, le=64,
        description="negative-curvature modes one curved step follows at most",
    )


class Dynamics(_Strict):
    """Inertial release: implicit damped dynamics, then settling."""

    release_time: float = Field(1.0, gt=0.0, le=1e5, description="duration of the release [s]")
    settle_time: float = Field(1.0, ge=0.0, le=1e6, description="settling after release [s]")
    dt: float = Field(0.01, gt=0.0, le=10.0, description="time step [s]")
    damping: float = Field(
        5.0, ge=0.0, le=1e6, description="mass-proportional damping coefficient [1/s]"
    )


class Case(_Strict):
    """Everything that defines one run. Defaults: one rod, L = 100 mm, h = 0.3 mm."""

    name: str = Field("case", min_length=1, max_length=200, description="label of the run")
    fabric: Fabric = Field(default_factory=Fabric)
    rods: Rods = Field(default_factory=Rods)
    release: Release = Field(default_factory=Release)
    imperfection: Imperfection = Field(default_factory=Imperfection)
    gravity: Gravity = Field(default_factory=Gravity)
    mesh: MeshOptions = Field(default_factory=MeshOptions)
    solver: SolverOptions = Field(default_factory=SolverOptions)
    mode: Literal["quasi-static", "inertial"] = Field(
        "quasi-static",
        description="quasi-static: a stable equilibrium at every release step; inertial: "
        "damped dynamics ([dynamics])",
    )
    dynamics: Dynamics = Field(default_factory=Dynamics)
    pattern: Pattern | None = Field(
        None, description="lines of any direction and shape instead of [rods] N, s, L, "
        "segments (which must then be left out)"
    )
    hang: Hang | None = Field(
        None, description="after the release, hold the fabric by these edges only (default: "
        "it stays in the clamps)"
    )

    @model_validator(mode="after")
    def _pull_on_free_edges(self) -> Case:
        if self.fabric.edge_tension > 0 and {"bottom", "top"} <= set(self.release.clamps):
            raise ValueError("fabric.edge_tension: pulls on the edges across the stretch that "
                             "are free, but release.clamps holds both bottom and top")
        return self

    @model_validator(mode="after")
    def _force_release(self) -> Case:
        if self.release.control == "force":
            if self.mode == "inertial":
                raise ValueError("release.control: 'force' is quasi-static only; use mode = "
                                 "'quasi-static' or control = 'displacement'")
            if self.hang is not None:
                raise ValueError("release.control: with 'force' the sample ends free (no "
                                 "clamp is left to let go): remove [hang]")
        return self

    @model_validator(mode="after")
    def _knit(self) -> Case:
        f = self.fabric
        if (f.E_y is None) != (f.G is None):
            raise ValueError("fabric.E_y: an orthotropic knit needs both E_y and G (or "
                             "neither, for the isotropic sheet)")
        if f.E_y is not None:
            if f.nu**2 * f.E_y / f.E >= 1.0:
                raise ValueError(f"fabric.nu: must be below sqrt(E / E_y) = "
                                 f"{math.sqrt(f.E / f.E_y):.3g} for an orthotropic knit")
            e0 = self.release.eps0
            if 1.0 - f.nu * ((1.0 + e0) ** 2 - 1.0) <= 0.1:
                raise ValueError(f"release.eps0: {e0:g} is too large a stretch for the "
                                 f"orthotropic (St Venant-Kirchhoff) knit with nu = {f.nu:g}: "
                                 "it must keep 1 - nu ((1 + eps0)^2 - 1) above 0.1")
        return self

    @model_validator(mode="after")
    def _geometry(self) -> Case:
        if self.mesh.kind == "structured" and (self.pattern is not None
                                               or self.release.direction != 0.0):
            raise ValueError(
                "mesh.kind: 'structured' takes rods along x stretched along x only; a pattern "
                "or a release.direction other than 0 needs kind = 'unstructured'")
        if self.pattern is not None:
            return self._check_pattern()
        segs = self.segments()
        b = self.rods.b
        if self.mesh.dx_rod > 0.5 * min(s[2] for s in segs):
            raise ValueError(
                f"mesh.dx_rod: must be <= half the shortest rod length "
                f"({0.5 * min(s[2] for s in segs):g} mm)"
            )
        # rods must not overlap or touch (footprints are b wide)
        for i in range(len(segs)):
            for j in range(i + 1, len(segs)):
                xi, yi, li = segs[i]
                xj, yj, lj = segs[j]
                overlap_x = min(xi + li, xj + lj) - max(xi, xj)
                if overlap_x > -1e-9 and abs(yi - yj) < b - 1e-9:
                    raise ValueError(
                        f"rods.segments: rods {i} and {j} overlap (their footprints of width "
                        f"b = {b} mm intersect); keep |y_i - y_j| >= b or separate them in x"
                    )
        return self

    @model_validator(mode="after")
    def _fits(self) -> Case:
        """With ``fabric.size``: every line on the fabric, 2 mm clear of each edge."""
        if self.fabric.size is None:
            return self
        from ..mesh import stretch_rotation

        xmin, xmax, ymin, ymax = self.fabric_extent()
        rot = stretch_rotation(self.release.direction)
        clear = 2.0
        for p in self.rod_paths():
            q = p.points @ rot  # stretch frame
            w = 0.5 * p.b
            wx = 0.0 if self.pattern is None and self.release.direction == 0.0 else w
            gaps = {"left": q[:, 0].min() - wx - xmin, "right": xmax - q[:, 0].max() - wx,
                    "bottom": q[:, 1].min() - w - ymin, "top": ymax - q[:, 1].max() - w}
            edge = min(gaps, key=gaps.get)
            g = gaps[edge]
            if g < clear:
                where = ("leaves the fabric across" if g < 0 else
                         f"is only {g:.3g} mm from")
                held = ("the clamp on" if edge in self.release.clamps else "")
                raise ValueError(
                    f"pattern: line {p.id}: {where} {held} the {edge} edge of the "
                    f"{xmax - xmin:g} x {ymax - ymin:g} mm fabric (fabric.size, stretch frame); "
                    f"keep at least {clear:g} mm of fabric between a line's footprint and every "
                    "edge".replace("  ", " ") if self.pattern is not None else
                    f"fabric.size: rod {p.id} {where} {held} the {edge} edge of the "
                    f"{xmax - xmin:g} x {ymax - ymin:g} mm fabric; keep at least {clear:g} mm "
                    "of fabric between a rod's footprint and every edge".replace("  ", " "))
        return self

    def _check_pattern(self) -> Case:
        from .pattern import PatternError, _min_radius, check_lines, line_from_points

        r = self.rods
        given = [k for k in ("N", "s", "L", "segments") if k in r.model_fields_set]
        if given:
            raise ValueError(
                f"pattern: rods.{', rods.'.join(given)} cannot be given together with a "
                "pattern (its lines have their own geometry; [rods] sets h, b and the material)"
            )
        if not self.pattern.lines and not self.pattern.families:
            raise ValueError("pattern: holds no lines")
        rods = self.rod_paths()
        dx = self.mesh.dx_rod
        try:
            lines = [line_from_points(p.points, k, id=p.id, h=p.h, b=p.b)
                     for k, p in enumerate(rods)]
            check_lines(lines, b=r.b, min_gap=self.pattern.min_gap)
        except PatternError as err:
            raise ValueError(f"pattern: {err}") from None
        from ..mesh import RodPath

        for p in rods:
            if dx > 0.5 * p.length:
                raise ValueError(f"pattern: line {p.id}: {p.length:.4g} mm long, shorter than "
                                 f"2 x mesh.dx_rod = {2 * dx:g} mm (make it longer or lower "
                                 "mesh.dx_rod)")
            need = max(p.b, 3.0 * dx)
            st = RodPath(p.points).stations(dx)
            if len(st) >= 3:
                rad = _min_radius(st)
                if rad < need:
                    raise ValueError(
                        f"pattern: line {p.id}: bends with a radius of {rad:.3g} mm, below the "
                        f"smallest its rod can follow, max(b, 3 x mesh.dx_rod) = {need:g} mm "
                        "(draw a wider bend, a narrower line or lower mesh.dx_rod)")
        return self

    # ---- derived geometry -------------------------------------------------------------
    def rod_paths(self) -> list[PrintedRod]:
        """Every rod as printed (polyline, id, h, b): the pattern's lines in their order, or
        the rods of [rods] (parallel or segments) sorted by y as :meth:`segments`."""
        r = self.rods
        if self.pattern is None:
            return [PrintedRod(str(k), np.array([[x0, y], [x0 + length, y]], dtype=float),
                               r.h, r.b) for k, (x0, y, length) in enumerate(self.segments())]
        out = []
        for k, ln in enumerate(self.pattern.lines):
            out.append(PrintedRod(ln.id or str(k), ln.polyline(self.pattern.resolution),
                                  ln.h if ln.h is not None else r.h,
                                  ln.b if ln.b is not None else r.b))
        for j, fam in enumerate(self.pattern.families):
            out.extend(PrintedRod(name, pts, fam.h if fam.h is not None else r.h,
                                  fam.b if fam.b is not None else r.b)
                       for name, pts in fam.lines(j))
        return out

    def segments(self) -> list[tuple[float, float, float]]:
        """Rods as (x_start, y_centre, length) in the printed configuration, sorted by y (rods
        along +x; a case with a pattern has no segments: use :meth:`rod_paths`)."""
        if self.pattern is not None:
            raise ValueError("case: a pattern's lines are not segments along x; use rod_paths()")
        r = self.rods
        if r.segments is not None:
            out = [(s.start[0], s.start[1], s.length) for s in r.segments]
        else:
            pitch = r.b + r.s
            ys = [(k - (r.N - 1) / 2.0) * pitch for k in range(r.N)]
            out = [(-r.L / 2.0, y, r.L) for y in ys]
        return sorted(out, key=lambda s: (s[1], s[0]))

    def fabric_extent(self) -> tuple[float, float, float, float]:
        """(xmin, xmax, ymin, ymax) of the fabric in the printed (stretched) configuration, in
        the stretch frame (x along the stretch; the drawing's frame for direction 0): the rods'
        footprints plus ``margin_x`` beyond them along the stretch and ``margin_y`` across."""
        from ..mesh import stretch_rotation

        rot = stretch_rotation(self.release.direction)
        paths = self.rod_paths()
        pts = [p.points @ rot for p in paths]  # in the stretch frame
        bs = [p.b for p in paths]
        lo = np.min([q.min(axis=0) - b / 2 for q, b in zip(pts, bs, strict=True)], axis=0)
        hi = np.max([q.max(axis=0) + b / 2 for q, b in zip(pts, bs, strict=True)], axis=0)
        if self.pattern is None and self.release.direction == 0.0:
            # rods along the stretch end exactly at their ends
            lo[0] = min(float(q[0, 0]) for q in pts)
            hi[0] = max(float(q[-1, 0]) for q in pts)
        if self.fabric.size is not None:
            a, c = self.fabric.size
            return -0.5 * a, 0.5 * a, -0.5 * c, 0.5 * c
        xmin = float(lo[0]) - self.fabric.margin_x
        xmax = float(hi[0]) + self.fabric.margin_x
        ymin = float(lo[1]) - self.fabric.margin_y
        ymax = float(hi[1]) + self.fabric.margin_y
        # symmetric about the origin in x so the clamps move symmetrically
        half = max(abs(xmin), abs(xmax))
        return -half, half, ymin, ymax


#: Rules that involve more than one field (checked by the validators above; listed in
#: docs/config.md, each with a test in tests/test_errors_doc.py)
RULES: tuple[str, ...] = (
    "`rods.segments`: at least one rod; `rods.N`, `rods.s` and `rods.L` must then be left out "
    "(each segment has its own `start` and `length`).",
    "`rods.s > 0` when `rods.N > 1` (`s = 0` would be one rod `N b` wide: write `N = 1`, "
    "`b = N b`).",
    "`mesh.dx_far >= mesh.dx_rod`.",
    "`mesh.dx_rod` <= half the shortest rod (`rods.L`, or the shortest segment `length`).",
    "Rods must not overlap or touch: their footprints are `rods.b` wide, so two rods that "
    "overlap in x need `|y_i - y_j| >= b`.",
    "`[pattern]`: at least one line; `rods.N`, `rods.s`, `rods.L` and `rods.segments` must "
    "then be left out, and `mesh.kind` must be `\"unstructured\"` (also for "
    "`release.direction` other than 0). In a case file, `pattern.file` adds the lines of an SVG "
    "or DXF drawing (path relative to the case file; centred on the origin) and "
    "`pattern.scale` multiplies its coordinates. Lines must not cross or touch (footprints "
    "`b` wide), keep `pattern.min_gap` apart, be at least `2 mesh.dx_rod` long and bend no "
    "tighter than a radius of `max(b, 3 mesh.dx_rod)`.",
    "A case file must hold at least one setting: an empty file is refused (`undulate demo` "
    "runs the default case; a file with only `name = \"...\"` runs the defaults).",
)


class ConfigError(ValueError):
    """A case description is invalid. The message names each bad field and its allowed range."""


_TYPE_HINTS = {
    "float_type": " (a number, written without quotes)",
    "int_type": " (a whole number, without quotes or decimal point)",
    "bool_type": " (true or false, without quotes)",
    "string_type": " (text in quotes)",
}


def _show(v: object) -> str:
    """A value as it is written in TOML (true, "text", 2.0)."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return '"' + v.replace('"', '\\"') + '"'
    if isinstance(v, list | tuple):
        return "[" + ", ".join(_show(x) for x in v) + "]"
    return repr(v)


def _field_range(loc: tuple) -> str:
    """The allowed range of the field at ``loc`` (e.g. ("rods", "h")), "" if none."""
    model: type[BaseModel] = Case
    for i, part in enumerate(loc):
        if not isinstance(part, str) or part not in model.model_fields:
            return ""
        if i == len(loc) - 1:
            return allowed_range(model, part)
        ann = model.model_fields[part].annotation
        if isinstance(ann, type) and issubclass(ann, BaseModel):
            model = ann
        else:
            return ""
    return ""


def _format_validation_error(err: ValidationError) -> str:
    lines = []
    for e in err.errors():
        loc = ".".join(str(p) for p in e["loc"])
        msg = e["msg"].removeprefix("Value error, ")
        # a rule between fields says which field it is about: "dx_far: must be ..."
        named = re.match(r"([A-Za-z_][\w.]*): (.*)", msg, re.S)
        if e["type"] == "value_error" and named:
            loc = f"{loc}.{named[1]}" if loc else named[1]
            msg = named[2]
        loc = loc or "case"
        rng = _field_range(e["loc"]) if e.get("ctx") else ""
        if not rng:
            ctx = e.get("ctx") or {}
            rng = ", ".join(f"{_BOUND_SYMBOLS[k]} {v:g}" for k, v in ctx.items()
                            if k in _BOUND_SYMBOLS and isinstance(v, int | float))
        extra = f" (allowed: {rng})" if rng else ""
        hint = _TYPE_HINTS.get(e["type"], "")
        got = e.get("input")
        got_s = f"; got {_show(got)}" if got is not None and not isinstance(got, dict) else ""
        if e["type"] == "value_error":
            got_s = ""  # the rule's own message says what was wrong
        lines.append(f"{loc}: {msg}{hint}{extra}{got_s}")
    return "\n".join(lines)


def case_from_dict(data: dict) -> Case:
    """Validate a plain dict (e.g. parsed TOML) into a :class:`Case`; raise ConfigError."""
    try:
        return Case.model_validate(data)
    except ValidationError as err:
        raise ConfigError(_format_validation_error(err)) from None


def load_case(path: str | Path) -> Case:
    """Read and validate a TOML case file; raise :class:`ConfigError` with a clear message."""
    p = Path(path)
    if p.is_dir():
        raise ConfigError(f"{p}: is a directory, not a case file (give a .toml file)")
    if not p.is_file():
        raise ConfigError(f"{p}: no such file")
    try:
        raw = p.read_bytes()
    except OSError as err:
        raise ConfigError(f"{p}: cannot read ({err.strerror})") from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as err:
        raise ConfigError(
            f"{p}: not a text file in UTF-8 (byte {err.start}); a case is a TOML text file"
        ) from None
    # a byte-order mark (some editors on Windows write one) is not part of the TOML
    text = text.removeprefix("\ufeff")
    if "\x00" in text:
        raise ConfigError(f"{p}: binary file (contains NUL bytes); a case is a TOML text file")
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise ConfigError(f"{p}: not valid TOML: {err}") from None
    if not data:
        raise ConfigError(
            f"{p}: empty case (no settings); write at least one setting, e.g. name = "
            '"my-case", to run the defaults, or use `undulate demo`'
        )
    pat = data.get("pattern")
    if isinstance(pat, dict) and "file" in pat:
        pat = dict(pat)
        drawing, scale = pat.pop("file"), pat.pop("scale", 1.0)
        if not isinstance(drawing, str) or not drawing:
            raise ConfigError(f"pattern.file: must be the path of an SVG or DXF drawing (got "
                              f"{drawing!r})")
        data = {**data, "pattern": pat}
        return with_drawing(data, p.parent / drawing, scale=scale)
    if isinstance(pat, dict) and "scale" in pat:
        raise ConfigError("pattern.scale: only with pattern.file (it scales a drawing)")
    return case_from_dict(data)


def with_drawing(data: dict, drawing: str | Path, *, scale: object = 1.0) -> Case:
    """The case ``data`` (a dict, as read from TOML) with the lines of an SVG or DXF
    ``drawing`` added to its pattern (after any lines it lists); ``scale`` multiplies the
    drawing's coordinates. Raises :class:`ConfigError` naming the file or the line."""
    from .pattern import PatternError, read_pattern

    problem = number_problem("pattern.scale", scale)
    if problem:
        raise ConfigError(problem)
    pat = dict(data.get("pattern") or {})
    res = pat.get("resolution", _default(Pattern, "resolution"))
    if number_problem("pattern.resolution", res) is not None:
        res = _default(Pattern, "resolution")  # reported by the validation below
    try:
        drawn = read_pattern(drawing, scale=float(scale), resolution=float(res))
    except PatternError as err:
        raise ConfigError(f"{Path(drawing).name}: {err}") from None
    pat["lines"] = list(pat.get("lines") or []) + [ln.to_dict() for ln in drawn]
    return case_from_dict({**data, "pattern": pat})


_BOUND_SYMBOLS = {"gt": ">", "ge": ">=", "lt": "<", "le": "<="}


def allowed_range(model: type[BaseModel], name: str) -> str:
    """The range of a numeric field as text, e.g. ``"> 0, <= 3"`` ("" if unbounded)."""
    parts = []
    for meta in model.model_fields[name].metadata:
        for key, sym in _BOUND_SYMBOLS.items():
            v = getattr(meta, key, None)
            if v is not None:
                parts.append(f"{sym} {v:g}")
    return ", ".join(parts)


def check_value(model: type[BaseModel], name: str, value: object, label: str) -> None:
    """Validate one field value exactly as a case file would; raise :class:`ConfigError`
    (one line starting with ``label``). Lets other interfaces share the case's ranges."""
    try:
        model.__pydantic_validator__.validate_assignment(
            model.model_construct(), name, value
        )
    except ValidationError as err:
        e = err.errors()[0]
        msg = e["msg"].removeprefix("Value error, ")
        rng = allowed_range(model, name)
        raise ConfigError(
            f"{label}: {msg}" + (f" (allowed: {rng})" if rng else "") + f"; got {value!r}"
        ) from None


def number_problem(name: str, value: object, *, above: float = 0.0,
                   inclusive: bool = False) -> str | None:
    """``None`` if ``value`` is a finite number > ``above`` (>= with ``inclusive``), else the
    one-line message ``"name: must be a number > above (got value)"``. Shared by the options
    checks of design, fabrication and patterns, each raising its own error type."""
    ok = (isinstance(value, int | float) and not isinstance(value, bool)
          and math.isfinite(value) and (value >= above if inclusive else value > above))
    if ok:
        return None
    return f"{name}: must be a number {'>=' if inclusive else '>'} {above:g} (got {value!r})"


def _default(model: type[BaseModel], name: str) -> Any:
    return model.model_fields[name].default


#: The material and section defaults of the case file, the one place they are set: rod width
#: b [mm], rod modulus E_B [MPa], fabric modulus E [MPa], fabric thickness t [mm]. The
#: analytical model, the study tables and the command line take theirs from here.
MATERIAL_DEFAULTS: dict[str, float] = {
    "b": _default(Rods, "b"), "E_B": _default(Rods, "E_B"),
    "E": _default(Fabric, "E"), "t": _default(Fabric, "t"),
}
