"""Turn a meshed case into element groups: fabric membrane and bending, and the bonded rods.

The fabric groups use the unstretched reference mesh. Rod groups are built *after* the
pre-stretch solve, from the printed node positions, so all rod strains are zero at printing.
"""

from __future__ import annotations

from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np
from scipy.optimize import brentq

from ..mesh import FabricMesh, RodChain
from .assemble import ElementGroup
from .compiled import CachedJit
from .fabric import hinge_bending, neo_hookean_membrane
from .rod import (
    edge_length,
    node_strains,
    rod_bend_twist,
    rod_footprint,
    rod_stretch,
    torsion_constant,
    vertex_strains,
)

__all__ = [
    "RodSection",
    "lame_plane_stress",
    "lateral_stretch",
    "fabric_groups",
    "rod_stencils",
    "rod_groups",
    "rod_centrelines",
]


@dataclass(frozen=True)
class RodSection:
    """Material and cross-section of the rods; ``t`` is the fabric thickness (for the offset)."""

    h: float
    b: float
    E_B: float
    nu_B: float
    t: float
    d: float | None = None  # override of the offset (0 for a rod alone: nodes on its axis)

    @property
    def offset(self) -> float:
        """Height of the rod's centre line above the fabric mid-surface, (t + h) / 2."""
        return 0.5 * (self.t + self.h) if self.d is None else self.d

    @property
    def EA(self) -> float:
        return self.E_B * self.b * self.h

    @property
    def EI_out(self) -> float:
        return self.E_B * self.b * self.h**3 / 12.0

    @property
    def EI_in(self) -> float:
        return self.E_B * self.h * self.b**3 / 12.0

    @property
    def GJ(self) -> float:
        return self.E_B / (2.0 * (1.0 + self.nu_B)) * torsion_constant(self.b, self.h)


def lame_plane_stress(E: float, nu: float) -> tuple[float, float]:
    """(mu, lam2): shear modulus and plane-stress Lame constant E nu / (1 - nu^2)."""
    return E / (2.0 * (1.0 + nu)), E * nu / (1.0 - nu**2)


def lateral_stretch(eps0: float, nu: float) -> float:
    """Lateral stretch lam_y of the membrane law under free uniaxial stretch 1 + eps0."""
    mu, lam2 = lame_plane_stress(1.0, nu)
    lx = 1.0 + eps0
    if lam2 == 0.0:
        return 1.0
    return float(brentq(lambda ly: mu * (ly**2 - 1.0) + lam2 * np.log(lx * ly), 1e-3, 1.0))


def fabric_groups(mesh: FabricMesh, E: float, nu: float, t: float) -> list[ElementGroup]:
    """Membrane (per triangle) and bending (per interior edge) groups of the fabric."""
    X = mesh.X
    tri = mesh.tris
    D0 = X[tri[:, 1]] - X[tri[:, 0]]
    D1 = X[tri[:, 2]] - X[tri[:, 0]]
    Dm = np.stack([D0, D1], axis=2)  # (n, 2, 2) columns = edges
    det = Dm[:, 0, 0] * Dm[:, 1, 1] - Dm[:, 0, 1] * Dm[:, 1, 0]
    if np.any(det <= 0):
        raise ValueError("mesh: triangles must be counter-clockwise with positive area")
    Dm_inv = np.linalg.inv(Dm)
    A0 = 0.5 * det
    mu, lam2 = lame_plane_stress(E, nu)
    n = tri.shape[0]
    membrane = ElementGroup(
        "fabric_membrane",
        neo_hookean_membrane,
        tri,
        (Dm_inv, A0, np.full(n, mu), np.full(n, lam2), np.full(n, t)),
    )
    hin = mesh.hinges()
    # areas of the two triangles at each hinge
    e_len2 = np.sum((X[hin[:, 1]] - X[hin[:, 0]]) ** 2, axis=1)
    a_a = 0.5 * np.abs(_cross2(X[hin[:, 1]] - X[hin[:, 0]], X[hin[:, 2]] - X[hin[:, 0]]))
    a_b = 0.5 * np.abs(_cross2(X[hin[:, 1]] - X[hin[:, 0]], X[hin[:, 3]] - X[hin[:, 0]]))
    D = E * t**3 / (12.0 * (1.0 - nu**2))
    k = D * mesh.hinge_factor * e_len2 / (a_a + a_b)
    bending = ElementGroup("fabric_bending", hinge_bending, hin, (k,))
    return [membrane, bending]


def _cross2(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]


def rod_stencils(chain: RodChain) -> np.ndarray:
    """(m, 5) node indices (p_a, p_b, p, qp, qm) defining each rod node's centre point."""
    p = chain.p
    m = p.size
    k = np.arange(m)
    pa = p[np.maximum(k - 1, 0)]
    pb = p[np.minimum(k + 1, m - 1)]
    return np.stack([pa, pb, p, chain.qp, chain.qm], axis=1)


