"""Patterns in a simulation: lines of any direction and shape, from TOML or a drawing.

Case validation (one clear line naming the line), the mesh of curved rods, per-line sections,
and real runs: an arc buckles and is measured along itself; a straight line turned together
with the stretch gives the same waves (slow).
"""

from __future__ import annotations

import copy
import json
import math
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from undulate.interfaces.cli import app
from undulate.mechanics.build import RodSection, rod_groups
from undulate.mesh import RodPath, build_unstructured_mesh
from undulate.model import ConfigError, case_from_dict, load_case, with_drawing

SMALL = {"fabric": {"margin_x": 12.0, "margin_y": 12.0}, "release": {"steps": 8},
         "mesh": {"dx_rod": 1.5, "h_far": 8.0}}


def _case(lines: list[dict], **pattern) -> dict:
    d = copy.deepcopy(SMALL)
    d["pattern"] = {"lines": lines, **pattern}
    return d


ARC = {"id": "arc", "arc": {"centre": [0.0, -40.0], "radius": 50.0, "start": 70.0,
                            "end": 110.0}}


@pytest.mark.parametrize(("lines", "extra", "needle"), [
    ([{"id": "a", "points": [[-10, 0], [10, 0]]}, {"id": "b", "points": [[0, -5], [0, 5]]}],
     {}, r"^pattern: lines a and b: cross at \(0, 0\) mm"),
    ([{"id": "a", "points": [[-10, 0], [10, 0]]}, {"id": "b", "points": [[-10, 0.8], [10, 0.8]]}],
     {}, r"lines a and b: touch \(their footprints overlap\)"),
    ([{"id": "a", "points": [[-10, 0], [10, 0]]}, {"id": "b", "points": [[-10, 2], [10, 2]]}],
     {"min_gap": 2.0}, "lines a and b: 1 mm apart edge to edge .* below the minimum gap 2 mm"),
    ([{"id": "z", "points": [[0, 0], [10, 0], [10, 10], [5, -5]]}], {}, "line z: crosses itself"),
    ([{"id": "d", "points": [[1, 1], [1, 1]]}], {}, "line d: has zero length"),
    ([{"id": "v", "points": [[-10, 0], [0, 10], [10, 0]]}], {},
     "line v: bends with a radius of .* below the smallest its rod can follow"),
    ([{"id": "s", "points": [[0, 0], [2, 0]]}], {}, "line s: 2 mm long, shorter than 2 x "
     "mesh.dx_rod"),
    ([{"id": "both", "points": [[0, 0], [9, 0]], "arc": ARC["arc"]}], {},
     "give exactly one of points"),
    ([{"id": "full", "arc": {"centre": [0, 0], "radius": 5, "start": 0, "end": 360}}], {},
     "must differ from start by more than 0 and less than 360"),
    ([], {}, "pattern: holds no lines"),
])
def test_bad_patterns_name_the_line(lines, extra, needle) -> None:
    with pytest.raises(ConfigError, match=needle) as err:
        case_from_dict(_case(lines, **extra))
    assert "\n" not in str(err.value)


def test_pattern_excludes_rod_geometry_and_the_structured_mesh() -> None:
    d = _case([ARC])
    with pytest.raises(ConfigError, match=r"pattern: rods.N cannot be given together"):
        case_from_dict({**d, "rods": {"N": 3}})
    with pytest.raises(ConfigError, match="needs kind = 'unstructured'"):
        case_from_dict({**d, "mesh": {"kind": "structured"}})
    with pytest.raises(ConfigError, match="release.direction other than 0"):
        case_from_dict({"release": {"direction": 30.0}, "mesh": {"kind": "structured"}})


def test_pattern_geometry_per_line_sections_and_extent() -> None:
    c = case_from_dict(_case([ARC, {"id": "d", "points": [[-20, -10], [20, 0]], "h": 0.2,
                                    "b": 2.0}]))
    arc, d = c.rod_paths()
    assert (arc.id, arc.h, arc.b, arc.straight) == ("arc", 0.3, 1.0, False)
    assert arc.length == pytest.approx(50.0 * math.radians(40.0), rel=1e-3)
    assert (d.h, d.b, d.straight) == (0.2, 2.0, True)
    xmin, xmax, ymin, ymax = c.fabric_extent()
    assert ymax == pytest.approx(10.0 + 0.5 + 12.0, abs=0.01)  # top of the arc + b/2 + margin
    assert ymin == pytest.approx(-10.0 - 1.0 - 12.0, abs=1e-9)
    assert xmax == -xmin == pytest.approx(20.0 + 1.0 + 12.0, abs=1e-6)
    # the stretch turned: the box is the lines' box in the stretch frame
    c2 = case_from_dict({**_case([{"points": [[0, -20], [0, 20]]}]),
                         "release": {"direction": 90.0}})
    assert c2.fabric_extent()[1] == pytest.approx(20.0 + 0.5 + 12.0)


