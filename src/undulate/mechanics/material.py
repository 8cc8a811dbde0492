"""The fabric's material law: one object per law that knows its membrane energy, its bending
modulus and how much the sheet narrows under a free uniaxial stretch.

* :class:`NeoHookean` (E, nu): the compressible neo-Hookean membrane of the isotropic knit
  (:func:`undulate.mechanics.fabric.neo_hookean_membrane`);
* :class:`OrthotropicSVK` (E_x, E_y, nu, G): a St Venant-Kirchhoff membrane with one material
  axis along the stretch (:func:`undulate.mechanics.fabric.orthotropic_membrane`).

:func:`fabric_law` picks the law a case's ``[fabric]`` table describes (orthotropic when
``E_y`` and ``G`` are given). Everything that depends on the law goes through these objects:
the membrane element group, the hinges' bending stiffness, the lateral stretch that places the
reference mesh under the printed one, and the relaxed-frame drawings of the print files.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np
from scipy.optimize import brentq

from .assemble import ElementGroup
from .fabric import neo_hookean_membrane, orthotropic_membrane, orthotropic_stiffness

__all__ = ["FabricLaw", "NeoHookean", "OrthotropicSVK", "fabric_law", "lame_plane_stress"]


def lame_plane_stress(E: float, nu: float) -> tuple[float, float]:
    """(mu, lam2): shear modulus and plane-stress Lame constant E nu / (1 - nu^2)."""
    return E / (2.0 * (1.0 + nu)), E * nu / (1.0 - nu**2)


class FabricLaw(Protocol):
    """What the rest of undulate asks of a fabric law."""

    @property
    def bending_modulus(self) -> float:
        """Young's modulus [MPa] of the plate bending stiffness E t^3 / (12 (1 - nu^2))."""
        ...

    @property
    def nu(self) -> float:
        """Poisson's ratio (contraction across under a pull along the stretch)."""
        ...

    def lateral_stretch(self, eps0: float) -> float:
        """Stretch across lam_y of a free strip stretched by 1 + eps0 along the stretch."""
        ...

    def membrane(self, tris: np.ndarray, Dm_inv: np.ndarray, A0: np.ndarray, t: float,
                 rotation: np.ndarray) -> ElementGroup:
        """The membrane group of these triangles (reference edge matrices' inverses
        ``Dm_inv``, areas ``A0``, thickness ``t``; ``rotation``: 2 x 2, stretch frame to
        mesh frame)."""
        ...


@dataclass(frozen=True)
class NeoHookean:
    """Isotropic compressible neo-Hookean membrane: Young's modulus E [MPa], Poisson nu."""

    E: float
    nu: float

    @property
    def bending_modulus(self) -> float:
        return self.E

    def lateral_stretch(self, eps0: float) -> float:
        """From the uniaxial state of the law: mu (lam_y^2 - 1) + lam2 ln(lam_x lam_y) = 0."""
        mu, lam2 = lame_plane_stress(1.0, self.nu)
        if lam2 == 0.0:
            return 1.0
        lx = 1.0 + eps0
        return float(brentq(lambda ly: mu * (ly**2 - 1.0) + lam2 * np.log(lx * ly), 1e-3, 1.0))

    def membrane(self, tris: np.ndarray, Dm_inv: np.ndarray, A0: np.ndarray, t: float,
                 rotation: np.ndarray) -> ElementGroup:
        n = len(tris)
        mu, lam2 = lame_plane_stress(self.E, self.nu)
        return ElementGroup("fabric_membrane", neo_hookean_membrane, tris,
                            (Dm_inv, A0, np.full(n, mu), np.full(n, lam2), np.full(n, t)))


@dataclass(frozen=True)
class OrthotropicSVK:
    """Orthotropic St Venant-Kirchhoff membrane of a knit: E_x along the stretch, E_y across,
    nu the contraction across under a pull along, G the in-plane shear modulus [MPa]."""

    E_x: float
    E_y: float
    nu: float
    G: float

    @property
    def bending_modulus(self) -> float:
        return float(np.sqrt(self.E_x * self.E_y))

    def lateral_stretch(self, eps0: float) -> float:
        """From S_yy = 0 with Green strains: lam_y^2 = 1 - nu ((1 + eps0)^2 - 1)."""
        return float(np.sqrt(1.0 - self.nu * ((1.0 + eps0) ** 2 - 1.0)))

    def membrane(self, tris: np.ndarray, Dm_inv: np.ndarray, A0: np.ndarray, t: float,
                 rotation: np.ndarray) -> ElementGroup:
        n = len(tris)
        Q = np.tile(orthotropic_stiffness(self.E_x, self.E_y, self.nu, self.G), (n, 1))
        R = np.tile(rotation, (n, 1, 1))
        return ElementGroup("fabric_membrane", orthotropic_membrane, tris,
                            (Dm_inv, A0, Q, R, np.full(n, t)))


def fabric_law(E: float, nu: float, E_y: float | None = None, G: float | None = None
               ) -> FabricLaw:
    """The law of a fabric given as in a case's ``[fabric]``: neo-Hookean (E, nu), or
    orthotropic with ``E_y`` and ``G`` (E then the modulus along the stretch)."""
    if E_y is None and G is None:
        return NeoHookean(E, nu)
    if E_y is None or G is None:
        raise ValueError("fabric: an orthotropic knit needs both E_y and its shear modulus G")
    return OrthotropicSVK(E, E_y, nu, G)
