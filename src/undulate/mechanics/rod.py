"""Energies of a rod bonded on top of the fabric: a discrete elastic rod framed by the fabric.

Kinematics (the bond). The rod's nodes sit above fabric nodes: for rod node k, ``p`` is the
fabric node under the rod's centre line and ``qm``/``qp`` the fabric nodes under the two edges of
its footprint (at -b/2 and +b/2 across). The fabric normal there is

    n = normalize((p_b - p_a) x (qp - qm))     (p_a, p_b: the rod neighbours of p)

and the rod's centre line is offset along it by d = (t + h) / 2 (half the fabric plus half the
rod), X = p + d n. This offset is what makes rod + fabric a bilayer: bending the pair changes
the length of the fabric under the rod, which breaks the up/down symmetry.

Strains (discrete elastic rods, Bergou et al. 2008, with the material frame taken from the
fabric instead of a free twist angle, since the rod is glued across its width):

* stretch of each edge ``|e| / |e_rest| - 1``;
* at each interior node the curvature binormal ``kb = 2 T0 x T1 / (1 + T0.T1)``, projected on
  the width direction W (out-of-plane bending, stiffness E_B b h^3 / 12) and on the normal
  N = T x W (in-plane bending, E_B h b^3 / 12);
* twist: per edge, the sine of the rotation about the edge tangent between the width
  directions of its two nodes, stiffness G_B J (St Venant torsion constant of a b x h
  rectangle);
* footprint rigidity: the rod's cross-section does not deform, so the fabric under it keeps
  its printed width, stays perpendicular to the rod, and p stays at the middle of qm-qp.

Every strain is measured against its value at printing (stress-free printing); energies are
``0.5 * stiffness * (strain - strain_rest)^2 * length`` in N mm.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from .forms import StrainForm, StrainTerm


def _unit(v: jnp.ndarray) -> jnp.ndarray:
    return v / jnp.linalg.norm(v)


def frame_point(x5: jnp.ndarray) -> jnp.ndarray:
    """(p, n, w) (9,) of one rod node from its fabric points (p_a, p_b, p, qp, qm) (5, 3).

    p: fabric point under the centre line, n: unit fabric normal, w = qp - qm: footprint width
    vector. The rod centre is X = p + d n.
    """
    pa, pb, p, qp, qm = x5[0], x5[1], x5[2], x5[3], x5[4]
    w = qp - qm
    n = _unit(jnp.cross(pb - pa, w))
    return jnp.concatenate([p, n, w])


def centre(x5: jnp.ndarray, d: jnp.ndarray) -> tuple[jnp.ndarray, jnp.ndarray]:
    """Rod centre X = p + d n and footprint width vector w from (p_a, p_b, p, qp, qm)."""
    q = frame_point(x5)
    return q[0:3] + d * q[3:6], q[6:9]


def _edge_length_q(q: jnp.ndarray, d: jnp.ndarray) -> jnp.ndarray:
    X0 = q[0:3] + d * q[3:6]
    X1 = q[9:12] + d * q[12:15]
    return jnp.linalg.norm(X1 - X0)


def edge_length(x10: jnp.ndarray, d: jnp.ndarray) -> jnp.ndarray:
    """Length of the rod edge between two consecutive centre points (2 x 5 fabric points)."""
    return _edge_length_q(jnp.concatenate([frame_point(x10[:5]), frame_point(x10[5:])]), d)


def _bend_strains(e0: jnp.ndarray, e1: jnp.ndarray, u0: jnp.ndarray, u1: jnp.ndarray
                  ) -> jnp.ndarray:
    """(kappa_out, kappa_in) at a vertex from its edge vectors e0, e1 and the sums u0, u1 of the
    width vectors at each edge's ends."""
    T0 = _unit(e0)
    T1 = _unit(e1)
    W0 = _unit(u0 - jnp.dot(u0, T0) * T0)
    W1 = _unit(u1 - jnp.dot(u1, T1) * T1)
    N0 = jnp.cross(T0, W0)
    N1 = jnp.cross(T1, W1)
    kb = 2.0 * jnp.cross(T0, T1) / (1.0 + jnp.dot(T0, T1))
    return jnp.stack([0.5 * jnp.dot(kb, W0 + W1), 0.5 * jnp.dot(kb, N0 + N1)])


def _vertex_strains_q(q: jnp.ndarray, d: jnp.ndarray) -> jnp.ndarray:
    Xa, wa = q[0:3] + d * q[3:6], q[6:9]
    Xb, wb = q[9:12] + d * q[12:15], q[15:18]
    Xc, wc = q[18:21] + d * q[21:24], q[24:27]
    k = _bend_strains(Xb - Xa, Xc - Xb, wa + wb, wb + wc)
    # twist of each edge from the nodes' own width directions (not averaged: an average
    # would not see a zig-zag rotation of the cross-sections, a spurious zero-energy mode)
    ta = _edge_twist(wa, wb, _unit(Xb - Xa))
    tb = _edge_twist(wb, wc, _unit(Xc - Xb))
    return jnp.stack([k[0], k[1], ta, tb])


