"""The case file's rules between fields (each a function of a whole :class:`Case`, run in
this order by its validation), and their list as the docs show it (:data:`RULES`)."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from .case import Case

__all__ = ["RULES", "check_case"]


def check_case(case: Case) -> None:
    """Raise ValueError (``"field: problem"``) at the first rule ``case`` breaks."""
    for rule in (_pull_on_free_edges, _force_release, _knit, _geometry, _fits):
        rule(case)


def _pull_on_free_edges(case: Case) -> None:
    if case.fabric.edge_tension > 0 and {"bottom", "top"} <= set(case.release.clamps):
        raise ValueError("fabric.edge_tension: pulls on the edges across the stretch that "
                         "are free, but release.clamps holds both bottom and top")


def _force_release(case: Case) -> None:
    if case.release.control == "force":
        if case.mode == "inertial":
            raise ValueError("release.control: 'force' is quasi-static only; use mode = "
                             "'quasi-static' or control = 'displacement'")
        if case.hang is not None:
            raise ValueError("release.control: with 'force' the sample ends free (no "
                             "clamp is left to let go): remove [hang]")


def _knit(case: Case) -> None:
    f = case.fabric
    if (f.E_y is None) != (f.G is None):
        raise ValueError("fabric.E_y: an orthotropic knit needs both E_y and G (or "
                         "neither, for the isotropic sheet)")
    if f.E_y is not None:
        if f.nu**2 * f.E_y / f.E >= 1.0:
            raise ValueError(f"fabric.nu: must be below sqrt(E / E_y) = "
                             f"{math.sqrt(f.E / f.E_y):.3g} for an orthotropic knit")
        e0 = case.release.eps0
        if 1.0 - f.nu * ((1.0 + e0) ** 2 - 1.0) <= 0.1:
            raise ValueError(f"release.eps0: {e0:g} is too large a stretch for the "
                             f"orthotropic (St Venant-Kirchhoff) knit with nu = {f.nu:g}: "
                             "it must keep 1 - nu ((1 + eps0)^2 - 1) above 0.1")


def _geometry(case: Case) -> None:
    if case.mesh.kind == "structured" and (case.pattern is not None
                                           or case.release.direction != 0.0):
        raise ValueError(
            "mesh.kind: 'structured' takes rods along x stretched along x only; a pattern "
            "or a release.direction other than 0 needs kind = 'unstructured'")
    if case.pattern is not None:
        _check_pattern(case)
        return
    segs = case.segments()
    b = case.rods.b
    if case.mesh.dx_rod > 0.5 * min(s[2] for s in segs):
        raise ValueError(
            f"mesh.dx_rod: must be <= half the shortest rod length "
            f"({0.5 * min(s[2] for s in segs):g} mm)"
        )
    # rods must not overlap or touch (footprints are b wide)
    for i in range(len(segs)):
        for j in range(i + 1, len(segs)):
            xi, yi, li = segs[i]
            xj, yj, lj = segs[j]
            overlap_x = min(xi + li, xj + lj) - max(xi, xj)
            if overlap_x > -1e-9 and abs(yi - yj) < b - 1e-9:
                raise ValueError(
                    f"rods.segments: rods {i} and {j} overlap (their footprints of width "
                    f"b = {b} mm intersect); keep |y_i - y_j| >= b or separate them in x"
                )


def _fits(case: Case) -> None:
    """With ``fabric.size``: every line on the fabric, 2 mm clear of each edge."""
    if case.fabric.size is None:
        return
    from ..mesh import stretch_rotation

    xmin, xmax, ymin, ymax = case.fabric_extent()
    rot = stretch_rotation(case.release.direction)
    clear = 2.0
    for p in case.rod_paths():
        q = p.points @ rot  # stretch frame
        w = 0.5 * p.b
        wx = 0.0 if case.pattern is None and case.release.direction == 0.0 else w
        gaps = {"left": q[:, 0].min() - wx - xmin, "right": xmax - q[:, 0].max() - wx,
                "bottom": q[:, 1].min() - w - ymin, "top": ymax - q[:, 1].max() - w}
        edge = min(gaps, key=gaps.get)
        g = gaps[edge]
        if g < clear:
            where = ("leaves the fabric across" if g < 0 else
                     f"is only {g:.3g} mm from")
            held = ("the clamp on" if edge in case.release.clamps else "")
            raise ValueError(
                f"pattern: line {p.id}: {where} {held} the {edge} edge of the "
                f"{xmax - xmin:g} x {ymax - ymin:g} mm fabric (fabric.size, stretch frame); "
                f"keep at least {clear:g} mm of fabric between a line's footprint and every "
                "edge".replace("  ", " ") if case.pattern is not None else
                f"fabric.size: rod {p.id} {where} {held} the {edge} edge of the "
                f"{xmax - xmin:g} x {ymax - ymin:g} mm fabric; keep at least {clear:g} mm "
                "of fabric between a rod's footprint and every edge".replace("  ", " "))


def _check_pattern(case: Case) -> None:
    from .pattern import PatternError, _min_radius, check_lines, line_from_points

    r = case.rods
    given = [k for k in ("N", "s", "L", "segments") if k in r.model_fields_set]
    if given:
        raise ValueError(
            f"pattern: rods.{', rods.'.join(given)} cannot be given together with a "
            "pattern (its lines have their own geometry; [rods] sets h, b and the material)"
        )
    if not case.pattern.lines and not case.pattern.arrays:
        raise ValueError("pattern: holds no lines")
    rods = case.rod_paths()
    dx = case.mesh.dx_rod
    try:
        lines = [line_from_points(p.points, k, id=p.id, h=p.h, b=p.b)
                 for k, p in enumerate(rods)]
        check_lines(lines, b=r.b, min_gap=case.pattern.min_gap)
    except PatternError as err:
        raise ValueError(f"pattern: {err}") from None
    from ..mesh import RodPath

    for p in rods:
        if dx > 0.5 * p.length:
            raise ValueError(f"pattern: line {p.id}: {p.length:.4g} mm long, shorter than "
                             f"2 x mesh.dx_rod = {2 * dx:g} mm (make it longer or lower "
                             "mesh.dx_rod)")
        need = max(p.b, 3.0 * dx)
        st = RodPath(p.points).stations(dx)
        if len(st) >= 3:
            rad = _min_radius(st)
            if rad < need:
                raise ValueError(
                    f"pattern: line {p.id}: bends with a radius of {rad:.3g} mm, below the "
                    f"smallest its rod can follow, max(b, 3 x mesh.dx_rod) = {need:g} mm "
                    "(draw a wider bend, a narrower line or lower mesh.dx_rod)")


#: Rules that involve more than one field (checked by :func:`check_case`; listed in
#: docs/config.md, each with a test in tests/test_errors_doc.py)
RULES: tuple[str, ...] = (
    "`rods.segments`: at least one rod; `rods.N`, `rods.s` and `rods.L` must then be left out "
    "(each segment has its own `start` and `length`).",
    "`rods.s > 0` when `rods.N > 1` (`s = 0` would be one rod `N b` wide: write `N = 1`, "
    "`b = N b`).",
    "`mesh.dx_far >= mesh.dx_rod`.",
    "`mesh.dx_rod` <= half the shortest rod (`rods.L`, or the shortest segment `length`).",
    "Rods must not overlap or touch: their footprints are `rods.b` wide, so two rods that "
    "overlap in x need `|y_i - y_j| >= b`.",
    "`[pattern]`: at least one line; `rods.N`, `rods.s`, `rods.L` and `rods.segments` must "
    "then be left out, and `mesh.kind` must be `\"unstructured\"` (also for "
    "`release.direction` other than 0). In a case file, `pattern.file` adds the lines of an SVG "
    "or DXF drawing (path relative to the case file; centred on the origin) and "
    "`pattern.scale` multiplies its coordinates. Lines must not cross or touch (footprints "
    "`b` wide), keep `pattern.min_gap` apart, be at least `2 mesh.dx_rod` long and bend no "
    "tighter than a radius of `max(b, 3 mesh.dx_rod)`.",
    "A case file must hold at least one setting: an empty file is refused (`undulate demo` "
    "runs the default case; a file with only `name = \"...\"` runs the defaults).",
)
