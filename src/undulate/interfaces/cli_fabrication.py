"""``undulate gcode`` and ``undulate export``: print files for a case's lines, 3D models of a
finished run (docs/fabrication.md, docs/design.md)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

__all__ = ["register"]


def gcode(
    out: Annotated[Path, typer.Option("--out", help="G-code file to write")],
    config: Annotated[Path | None, typer.Argument(
        help="case description (TOML); or give --pattern")] = None,
    pattern: Annotated[Path | None, typer.Option(
        "--pattern", help="lines of an .svg or .dxf drawing instead of a case (print frame, "
        "centred on the fabric; docs/web.md for units)")] = None,
    scale: Annotated[float, typer.Option("--scale", help="with --pattern: multiply the "
                                         "drawing's coordinates")] = 1.0,
    h: Annotated[float, typer.Option("--h", help="with --pattern: rod thickness, mm")] = 0.3,
    b: Annotated[float, typer.Option("--b", help="with --pattern: rod width, mm")] = 1.0,
    eps0: Annotated[float, typer.Option("--eps0", help="with --pattern: pre-stretch")] = 0.5,
    t: Annotated[float, typer.Option("--t", help="with --pattern: fabric thickness, mm")]
    = 0.4,
    preview: Annotated[Path | None, typer.Option(
        "--preview", help="PNG top view of the toolpaths [default: beside --out, .png]")]
    = None,
    no_preview: Annotated[bool, typer.Option("--no-preview", help="write no preview PNG")]
    = False,
    drawing: Annotated[Path | None, typer.Option(
        "--drawing", help="also draw the lines (.svg or .dxf): this file in the print frame, "
        "NAME-relaxed.EXT in the relaxed fabric's frame")] = None,
    bed: Annotated[str, typer.Option(
        "--bed", help="bed size WIDTHxDEPTH along X and Y, mm")] = "220x220",
    flavour: Annotated[str, typer.Option(
        "--flavour", help="firmware of the start and end blocks: marlin, klipper or reprap")]
    = "marlin",
    overhang: Annotated[bool, typer.Option(
        "--overhang", help="the frame holds the stretched fabric beyond the bed's edges: "
        "a fabric larger than the bed is a warning, not an error (lines must still be on "
        "the bed)")] = False,
    origin_x: Annotated[float | None, typer.Option(
        "--origin-x", help="bed X of the fabric centre, mm (default: bed centre)")] = None,
    origin_y: Annotated[float | None, typer.Option("--origin-y", help="bed Y of it, mm")]
    = None,
    nozzle: Annotated[float, typer.Option("--nozzle", help="nozzle diameter, mm")] = 0.4,
    filament: Annotated[float, typer.Option("--filament", help="filament diameter, mm")]
    = 1.75,
    fabric_z: Annotated[float | None, typer.Option(
        "--fabric-z", help="height of the fabric's top above the bed, mm (default: t)")]
    = None,
    print_speed: Annotated[float, typer.Option("--print-speed", help="mm/s")] = 20.0,
    travel_speed: Annotated[float, typer.Option("--travel-speed", help="mm/s")] = 120.0,
    nozzle_temp: Annotated[float, typer.Option("--nozzle-temp", help="degrees C")] = 210.0,
    bed_temp: Annotated[float, typer.Option("--bed-temp", help="degrees C")] = 60.0,
) -> None:
    """G-code that prints the case's lines on the fabric clamped stretched on the bed.

    Layers and passes give the rods' thickness h and width b; travel moves keep clear of
    printed lines; the header says how far to stretch the fabric. Examples:
    undulate gcode examples/single_rod.toml --out rod.gcode (and rod.png);
    undulate gcode --pattern lines.svg --h 0.4 --out lines.gcode --bed 300x300 --flavour klipper
    """
    from ..fabrication import (
        GcodeError,
        PrintSettings,
        lines_of_case,
        make_gcode,
        parse_bed,
        preview_png,
    )
    from ..fabrication.drawing import write_drawing
    from ..model import ConfigError, Fabric, Release, Rods, load_case
    from ..model.config import check_value
    from .common import fail as _fail

    if (config is None) == (pattern is None):
        raise _fail("give a case file (CONFIG) or --pattern FILE, not both" if config
                    else "give a case file (CONFIG) or --pattern FILE (.svg or .dxf)")
    if config is not None:
        try:
            case = load_case(config)
        except ConfigError as err:
            line = (str(err).splitlines() or ["invalid case"])[0]
            raise _fail(line if line.startswith(str(config)) else f"{config}: {line}") from None
        lines = lines_of_case(case)
        from ..solve.release import printed_lateral_stretch

        name, e0, ft, nu = case.name, case.release.eps0, case.fabric.t, case.fabric.nu
        extent = case.fabric_extent()
        lam_y, direction = printed_lateral_stretch(case), case.release.direction
    else:
        from ..fabrication import PrintLine
        from ..model.pattern import PatternError, check_lines, read_pattern

        try:
            for opt, model, field, val in (("--h", Rods, "h", h), ("--b", Rods, "b", b),
                                           ("--eps0", Release, "eps0", eps0),
                                           ("--t", Fabric, "t", t)):
                check_value(model, field, val, opt)
            drawn_lines = read_pattern(pattern, scale=scale)
            check_lines(drawn_lines, b=b)
        except (ConfigError, PatternError) as err:
            msg = str(err)
            raise _fail(f"{pattern}: {msg}" if isinstance(err, PatternError)
                        and str(pattern) not in msg else msg) from None
        lines = [PrintLine(k, ln.points, ln.h or h, ln.b or b, ln.id)
                 for k, ln in enumerate(drawn_lines)]
        name, e0, ft, nu = pattern.stem, eps0, t, Fabric().nu
        extent = None
        lam_y, direction = None, 0.0
    if (origin_x is None) != (origin_y is None):
        raise _fail("--origin-x, --origin-y: give both or neither")
    try:
        bed_x, bed_y = parse_bed(bed)
    except GcodeError as err:
        raise _fail(str(err)) from None
    st = PrintSettings(bed_x=bed_x, bed_y=bed_y, nozzle=nozzle, filament=filament,
                       flavour=flavour, overhang=overhang,
                       origin=None if origin_x is None else (origin_x, origin_y),
                       fabric_z=fabric_z, print_speed=print_speed, travel_speed=travel_speed,
                       nozzle_temp=nozzle_temp, bed_temp=bed_temp)
    try:
        text, plan = make_gcode(lines, st, eps0=e0, fabric_t=ft, name=name,
                                fabric_extent=extent)
    except GcodeError as err:
        raise _fail(str(err)) from None
    if drawing is not None and drawing.suffix.lower() not in (".svg", ".dxf"):
        raise _fail(f"--drawing {drawing}: must end in .svg or .dxf")
    drawn: list[Path] = []
    if preview is None and not no_preview:
        preview = out.with_suffix(".png") if out.suffix.lower() != ".png" else None
    try:
        out.write_text(text)
        if preview is not None:
            preview_png(plan, preview, title=f"{name}: toolpaths on the bed")
        if drawing is not None:
            drawn = write_drawing(lines, drawing, eps0=e0, nu=nu, name=name, lam_y=lam_y,
                                  direction=direction)
    except OSError as err:
        raise _fail(f"cannot write {err.filename or out} ({err.strerror or err})") from None
    for msg in plan.warnings:
        typer.echo(f"Warning: {msg}", err=True)
    n_print = sum(m.kind == "print" for m in plan.moves)
    typer.echo(f"wrote {out}: {len(lines)} line(s), {plan.layers} layer(s) of "
               f"{plan.layer_height:.4g} mm, {n_print} printed moves; stretch the fabric by "
               f"eps0 = {e0:g} along "
               + ("X" if direction == 0.0 else f"{direction:g} degrees from X")
               + " before printing"
               + (f"; preview {preview}" if preview else "")
               + (f"; drawings {', '.join(map(str, drawn))}" if drawn else ""))


def export(
    run_dir: Annotated[Path, typer.Argument(help="a finished run folder (the --out of "
                                            "'undulate run' or 'undulate demo')")],
    out: Annotated[Path, typer.Option("--out", help="file to write (.glb, .obj or .stl)")],
    fmt: Annotated[str | None, typer.Option(
        "--format", help="glb, obj or stl [default: from --out's suffix]")] = None,
) -> None:
    """3D model of a run's final state for design tools: the deformed fabric surface and each
    rod as a b x h solid along its centre line, in mm, one named part each.

    glb (binary glTF: Blender, three.js, model-viewer), obj (Rhino, Blender), stl (one named,
    watertight solid per rod; the fabric as a surface). Example:
    undulate export undulate-demo --out demo.glb
    """
    from ..fabrication.model3d import ExportError, export_run
    from .common import fail as _fail

    try:
        path = export_run(run_dir, out, fmt)
    except ExportError as err:
        raise _fail(str(err)) from None
    typer.echo(f"wrote {path} ({path.stat().st_size / 1024:.0f} kB, units mm)")


def register(app: typer.Typer) -> None:
    """Add the ``gcode`` and ``export`` commands to ``app``."""
    app.command("gcode")(gcode)
    app.command("export")(export)
