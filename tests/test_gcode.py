"""G-code of a case's lines, parsed back: paths, extrusion, travel, bed (docs/fabrication.md)."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from undulate.fabrication import GcodeError, PrintSettings, lines_of_case, make_gcode
from undulate.fabrication.gcode import PrintLine
from undulate.interfaces.cli import app
from undulate.model import case_from_dict

WORD = re.compile(r"([GXYZEF])(-?\d+(?:\.\d*)?)")


def parse(text: str) -> list[dict]:
    """Moves of absolute G0/G1 code: from, to, z, filament fed, G0 or G1."""
    x = y = z = e = 0.0
    moves = []
    for raw in text.splitlines():
        code = raw.split(";", 1)[0].strip()
        if not re.match(r"G[01](\s|$)", code):  # G0/G1, not G10 (RepRapFirmware's tools)
            assert not code.startswith(("G91", "M83")), raw  # absolute only
            continue
        w = {k: float(v) for k, v in WORD.findall(code)}
        nx, ny, nz, ne = w.get("X", x), w.get("Y", y), w.get("Z", z), w.get("E", e)
        moves.append(dict(g=int(w["G"]), p0=(x, y), p1=(nx, ny), z=nz, de=ne - e))
        x, y, z, e = nx, ny, nz, ne
    return moves


def _seg_dist(p, a, b):
    a, b, p = np.asarray(a), np.asarray(b), np.asarray(p)
    t = np.clip(np.dot(p - a, b - a) / max(np.dot(b - a, b - a), 1e-300), 0, 1)
    return float(np.linalg.norm(p - (a + t * (b - a))))


CASE = {"rods": {"h": 0.3, "N": 5, "s": 5.0, "L": 60.0}, "release": {"eps0": 0.5}}


def _gcode(case_dict=CASE, **kw):
    # the simulated sheet (200 mm of fabric beside the rods) is wider than the 220 mm bed:
    # its frame holds it beyond the bed's edges
    kw.setdefault("overhang", True)
    case = case_from_dict(case_dict)
    lines = lines_of_case(case)
    text, plan = make_gcode(lines, PrintSettings(**kw), eps0=case.release.eps0,
                            fabric_t=case.fabric.t, fabric_extent=case.fabric_extent())
    return case, lines, text, plan


def test_printed_paths_equal_the_lines_layers_and_passes():
    case, lines, text, plan = _gcode()
    mv = parse(text)
    prints = [m for m in mv if m["g"] == 1 and m["p0"] != m["p1"]]
    assert all(m["de"] > 0 for m in prints)
    assert plan.layers == 1 and plan.layer_height == pytest.approx(0.3)  # 0.3 <= 0.75 x 0.4
    # b = 1 mm as two passes of 0.5 mm at y +- 0.25 of each line, shifted to the bed centre
    total = sum(math.dist(m["p0"], m["p1"]) for m in prints)
    assert total == pytest.approx(sum(ln.length for ln in lines) * 2 * plan.layers, rel=1e-6)
    for ln in lines:
        yc = ln.points[0, 1] + 110.0
        ys = sorted({round(m["p0"][1], 3) for m in prints if abs(m["p0"][1] - yc) < 0.6})
        assert ys == pytest.approx([yc - 0.25, yc + 0.25], abs=1e-3)
        xs = [c for m in prints if abs(m["p0"][1] - yc) < 0.6 for c in (m["p0"][0], m["p1"][0])]
        assert min(xs) == pytest.approx(ln.points[0, 0] + 110.0, abs=1e-3)
        assert max(xs) == pytest.approx(ln.points[-1, 0] + 110.0, abs=1e-3)
    # first layer a layer height above the fabric's top (t = 0.4 mm)
    assert {round(m["z"], 4) for m in prints} == {round(0.4 + 0.3, 4)}
    assert "stretched along X by eps0 = 0.5" in text.replace("STRETCHED", "stretched")


def test_extrusion_per_mm_is_width_times_layer_over_filament_area():
    _, _, text, plan = _gcode({**CASE, "rods": {**CASE["rods"], "h": 0.5}})
    assert plan.layers == 2 and plan.layer_height == pytest.approx(0.25)
    area = math.pi * 1.75**2 / 4
    for m in parse(text):
        if m["g"] == 1 and m["p0"] != m["p1"]:
            per_mm = m["de"] / math.dist(m["p0"], m["p1"])
            assert per_mm == pytest.approx(0.5 * 0.25 / area, rel=1e-3)  # one pass: b/2 wide


@pytest.mark.parametrize("case_dict", [
    CASE,
    {"rods": {"h": 0.3, "b": 1.0, "segments": [
        {"start": [-40.0, 0.0], "length": 30.0}, {"start": [5.0, 0.0], "length": 30.0},
        {"start": [-20.0, 6.0], "length": 50.0}, {"start": [-30.0, -6.0], "length": 20.0}]}},
])
def test_travel_never_crosses_a_printed_line_and_stays_on_the_bed(case_dict):
    case, lines, text, plan = _gcode(case_dict)
    mv = parse(text)
    segs = [(ln.points[0] + 110.0, ln.points[-1] + 110.0, ln.b) for ln in lines]
    travels = [m for m in mv if m["g"] == 0 and m["p0"] != m["p1"]][1:]  # not the first
    assert travels
    for m in travels:
        a, b = np.array(m["p0"]), np.array(m["p1"])
        for t in np.linspace(0, 1, 200):
            p = a + t * (b - a)
            for s0, s1, width in segs:
                d = _seg_dist(p, s0, s1)
                near_end = min(np.linalg.norm(p - a), np.linalg.norm(p - b)) <= width
                assert d > width / 2 or near_end, (m, p)
    for m in mv:
        for x, y in (m["p0"], m["p1"]):
            assert 0 <= x <= 220 and 0 <= y <= 220


def test_bad_prints_raise_one_clear_error():
    line = PrintLine(0, np.array([[0.0, 0.0], [10.0, 0.0]]), 0.3, 0.1)
    with pytest.raises(GcodeError, match="cannot be laid in passes"):
        make_gcode([line], eps0=0.5, fabric_t=0.4)
    thin = PrintLine(0, np.array([[0.0, 0.0], [10.0, 0.0]]), 0.02, 1.0)
    with pytest.raises(GcodeError, match="thinner than the thinnest layer"):
        make_gcode([thin], eps0=0.5, fabric_t=0.4)
    with pytest.raises(GcodeError, match=r"the print .* of the 50 x 50 mm bed"):
        _gcode(bed_x=50.0, bed_y=50.0)
    with pytest.raises(GcodeError, match="nozzle: must be a number > 0"):
        _gcode(nozzle=-1.0)


def test_cli_writes_gcode_and_preview(tmp_path: Path):
    case = tmp_path / "five.toml"
    case.write_text('[rods]\nh = 0.4\nN = 5\ns = 10.0\nL = 60.0\n')
    out, png = tmp_path / "five.gcode", tmp_path / "five.png"
    res = CliRunner().invoke(app, ["gcode", str(case), "--out", str(out), "--preview", str(png),
                                   "--overhang"])
    assert res.exit_code == 0, res.output
    assert parse(out.read_text()) and png.stat().st_size > 5000
    assert "Warning: the stretched fabric" in res.stderr
    bad = CliRunner().invoke(app, ["gcode", str(case), "--out", str(out), "--bed", "30x220",
                                   "--overhang"])
    assert bad.exit_code == 2 and "bed" in bad.stderr and "Traceback" not in bad.stderr
    # the preview goes beside the G-code unless told otherwise
    small = tmp_path / "small.toml"
    small.write_text('[rods]\nh = 0.4\nL = 60.0\n[fabric]\nmargin_y = 30.0\n')
    res = CliRunner().invoke(app, ["gcode", str(small), "--out", str(tmp_path / "s.gcode")])
    assert res.exit_code == 0, res.output
    assert (tmp_path / "s.png").stat().st_size > 5000
    res = CliRunner().invoke(app, ["gcode", str(small), "--out", str(tmp_path / "t.gcode"),
                                   "--no-preview"])
    assert res.exit_code == 0 and not (tmp_path / "t.png").exists()


def test_fabric_off_the_bed_says_how_far_unless_the_frame_overhangs():
    # five rods on the default sheet: 200 mm of fabric beside the outer rods
    case = case_from_dict(CASE)
    x0, x1, y0, y1 = case.fabric_extent()
    with pytest.raises(GcodeError) as err:
        _gcode(overhang=False)
    msg = str(err.value)
    assert f"{-(y0 + 110.0):.1f} mm past the front (Y 0) edge" in msg
    assert f"{y1 + 110.0 - 220.0:.1f} mm past the back (Y 220) edge" in msg
    assert "--overhang" in msg and "past the left" not in msg
    _, _, text, plan = _gcode(overhang=True)
    assert len(plan.warnings) == 1 and "; WARNING: the stretched fabric" in text
    # a bed that holds the whole fabric: no warning
    _, _, _, plan = _gcode(overhang=False, bed_x=x1 - x0 + 2, bed_y=y1 - y0 + 2)
    assert plan.warnings == []
    # lines off the bed stay an error with overhang
    with pytest.raises(GcodeError, match=r"the print .* reaches .* mm past the left"):
        _gcode(origin=(10.0, 110.0))


@pytest.mark.parametrize(("flavour", "start", "end"), [
    ("marlin", "M109 S210", "M104 S0"),
    ("klipper", "M109 S210", "TURN_OFF_HEATERS"),
    ("reprap", "G10 P0 S210 R210", "G10 P0 S0 R0"),
])
def test_flavours_change_only_the_start_and_end_blocks(flavour, start, end):
    _, _, text, _ = _gcode(flavour=flavour)
    _, _, marlin, _ = _gcode()
    assert start in text and end in text and f"firmware flavour: {flavour}" in text
    assert parse(text) == parse(marlin)
    with pytest.raises(GcodeError, match="flavour: must be one of marlin, klipper, reprap"):
        _gcode(flavour="prusa")


def test_drawings_in_the_print_and_relaxed_frames(tmp_path: Path):
    import xml.etree.ElementTree as ET

    import ezdxf

    from undulate.fabrication.drawing import write_drawing
    from undulate.mechanics.build import lateral_stretch

    case = case_from_dict(CASE)
    lines = lines_of_case(case)
    lam_y = lateral_stretch(0.5, case.fabric.nu)
    for ext in (".svg", ".dxf"):
        printed, relaxed = write_drawing(lines, tmp_path / f"lines{ext}", eps0=0.5,
                                         nu=case.fabric.nu)
        assert relaxed.name == f"lines-relaxed{ext}"
        for path, sx, sy in ((printed, 1.0, 1.0), (relaxed, 1 / 1.5, 1 / lam_y)):
            if ext == ".svg":
                ns = {"s": "http://www.w3.org/2000/svg"}
                polys = ET.parse(path).getroot().findall(".//s:polyline", ns)
                pts = [np.array([[float(v) for v in c.split(",")]
                                 for c in p.get("points").split()]) for p in polys]
                # SVG: shifted and y flipped; compare lengths and the gaps between lines
                assert [math.dist(*p) for p in pts] == pytest.approx(
                    [ln.length * sx for ln in lines], abs=2e-4)
                ys = sorted(p[0, 1] for p in pts)
                want = sorted(ln.points[0, 1] * sy for ln in lines)
                assert np.diff(ys) == pytest.approx(np.diff(want), abs=2e-4)  # 4 decimals
                assert float(polys[0].get("stroke-width")) == pytest.approx(1.0 * sy, abs=1e-4)
            else:
                msp = ezdxf.readfile(path).modelspace()
                got = sorted([tuple(np.round(np.array(e.get_points("xy")), 6).ravel())
                              for e in msp.query("LWPOLYLINE[layer=='LINES']")])
                want = sorted([tuple(np.round(ln.points * [sx, sy], 6).ravel())
                               for ln in lines])
                assert np.array(got) == pytest.approx(np.array(want))
                assert len(msp.query("LWPOLYLINE[layer=='FOOTPRINTS']")) == len(lines)


def test_gcode_from_an_svg_pattern(tmp_path) -> None:
    """`undulate gcode --pattern lines.svg`: the drawing's lines, curved ones included."""
    from typer.testing import CliRunner

    from undulate.interfaces.cli import app

    svg = tmp_path / "lines.svg"
    svg.write_text('<svg xmlns="http://www.w3.org/2000/svg" width="120mm" height="60mm" '
                   'viewBox="0 0 120 60"><line x1="10" y1="10" x2="110" y2="10"/>'
                   '<path d="M10 45 C 40 35, 80 55, 110 45"/></svg>')
    out = tmp_path / "lines.gcode"
    r = CliRunner().invoke(app, ["gcode", "--pattern", str(svg), "--h", "0.4", "--out",
                                 str(out)])
    assert r.exit_code == 0, r.output
    assert "2 line(s)" in r.output
    text = out.read_text()
    xy = [(float(w[1:]) for w in ln.split() if w[0] in "XY") for ln in text.splitlines()
          if ln.startswith("G1") and " E" in ln]
    assert len(xy) > 20  # the curve is printed as many short moves