_edge_len_v = CachedJit(jax.vmap(edge_length, in_axes=(0, None)), "build.rod_edge_length")
_vertex_v = CachedJit(jax.vmap(vertex_strains, in_axes=(0, None)), "build.rod_vertex_strains")
_node_v = CachedJit(jax.vmap(node_strains), "build.rod_node_strains")


def rod_groups(
    chains: list[RodChain], x_printed: np.ndarray, sec: RodSection
) -> list[ElementGroup]:
    """Stretch, bend/twist and footprint groups of all rods, stress-free at ``x_printed``."""
    d = sec.offset
    edges, verts, nodes_ = [], [], []
    for ch in chains:
        st = rod_stencils(ch)
        m = st.shape[0]
        edges.append(np.concatenate([st[:-1], st[1:]], axis=1))  # (m-1, 10)
        if m >= 3:
            verts.append(np.concatenate([st[:-2], st[1:-1], st[2:]], axis=1))  # (m-2, 15)
        nodes_.append(st)
    e_idx = np.concatenate(edges)
    n_idx = np.concatenate(nodes_)
    xj = jnp.asarray(x_printed)
    L0 = np.asarray(_edge_len_v(xj[e_idx], d))
    groups = [
        ElementGroup(
            "rod_stretch",
            rod_stretch,
            e_idx,
            (np.full(len(L0), d), L0, np.full(len(L0), sec.EA)),
        )
    ]
    if verts:
        v_idx = np.concatenate(verts)
        rest = np.asarray(_vertex_v(xj[v_idx], d))
        # Voronoi length: half of the two adjacent rest edges
        lv_parts = []
        for ch in chains:
            st = rod_stencils(ch)
            le = np.asarray(_edge_len_v(xj[np.concatenate([st[:-1], st[1:]], axis=1)], d))
            if le.size >= 2:
                lv_parts.append(0.5 * (le[:-1] + le[1:]))
        lv = np.concatenate(lv_parts)
        nv = v_idx.shape[0]
        groups.append(
            ElementGroup(
                "rod_bend_twist",
                rod_bend_twist,
                v_idx,
                (np.full(nv, d), rest, lv, np.full(nv, sec.EI_out), np.full(nv, sec.EI_in),
                 np.full(nv, sec.GJ)),
            )
        )
    rest_n = np.asarray(_node_v(xj[n_idx]))
    # length of rod each node carries (half edges)
    ln_parts = []
    for ch in chains:
        st = rod_stencils(ch)
        le = np.asarray(_edge_len_v(xj[np.concatenate([st[:-1], st[1:]], axis=1)], d))
        ln = np.zeros(st.shape[0])
        ln[:-1] += 0.5 * le
        ln[1:] += 0.5 * le
        ln_parts.append(ln)
    ln = np.concatenate(ln_parts)
    G_B = sec.E_B / (2.0 * (1.0 + sec.nu_B))
    k = np.stack(
        [sec.E_B * sec.b * sec.h * ln, G_B * sec.b * sec.h * ln, sec.E_B * sec.h * ln / sec.b],
        axis=1,
    )
    groups.append(ElementGroup("rod_footprint", rod_footprint, n_idx, (rest_n, k)))
    return groups


def _centre_point(x5: jnp.ndarray, d: jnp.ndarray) -> jnp.ndarray:
    from .rod import centre

    return centre(x5, d)[0]


_centre_v = CachedJit(jax.vmap(_centre_point, in_axes=(0, None)), "build.rod_centre")


def rod_centrelines(chains: list[RodChain], x: np.ndarray, sec: RodSection) -> list[np.ndarray]:
    """Rod centre lines (m, 3) at node positions ``x`` (offset along the fabric normal).

    One jitted kernel for every call (the offset is an argument, not a constant baked into a
    new function), so the release loop, which calls this at every step, never retraces.
    """
    xj = jnp.asarray(x)
    d = jnp.asarray(sec.offset, dtype=jnp.float64)
    return [np.asarray(_centre_v(xj[rod_stencils(ch)], d)) for ch in chains]


def free_rod(n_nodes: int, length: float, b: float) -> tuple[RodChain, np.ndarray]:
    """A straight rod alone (no fabric) along x: its node chain and node positions (3n, 3).

    Nodes 0..n-1 are the centre row, n..2n-1 the +b/2 row, 2n..3n-1 the -b/2 row. Used to
    verify the rod model by itself (Euler buckling, beam on a Winkler foundation).
    """
    xs = np.linspace(0.0, length, n_nodes)
    idx = np.arange(n_nodes)
    chain = RodChain(p=idx, qp=idx + n_nodes, qm=idx + 2 * n_nodes)
    x = np.zeros((3 * n_nodes, 3))
    x[:, 0] = np.tile(xs, 3)
    x[n_nodes : 2 * n_nodes, 1] = b / 2
    x[2 * n_nodes :, 1] = -b / 2
    return chain, x
