"""3D models of a run (undulate export): rods as watertight b x h solids along their centre
lines, the fabric as the deformed surface, every format loaded back with trimesh."""

from __future__ import annotations

from pathlib import Path

import meshio
import numpy as np
import pytest
import trimesh
from error_cases import TINY
from typer.testing import CliRunner

from undulate.fabrication.model3d import FORMATS, export_run, rod_solid
from undulate.interfaces.cli import app

# the tiny case of the error tests, with two rods 4 mm apart
TWO_RODS = TINY.replace("[rods]\nL = 20.0\n", "[rods]\nL = 20.0\nN = 2\ns = 4.0\n")
assert "N = 2" in TWO_RODS


def test_rod_solid_is_a_closed_box_along_the_line() -> None:
    # a quarter circle of radius 10 in the x-z plane, thickness along the circle's normal
    s = np.linspace(0.0, 0.5 * np.pi, 40)
    c = np.c_[10 * np.sin(s), np.zeros_like(s), 10 * (1 - np.cos(s))]
    up = np.c_[-np.sin(s), np.zeros_like(s), np.cos(s)]
    b, h = 1.0, 0.3
    v, f = rod_solid(c, up, b, h)
    m = trimesh.Trimesh(v, f, process=False)
    assert m.is_watertight and m.is_winding_consistent and m.is_volume
    # volume of a bent box: b h times the length of its centre line (Pappus), to the chords
    length = np.sum(np.linalg.norm(np.diff(c, axis=0), axis=1))
    assert m.volume == pytest.approx(b * h * length, rel=1e-3)
    corners = v.reshape(-1, 4, 3)
    np.testing.assert_allclose(corners.mean(axis=1), c, atol=1e-12)
    # thickness h along up, width b across: the section's edges have these lengths
    np.testing.assert_allclose(np.linalg.norm(corners[:, 1] - corners[:, 0], axis=1), b)
    np.testing.assert_allclose(np.linalg.norm(corners[:, 2] - corners[:, 1], axis=1), h)
    np.testing.assert_allclose(np.sum((corners[:, 2] - corners[:, 1]) * up, axis=1), h, rtol=1e-4)


@pytest.fixture(scope="module")
def two_rod_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("run")
    (d / "two.toml").write_text(TWO_RODS)
    res = CliRunner().invoke(app, ["run", str(d / "two.toml"), "--out", str(d / "run")])
    assert res.exit_code == 0, res.output
    return d / "run"


def _load(path: Path) -> trimesh.Scene:
    kw = {"split_objects": True, "group_material": False} if path.suffix == ".obj" else {}
    scene = trimesh.load(path, force="scene", **kw)
    return scene


@pytest.mark.parametrize("fmt", FORMATS)
def test_export_loads_back_with_the_runs_geometry(two_rod_run: Path, tmp_path: Path,
                                                  fmt: str) -> None:
    out = tmp_path / f"model.{fmt}"
    res = CliRunner().invoke(app, ["export", str(two_rod_run), "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert f"wrote {out}" in res.stdout
    scene = _load(out)
    names = set(scene.geometry)
    assert names == {"fabric", "rod_0", "rod_1"}, names
    vtu = meshio.read(two_rod_run / "final.vtu")
    fabric_pts = vtu.points[vtu.point_data["is_rod"] == 0]
    tol = 1e-5 * np.abs(fabric_pts).max()  # ASCII formats keep 7-9 digits
    fabric = scene.geometry["fabric"]
    assert len(fabric.faces) == len(vtu.cells_dict["triangle"])
    if fmt != "stl":  # STL has no shared vertices
        assert len(fabric.vertices) == len(fabric_pts)
    np.testing.assert_allclose(fabric.bounds, [fabric_pts.min(0), fabric_pts.max(0)], atol=tol)
    with np.load(two_rod_run / "centerlines.npz") as z:
        cls = [z["rod0"], z["rod1"]]
    for k, c in enumerate(cls):
        rod = scene.geometry[f"rod_{k}"]
        assert len(rod.faces) == 8 * (len(c) - 1) + 4
        merged = rod.copy()
        merged.merge_vertices()
        assert merged.is_watertight and merged.is_volume, fmt
        # b = 1, h = 0.3 around the centre line: within 0.6 mm of it, reaching 0.5 mm aside
        assert merged.volume == pytest.approx(
            0.3 * np.sum(np.linalg.norm(np.diff(c, axis=0), axis=1)), rel=0.05)
        lo, hi = rod.bounds
        assert np.all(lo <= c.min(0) + tol) and np.all(hi >= c.max(0) - tol)
        assert np.all(lo >= c.min(0) - 0.6) and np.all(hi <= c.max(0) + 0.6)


def test_glb_fabric_is_double_sided_with_normals(two_rod_run: Path, tmp_path: Path) -> None:
    out = export_run(two_rod_run, tmp_path / "m.glb")
    fabric = trimesh.load(out, force="scene").geometry["fabric"]
    assert fabric.visual.material.doubleSided
    assert np.allclose(np.linalg.norm(fabric.vertex_normals, axis=1), 1.0)
