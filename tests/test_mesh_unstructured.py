"""The unstructured, graded, rod-conforming mesh (mesh/unstructured.py, Triangle)."""

import numpy as np
import pytest

from undulate.mechanics.assemble import Assembly
from undulate.mechanics.build import fabric_groups, lateral_stretch
from undulate.mesh import RodLine, build_mesh, build_unstructured_mesh
from undulate.model import Case

EPS0, NU, B = 0.5, 0.3, 1.0
LY = lateral_stretch(EPS0, NU)
SCALE = np.array([1.0 + EPS0, LY])  # reference -> printed (homogeneous map)


def _case(**kw) -> Case:
    d: dict = {"fabric": {}, "rods": {}, "mesh": {}}
    for k, v in kw.items():
        sec, key = k.split("__")
        d[sec][key] = v
    return Case.model_validate(d)


def _mesh(c: Case, kind: str = "unstructured", segments=None, extent=None):
    m = c.mesh
    return build_mesh(
        c.segments() if segments is None else segments, c.rods.b,
        c.fabric_extent() if extent is None else extent, eps0=EPS0, lam_y=LY,
        dx_rod=m.dx_rod, dx_far=m.dx_far, dy_far=m.dy_far, grading=m.grading, kind=kind,
        h_far=m.h_far,
    )


def _angles(X: np.ndarray, T: np.ndarray) -> np.ndarray:
    """Smallest angle of each triangle [deg]."""
    out = []
    for i in range(3):
        u = X[T[:, (i + 1) % 3]] - X[T[:, i]]
        v = X[T[:, (i + 2) % 3]] - X[T[:, i]]
        c = np.sum(u * v, 1) / np.linalg.norm(u, axis=1) / np.linalg.norm(v, axis=1)
        out.append(np.degrees(np.arccos(np.clip(c, -1, 1))))
    return np.min(out, axis=0)


def _areas(X: np.ndarray, T: np.ndarray) -> np.ndarray:
    return 0.5 * ((X[T[:, 1], 0] - X[T[:, 0], 0]) * (X[T[:, 2], 1] - X[T[:, 0], 1])
                  - (X[T[:, 1], 1] - X[T[:, 0], 1]) * (X[T[:, 2], 0] - X[T[:, 0], 0]))


def _strip_mask(m) -> np.ndarray:
    """Triangles whose three nodes all belong to one rod footprint."""
    mask = np.zeros(len(m.tris), bool)
    for ch in m.rods:
        ids = np.zeros(m.n_nodes, bool)
        ids[np.concatenate([ch.p, ch.qm, ch.qp])] = True
        mask |= ids[m.tris].all(axis=1)
    return mask


def _edge_counts(T: np.ndarray) -> dict:
    e = np.sort(np.concatenate([T[:, [0, 1]], T[:, [1, 2]], T[:, [2, 0]]]), axis=1)
    keys, counts = np.unique(e, axis=0, return_counts=True)
    return {tuple(k): int(c) for k, c in zip(keys.tolist(), counts, strict=True)}


def _check_mesh(m, extent, *, min_angle=25.0):
    """CCW, quality outside the footprints, conforming, boundary only on the outer box."""
    X, T = m.X, m.tris
    assert np.all(_areas(X, T) > 0), "all triangles counter-clockwise"
    strip = _strip_mask(m)
    assert _angles(X, T[~strip]).min() >= min_angle
    # conforming: every edge has 1 or 2 triangles; edges with 1 lie on the outer rectangle
    cnt = _edge_counts(T)
    assert max(cnt.values()) == 2
    box = np.array(extent) / np.repeat(SCALE, 2)
    span = box[1] - box[0]
    for (a, b), c in cnt.items():
        if c == 1:
            on = [np.allclose(X[[a, b], 0], box[0]), np.allclose(X[[a, b], 0], box[1]),
                  np.allclose(X[[a, b], 1], box[2]), np.allclose(X[[a, b], 1], box[3])]
            assert any(on), f"free edge {a}-{b} inside the sheet: {X[[a, b]]}"
    # every footprint edge is a mesh edge shared by two triangles unless on its outline
    for ch in m.rods:
        for row in (ch.qm, ch.p, ch.qp):
            for a, b in zip(row[:-1], row[1:], strict=True):
                assert cnt[tuple(sorted((int(a), int(b))))] == 2
        for a, b in zip(ch.p, ch.qp, strict=True):
            assert tuple(sorted((int(a), int(b)))) in cnt
        for a, b in zip(ch.p, ch.qm, strict=True):
            assert tuple(sorted((int(a), int(b)))) in cnt
    # node sets: exactly the nodes on each edge, sorted
    tol = 1e-9 * span
    for name, axis, val, other in (("left", 0, box[0], 1), ("right", 0, box[1], 1),
                                   ("bottom", 1, box[2], 0), ("top", 1, box[3], 0)):
        want = np.nonzero(np.abs(X[:, axis] - val) <= tol)[0]
        got = m.node_sets[name]
        assert sorted(got.tolist()) == sorted(want.tolist())
        assert np.all(np.diff(X[got, other]) > 0)
    np.testing.assert_array_equal(m.left, m.node_sets["left"])
    np.testing.assert_array_equal(m.right, m.node_sets["right"])
    # all nodes are used by some triangle
    assert np.unique(T).size == m.n_nodes


