"""How the frame holds the fabric and how its tension is released: one object per protocol.

* :class:`DisplacementControl` (``release.control = "displacement"``, the default): the
  clamped edges move back from the pre-stretch to ``final_strain`` and hold the fabric to the
  end, as a frame whose bars are wound in.
* :class:`ForceControl` (``"force"``): after the pre-stretch the clamps let go and their
  forces become dead loads on the edge nodes, taken down to zero (or to the share
  ``final_strain / eps0``) with the release parameter: the edges are free to move, turn and
  lift, and at the end the fabric is a free sample, as one cut off its frame. Its six
  rigid-body motions are removed by a statically determinate set of pins (:func:`gauge_pins`)
  that adds no stiffness: the pins carry no force, because the loads are in equilibrium.

:func:`prestretch` is the frame's first act, common to both: the in-plane equilibrium of the
fabric stretched by eps0 between the clamps, before anything is printed.

Both are driven by the release loop of :mod:`undulate.solve.release` through one parameter
``e``, the nominal clamp strain (eps0 at the start, ``final_strain`` at the end):
:meth:`place` puts the boundary at ``e`` (moves the clamps, or sets the loads) and returns
the start of the step, :meth:`strain` is the fabric's strain between its ends that the
records call the clamp strain (the release strain is eps0 minus it).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol

import numpy as np

from ..mechanics.assemble import Assembly, ElementGroup
from ..mechanics.fabric import dead_load
from ..mesh import FabricMesh
from .newton import ConvergenceError, NewtonOptions, minimize

if TYPE_CHECKING:
    from .simulation import Simulation

__all__ = ["Boundary", "DisplacementControl", "ForceControl", "clamp_positions",
           "clamped_nodes", "edge_nodes", "gauge_pins", "make_boundary", "prestretch"]


def edge_nodes(mesh: FabricMesh, edges: list[str] | tuple[str, ...]) -> np.ndarray:
    """Mask of the nodes on the named edges ("left", "right", "bottom", "top": stretch frame)."""
    mask = np.zeros(mesh.n_nodes, dtype=bool)
    for name in edges:
        mask[mesh.node_sets[name]] = True
    return mask


def clamped_nodes(sim: Simulation) -> np.ndarray:
    """Nodes held by the frame during the pre-stretch (``release.clamps``)."""
    return edge_nodes(sim.mesh, sim.case.release.clamps)


def clamp_positions(sim: Simulation, e: float, x: np.ndarray) -> np.ndarray:
    """Copy of ``x`` with the clamped edges at clamp strain ``e`` (stretch frame: x scaled,
    y and z at their reference values)."""
    out = x.copy()
    clamp = clamped_nodes(sim)
    rot = sim.rotation
    u = sim.X3[clamp] @ rot  # reference, stretch frame
    u[:, 0] *= 1.0 + e
    u[:, 2] = 0.0
    out[clamp] = u @ rot.T
    return out


def gauge_pins(sim: Simulation) -> np.ndarray:
    """(n, 3) mask of six pinned components that remove a free sheet's rigid-body motions and
    nothing else: along the stretch at the middle of the bottom edge; across it at the
    middles of the left and right edges; out of plane at all three (three points not on one
    line). Six constraints for six rigid motions make the support statically determinate, so
    under loads in equilibrium the pins carry no force and add no stiffness. In a symmetric
    case the pinned points are those the symmetry keeps in place anyway (stretch frame)."""
    rot = sim.rotation
    X = sim.X3 @ rot  # reference, stretch frame
    fixed = np.zeros((sim.mesh.n_nodes, 3), dtype=bool)
    x_mid = 0.5 * (X[:, 0].min() + X[:, 0].max())
    y_mid = 0.5 * (X[:, 1].min() + X[:, 1].max())

    def nearest(edge: str, x: float | None, y: float | None) -> int:
        nodes = np.asarray(sim.mesh.node_sets[edge])
        along = X[nodes, 0] - x if x is not None else X[nodes, 1] - y
        return int(nodes[np.argmin(np.abs(along))])

    bottom = nearest("bottom", x_mid, None)
    left = nearest("left", None, y_mid)
    right = nearest("right", None, y_mid)
    # components in the stretch frame; for a turned stretch pin the drawing-frame components
    # that the frame's axes map to (the turn is about z, so z stays z)
    along, across = np.abs(rot[:2, 0]), np.abs(rot[:2, 1])
    fixed[bottom, int(np.argmax(along))] = True
    fixed[left, int(np.argmax(across))] = True
    fixed[right, int(np.argmax(across))] = True
    fixed[[bottom, left, right], 2] = True
    return fixed


def equilibrated(w: np.ndarray, x: np.ndarray) -> np.ndarray:
    """In-plane forces ``w`` (m, 3) at points ``x`` made exactly self-equilibrated: their
    net force and their net moment about z taken out (least-squares: the smallest change).
    The clamps' forces at the pre-stretch balance only to its solver tolerance; an
    unbalanced rest would be carried by the gauge pins."""
    w = w - w.mean(axis=0) * np.array([1.0, 1.0, 0.0])
    r = x[:, :2] - x[:, :2].mean(axis=0)
    moment = np.sum(r[:, 0] * w[:, 1] - r[:, 1] * w[:, 0])
    c = moment / np.sum(r**2)
    out = w.copy()
    out[:, 0] += c * r[:, 1]
    out[:, 1] -= c * r[:, 0]
    return out


class Boundary(Protocol):
    """A release protocol, driven by the nominal clamp strain ``e`` (eps0 -> final_strain)."""

    #: (n, 3) mask of the components the boundary holds during the release
    fixed: np.ndarray

    def groups(self) -> list[ElementGroup]:
        """Element groups the boundary adds to the release's energy (its loads)."""
        ...

    def place(self, e: float, x: np.ndarray) -> np.ndarray:
        """The boundary at ``e``: a copy of ``x`` with the clamps moved there, or the loads
        set for it."""
        ...

    def strain(self, e: float, x: np.ndarray) -> float:
        """The fabric's strain between its ends in state ``x`` (the records' clamp strain)."""
        ...