def _edge_twist(w0: jnp.ndarray, w1: jnp.ndarray, T: jnp.ndarray) -> jnp.ndarray:
    """Sine of the rotation about T from node director w0 to w1 (both projected normal to T)."""
    a = _unit(w0 - jnp.dot(w0, T) * T)
    b = _unit(w1 - jnp.dot(w1, T) * T)
    return jnp.dot(jnp.cross(a, b), T)


def vertex_strains(x15: jnp.ndarray, d: jnp.ndarray) -> jnp.ndarray:
    """(kappa_out, kappa_in, twist_a, twist_b) at the middle of three rod nodes (3 x 5 points).

    Energies use (strain - strain_at_printing)^2, so no sign convention is relied upon.
    """
    q = jnp.concatenate([frame_point(x15[0:5]), frame_point(x15[5:10]), frame_point(x15[10:15])])
    return _vertex_strains_q(q, d)


def node_strains(x5: jnp.ndarray) -> jnp.ndarray:
    """Footprint strains at one rod node: (width, shear, offset of p from the middle of qm-qp
    along the rod, across it and along the normal). The offset is measured in the node's own
    frame, so the footprint energy does not change when rod and fabric turn together (in the
    drawing's frame, the offset a mesh leaves at printing, ~1e-3 mm, made a free sample that
    rolls up carry a spurious moment)."""
    pa, pb, p, qp, qm = x5[0], x5[1], x5[2], x5[3], x5[4]
    w = qp - qm
    tvec = pb - pa
    width = jnp.linalg.norm(w)
    tlen = jnp.linalg.norm(tvec)
    shear = jnp.dot(w, tvec) / (width * tlen)
    mid = p - 0.5 * (qp + qm)
    t_hat = tvec / tlen
    n_hat = _unit(jnp.cross(tvec, w))
    b_hat = jnp.cross(n_hat, t_hat)
    local = jnp.stack([jnp.dot(mid, t_hat), jnp.dot(mid, b_hat), jnp.dot(mid, n_hat)])
    return jnp.concatenate([jnp.stack([width, shear]), local])


def _stretch_q(q: jnp.ndarray, d: jnp.ndarray, L0: jnp.ndarray, EA: jnp.ndarray) -> jnp.ndarray:
    eps = _edge_length_q(q, d) / L0 - 1.0
    return 0.5 * EA * eps**2 * L0


def rod_stretch(x10: jnp.ndarray, d: jnp.ndarray, L0: jnp.ndarray, EA: jnp.ndarray) -> jnp.ndarray:
    """Axial energy of one edge: 0.5 EA (|e| / L0 - 1)^2 L0."""
    q = jnp.concatenate([frame_point(x10[:5]), frame_point(x10[5:])])
    return _stretch_q(q, d, L0, EA)


def _bend_twist_q(q: jnp.ndarray, d: jnp.ndarray, rest: jnp.ndarray, lv: jnp.ndarray,
                  EI_out: jnp.ndarray, EI_in: jnp.ndarray, GJ: jnp.ndarray) -> jnp.ndarray:
    s = _vertex_strains_q(q, d) - rest
    # each edge's twist is shared by the two vertices at its ends: half weight here
    return 0.5 * (EI_out * s[0] ** 2 + EI_in * s[1] ** 2 + 0.5 * GJ * (s[2] ** 2 + s[3] ** 2)) / lv


def rod_bend_twist(x15: jnp.ndarray, d: jnp.ndarray, rest: jnp.ndarray, lv: jnp.ndarray,
                   EI_out: jnp.ndarray, EI_in: jnp.ndarray, GJ: jnp.ndarray) -> jnp.ndarray:
    """Bending (out of plane and in plane) and twist energy at one interior node."""
    q = jnp.concatenate([frame_point(x15[0:5]), frame_point(x15[5:10]), frame_point(x15[10:15])])
    return _bend_twist_q(q, d, rest, lv, EI_out, EI_in, GJ)


# Strain forms (energy = 0.5 sum k e^2 of strains through the per-node frame): the assembly
# builds the kernels by the chain rule (cheap to compile), and the Newton solver may carry the
# stresses k e of these stiff strains itself (mixed Newton, see undulate.solve.newton).
def _stretch_moduli(d, L0, EA):
    return jnp.reshape(EA * L0, (1,))


def _bend_twist_moduli(d, rest, lv, EI_out, EI_in, GJ):
    return jnp.stack([EI_out, EI_in, 0.5 * GJ, 0.5 * GJ]) / lv


