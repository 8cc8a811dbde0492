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

if TYPE_CHECKING:
    from .release import Simulation

__all__ = ["EnergyTerm", "TermState", "TERMS", "groups"]

Stage = Literal["prestretch", "print"]


@dataclass(frozen=True)
class TermState:
    """What a builder may need beyond the simulation: the positions at printing (None before
    printing) and the mask of nodes that can move (loads act on those only)."""

    x_print: np.ndarray | None = None
    loaded: np.ndarray | None = None


@dataclass(frozen=True)
class EnergyTerm:
    """One energy term: ``build(sim, state)`` returns its element groups (empty when the term
    is off for this case)."""

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
    from .dynamics import gravity_group

    loaded = np.ones(sim.mesh.n_nodes, bool) if state.loaded is None else state.loaded
    g = gravity_group(sim, loaded)
    return [g] if g is not None else []


#: the model's energy terms, in the order their groups are assembled
TERMS: tuple[EnergyTerm, ...] = (
    EnergyTerm("fabric", "prestretch", _fabric),  # membrane (neo-Hookean or orthotropic) + bending
    EnergyTerm("edge_tension", "prestretch", _edge_tension),  # fabric.edge_tension
    EnergyTerm("rods", "print", _rods),  # stretch, bending and twist, footprint on the fabric
    EnergyTerm("gravity", "print", _weight),  # [gravity]: weight of fabric and rods
)


def groups(sim: Simulation, stages: tuple[Stage, ...], state: TermState | None = None,
           terms: tuple[EnergyTerm, ...] = TERMS) -> list[ElementGroup]:
    """Element groups of the ``terms`` that act from one of ``stages``, in their order."""
    st = state or TermState()
    out: list[ElementGroup] = []
    for term in terms:
        if term.acts_from in stages:
            out += term.build(sim, st)
    return out