class DisplacementControl:
    """The clamps move back to ``e`` and hold the edges to the end (the default)."""

    def __init__(self, sim: Simulation) -> None:
        self.sim = sim
        self.fixed = np.zeros((sim.mesh.n_nodes, 3), dtype=bool)
        self.fixed[clamped_nodes(sim)] = True

    def groups(self) -> list[ElementGroup]:
        return []

    def place(self, e: float, x: np.ndarray) -> np.ndarray:
        return clamp_positions(self.sim, e, x)

    def strain(self, e: float, x: np.ndarray) -> float:
        return e


class ForceControl:
    """The clamps' forces at the pre-stretch as dead loads on the edge nodes, scaled by
    ``e / eps0``: the tension is taken off, the edges follow; a free sample at ``e = 0``.

    ``fabric``: the groups of the fabric at the pre-stretch and ``x_print`` its equilibrium
    there (what gives the clamps' forces)."""

    def __init__(self, sim: Simulation, fabric: list[ElementGroup], x_print: np.ndarray) -> None:
        self.sim = sim
        self.eps0 = sim.case.release.eps0
        held = clamped_nodes(sim)
        fixed = np.zeros((sim.mesh.n_nodes, 3), dtype=bool)
        fixed[held] = True
        self.nodes = np.nonzero(held)[0]
        w0 = Assembly(sim.mesh.n_nodes, fabric, fixed).gradient_full(x_print)[self.nodes]
        self.w0 = equilibrated(w0, x_print[self.nodes])
        self.load = ElementGroup("edge_load", dead_load, self.nodes[:, None], (self.w0,))
        self.fixed = gauge_pins(sim)
        X = sim.X3 @ sim.rotation
        self._left = np.asarray(sim.mesh.node_sets["left"])
        self._right = np.asarray(sim.mesh.node_sets["right"])
        self._length = float(X[self._right, 0].mean() - X[self._left, 0].mean())

    def groups(self) -> list[ElementGroup]:
        return [self.load]

    def place(self, e: float, x: np.ndarray) -> np.ndarray:
        self.load.set_params(self.w0 * (e / self.eps0))
        return x.copy()

    def strain(self, e: float, x: np.ndarray) -> float:
        xs = x @ self.sim.rotation
        return float(xs[self._right, 0].mean() - xs[self._left, 0].mean()) / self._length - 1.0


def make_boundary(sim: Simulation, x_print: np.ndarray) -> Boundary:
    """The boundary of ``case.release.control`` (``x_print``: the pre-stretched state)."""
    if sim.case.release.control == "force":
        return ForceControl(sim, sim.fabric, x_print)
    return DisplacementControl(sim)


def prestretch(sim: Simulation, opts: NewtonOptions) -> tuple[np.ndarray, dict]:
    """In-plane equilibrium of the fabric stretched by eps0 between the clamps (z = 0)."""
    eps0 = sim.case.release.eps0
    # start from the fabric stretched along x only, as the clamps hold it (y = Y): the solve
    # lets it narrow (3 Newton iterations on the default sheet). Starting from the free strip's
    # lateral contraction instead puts the elements next to the clamps' corners, held at y = Y,
    # in a state from which Newton ended with three of them folded over (a mirrored, higher
    # energy in-plane equilibrium: 427.9 against 418.0 N mm, 16 iterations; measured)
    rot = sim.rotation
    x = ((sim.X3 @ rot) * np.array([1.0 + eps0, 1.0, 0.0])) @ rot.T
    x = clamp_positions(sim, eps0, x)
    fixed = np.zeros((sim.mesh.n_nodes, 3), dtype=bool)
    fixed[clamped_nodes(sim)] = True
    fixed[:, 2] = True
    asm = Assembly(sim.mesh.n_nodes, sim.fabric, fixed)
    o = NewtonOptions(**{**opts.__dict__, "require_stable": True, "negative_curvature": False})
    res = minimize(asm, x, asm.free(x), o)
    if not res.converged:
        raise ConvergenceError(f"pre-stretch: {res.message}", step=0, residual=res.residual)
    x = asm.full(res.u, x)
    folded = int(np.count_nonzero(_signed_areas(sim.mesh.tris, x) <= 0.0))
    if folded:
        raise ConvergenceError(f"pre-stretch: {folded} fabric triangle(s) folded over in the "
                               "stretched state (not a physical equilibrium)", step=0,
                               residual=res.residual)
    return x, {"iterations": res.iterations, "residual": res.residual}


def _signed_areas(tris: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Twice the signed in-plane area of each triangle (reference triangles are positive)."""
    a = x[tris[:, 1], :2] - x[tris[:, 0], :2]
    b = x[tris[:, 2], :2] - x[tris[:, 0], :2]
    return a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
