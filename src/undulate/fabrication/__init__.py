"""Fabrication: print files for the lines of a case (docs/fabrication.md).

:func:`gcode.write_gcode` turns a case's rods into G-code for an FDM printer that prints them
on the fabric clamped stretched on the bed.
"""

from .gcode import (
    FLAVOURS,
    GcodeError,
    PrintLine,
    PrintSettings,
    lines_of_case,
    make_gcode,
    parse_bed,
    preview_png,
)

__all__ = ["FLAVOURS", "GcodeError", "PrintLine", "PrintSettings", "lines_of_case", "make_gcode",
           "parse_bed", "preview_png"]