def _check_rod(m, k: int, line: RodLine, dx_rod: float, b: float = B):
    ch = m.rods[k]
    n_int = int(np.ceil(line.length / dx_rod - 1e-9))
    assert ch.p.size == ch.qm.size == ch.qp.size == n_int + 1
    d = np.asarray(line.direction)
    nrm = np.array([-d[1], d[0]])
    P = m.X[ch.p] * SCALE  # printed, homogeneous map
    st = np.asarray(line.start) + np.linspace(0, line.length, n_int + 1)[:, None] * d
    np.testing.assert_allclose(P, st, atol=1e-9)
    np.testing.assert_allclose(m.X[ch.qp] * SCALE, st + b / 2 * nrm, atol=1e-9)
    np.testing.assert_allclose(m.X[ch.qm] * SCALE, st - b / 2 * nrm, atol=1e-9)


def test_single_rod_mesh_properties_and_same_rod_stations_as_structured():
    c = _case()
    m = _mesh(c)
    assert m.xs is None and m.ys is None and m.kind == "unstructured"
    _check_mesh(m, c.fabric_extent(), min_angle=25.0)
    line = RodLine((-50.0, 0.0), (1.0, 0.0), 100.0)
    _check_rod(m, 0, line, c.mesh.dx_rod)
    s = _mesh(c, "structured")
    for row in ("p", "qm", "qp"):
        np.testing.assert_allclose(m.X[getattr(m.rods[0], row)], s.X[getattr(s.rods[0], row)],
                                   atol=1e-12)
    # graded: small elements at the rod, large far away
    X, T = m.X, m.tris
    cen = X[T].mean(axis=1)
    h = np.sqrt(4 / np.sqrt(3) * _areas(X, T))  # side of the equilateral of the same area
    near = np.abs(cen[:, 1]) < 2.0
    far = np.abs(cen[:, 1]) > 15.0
    assert h[near].mean() < 1.2 and h[far].mean() > 4.0


def test_wide_sheet_has_far_fewer_nodes_than_structured():
    c = _case(fabric__margin_y=100.0)
    u, s = _mesh(c), _mesh(c, "structured")
    print(f"margin_y = 100 mm: structured {s.n_nodes} nodes, unstructured {u.n_nodes}")
    assert u.n_nodes < 0.5 * s.n_nodes
    _check_mesh(u, c.fabric_extent())


@pytest.mark.parametrize("deg", [30.0, 90.0, -45.0])
def test_rotated_rod(deg):
    a = np.radians(deg)
    d = (np.cos(a), np.sin(a))
    line = RodLine((-20 * d[0] + 3.0, -20 * d[1] - 2.0), d, 40.0)
    extent = (-50.0, 50.0, -45.0, 45.0)
    c = _case()
    m = _mesh(c, segments=[line], extent=extent)
    _check_mesh(m, extent)
    _check_rod(m, 0, line, 1.0)
    if deg == 30.0:  # footprint triangles: sheared by the map, still fine
        assert _angles(m.X, m.tris).min() > 20.0


def test_five_close_rods():
    c = _case(rods__N=5, rods__s=2.5, fabric__margin_y=40.0)
    m = _mesh(c)
    _check_mesh(m, c.fabric_extent())
    for k, (x0, y0, L) in enumerate(c.segments()):
        _check_rod(m, k, RodLine((x0, y0), (1.0, 0.0), L), c.mesh.dx_rod)
    # narrower gaps and a finer rod spacing still mesh
    c = _case(rods__N=6, rods__s=1.0, rods__L=40.0, mesh__dx_rod=0.5)
    m = _mesh(c)
    _check_mesh(m, c.fabric_extent())