def test_relaxed_drawing_follows_the_law_the_frame_and_the_direction() -> None:
    """The relaxed-frame lines undo the case's own pre-stretch: the orthotropic knit's lateral
    stretch, none across in a four-edge frame, and the stretch along a turned direction."""
    from undulate.fabrication import PrintLine
    from undulate.fabrication.drawing import relaxed_lines
    from undulate.mechanics.material import OrthotropicSVK
    from undulate.solve.release import printed_lateral_stretch

    line = [PrintLine(0, np.array([[-30.0, 5.0], [30.0, 5.0]]), 0.3, 1.0)]
    knit = case_from_dict({"fabric": {"E_y": 0.2, "G": 0.08, "nu": 0.3}})
    ly = printed_lateral_stretch(knit)
    assert ly == pytest.approx(OrthotropicSVK(0.45, 0.2, 0.3, 0.08).lateral_stretch(0.5))
    assert ly == pytest.approx(math.sqrt(1 - 0.3 * (1.5**2 - 1)))
    (r,) = relaxed_lines(line, 0.5, 0.3, lam_y=ly)
    assert r.points == pytest.approx(np.array([[-20.0, 5.0 / ly], [20.0, 5.0 / ly]]))
    assert r.b == pytest.approx(1.0 / ly)
    framed = case_from_dict({"release": {"clamps": ["left", "right", "bottom", "top"]}})
    assert printed_lateral_stretch(framed) == 1.0
    # stretch along y (direction 90): y shrinks by 1 + eps0, x by the lateral stretch
    (t,) = relaxed_lines(line, 0.5, 0.3, lam_y=0.8, direction=90.0)
    assert t.points == pytest.approx(np.array([[-37.5, 5.0 / 1.5], [37.5, 5.0 / 1.5]]))
    assert t.b == pytest.approx(1.0 / 1.5)  # the line runs across the stretch