def test_case_file_reads_a_drawing_relative_to_itself(tmp_path: Path) -> None:
    (tmp_path / "lines.svg").write_text(
        '<svg xmlns="http://www.w3.org/2000/svg" width="100mm" height="50mm" '
        'viewBox="0 0 100 50"><line id="top" x1="10" y1="10" x2="70" y2="10"/>'
        '<polyline id="low" points="10,40 40,39.9 70,40"/></svg>')
    (tmp_path / "case.toml").write_text('[pattern]\nfile = "lines.svg"\nscale = 0.5\n'
                                        '[rods]\nh = 0.2\n')
    c = load_case(tmp_path / "case.toml")
    ids = [p.id for p in c.rod_paths()]
    assert ids == ["top", "low"]
    assert c.rod_paths()[0].length == pytest.approx(30.0)
    with pytest.raises(ConfigError, match=r"^bad.svg: svg: a text element"):
        (tmp_path / "bad.svg").write_text(
            '<svg xmlns="http://www.w3.org/2000/svg"><line x1="0" y1="0" x2="50" y2="0"/>'
            '<text>x</text></svg>')
        with_drawing({}, tmp_path / "bad.svg")
    (tmp_path / "scale.toml").write_text("[pattern]\nscale = 2.0\n")
    with pytest.raises(ConfigError, match="pattern.scale: only with pattern.file"):
        load_case(tmp_path / "scale.toml")


def test_curved_rods_mesh_as_curved_strips_of_their_own_width() -> None:
    th = np.linspace(0.2 * np.pi, 0.8 * np.pi, 90)
    arc = RodPath(np.c_[40 * np.cos(th), 40 * np.sin(th) - 30], b=1.5, id="arc")
    diag = RodPath(np.array([[-30.0, -40.0], [30.0, -20.0]]), id="diag")
    m = build_unstructured_mesh([arc, diag], 1.0, (-80, 80, -80, 80), eps0=0.5, lam_y=0.85,
                                dx_rod=1.0, h_far=20.0, grading=1.3)
    X = m.X
    a, b = X[m.tris[:, 1]] - X[m.tris[:, 0]], X[m.tris[:, 2]] - X[m.tris[:, 0]]
    assert np.all(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0] > 0)
    printed = X * np.array([1.5, 0.85])  # the homogeneous map back to the print frame
    for rod, width in zip(m.rods, (1.5, 1.0), strict=True):
        p, qp, qm = printed[rod.p], printed[rod.qp], printed[rod.qm]
        assert np.allclose(np.linalg.norm(qp - qm, axis=1), width)
        assert np.allclose(0.5 * (qp + qm), p, atol=1e-9)
        step = np.linalg.norm(np.diff(p, axis=0), axis=1)
        assert step.max() <= 1.0 + 1e-9 and step.max() - step.min() < 0.01
    # centre nodes on the arc, side rows across it (radius +- b/2)
    r = np.linalg.norm(printed[m.rods[0].qp] - [0.0, -30.0], axis=1)
    assert np.allclose(r, 39.25, atol=3e-3)  # +normal of a counter-clockwise arc: inwards
    near = RodPath(np.array([[-30.0, 10.2], [30.0, 10.2]]))
    with pytest.raises(ValueError, match="rod arc .* overlap or touch"):
        build_unstructured_mesh([arc, near], 1.0, (-80, 80, -80, 80), eps0=0.5, lam_y=0.85,
                                dx_rod=1.0, h_far=20.0, grading=1.3)


