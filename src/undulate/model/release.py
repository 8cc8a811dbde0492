"""The loading: tables ``[release]``, ``[hang]``, ``[gravity]`` and ``[imperfection]`` of a
case file (pre-stretch, how it is released, what holds the sample after, and the start
noise)."""

from __future__ import annotations

from typing import Literal

from pydantic import (
    Field,
    StrictFloat,
    model_validator,
)

from .validators import Edge, _Strict


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
    stall_curved_steps: int = Field(
        50, ge=0, le=100000,
        description="steps along negative curvature of the rods a release step may take while "
        "it can still be halved (with adaptive); one that needs more, its rods passing from "
        "one unstable state to the next without settling, is taken again in halves (0: no "
        "limit, the step runs to solver.max_iter)",
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