def test_bad_rods_raise_a_clear_error():
    extent = (-60.0, 60.0, -30.0, 30.0)
    kw = dict(eps0=EPS0, lam_y=LY, dx_rod=1.0, h_far=8.0, grading=1.5)
    ok = RodLine((-40.0, 0.0), (1.0, 0.0), 80.0)
    cross = RodLine((0.0, -10.0), (0.0, 1.0), 20.0)
    with pytest.raises(ValueError, match=r"rod 0 .*and rod 1 .*overlap"):
        build_unstructured_mesh([ok, cross], B, extent, **kw)
    near = RodLine((-40.0, 0.8), (1.0, 0.0), 80.0)  # |dy| < b: footprints intersect
    with pytest.raises(ValueError, match="overlap"):
        build_unstructured_mesh([ok, near], B, extent, **kw)
    out = RodLine((-40.0, 0.0), (1.0, 0.0), 120.0)
    with pytest.raises(ValueError, match=r"rod 1 .*not strictly inside"):
        build_unstructured_mesh([ok.__class__((-40.0, 10.0), (1.0, 0.0), 80.0), out], B,
                                extent, **kw)
    edge = RodLine((-40.0, 29.7), (1.0, 0.0), 80.0)
    with pytest.raises(ValueError, match="rod 0"):
        build_unstructured_mesh([edge], B, extent, **kw)
    with pytest.raises(ValueError, match="direction"):
        RodLine((0.0, 0.0), (0.0, 0.0), 1.0)
    # the structured grid refuses rods that are not along +x
    with pytest.raises(ValueError, match="structured"):
        build_mesh([cross], B, extent, eps0=EPS0, lam_y=LY, dx_rod=1.0, dx_far=4.0,
                   dy_far=5.0, grading=1.5, kind="structured")


def _bending_ratio(m, deg: float, R: float = 300.0) -> float:
    """Discrete bending energy of a cylinder of axis at deg + 90 over (D/2) A / R^2."""
    E, nu, t = 0.45, 0.0, 0.4
    groups = [g for g in fabric_groups(m, E, nu, t) if g.name == "fabric_bending"]
    a = np.radians(deg)
    u = np.array([np.cos(a), np.sin(a)])
    w = np.array([-u[1], u[0]])
    s, r = m.X @ u, m.X @ w
    x = np.zeros((m.n_nodes, 3))
    x[:, :2] = (R * np.sin(s / R))[:, None] * u + r[:, None] * w
    x[:, 2] = R * (1 - np.cos(s / R))
    asm = Assembly(m.n_nodes, groups, np.ones((m.n_nodes, 3), bool))
    area = _areas(m.X, m.tris)
    D = E * t**3 / 12.0
    return asm.energy(x) / (0.5 * D * area.sum() / R**2)


@pytest.mark.parametrize("graded", [False, True])
def test_fabric_bending_cylinder_unstructured(graded):
    """(D/2) * integral kappa^2 dA for cylinders along x, y and at 45 degrees, within 15 %,
    on a uniform and a graded unstructured mesh, and at two resolutions."""
    ratios = {}
    for dx in (1.0, 0.5):
        # b = dx: the footprint's edges (and with them h_near) halve with dx
        c = _case(rods__L=40.0, rods__b=dx, fabric__margin_x=15.0, fabric__margin_y=25.0,
                  mesh__dx_rod=dx, mesh__h_far=12.0 if graded else dx,
                  mesh__grading=1.5 if graded else 1.0)
        m = _mesh(c)
        ratios[dx] = np.array([_bending_ratio(m, d) for d in (0.0, 90.0, 45.0, -45.0)])
        print(f"graded={graded} dx_rod={dx} nodes={m.n_nodes} ratios={ratios[dx].round(3)}")
        assert np.all(np.abs(ratios[dx] - 1.0) < 0.15)
    # refinement: halving dx_rod changes the energies by less than 10 %
    assert np.all(np.abs(ratios[0.5] / ratios[1.0] - 1.0) < 0.10)


def test_structured_mesh_keeps_its_factor_and_sets():
    c = _case()
    s = _mesh(c, "structured")
    assert s.hinge_factor == pytest.approx(0.57) and s.kind == "structured"
    np.testing.assert_array_equal(s.node_sets["left"], s.left)
    assert set(s.node_sets) == {"left", "right", "bottom", "top"}
    u = _mesh(c)
    assert u.hinge_factor != s.hinge_factor


def test_prepare_and_masses_on_unstructured_mesh():
    from undulate.solve.dynamics import lumped_masses
    from undulate.solve.release import prepare

    c = _case(mesh__kind="unstructured", fabric__margin_y=30.0)
    sim = prepare(c)
    assert sim.mesh.kind == "unstructured"
    area = _areas(sim.mesh.X, sim.mesh.tris).sum()
    xmin, xmax, ymin, ymax = c.fabric_extent()
    assert area == pytest.approx((xmax - xmin) * (ymax - ymin) / (SCALE[0] * SCALE[1]),
                                 rel=1e-12)
    f, r = c.fabric, c.rods
    m = lumped_masses(sim)
    # the rod carries rho_B b h per unit of its printed length (half a spacing at each end)
    assert m.sum() == pytest.approx(f.rho * f.t * area + r.rho_B * r.b * r.h * r.L, rel=1e-12)
