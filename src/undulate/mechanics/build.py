"""Turn a meshed case into element groups: fabric membrane and bending, and the bonded rods.

The fabric groups use the unstretched reference mesh. Rod groups are built *after* the
pre-stretch solve, from the printed node positions, so all rod strains are zero at printing.
"""

from __future__ import annotations

from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from ..mesh import FabricMesh, RodChain
from .assemble import ElementGroup
from .compiled import CachedJit
from .fabric import (
    dead_load,
    hinge_bending,
)
from .frames import FrameLayout, FrameSlots
from .material import FabricLaw, NeoHookean, OrthotropicSVK, fabric_law, lame_plane_stress
from .rod import (
    edge_length,
    frame_point,
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
    "edge_tension_group",
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


def lateral_stretch(eps0: float, nu: float, *, orthotropic: bool = False) -> float:
    """Lateral stretch lam_y of the membrane law under free uniaxial stretch 1 + eps0 (along
    a material axis for the orthotropic law; :meth:`FabricLaw.lateral_stretch`: it does not
    depend on the moduli)."""
    law = OrthotropicSVK(1.0, 1.0, nu, 1.0) if orthotropic else NeoHookean(1.0, nu)
    return law.lateral_stretch(eps0)


def fabric_groups(mesh: FabricMesh, E: float | FabricLaw, nu: float | None = None,
                  t: float = 0.4, *, E_y: float | None = None, G: float | None = None,
                  direction: float = 0.0, bending_factor: float = 1.0) -> list[ElementGroup]:
    """Membrane (per triangle) and bending (per interior edge) groups of the fabric.

    ``E``: a :class:`~undulate.mechanics.material.FabricLaw`, or the scalars of
    :func:`~undulate.mechanics.material.fabric_law` (E, nu and, for an orthotropic knit,
    ``E_y`` and ``G``: E along the stretch, at ``direction`` degrees in the mesh's frame). The
    hinges' bending stiffness uses the law's bending modulus (sqrt(E E_y) for the knit),
    times ``bending_factor`` (a knit bends more easily than a continuum sheet)."""
    from ..mesh import stretch_rotation

    if isinstance(E, int | float):
        if nu is None:
            raise ValueError("fabric_groups: nu is needed with a modulus E")
        law = fabric_law(float(E), nu, E_y, G)
    else:
        law = E
    nu = law.nu
    X = mesh.X
    tri = mesh.tris
    D0 = X[tri[:, 1]] - X[tri[:, 0]]
    D1 = X[tri[:, 2]] - X[tri[:, 0]]
    Dm = np.stack([D0, D1], axis=2)  # (n, 2, 2) columns = edges
    det = Dm[:, 0, 0] * Dm[:, 1, 1] - Dm[:, 0, 1] * Dm[:, 1, 0]
    if np.any(det <= 0):
        raise ValueError("mesh: triangles must be counter-clockwise with positive area")
    membrane = law.membrane(tri, np.linalg.inv(Dm), 0.5 * det, t, stretch_rotation(direction))
    E_bend = law.bending_modulus
    hin = mesh.hinges()
    # areas of the two triangles at each hinge
    e_len2 = np.sum((X[hin[:, 1]] - X[hin[:, 0]]) ** 2, axis=1)
    a_a = 0.5 * np.abs(_cross2(X[hin[:, 1]] - X[hin[:, 0]], X[hin[:, 2]] - X[hin[:, 0]]))
    a_b = 0.5 * np.abs(_cross2(X[hin[:, 1]] - X[hin[:, 0]], X[hin[:, 3]] - X[hin[:, 0]]))
    D = bending_factor * E_bend * t**3 / (12.0 * (1.0 - nu**2))
    k = D * mesh.hinge_factor * e_len2 / (a_a + a_b)
    bending = ElementGroup("fabric_bending", hinge_bending, hin, (k,))
    return [membrane, bending]


def edge_tension_group(mesh: FabricMesh, T: float, direction: float = 0.0,
                       edges: tuple[str, ...] | list[str] = ("bottom", "top")
                       ) -> ElementGroup | None:
    """A pull of ``T`` [N per mm of unstretched edge] on the free edges across the stretch
    (``edges``, of "bottom" and "top"), outwards along the fabric's plane (a dead load: its
    direction does not follow the edge); None for T = 0 or no edge. Each edge node carries
    half of its two neighbouring segments."""
    if T == 0.0 or not edges:
        return None
    from ..mesh import stretch_rotation

    rot = stretch_rotation(direction)
    nodes, forces = [], []
    for name, sign in (("bottom", -1.0), ("top", 1.0)):
        if name not in edges:
            continue
        idx = mesh.node_sets[name]
        seg = np.linalg.norm(np.diff(mesh.X[idx], axis=0), axis=1)
        share = np.zeros(len(idx))
        share[:-1] += 0.5 * seg
        share[1:] += 0.5 * seg
        normal = rot @ np.array([0.0, sign])  # outwards, in the mesh's frame
        nodes.append(idx)
        forces.append(T * share[:, None] * np.r_[normal, 0.0][None, :])
    return ElementGroup("edge_tension", dead_load, np.concatenate(nodes)[:, None],
                        (np.concatenate(forces),))


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


_edge_len_v = CachedJit(jax.vmap(edge_length), "build.rod_edge_length_d")
_vertex_v = CachedJit(jax.vmap(vertex_strains), "build.rod_vertex_strains_d")
_node_v = CachedJit(jax.vmap(node_strains), "build.rod_node_strains")


def _per_rod(chains: list[RodChain], sec: RodSection | list[RodSection]) -> list[RodSection]:
    secs = [sec] * len(chains) if isinstance(sec, RodSection) else list(sec)
    if len(secs) != len(chains):
        raise ValueError(f"rod sections: {len(secs)} given for {len(chains)} rods")
    return secs


def _col(secs: list[RodSection], name: str) -> np.ndarray:
    return np.array([getattr(q, name) for q in secs], dtype=float)


def rod_groups(
    chains: list[RodChain], x_printed: np.ndarray, sec: RodSection | list[RodSection]
) -> list[ElementGroup]:
    """Stretch, bend/twist and footprint groups of all rods, stress-free at ``x_printed``.

    ``sec``: one section for every rod, or one per rod (a pattern's lines may differ in h
    and b); each element carries its rod's stiffnesses and offset.
    """
    secs = _per_rod(chains, sec)
    # gathers on the host: indexing a device array is a JAX operation of its own, compiled
    # (or loaded from the cache) for every new index shape, once per process
    xp = np.asarray(x_printed)
    stencils = [rod_stencils(ch) for ch in chains]
    # every rod node's frame is read by the edges and vertices around it: the Hessian is made
    # through the frames, once per node (undulate.mechanics.frames)
    layout = FrameLayout(np.concatenate(stencils), frame_point)
    start = np.cumsum([len(st) for st in stencils]) - np.array([len(st) for st in stencils])
    stretch, L0_rod = _stretch_group(stencils, secs, xp, layout, start)
    groups = [stretch]
    bend = _bend_twist_group(stencils, secs, xp, layout, start, L0_rod)
    if bend is not None:
        groups.append(bend)
    groups.append(_footprint_group(stencils, secs, xp, L0_rod))
    return groups


def _stretch_group(stencils: list[np.ndarray], secs: list[RodSection], xp: np.ndarray,
                   layout: FrameLayout, start: np.ndarray
                   ) -> tuple[ElementGroup, list[np.ndarray]]:
    """The rods' edges (stretch), and each rod's rest edge lengths."""
    e_idx = [np.concatenate([st[:-1], st[1:]], axis=1) for st in stencils]  # (m-1, 10) each
    e_sec = [sk for st, sk in zip(stencils, secs, strict=True) for _ in range(len(st) - 1)]
    e_all = np.concatenate(e_idx)
    d_e = _col(e_sec, "offset")
    # one kernel call for all rods (rods of different lengths would each compile their own)
    L0 = np.asarray(_edge_len_v(xp[e_all], d_e))
    L0_rod = np.split(L0, np.cumsum([len(e) for e in e_idx])[:-1])
    e_first = np.concatenate([s0 + np.arange(len(st) - 1)
                              for s0, st in zip(start, stencils, strict=True)])
    return ElementGroup("rod_stretch", rod_stretch, e_all, (d_e, L0, _col(e_sec, "EA")),
                        frames=FrameSlots(layout, e_first)), L0_rod


def _bend_twist_group(stencils: list[np.ndarray], secs: list[RodSection], xp: np.ndarray,
                      layout: FrameLayout, start: np.ndarray, L0_rod: list[np.ndarray]
                      ) -> ElementGroup | None:
    """The rods' inner vertices (bending and twist); None when no rod has one."""
    v_idx, v_sec, lv = [], [], []
    for st, sk, le in zip(stencils, secs, L0_rod, strict=True):
        m = st.shape[0]
        if m >= 3:
            v_idx.append(np.concatenate([st[:-2], st[1:-1], st[2:]], axis=1))  # (m-2, 15)
            v_sec += [sk] * (m - 2)
            lv.append(0.5 * (le[:-1] + le[1:]))  # Voronoi length: half the two rest edges
    if not v_idx:
        return None
    v_all = np.concatenate(v_idx)
    d_v = _col(v_sec, "offset")
    rest = np.asarray(_vertex_v(xp[v_all], d_v))
    slots = np.concatenate([s0 + np.arange(len(st) - 2)
                            for s0, st in zip(start, stencils, strict=True) if len(st) >= 3])
    return ElementGroup(
        "rod_bend_twist", rod_bend_twist, v_all,
        (d_v, rest, np.concatenate(lv), _col(v_sec, "EI_out"), _col(v_sec, "EI_in"),
         _col(v_sec, "GJ")),
        frames=FrameSlots(layout, slots))


def _footprint_group(stencils: list[np.ndarray], secs: list[RodSection], xp: np.ndarray,
                     L0_rod: list[np.ndarray]) -> ElementGroup:
    """The rods' nodes bonded to the fabric (each carries half its two edges' length)."""
    n_sec = [sk for st, sk in zip(stencils, secs, strict=True) for _ in range(st.shape[0])]
    ln = []
    for st, le in zip(stencils, L0_rod, strict=True):
        lnk = np.zeros(st.shape[0])  # length of rod each node carries (half edges)
        lnk[:-1] += 0.5 * le
        lnk[1:] += 0.5 * le
        ln.append(lnk)
    n_all = np.concatenate(stencils)
    rest_n = np.asarray(_node_v(xp[n_all]))
    lnn = np.concatenate(ln)
    E_B, nu_B, b, h = (_col(n_sec, k) for k in ("E_B", "nu_B", "b", "h"))
    G_B = E_B / (2.0 * (1.0 + nu_B))
    k = np.stack([E_B * b * h * lnn, G_B * b * h * lnn, E_B * h * lnn / b], axis=1)
    return ElementGroup("rod_footprint", rod_footprint, n_all, (rest_n, k))


def _centre_point(x5: jnp.ndarray, d: jnp.ndarray) -> jnp.ndarray:
    from .rod import centre

    return centre(x5, d)[0]


_centre_v = CachedJit(jax.vmap(_centre_point, in_axes=(0, None)), "build.rod_centre")


def rod_centrelines(chains: list[RodChain], x: np.ndarray,
                    sec: RodSection | list[RodSection]) -> list[np.ndarray]:
    """Rod centre lines (m, 3) at node positions ``x`` (offset along the fabric normal; one
    section for all rods or one per rod).

    One jitted kernel for every call (the offset is an argument, not a constant baked into a
    new function), so the release loop, which calls this at every step, never retraces.
    """
    xp = np.asarray(x)
    return [np.asarray(_centre_v(xp[rod_stencils(ch)], np.asarray(sk.offset, np.float64)))
            for ch, sk in zip(chains, _per_rod(chains, sec), strict=True)]


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
