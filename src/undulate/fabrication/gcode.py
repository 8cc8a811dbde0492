"""G-code that prints a case's lines on the fabric, clamped stretched on the printer's bed.

The lines are drawn where the case prints them: in the stretched configuration (the fabric
pulled to 1 + eps0 times its length along x), origin at the fabric's centre, placed at
``PrintSettings.origin`` on the bed (default: the bed's centre). Each line of thickness h and
width b is printed as ``layers`` layers of height ``h / layers`` (each at most
``layer_max`` x the nozzle) and ``passes`` side-by-side passes of width ``b / passes`` (each
between ``width_min`` and ``width_max`` x the nozzle), the first layer ``h / layers`` above the
fabric's top (``fabric_z``, default the fabric thickness t). Extrusion is absolute (M82): a
pass of width w and layer height z takes ``w z / (pi d^2 / 4)`` mm of filament of diameter d
per mm of path, so one line's passes together lay b z mm^2 of cross-section.

Travel moves never cross a printed line in plan view: a move goes straight to the next start
when that keeps more than b/2 from every other line, otherwise around the group of lines
(out along x beyond every line by ``clearance``, along y, back in). A move that finds no such
route is an error, not a G-code.

Everything printed must lie on the bed, and so must the stretched fabric it is printed on
(its frame clamps it flat on the bed): either off the bed is an error that says by how many mm
and past which edge. Where the frame holds the fabric beyond the bed's edges, ``overhang``
lets the fabric (never a line) reach past them, with a warning in the header and in
:attr:`Plan.warnings`. The start and end blocks follow the firmware's ``flavour``
(:data:`FLAVOURS`); the moves are the same G0/G1 for all.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..model.config import number_problem

__all__ = ["FLAVOURS", "GcodeError", "PrintLine", "PrintSettings", "lines_of_case", "make_gcode",
           "off_bed", "parse_bed",
           "preview_png", "Move"]


class GcodeError(ValueError):
    """A print cannot be made as asked (the message names the option or the line)."""


@dataclass(frozen=True)
class PrintLine:
    """One line to print: a polyline in the print (stretched) frame [mm], thickness, width."""

    index: int
    points: np.ndarray
    h: float
    b: float
    name: str | None = None  # the line's id in the case or drawing (None: its index)

    @property
    def label(self) -> str:
        """The name to show: the line's id, or its index."""
        return self.name if self.name is not None else str(self.index)

    @property
    def length(self) -> float:
        return float(np.sum(np.linalg.norm(np.diff(self.points, axis=0), axis=1)))


@dataclass(frozen=True)
class PrintSettings:
    """Printer, material and placement. Defaults: PLA, 0.4 mm nozzle, 1.75 mm filament, a
    220 x 220 mm bed. Units: mm, mm/s, degrees C."""

    bed_x: float = 220.0
    bed_y: float = 220.0
    origin: tuple[float, float] | None = None
    nozzle: float = 0.4
    filament: float = 1.75
    layer_max: float = 0.75
    layer_min: float = 0.05
    width_min: float = 0.8
    width_max: float = 1.5
    fabric_z: float | None = None
    print_speed: float = 20.0
    travel_speed: float = 120.0
    z_hop: float = 1.0
    retract: float = 0.8
    clearance: float = 3.0
    nozzle_temp: float = 210.0
    bed_temp: float = 60.0
    flavour: str = "marlin"
    overhang: bool = False

    def check(self) -> None:
        """Raise GcodeError naming the first invalid option."""
        if self.flavour not in FLAVOURS:
            raise GcodeError(f"flavour: must be one of {', '.join(FLAVOURS)} (got "
                             f"{self.flavour!r})")
        positive = ("bed_x", "bed_y", "nozzle", "filament", "layer_max", "layer_min",
                    "width_min", "width_max", "print_speed", "travel_speed", "clearance")
        for k in positive:
            if (msg := number_problem(k, getattr(self, k))) is not None:
                raise GcodeError(msg)
        for k in ("z_hop", "retract", "nozzle_temp", "bed_temp"):
            if (msg := number_problem(k, getattr(self, k), inclusive=True)) is not None:
                raise GcodeError(msg)
        if self.nozzle_temp > 350 or self.bed_temp > 150:
            raise GcodeError("nozzle_temp, bed_temp: must be <= 350 and <= 150 degrees C")
        if self.width_min >= self.width_max:
            raise GcodeError("width_min: must be < width_max (fractions of the nozzle)")
        if self.layer_max > 1.0:
            raise GcodeError(f"layer_max: must be <= 1 (a fraction of the nozzle; got "
                             f"{self.layer_max:g})")
        if self.layer_min >= self.layer_max * self.nozzle:
            raise GcodeError(f"layer_min: must be < layer_max x nozzle = "
                             f"{self.layer_max * self.nozzle:g} mm")
        if self.fabric_z is not None and not (0 <= self.fabric_z <= 50):
            raise GcodeError(f"fabric_z: must be from 0 to 50 mm (got {self.fabric_z:g})")


