"""Line patterns: SVG and DXF import (units, curves, flips) and the checks' clear errors."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from undulate.model.pattern import (
    PatternError,
    check_lines,
    line_from_points,
    read_dxf,
    read_pattern,
    read_svg,
)
from undulate.theory.lines import eps_along, predict_lines


def test_svg_units_curves_and_transforms(tmp_path: Path) -> None:
    svg = ('<svg xmlns="http://www.w3.org/2000/svg" width="10cm" height="5cm" '
           'viewBox="0 0 200 100">'  # 2 user units per mm
           '<line id="a" x1="0" y1="0" x2="100" y2="0"/>'
           '<path id="arc" d="M 0 60 A 50 50 0 0 1 100 60"/>'
           '<g transform="rotate(90 150 50)"><polyline id="p" points="100,50 200,50"/></g>'
           '</svg>')
    f = tmp_path / "p.svg"
    f.write_text(svg)
    lines = read_pattern(f)
    by = {ln.id: ln for ln in lines}
    assert by["a"].length == pytest.approx(50.0, rel=1e-6)
    assert by["a"].is_straight() and by["a"].angle_deg == pytest.approx(0.0)
    # half circle of radius 25 mm, sampled every 0.5 mm or finer
    assert by["arc"].length == pytest.approx(np.pi * 25.0, rel=2e-3)
    assert len(by["arc"].points) >= 150 and not by["arc"].is_straight()
    assert by["p"].length == pytest.approx(50.0, rel=1e-6)
    assert abs(by["p"].angle_deg) == pytest.approx(90.0)
    # y up: the arc bulges to -y in SVG coordinates, i.e. up on the fabric
    arc = by["arc"].points
    assert arc[:, 1].max() > arc[0, 1] + 20.0
    # centred on the bounding box
    allp = np.vstack([ln.points for ln in lines])
    assert np.allclose(allp.min(axis=0) + allp.max(axis=0), 0.0, atol=1e-9)
    assert read_svg(svg, scale=2.0)[0].length == pytest.approx(100.0, rel=1e-6)


@pytest.mark.parametrize(("svg", "needle"), [
    ('<circle id="c" cx="5" cy="5" r="2"/>', "line c: a closed circle"),
    ('<path id="z" d="M0 0 L 10 0 L 10 10 Z"/>', "line z: a closed path"),
    ('<text x="0" y="0">hi</text>', "a text element is not a line"),
    ('<line x1="0" y1="0" x2="9" y2="0"/><text id="t" x="0" y="0">hi</text>',
     "a text element 't' is not a line"),
    ('<g/>', "holds no lines"),
])
def test_svg_refusals(svg: str, needle: str) -> None:
    with pytest.raises(PatternError, match=needle):
        read_svg(f'<svg xmlns="http://www.w3.org/2000/svg">{svg}</svg>')


def test_dxf_lines_arcs_and_units(tmp_path: Path) -> None:
    import ezdxf

    doc = ezdxf.new()
    doc.header["$INSUNITS"] = 5  # cm
    msp = doc.modelspace()
    msp.add_line((0, 0), (10, 0))
    msp.add_lwpolyline([(0, 2), (5, 2), (10, 3)])
    msp.add_arc((5, 10), radius=2, start_angle=0, end_angle=180)
    msp.add_spline(fit_points=[(0, 20), (5, 22), (10, 20)])
    path = tmp_path / "p.dxf"
    doc.saveas(path)
    lines = read_dxf(path)
    assert len(lines) == 4
    # the spline through (0, 20), (5, 22), (10, 20) cm: a bow 20 mm high over its 100 mm
    # chord (a parabola through those points would be 110.3 mm long)
    assert 105.0 < lines[3].length < 112.0
    assert np.ptp(lines[3].points[:, 1]) == pytest.approx(20.0, rel=0.05)
    assert [round(ln.length, 3) for ln in lines[:1]] == [100.0]
    assert lines[1].length == pytest.approx(50.0 + np.hypot(50.0, 10.0), rel=1e-9)
    assert lines[2].length == pytest.approx(np.pi * 20.0, rel=2e-3)
    closed = ezdxf.new()
    closed.modelspace().add_lwpolyline([(0, 0), (1, 0), (1, 1)], close=True)
    closed.saveas(tmp_path / "c.dxf")
    with pytest.raises(PatternError, match="closed lwpolyline"):
        read_dxf(tmp_path / "c.dxf")
    texted = ezdxf.new()
    texted.modelspace().add_line((0, 0), (10, 0))
    texted.modelspace().add_text("label", dxfattribs={"layer": "NOTES"})
    texted.saveas(tmp_path / "t.dxf")
    with pytest.raises(PatternError, match=r"dxf: a TEXT entity \(TEXT#\w+, layer NOTES\) is "
                       "not a line"):
        read_dxf(tmp_path / "t.dxf")
    with pytest.raises(PatternError, match="unknown kind .png"):
        read_pattern(tmp_path / "x.png")


def test_checks_name_the_lines_and_the_point() -> None:
    a = line_from_points([[-10, 0], [10, 0]], 0)
    zig = line_from_points([[0, 5], [10, 5], [10, 10], [5, 10], [5, 0]], 1)
    with pytest.raises(PatternError, match=r"line 1: crosses itself at \(5, 5\)"):
        check_lines([zig])
    near = line_from_points([[-10, 3], [10, 3]], 1)
    check_lines([a, near], b=1.0)
    with pytest.raises(PatternError, match="below the minimum gap 5 mm"):
        check_lines([a, near], b=1.0, min_gap=5.0)
    with pytest.raises(PatternError, match="line 0: leaves the fabric"):
        check_lines([a], bounds=(-5, 5, -5, 5))
    bend = line_from_points([[0, 0], [1, 1], [2, 0]], 0)
    with pytest.raises(PatternError, match="radius of 1 mm"):
        check_lines([bend], min_radius=3.0)
    with pytest.raises(PatternError, match="line 7: points must be"):
        line_from_points([[0, 0]], 7)
    with pytest.raises(PatternError, match="ids must be unique"):
        check_lines([a, line_from_points([[0, 9], [1, 9]], 5, id="0")])


def test_pre_stretch_along_inclined_lines() -> None:
    assert eps_along(0.0, 0.5, 0.3) == pytest.approx(0.5)
    assert eps_along(90.0, 0.5, 0.3) == pytest.approx(1.5**-0.3 - 1.0)
    e45 = eps_along(45.0, 0.5, 0.3)
    assert eps_along(90.0, 0.5, 0.3) < 0 < e45 < 0.5
    # monotone from along to across the stretch
    es = [eps_along(t, 0.5, 0.3) for t in range(0, 91, 5)]
    assert all(x > y for x, y in zip(es, es[1:], strict=False))


def test_predict_lines_groups_by_relaxation_distance() -> None:
    from undulate import theory as T

    sh = float(T.s_hat(0.3, 0.5))
    ys = [0.0, 1.0 + 0.5 * sh, 2.0 + 2.0 * sh + 0.5 * sh]  # gaps 0.5 s_hat, then 2 s_hat
    lines = [line_from_points([[-50, y], [50, y]], k) for k, y in enumerate(ys)]
    out = predict_lines(lines, h=0.3, eps0=0.5)
    assert [g["N"] for g in out["groups"]] in ([2, 1], [1, 2])
    fams = {ln["id"]: ln["family"] for ln in out["lines"]}
    assert fams["0"] == fams["1"] == "coherent" and fams["2"] == "waves"


def test_toml_splines_and_arrays() -> None:
    """A spline passes through its points, sampled no coarser than the resolution; an array
    lays parallel lines at the given (graded) spacing across its direction."""
    from undulate.model import case_from_dict

    through = [[-30.0, 0.0], [-10.0, 8.0], [10.0, -8.0], [30.0, 0.0]]
    case = case_from_dict({"pattern": {"resolution": 0.4, "lines": [
        {"id": "s", "spline": through}], "arrays": [
        {"id": "f", "centre": [0.0, 30.0], "angle": 90.0, "length": [20.0, 30.0, 40.0],
         "gaps": [3.0, 7.0]},
        {"centre": [0.0, -40.0], "length": 50.0, "count": 3, "spacing": 4.0}]}})
    s, *fam = case.rod_paths()
    steps = np.linalg.norm(np.diff(s.points, axis=0), axis=1)
    assert steps.max() <= 0.4 and steps.min() > 0.25
    for p in through:  # the curve keeps every given point
        assert np.min(np.linalg.norm(s.points - p, axis=1)) < 1e-9
    assert [p.id for p in fam] == ["f0", "f1", "f2", "f1.0", "f1.1", "f1.2"]
    # angle 90: lines along +y, laid out to their left (-x) at 0, 3 and 10 mm
    assert [p.points[0, 0] for p in fam[:3]] == pytest.approx([0.0, -3.0, -10.0])
    assert [p.length for p in fam[:3]] == pytest.approx([20.0, 30.0, 40.0])
    assert [p.points[:, 1].mean() for p in fam[:3]] == pytest.approx([30.0] * 3)
    assert [p.points[0, 1] for p in fam[3:]] == pytest.approx([-40.0, -36.0, -32.0])


def test_every_toml_example_of_the_patterns_doc_is_a_valid_case() -> None:
    """The TOML blocks of docs/patterns.md, each on its own, pass the case checks."""
    import re
    import textwrap
    import tomllib

    from undulate.model import case_from_dict

    doc = (Path(__file__).resolve().parents[1] / "docs" / "patterns.md").read_text()
    blocks = re.findall(r"```toml\n(.*?)```", doc, flags=re.S)
    assert len(blocks) >= 4
    for block in blocks:
        case_from_dict(tomllib.loads(textwrap.dedent(block)))


def test_cases_saved_before_the_arrays_rename_still_load() -> None:
    """Cases written before [[pattern.families]] became [[pattern.arrays]] hold an empty
    "families" list (metrics.json, study records): they load; a non-empty one is refused with
    the new name (docs/errors.md)."""
    from undulate.model import ConfigError, case_from_dict

    line = {"id": "a", "points": [[0.0, 0.0], [30.0, 0.0]]}
    case = case_from_dict({"pattern": {"lines": [line], "families": []}})
    assert [p.id for p in case.rod_paths()] == ["a"]
    with pytest.raises(ConfigError, match=r"pattern.families: renamed arrays"):
        case_from_dict({"pattern": {"lines": [line],
                                    "families": [{"length": 20.0, "count": 1}]}})
