"""The sheet and the rods: tables ``[fabric]`` and ``[rods]`` of a case file, and the
material defaults. Units: mm, MPa."""

from __future__ import annotations

import math

from pydantic import (
    Field,
    StrictFloat,
    model_validator,
)

from .validators import PosFloat, _default, _Strict


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




#: The material and section defaults of the case file, the one place they are set: rod width
#: b [mm], rod modulus E_B [MPa], fabric modulus E [MPa], fabric thickness t [mm]. The
#: analytical model, the study tables and the command line take theirs from here.
MATERIAL_DEFAULTS: dict[str, float] = {
    "b": _default(Rods, "b"), "E_B": _default(Rods, "E_B"),
    "E": _default(Fabric, "E"), "t": _default(Fabric, "t"),
}
