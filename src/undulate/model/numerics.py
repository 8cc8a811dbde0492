"""How a case is solved: tables ``[mesh]``, ``[solver]`` and ``[dynamics]`` of a case file."""

from __future__ import annotations

import math
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray
from pydantic import (
    Field,
    model_validator,
)

from .validators import _Strict


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
    dx_rod: float = Field(
        1.0, gt=0.0, le=20.0,
        description="node spacing along rods [mm]; if not given: 1 mm, or 1/2, 1/3, 1/4 mm "
        "for rods so thin that a half-wave of eq. (1) would span fewer than 8 nodes")
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


#: nodes per half-wave the default rod spacing gives at least, counted on eq. (1)'s
#: half-wave length (0.7-0.85 of the simulated one): with fewer, the arcs of thin rods are
#: 4-7 nodes long, the arc-chain fit fails ("noisy") and n comes out wrong
#: (docs/studies/predict-data/README.md, "thin-mesh")
NODES_PER_HALF_WAVE = 8
#: the spacings the default chooses from [mm]: 1 / k, so that rods of one sweep share few
#: mesh sizes
DX_ROD_LADDER = (1.0, 0.5, 1.0 / 3.0, 0.25)


def eq1_arc_length(h: ArrayLike, eps0: ArrayLike, *, b: ArrayLike, E_B: ArrayLike,
                   E: ArrayLike, t: ArrayLike) -> NDArray[np.float64]:
    """Eq. (1), the arc length of one circular segment [mm]:
    l = (24 sqrt(6) E_B I / (E t))^(1/3) eps0^(-1/2) with I = b h^3 / 12. Written once here,
    below the mesh options that size the rod spacing on it; :func:`undulate.theory.l` is the
    documented entry point (defaults, scalars back)."""
    inertia = np.asarray(h, dtype=float) ** 3 * np.asarray(b, dtype=float) / 12.0
    stiff = 24.0 * math.sqrt(6.0) * np.asarray(E_B, dtype=float) * inertia
    return (np.cbrt(stiff / (np.asarray(E, dtype=float) * np.asarray(t, dtype=float)))
            * np.asarray(eps0, dtype=float) ** -0.5)


def auto_dx_rod(h: float, eps0: float, *, b: float, E_B: float, E: float, t: float) -> float:
    """The default node spacing along a rod [mm]: the largest of 1, 1/2, 1/3, 1/4 mm that
    puts at least :data:`NODES_PER_HALF_WAVE` nodes on a half-wave of eq. (1)
    (:func:`eq1_arc_length`; 1/4 mm for anything thinner)."""
    l_half = float(eq1_arc_length(h, eps0, b=b, E_B=E_B, E=E, t=t))
    for dx in DX_ROD_LADDER:
        if l_half >= NODES_PER_HALF_WAVE * dx:
            return dx
    return DX_ROD_LADDER[-1]