# The strains as terms of few variables each (a StrainTerm: strains of a linear projection of
# the frame points q = (p, n, w) per node, X = p + d n): their second derivatives are then
# Hessians of 12 and 9 variables instead of 27 (see forms.StrainTerm).
def _select(n_nodes: int, node: int, part: int) -> np.ndarray:
    """(3, 9 n_nodes) matrix picking p (part 0), n (1) or w (2) of one node from q."""
    m = np.zeros((3, 9 * n_nodes))
    m[:, 9 * node + 3 * part : 9 * node + 3 * part + 3] = np.eye(3)
    return m


def _centre_maps(n_nodes: int) -> tuple[list[np.ndarray], list[np.ndarray], list[np.ndarray]]:
    """Per node: (P_p, P_n, P_w) with X = (P_p + d P_n) q and w = P_w q."""
    return ([_select(n_nodes, i, 0) for i in range(n_nodes)],
            [_select(n_nodes, i, 1) for i in range(n_nodes)],
            [_select(n_nodes, i, 2) for i in range(n_nodes)])


_P3, _N3, _W3 = _centre_maps(3)
_BEND_A = np.concatenate([_P3[1] - _P3[0], _P3[2] - _P3[1], _W3[0] + _W3[1], _W3[1] + _W3[2]])
_BEND_B = np.concatenate([_N3[1] - _N3[0], _N3[2] - _N3[1], 0 * _W3[0], 0 * _W3[0]])
_TWIST_A = [np.concatenate([_W3[i], _W3[i + 1], _P3[i + 1] - _P3[i]]) for i in (0, 1)]
_TWIST_B = [np.concatenate([0 * _W3[i], 0 * _W3[i], _N3[i + 1] - _N3[i]]) for i in (0, 1)]


def _bend_project(d, *_):
    """(e0, e1, u0, u1) = (X_b - X_a, X_c - X_b, w_a + w_b, w_b + w_c) from q."""
    return jnp.asarray(_BEND_A) + d * jnp.asarray(_BEND_B)


def _bend_term(z, d, rest, *_):
    return _bend_strains(z[0:3], z[3:6], z[6:9], z[9:12]) - rest[0:2]


def _twist_project(i: int):
    def project(d, *_):
        """(w_i, w_i+1, X_i+1 - X_i) of edge i from q."""
        return jnp.asarray(_TWIST_A[i]) + d * jnp.asarray(_TWIST_B[i])
    return project


def _twist_term(i: int):
    def strains(z, d, rest, *_):
        return jnp.reshape(_edge_twist(z[0:3], z[3:6], _unit(z[6:9])) - rest[2 + i], (1,))
    return strains


_P2, _N2, _ = _centre_maps(2)
_STRETCH_A = _P2[1] - _P2[0]
_STRETCH_B = _N2[1] - _N2[0]


def _stretch_project(d, *_):
    """The edge vector X_1 - X_0 from q."""
    return jnp.asarray(_STRETCH_A) + d * jnp.asarray(_STRETCH_B)


def _stretch_term(z, d, L0, EA):
    return jnp.reshape(jnp.linalg.norm(z) / L0 - 1.0, (1,))


rod_stretch.strain_form = StrainForm(  # type: ignore[attr-defined]
    frame_point, 2, None, _stretch_moduli, terms=(StrainTerm(_stretch_project, _stretch_term),))
rod_bend_twist.strain_form = StrainForm(  # type: ignore[attr-defined]
    frame_point, 3, None, _bend_twist_moduli,
    terms=(StrainTerm(_bend_project, _bend_term),
           StrainTerm(_twist_project(0), _twist_term(0)),
           StrainTerm(_twist_project(1), _twist_term(1))))


def rod_footprint(x5: jnp.ndarray, rest: jnp.ndarray, k: jnp.ndarray) -> jnp.ndarray:
    """Rigidity of the rod's cross-section over the fabric it is glued to (penalty form).

    ``k`` = (k_width [N mm], k_shear [N mm], k_mid [N/mm]); width strain is relative to rest.
    """
    s = node_strains(x5)
    ew = s[0] / rest[0] - 1.0
    gs = s[1] - rest[1]
    dm = s[2:] - rest[2:]
    return 0.5 * (k[0] * ew**2 + k[1] * gs**2 + k[2] * jnp.dot(dm, dm))


def torsion_constant(b: float, h: float) -> float:
    """St Venant torsion constant J [mm^4] of a b x h rectangle (Roark's series, 1 term)."""
    a_, c_ = max(b, h), min(b, h)
    r = c_ / a_
    return a_ * c_**3 * (1.0 / 3.0 - 0.21 * r * (1.0 - r**4 / 12.0))


def _footprint_resid(q, rest, k):
    s = node_strains(q.reshape(5, 3))
    return jnp.concatenate([jnp.stack([s[0] / rest[0] - 1.0, s[1] - rest[1]]), s[2:] - rest[2:]])


def _footprint_moduli(rest, k):
    return jnp.stack([k[0], k[1], k[2], k[2], k[2]])


rod_footprint.strain_form = StrainForm(  # type: ignore[attr-defined]
    lambda y: y.ravel(), 1, _footprint_resid, _footprint_moduli)
