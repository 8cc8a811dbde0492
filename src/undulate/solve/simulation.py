"""A case made ready to solve: its mesh, rod sections and the fabric's element groups
(:class:`Simulation`), and the record a finished release leaves (:class:`SimResult`).

Also the few measures every release protocol reports at each step (:func:`rod_heights`) and
the start imperfection (:func:`imperfection_field`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from ..mechanics.assemble import ElementGroup
from ..mechanics.build import RodSection, rod_centrelines
from ..mechanics.material import FabricLaw, fabric_law
from ..mesh import FabricMesh, RodPath, build_mesh, stretch_rotation
from ..model import Case
from .terms import groups

__all__ = ["ProgressFn", "SimResult", "Simulation", "case_law", "imperfection_field",
           "prepare", "printed_lateral_stretch", "rod_heights"]

ProgressFn = Callable[[float, dict], None]


@dataclass
class SimResult:
    """Final rest state and the record of how it was reached."""

    case: Case
    mesh: FabricMesh
    sections: list[RodSection]  # one per rod, in the order of mesh.rods and case.rod_paths()
    x_reference: np.ndarray  # (n, 3) unstretched fabric
    x_printed: np.ndarray  # (n, 3) pre-stretched, flat, at printing
    x_final: np.ndarray  # (n, 3) rest state after release
    centerlines: list[np.ndarray]  # final rod centre lines (m, 3)
    centerlines_printed: list[np.ndarray]
    history: list[dict]
    stats: dict
    energies: dict
    element_energy: dict = field(default_factory=dict)


@dataclass
class Simulation:
    case: Case
    mesh: FabricMesh
    sections: list[RodSection]  # one per rod
    X3: np.ndarray
    fabric: list[ElementGroup]  # groups of the terms acting from the pre-stretch on (terms.py)
    force_scale: float

    @property
    def law(self) -> FabricLaw:
        """The fabric's material law (:mod:`undulate.mechanics.material`)."""
        return case_law(self.case)

    @property
    def rotation(self) -> np.ndarray:
        """(3, 3) rotation from the stretch frame (x along the stretch) to the drawing frame."""
        rot = np.eye(3)
        rot[:2, :2] = stretch_rotation(self.case.release.direction)
        return rot


def case_law(case: Case) -> FabricLaw:
    """The material law of ``case.fabric`` (neo-Hookean, or orthotropic with E_y and G)."""
    f = case.fabric
    return fabric_law(f.E, f.nu, f.E_y, f.G)


def printed_lateral_stretch(case: Case) -> float:
    """Stretch across the stretch lam_y of the homogeneous pre-stretched state that maps the
    reference mesh onto the printed one: the law's free uniaxial value, or 1 when the frame
    also holds both edges across the stretch (``release.clamps`` with bottom and top; with one
    of them the sheet narrows towards it, see :func:`prepare`)."""
    if {"bottom", "top"} <= set(case.release.clamps):
        return 1.0
    return case_law(case).lateral_stretch(case.release.eps0)


def prepare(case: Case) -> Simulation:
    """Mesh the case and build the fabric's element groups."""
    f, r = case.fabric, case.rods
    eps0 = case.release.eps0
    lam_y = printed_lateral_stretch(case)
    m = case.mesh
    paths = case.rod_paths()
    if case.pattern is None:  # rods along x: the structured grid can take them too
        rods_in: list = case.segments()
    else:
        rods_in = [RodPath(p.points, b=p.b, id=p.id) for p in paths]
    mesh = build_mesh(
        rods_in, r.b, case.fabric_extent(), eps0=eps0, lam_y=lam_y,
        dx_rod=m.dx_rod, dx_far=m.dx_far, dy_far=m.dy_far, grading=m.grading, kind=m.kind,
        h_far=m.h_far, direction=case.release.direction,
    )
    secs = [RodSection(h=p.h, b=p.b, E_B=r.E_B, nu_B=r.nu_B, t=f.t, d=r.offset) for p in paths]
    across = [e for e in ("bottom", "top") if e in case.release.clamps]
    if len(across) == 1 and lam_y != 1.0:
        # one edge across the stretch held (at its printed place): the homogeneous state
        # narrows towards it, y_p = y_e + lam_y (Y - y_e), so the reference sheet is moved
        # by y_e (1 - 1 / lam_y) across the stretch (a rigid shift of the reference)
        y_e = case.fabric_extent()[2 if across[0] == "bottom" else 3]
        shift = stretch_rotation(case.release.direction) @ np.array(
            [0.0, y_e * (1.0 - 1.0 / lam_y)])
        mesh = replace(mesh, X=mesh.X + shift,
                       ys=None if mesh.ys is None else mesh.ys + shift[1])
    X3 = np.c_[mesh.X, np.zeros(mesh.n_nodes)]
    sim = Simulation(case, mesh, secs, X3, [], force_scale=f.E * f.t * m.dx_rod)
    sim.fabric = groups(sim, ("prestretch",))
    return sim


def imperfection_field(n: int, dx: float, amplitude: float, correlation: float,
                       rng: np.random.Generator) -> np.ndarray:
    """Smooth random profile of RMS ``amplitude`` along ``n`` nodes spaced ``dx``."""
    if amplitude == 0.0 or n == 0:
        return np.zeros(n)
    w = rng.standard_normal(n + 64)
    sig = max(correlation / dx, 0.5)
    k = np.arange(-int(4 * sig) - 1, int(4 * sig) + 2)
    ker = np.exp(-0.5 * (k / sig) ** 2)
    z = np.convolve(w, ker, mode="same")[32 : 32 + n]
    z -= z.mean()
    rms = np.sqrt(np.mean(z**2))
    return amplitude * z / rms if rms > 0 else np.zeros(n)


def rod_heights(sim: Simulation, x: np.ndarray) -> dict[str, float]:
    """Highest point of the rods' centre lines above their printed level (``max_height``, as
    in metrics.json), the largest deflection up or down (``max_deflection``) and the same per
    rod (``rod_max_deflection``)."""
    z = [c[:, 2] - sk.offset for c, sk in
         zip(rod_centrelines(sim.mesh.rods, x, sim.sections), sim.sections, strict=True)]
    return dict(max_height=float(max(np.max(zi) for zi in z)),
                max_deflection=float(max(np.max(np.abs(zi)) for zi in z)),
                rod_max_deflection=[float(np.max(np.abs(zi))) for zi in z])
