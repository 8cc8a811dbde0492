"""One simulation case: the tables of a case file together (:class:`Case`), checked by the
rules between fields (:mod:`undulate.model.rules`), with the geometry derived from it
(:mod:`undulate.model.geometry`)."""

from __future__ import annotations

from typing import Literal

from pydantic import Field, model_validator

from . import geometry
from .lines import Pattern, PrintedRod
from .materials import Fabric, Rods
from .numerics import Dynamics, MeshOptions, SolverOptions, auto_dx_rod
from .release import Gravity, Hang, Imperfection, Release
from .rules import check_case
from .validators import _Strict

__all__ = ["Case"]


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
    def _rules(self) -> Case:
        if "dx_rod" not in self.mesh.model_fields_set:
            dx = min(auto_dx_rod(h, self.release.eps0, b=b, E_B=self.rods.E_B,
                                 E=self.fabric.E, t=self.fabric.t)
                     for h, b in geometry.rod_sections(self))
            if dx != self.mesh.dx_rod:
                self.mesh.dx_rod = dx
        check_case(self)
        return self

    # ---- derived geometry (undulate.model.geometry) ------------------------------------
    def rod_paths(self) -> list[PrintedRod]:
        """Every rod as printed (polyline, id, h, b): the pattern's lines in their order, or
        the rods of [rods] (parallel or segments) sorted by y as :meth:`segments`."""
        return geometry.rod_paths(self)

    def segments(self) -> list[tuple[float, float, float]]:
        """Rods as (x_start, y_centre, length) in the printed configuration, sorted by y (rods
        along +x; a case with a pattern has no segments: use :meth:`rod_paths`)."""
        return geometry.segments(self)

    def fabric_extent(self) -> tuple[float, float, float, float]:
        """(xmin, xmax, ymin, ymax) of the fabric in the printed (stretched) configuration, in
        the stretch frame: the rods' footprints plus ``margin_x`` beyond them along the
        stretch and ``margin_y`` across (or ``fabric.size``)."""
        return geometry.fabric_extent(self)
