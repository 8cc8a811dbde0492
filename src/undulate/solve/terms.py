"""Every energy of the model, declared once.

A run's total potential energy is the sum of the terms in :data:`TERMS`. Each term has a name,
the moment from which it acts, and a builder that turns a prepared simulation into element
groups (the kernels themselves are in :mod:`undulate.mechanics`):

* ``"prestretch"``: acts on the bare fabric from the pre-stretch on (its membrane and
  bending energy, the extra edge tension);
* ``"print"``: acts from printing on and may depend on the printed positions (the rods, which
  are stress-free there; the weight, which the flat print bed carries until the release).

:func:`groups` is how the pre-stretch, the quasi-static and inertial release and letting go of
the clamps (``[hang]``) collect their groups, so a new energy (a contact, a foundation, another
load) is one more entry here rather than an edit in each of them. Terms that only exist inside
one algorithm (the inertial mode's mass term, the let-go clamps' forces) stay with that
algorithm.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

import numpy as np

from ..mechanics.assemble import ElementGroup
from ..mechanics.build import edge_tension_group, fabric_groups, rod_groups
from ..mechanics.fabric import dead_load

if TYPE_CHECKING:
    from .simulation import Simulation

__all__ = ["ModelTerm", "TermState", "TERMS", "groups"]

Stage = Literal["prestretch", "print"]


@dataclass(frozen=True)
class TermState:
    """What a builder may need beyond the simulation: the positions at printing (None before
    printing) and the mask of nodes that can move (loads act on those only)."""

    x_print: np.ndarray | None = None
    loaded: np.ndarray | None = None


@dataclass(frozen=True)
class ModelTerm:
    """One energy term of the model: ``build(sim, state)`` returns its element groups (the
    assembler's :class:`undulate.mechanics.assemble.EnergyTerm`; empty when the term is off
    for this case)."""

    name: str
    acts_from: Stage
    build: Callable[[Simulation, TermState], list[ElementGroup]]


def _fabric(sim: Simulation, state: TermState) -> list[ElementGroup]:
    return fabric_groups(sim.mesh, sim.law, t=sim.case.fabric.t,
                         direction=sim.case.release.direction,
                         bending_factor=sim.case.fabric.bending_factor)


def _edge_tension(sim: Simulation, state: TermState) -> list[ElementGroup]:
    free_edges = [e for e in ("bottom", "top") if e not in sim.case.release.clamps]
    g = edge_tension_group(sim.mesh, sim.case.fabric.edge_tension, sim.case.release.direction,
                           free_edges)
    return [g] if g is not None else []


def _rods(sim: Simulation, state: TermState) -> list[ElementGroup]:
    if state.x_print is None:
        raise ValueError("energy term 'rods': needs the printed positions")
    return rod_groups(sim.mesh.rods, state.x_print, sim.sections)


def _weight(sim: Simulation, state: TermState) -> list[ElementGroup]:
    loaded = np.ones(sim.mesh.n_nodes, bool) if state.loaded is None else state.loaded
    g = gravity_group(sim, loaded)
    return [g] if g is not None else []


#: the model's energy terms, in the order their groups are assembled
TERMS: tuple[ModelTerm, ...] = (
    ModelTerm("fabric", "prestretch", _fabric),  # membrane (neo-Hookean or orthotropic) + bending
    ModelTerm("edge_tension", "prestretch", _edge_tension),  # fabric.edge_tension
    ModelTerm("rods", "print", _rods),  # stretch, bending and twist, footprint on the fabric
    ModelTerm("gravity", "print", _weight),  # [gravity]: weight of fabric and rods
)


def groups(sim: Simulation, stages: tuple[Stage, ...], state: TermState | None = None,
           terms: tuple[ModelTerm, ...] = TERMS) -> list[ElementGroup]:
    """Element groups of the ``terms`` that act from one of ``stages``, in their order."""
    st = state or TermState()
    out: list[ElementGroup] = []
    for term in terms:
        if term.acts_from in stages:
            out += term.build(sim, st)
    return out


def lumped_masses(sim) -> np.ndarray:
    """Node masses [t] of fabric and rods."""
    mesh, case = sim.mesh, sim.case
    X = mesh.X
    tri = mesh.tris
    A0 = 0.5 * np.abs(
        (X[tri[:, 1], 0] - X[tri[:, 0], 0]) * (X[tri[:, 2], 1] - X[tri[:, 0], 1])
        - (X[tri[:, 1], 1] - X[tri[:, 0], 1]) * (X[tri[:, 2], 0] - X[tri[:, 0], 0])
    )
    m = np.zeros(mesh.n_nodes)
    for c in range(3):
        m += np.bincount(tri[:, c], weights=case.fabric.rho * case.fabric.t * A0 / 3.0,
                         minlength=mesh.n_nodes)
    for ch, sec, path in zip(mesh.rods, sim.sections, case.rod_paths(), strict=True):
        seg = path.length / max(ch.n_nodes - 1, 1)  # nodes are equally spaced along the rod
        ln = np.full(ch.n_nodes, seg)
        ln[[0, -1]] = 0.5 * seg
        m[ch.p] += case.rods.rho_B * sec.b * sec.h * ln
    return m


def gravity_group(sim, free: np.ndarray) -> ElementGroup | None:
    """The weight of fabric and rods (lumped masses times ``case.gravity.g``) on the free
    nodes, or None when gravity is off."""
    grav = sim.case.gravity
    if not grav.on:
        return None
    nodes = np.nonzero(free)[0]
    w = lumped_masses(sim)[nodes, None] * np.asarray(grav.g, dtype=float)[None, :]
    return ElementGroup("gravity", dead_load, nodes[:, None], (w,))
