"""Drawings (SVG, DXF) of a case's lines, in the print frame and in the relaxed frame.

The **print frame** is where the lines are printed: the fabric stretched by ``1 + eps0``
along x, origin at its centre. The **relaxed frame** is where the same material points of the
fabric lie once it is unstretched and flat: under the uniform uniaxial pre-stretch (long
edges free), ``x / (1 + eps0)`` and ``y / lambda_y`` with ``lambda_y`` the fabric's own
lateral contraction (:func:`undulate.mechanics.build.lateral_stretch`). Near the clamps the
real pre-stretch is not uniform; the drawing does not model that.

Each line is drawn as its centre line (SVG: a polyline stroked b wide; DXF: an LWPOLYLINE
on layer ``LINES``) and its footprint outline (DXF layer ``FOOTPRINTS``). Units: mm.
"""

from __future__ import annotations

import re
from pathlib import Path
from xml.sax.saxutils import escape

import numpy as np

from .gcode import GcodeError, PrintLine, _offset

__all__ = ["relaxed_lines", "write_drawing", "relaxed_path"]

def relaxed_lines(lines: list[PrintLine], eps0: float, nu: float, *,
                  lam_y: float | None = None, direction: float = 0.0) -> list[PrintLine]:
    """The lines mapped to the relaxed fabric (uniform pre-stretch, see the module text).

    ``lam_y``: the printed sheet's stretch across the stretch (default: the neo-Hookean
    knit's free value for ``nu``; a case's own, orthotropic or framed, from
    :func:`undulate.solve.release.printed_lateral_stretch`); ``direction``: of the stretch,
    degrees from the drawing's x axis. A line's width is scaled by the stretch across it
    along its own normal (exactly for lines along the stretch, approximately for others)."""
    from ..mechanics.build import lateral_stretch
    from ..mesh import stretch_rotation

    ly = lateral_stretch(eps0, nu) if lam_y is None else lam_y
    rot = stretch_rotation(direction)  # stretch frame -> drawing frame
    inv = rot @ np.diag([1.0 / (1.0 + eps0), 1.0 / ly]) @ rot.T  # printed -> relaxed
    out = []
    for ln in lines:
        d = ln.points[-1] - ln.points[0]
        chord = float(np.hypot(*d))
        across = (float(np.linalg.norm(inv @ np.array([-d[1], d[0]]))) / chord
                  if chord > 1e-12 else 1.0 / ly)
        out.append(PrintLine(ln.index, ln.points @ inv.T, ln.h, ln.b * across, ln.name))
    return out


def relaxed_path(path: str | Path) -> Path:
    """Where the relaxed-frame drawing of ``path`` goes: ``NAME-relaxed.EXT``."""
    p = Path(path)
    return p.with_name(f"{p.stem}-relaxed{p.suffix}")


def _footprint(ln: PrintLine) -> np.ndarray:
    left = _offset(ln.points, ln.b / 2.0)
    right = _offset(ln.points, -ln.b / 2.0)
    return np.vstack([left, right[::-1], left[:1]])


def _svg(lines: list[PrintLine], title: str) -> str:
    pts = np.vstack([_footprint(ln) for ln in lines])
    pad = 5.0
    x0, y0 = pts.min(axis=0) - pad
    x1, y1 = pts.max(axis=0) + pad
    w, h = x1 - x0, y1 - y0
    out = ['<?xml version="1.0" encoding="UTF-8"?>',
           f'<svg xmlns="http://www.w3.org/2000/svg" width="{w:.3f}mm" height="{h:.3f}mm" '
           f'viewBox="0 0 {w:.3f} {h:.3f}">',
           f"<title>{escape(title)}</title>",
           '<g id="lines" fill="none" stroke="black" stroke-linecap="butt">']
    for ln in lines:
        # SVG's y grows downwards: flip so that the drawing reads like the case's (x, y)
        p = np.column_stack([ln.points[:, 0] - x0, y1 - ln.points[:, 1]])
        coords = " ".join(f"{a:.4f},{b:.4f}" for a, b in p)
        ident = re.sub(r"[^A-Za-z0-9_.-]", "_", ln.label)
        out.append(f'<polyline id="line-{ident}" points="{coords}" '
                   f'stroke-width="{ln.b:.4f}" data-h="{ln.h:g}" data-b="{ln.b:.4f}"/>')
    out += ["</g>", "</svg>", ""]
    return "\n".join(out)


def _dxf(lines: list[PrintLine], path: Path, title: str) -> None:
    import ezdxf

    doc = ezdxf.new("R2010", units=ezdxf.units.MM)
    doc.header["$INSUNITS"] = ezdxf.units.MM
    doc.layers.add("LINES", color=7)
    doc.layers.add("FOOTPRINTS", color=8)
    msp = doc.modelspace()
    for ln in lines:
        msp.add_lwpolyline([tuple(p) for p in ln.points], dxfattribs={"layer": "LINES"})
        msp.add_lwpolyline([tuple(p) for p in _footprint(ln)[:-1]], close=True,
                           dxfattribs={"layer": "FOOTPRINTS"})
    doc.header["$PROJECTNAME"] = title[:255]
    doc.saveas(path)


def write_drawing(lines: list[PrintLine], path: str | Path, *, eps0: float, nu: float,
                  name: str = "case", lam_y: float | None = None, direction: float = 0.0
                  ) -> list[Path]:
    """Write the print-frame drawing to ``path`` (.svg or .dxf) and the relaxed-frame one to
    :func:`relaxed_path` of it; return both paths."""
    p = Path(path)
    kind = p.suffix.lower()
    if kind not in (".svg", ".dxf"):
        raise GcodeError(f"--drawing {p}: must end in .svg or .dxf")
    written = []
    for frame, lns, target in (("print", lines, p),
                               ("relaxed", relaxed_lines(lines, eps0, nu, lam_y=lam_y,
                                                       direction=direction),
                                relaxed_path(p))):
        title = (f"{name}: lines in the {frame} frame ("
                 + ("fabric stretched by eps0 = " if frame == "print" else
                    "fabric relaxed from eps0 = ") + f"{eps0:g}), mm")
        if kind == ".svg":
            target.write_text(_svg(lns, title))
        else:
            _dxf(lns, target, title)
        written.append(target)
    return written