def test_rod_groups_take_one_section_per_rod() -> None:
    c = case_from_dict(_case([{"points": [[-20, 0], [20, 0]]}, {"points": [[-20, 6], [20, 6]]}]))
    from undulate.solve.release import prepare

    sim = prepare(c)
    x = np.c_[sim.mesh.X * [1.5, 1.0], np.zeros(sim.mesh.n_nodes)]
    s1 = RodSection(h=0.3, b=1.0, E_B=3000.0, nu_B=0.35, t=0.4)
    s2 = RodSection(h=0.6, b=1.0, E_B=3000.0, nu_B=0.35, t=0.4)
    same = rod_groups(sim.mesh.rods, x, s1)
    listed = rod_groups(sim.mesh.rods, x, [s1, s1])
    for g, h in zip(same, listed, strict=True):
        for p, q in zip(g.params, h.params, strict=True):
            assert np.array_equal(p, q)
    mixed = rod_groups(sim.mesh.rods, x, [s1, s2])
    ea = mixed[0].params[2]
    half = len(ea) // 2
    assert np.allclose(ea[:half], s1.EA) and np.allclose(ea[half:], s2.EA)
    with pytest.raises(ValueError, match="2 given for"):
        rod_groups(sim.mesh.rods[:1], x, [s1, s2])


def test_run_a_drawing_from_the_command_line(tmp_path: Path) -> None:
    """`undulate run case.toml --pattern lines.svg`: an arc and a short line, measured per
    line (the arc along its own arc length), top and 3D views written; a bad drawing is one
    line, no traceback."""
    (tmp_path / "lines.svg").write_text(
        '<svg xmlns="http://www.w3.org/2000/svg" width="60mm" height="40mm" '
        'viewBox="0 0 60 40"><path id="arc" d="M 5 25 A 40 40 0 0 1 55 25"/>'
        '<line id="flat" x1="10" y1="38" x2="50" y2="38"/></svg>')
    (tmp_path / "case.toml").write_text(
        '[rods]\nh = 0.2\n[fabric]\nmargin_x = 12.0\nmargin_y = 12.0\n[release]\nsteps = 8\n'
        '[mesh]\ndx_rod = 1.5\nh_far = 8.0\n')
    out = tmp_path / "out"
    res = CliRunner().invoke(app, ["run", str(tmp_path / "case.toml"), "--pattern",
                                   str(tmp_path / "lines.svg"), "--out", str(out)])
    assert res.exit_code == 0, res.output
    m = json.loads((out / "metrics.json").read_text())
    rods = {r["id"]: r for r in m["rods"]}
    assert set(rods) == {"arc", "flat"}
    arc = rods["arc"]
    assert arc["straight"] is False and arc["n"] >= 1 and arc["quality"] == "ok"
    # measured along the arc: its measured length is the arc's, not its chord (50 mm)
    assert arc["L_measured"] == pytest.approx(arc["length"], rel=0.05)
    assert arc["L_measured"] > 52.0
    for name in ("top_view.png", "view_3d.png", "rod_0_side.png"):
        assert (out / name).stat().st_size > 10_000
    (tmp_path / "bad.svg").write_text(
        '<svg xmlns="http://www.w3.org/2000/svg"><line id="a" x1="0" y1="0" x2="50" y2="0"/>'
        '<line id="b" x1="25" y1="-10" x2="25" y2="10"/></svg>')
    res = CliRunner().invoke(app, ["run", "--pattern", str(tmp_path / "bad.svg"), "--out",
                                   str(tmp_path / "bad")])
    assert res.exit_code == 2
    assert "lines a and b: cross at" in res.output and "Traceback" not in res.output
    res = CliRunner().invoke(app, ["run", "--out", str(tmp_path / "none")])
    assert res.exit_code == 2 and "give a case file (TOML), a drawing (--pattern), or both" in (
        res.output)


@pytest.mark.slow
def test_a_line_turned_with_the_stretch_gives_the_same_waves() -> None:
    """A straight line at 0, 30 and -60 degrees, the stretch along it: the meshes differ
    (Triangle meshes the turned sheet), the physics must not: same n, l within 2 %."""
    from undulate import api

    out = {}
    for th in (0.0, 30.0, -60.0):
        c, s = math.cos(math.radians(th)), math.sin(math.radians(th))
        d = _case([{"points": [[-20 * c, -20 * s], [20 * c, 20 * s]]}])
        d["rods"] = {"h": 0.12}
        d["fabric"] = {"margin_x": 15.0, "margin_y": 15.0}
        d["mesh"]["dx_rod"] = 1.0
        d["release"] = {"steps": 10, "direction": th}
        out[th] = api.run_case(case_from_dict(d), None, artifacts=False)
    assert out[0.0]["n"] >= 3
    for th in (30.0, -60.0):
        assert out[th]["n"] == out[0.0]["n"]
        assert out[th]["l_mean"] == pytest.approx(out[0.0]["l_mean"], rel=0.02)