@dataclass(frozen=True)
class Move:
    """One move of the print head in bed coordinates: ``kind`` 'print' or 'travel'."""

    x0: float
    y0: float
    x1: float
    y1: float
    z: float
    kind: str
    e: float = 0.0  # filament fed [mm]


@dataclass
class Plan:
    """What :func:`make_gcode` decided: layers, passes and every move."""

    layers: int
    layer_height: float
    passes: dict[int, int]
    moves: list[Move] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)


def _start_marlin(st: PrintSettings) -> list[str]:
    return [f"M140 S{st.bed_temp:g}", f"M104 S{st.nozzle_temp:g}", f"M190 S{st.bed_temp:g}",
            f"M109 S{st.nozzle_temp:g}", "G28 ; home", "G92 E0"]


def _end_marlin(st: PrintSettings) -> list[str]:
    return ["M104 S0", "M140 S0", "M84 ; motors off"]


def _start_klipper(st: PrintSettings) -> list[str]:
    # Klipper runs the same M-codes; its own commands where they say more
    return [f"M140 S{st.bed_temp:g}", f"M104 S{st.nozzle_temp:g}", f"M190 S{st.bed_temp:g}",
            f"M109 S{st.nozzle_temp:g}", "G28 ; home", "G92 E0"]


def _end_klipper(st: PrintSettings) -> list[str]:
    return ["TURN_OFF_HEATERS", "M84 ; motors off"]


def _start_reprap(st: PrintSettings) -> list[str]:
    # RepRapFirmware: tool temperatures with G10, select the tool, wait with M116
    return [f"M140 S{st.bed_temp:g}", f"G10 P0 S{st.nozzle_temp:g} R{st.nozzle_temp:g}",
            "T0", "M116 ; wait for the temperatures", "G28 ; home", "G92 E0"]


def _end_reprap(st: PrintSettings) -> list[str]:
    return ["G10 P0 S0 R0", "M140 S0", "M84 ; motors off"]


#: firmware flavour -> (start block, end block) of the G-code
FLAVOURS: dict[str, tuple[Any, Any]] = {
    "marlin": (_start_marlin, _end_marlin),
    "klipper": (_start_klipper, _end_klipper),
    "reprap": (_start_reprap, _end_reprap),
}


def parse_bed(text: str) -> tuple[float, float]:
    """``"220x220"`` (WIDTHxDEPTH in mm; ``X`` or spaces also) -> (220.0, 220.0)."""
    parts = text.lower().replace(" ", "").split("x")
    try:
        if len(parts) != 2:
            raise ValueError
        size = float(parts[0]), float(parts[1])
    except ValueError:
        raise GcodeError(f"--bed: must be WIDTHxDEPTH in mm, e.g. 220x220 (got {text!r})"
                         ) from None
    if not all(math.isfinite(v) and 0 < v <= 2000 for v in size):
        raise GcodeError(f"--bed: width and depth must be > 0 and <= 2000 mm (got {text!r})")
    return size


def off_bed(x0: float, x1: float, y0: float, y1: float, bed_x: float, bed_y: float
            ) -> list[str]:
    """How far a box (bed coordinates) reaches past each edge of the bed, as phrases."""
    out = []
    for past, edge, at in ((-x0, "left (X 0)", x0), (x1 - bed_x, f"right (X {bed_x:g})", x1),
                           (-y0, "front (Y 0)", y0), (y1 - bed_y, f"back (Y {bed_y:g})", y1)):
        if past > 1e-9:
            out.append(f"{past:.1f} mm past the {edge} edge (at {at:.1f})")
    return out


def lines_of_case(case: Any) -> list[PrintLine]:
    """The case's rods as print lines (printed configuration, origin at the fabric centre):
    the rods along x, or every line of its pattern with its own h and b."""
    return [PrintLine(k, p.points.astype(float), p.h, p.b, p.id)
            for k, p in enumerate(case.rod_paths())]


def _layers(h: float, st: PrintSettings) -> tuple[int, float]:
    n = max(1, math.ceil(h / (st.layer_max * st.nozzle) - 1e-9))
    z = h / n
    if z < st.layer_min - 1e-12:
        raise GcodeError(f"h = {h:g} mm: thinner than the thinnest layer, layer_min = "
                         f"{st.layer_min:g} mm")
    return n, z


def _passes(line: PrintLine, st: PrintSettings) -> int:
    lo, hi = st.width_min * st.nozzle, st.width_max * st.nozzle
    k_min = max(1, math.ceil(line.b / hi - 1e-9))
    k_max = math.floor(line.b / lo + 1e-9)
    if k_max < k_min:
        raise GcodeError(f"line {line.index}: b = {line.b:g} mm cannot be laid in passes "
                         f"{lo:g} to {hi:g} mm wide (a {st.nozzle:g} mm nozzle)")
    return k_min


def _offset(points: np.ndarray, d: float) -> np.ndarray:
    """The polyline moved sideways by d (left of its direction), with mitred vertices."""
    seg = np.diff(points, axis=0)
    t = seg / np.linalg.norm(seg, axis=1, keepdims=True)
    nrm = np.stack([-t[:, 1], t[:, 0]], axis=1)
    vn = np.vstack([nrm[:1], nrm[:-1] + nrm[1:], nrm[-1:]])
    vn /= np.linalg.norm(vn, axis=1, keepdims=True)
    cosang = np.ones(len(points))
    if len(nrm) > 1:
        cosang[1:-1] = np.sum(vn[1:-1] * nrm[:-1], axis=1)
    return points + d * vn / np.maximum(cosang, 0.2)[:, None]


def _seg_dist(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance of points p (m, 2) to the segment a-b."""
    ab = b - a
    t = np.clip(((p - a) @ ab) / max(float(ab @ ab), 1e-300), 0.0, 1.0)
    return np.linalg.norm(p - (a + t[:, None] * ab), axis=1)


def line_distance(p: np.ndarray, line: PrintLine, shift: np.ndarray) -> np.ndarray:
    """Distance of points p (bed frame) to a line's centre polyline placed at ``shift``."""
    pts = line.points + shift
    return np.min([_seg_dist(p, pts[i], pts[i + 1]) for i in range(len(pts) - 1)], axis=0)


def _route_clear(path: np.ndarray, lines: list[PrintLine], shift: np.ndarray,
                 start_line: int | None, end_line: int | None) -> bool:
    """Whether a travel path (bed frame) keeps more than b/2 from every line, except near its
    own start (on ``start_line``) and end (on ``end_line``)."""
    samples = []
    for a, b in zip(path[:-1], path[1:], strict=True):
        k = max(2, int(np.linalg.norm(b - a) / 0.1) + 2)
        samples.append(a + np.linspace(0.0, 1.0, k)[:, None] * (b - a))
    p = np.vstack(samples)
    d0 = np.linalg.norm(p - path[0], axis=1)
    d1 = np.linalg.norm(p - path[-1], axis=1)
    for ln in lines:
        keep = np.sqrt(2.0) * ln.b / 2.0 + 1e-6  # the corner of the line's end cap
        dist = line_distance(p, ln, shift)
        ok = dist > ln.b / 2.0 + 1e-6
        if ln.index == start_line:
            ok |= d0 <= keep
        if ln.index == end_line:
            ok |= d1 <= keep
        if not np.all(ok):
            return False
    return True


def _nearest_end(line: PrintLine, pos: np.ndarray | None, origin: np.ndarray) -> float:
    """How far the head is from the nearer end of ``line`` (the first line: lowest y, x)."""
    if pos is None:
        return float(line.points[0, 1] * 1e6 + line.points[0, 0])
    ends = line.points[[0, -1]] + origin
    return float(np.min(np.linalg.norm(ends - pos, axis=1)))


def _route(a: np.ndarray, b: np.ndarray, lines: list[PrintLine], shift: np.ndarray,
           i: int | None, j: int | None, st: PrintSettings) -> np.ndarray | None:
    """A clear travel path from a to b (bed frame), or None: straight, then the two L-shaped
    paths, then around the group of lines in x or in y (nearest side first)."""
    cands = [np.array([a, b]), np.array([a, [a[0], b[1]], b]), np.array([a, [b[0], a[1]], b])]
    pts = np.vstack([ln.points for ln in lines]) + shift
    pad = st.clearance + max(ln.b for ln in lines) / 2.0
    xs = [float(pts[:, 0].min()) - pad, float(pts[:, 0].max()) + pad]
    ys = [float(pts[:, 1].min()) - pad, float(pts[:, 1].max()) + pad]
    for x_out in sorted(xs, key=lambda x: abs(x - a[0]) + abs(x - b[0])):
        cands.append(np.array([a, [x_out, a[1]], [x_out, b[1]], b]))
    for y_out in sorted(ys, key=lambda y: abs(y - a[1]) + abs(y - b[1])):
        cands.append(np.array([a, [a[0], y_out], [b[0], y_out], b]))
    for path in cands:
        if _route_clear(path, lines, shift, i, j):
            return path
    return None


def make_gcode(lines: list[PrintLine], settings: PrintSettings | None = None, *,
               eps0: float, fabric_t: float, name: str = "case",
               fabric_extent: tuple[float, float, float, float] | None = None
               ) -> tuple[str, Plan]:
    """G-code text and the plan (layers, passes, moves) for ``lines``.

    ``eps0`` and ``fabric_extent`` (xmin, xmax, ymin, ymax of the stretched fabric) go into
    the header; ``fabric_t`` is the fabric's top above the bed unless
    ``settings.fabric_z`` says otherwise.
    """
    st = settings or PrintSettings()
    st.check()
    if not lines:
        raise GcodeError("lines: nothing to print")
    hs = {round(ln.h, 9) for ln in lines}
    if len(hs) > 1:
        raise GcodeError("lines: all lines of one print must have the same thickness h "
                         f"(got {sorted(hs)})")
    n_layers, zl = _layers(lines[0].h, st)
    passes = {ln.index: _passes(ln, st) for ln in lines}
    origin = np.array(st.origin if st.origin is not None else (st.bed_x / 2, st.bed_y / 2))
    z_fab = fabric_t if st.fabric_z is None else st.fabric_z
    area = math.pi * st.filament ** 2 / 4.0
    plan = Plan(n_layers, zl, passes)
    out: list[str] = []
    w = out.append
    n_lines = len(lines)
    w(f"; undulate G-code for {name}")
    w(f"; CLAMP THE FABRIC STRETCHED along X by eps0 = {eps0:g}: {1 + eps0:g} x its relaxed "
      "length, long edges free; the lines are placed in that stretched frame")
    if fabric_extent is not None:
        x0, x1, y0, y1 = (fabric_extent[0] + origin[0], fabric_extent[1] + origin[0],
                          fabric_extent[2] + origin[1], fabric_extent[3] + origin[1])
        w(f"; stretched fabric: x {x0:.2f} .. {x1:.2f}, y {y0:.2f} .. {y1:.2f} mm on the bed "
          f"(centre at X {origin[0]:g} Y {origin[1]:g})")
        if past := off_bed(x0, x1, y0, y1, st.bed_x, st.bed_y):
            msg = (f"the stretched fabric (x {x0:.1f} .. {x1:.1f}, y {y0:.1f} .. {y1:.1f} mm) "
                   f"reaches {' and '.join(past)} of the {st.bed_x:g} x {st.bed_y:g} mm bed")
            if not st.overhang:
                raise GcodeError(f"bed: {msg} (use a larger --bed, a smaller fabric in the "
                                 "case, or --overhang if its frame holds it beyond the bed)")
            plan.warnings.append(msg)
            w(f"; WARNING: {msg}; its frame must hold it flat beyond the bed's edges")
    w(f"; {n_lines} line(s): h = {lines[0].h:g} mm as {n_layers} layer(s) of {zl:.4g} mm, "
      f"first layer {zl:.4g} mm above the fabric top at Z {z_fab:g}")
    for ln in lines:
        w(f"; line {ln.index} ({ln.label}): length {ln.length:.3f} mm, b = {ln.b:g} mm as "
          f"{passes[ln.index]} pass(es) of {ln.b / passes[ln.index]:.4g} mm")
    w(f"; nozzle {st.nozzle:g} mm, filament {st.filament:g} mm, PLA defaults; "
      f"print {st.print_speed:g} mm/s, travel {st.travel_speed:g} mm/s")
    w("G21 ; millimetres")
    w("G90 ; absolute positions")
    w("M82 ; absolute extrusion")
    start, end = FLAVOURS[st.flavour]
    w(f"; firmware flavour: {st.flavour}")
    out.extend(start(st))
    f_print = st.print_speed * 60.0
    f_travel = st.travel_speed * 60.0
    e = 0.0
    pos: np.ndarray | None = None
    cur_line: int | None = None
    z_safe = z_fab + n_layers * zl + st.z_hop
    w(f"G0 Z{z_safe:.3f} F{f_travel:.0f}")
    for layer in range(1, n_layers + 1):
        z = z_fab + layer * zl
        w(f"; layer {layer} of {n_layers}, Z {z:.3f}")
        remaining = list(lines)
        while remaining:
            # the next line: the one whose nearer end is closest to the head
            ln = min(remaining, key=lambda c, p=pos: _nearest_end(c, p, origin))
            remaining.remove(ln)
            k = passes[ln.index]
            wp = ln.b / k
            first = _offset(ln.points, -(k - 1) / 2.0 * wp) + origin
            # start at the nearer end unless only the other one can be reached
            ends = [True, False]
            if pos is not None:
                ends.sort(key=lambda f: float(np.linalg.norm((first if f else first[::-1])[0]
                                                             - pos)))
            route0 = None
            for fwd in ends:
                if pos is None or cur_line == ln.index:
                    break
                route0 = _route(pos, (first if fwd else first[::-1])[0], lines, origin,
                                cur_line, ln.index, st)
                if route0 is not None:
                    break
            else:
                raise GcodeError(f"travel from line {cur_line} to line {ln.index}: no route "
                                 "that keeps clear of the printed lines (lines too close "
                                 "together for the nozzle to pass between them)")
            for j in range(k):
                off = (j - (k - 1) / 2.0) * wp
                path = _offset(ln.points, off) + origin
                if not fwd:
                    path = path[::-1]
                fwd = not fwd
                start = path[0]
                if pos is None:
                    w(f"G0 X{start[0]:.3f} Y{start[1]:.3f} F{f_travel:.0f}")
                elif np.linalg.norm(start - pos) > 1e-9:
                    route = route0 if (j == 0 and route0 is not None) else np.array([pos, start])
                    if st.retract > 0:
                        e -= st.retract
                        w(f"G1 E{e:.5f} F2400 ; retract")
                    w(f"G0 Z{z + st.z_hop:.3f} F{f_travel:.0f}")
                    for p0, p1 in zip(route[:-1], route[1:], strict=True):
                        w(f"G0 X{p1[0]:.3f} Y{p1[1]:.3f} F{f_travel:.0f}")
                        plan.moves.append(Move(*p0, *p1, z + st.z_hop, "travel"))
                    if st.retract > 0:
                        e += st.retract
                        w(f"G1 E{e:.5f} F2400 ; unretract")
                w(f"G0 Z{z:.3f} F{f_travel:.0f}")
                per_mm = wp * zl / area
                for p0, p1 in zip(path[:-1], path[1:], strict=True):
                    de = float(np.linalg.norm(p1 - p0)) * per_mm
                    e += de
                    w(f"G1 X{p1[0]:.3f} Y{p1[1]:.3f} E{e:.5f} F{f_print:.0f}")
                    plan.moves.append(Move(*p0, *p1, z, "print", de))
                pos = path[-1]
                cur_line = ln.index
    w(f"G0 Z{z_safe + 10:.3f} F{f_travel:.0f}")
    out.extend(end(st))
    xs = [c for m in plan.moves for c in (m.x0, m.x1)]
    ys = [c for m in plan.moves for c in (m.y0, m.y1)]
    if past := off_bed(min(xs), max(xs), min(ys), max(ys), st.bed_x, st.bed_y):
        raise GcodeError(f"bed: the print (x {min(xs):.1f} .. {max(xs):.1f}, y {min(ys):.1f} "
                         f".. {max(ys):.1f} mm) reaches {' and '.join(past)} of the "
                         f"{st.bed_x:g} x {st.bed_y:g} mm bed (move it with "
                         "--origin-x/--origin-y or use a larger --bed)")
    return "\n".join(out) + "\n", plan


def preview_png(plan: Plan, path: str | Path, *, title: str = "toolpaths") -> Path:
    """A top view of the moves: printed passes (solid) and travel (dashed)."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(7, 5), layout="constrained")
    ax = fig.subplots()
    last = max(m.z for m in plan.moves if m.kind == "print")
    hop = max((m.z for m in plan.moves if m.kind == "travel"), default=last) - last
    for m in plan.moves:
        if m.kind == "print" and m.z == last:
            ax.plot([m.x0, m.x1], [m.y0, m.y1], "-", color="C0", lw=1.2)
        elif m.kind == "travel" and math.isclose(m.z, last + hop):
            ax.plot([m.x0, m.x1], [m.y0, m.y1], "--", color="0.5", lw=0.7)
    ax.plot([], [], "-", color="C0", label="printed passes (top layer)")
    ax.plot([], [], "--", color="0.5", label="travel (top layer)")
    ax.set_aspect("equal")
    ax.set_xlabel("bed X [mm]")
    ax.set_ylabel("bed Y [mm]")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.18), ncol=2)
    ax.set_title(title, fontsize=9)
    out = Path(path)
    fig.savefig(out, dpi=120)
    return out
