"""Validated description of one simulation case.

Units everywhere in undulate: lengths in mm, moduli and stresses in MPa (= N/mm^2), forces in N,
energies in N*mm (= mJ), times in s, densities in t/mm^3 (so that N = t*mm/s^2).

A case is a pre-stretched fabric with rods printed on it. The coordinates of rods are given in
the *printed* configuration, i.e. on the fabric while it is stretched by ``eps0`` along x, with
the origin at the centre of the fabric. Rod lengths ``L`` are printed lengths.

Every model is strict: unknown keys, NaN/inf, out-of-range values and values of the wrong type
(``h = "0.3"``, ``N = true``, ``N = 2.0``, ``adaptive = "yes"``: nothing is converted; an
integer is accepted where a real number is expected) raise a :class:`pydantic.ValidationError`
whose message names the field and the allowed range.
:func:`load_case` turns that into a one-line-per-problem :class:`ConfigError`.

This module gathers the case file's parts, each in its own module: the tables
(:mod:`~undulate.model.materials` for [fabric] and [rods], :mod:`~undulate.model.lines` for
[pattern], :mod:`~undulate.model.release` for [release], [hang], [gravity], [imperfection],
:mod:`~undulate.model.numerics` for [mesh], [solver], [dynamics]), the whole case
(:mod:`~undulate.model.case`), the rules between fields (:mod:`~undulate.model.rules`), the
derived geometry (:mod:`~undulate.model.geometry`), reading and messages
(:mod:`~undulate.model.loading`) and the shared validators (:mod:`~undulate.model.validators`).
"""

from .case import Case
from .lines import Arc, LineArray, Pattern, PatternLine, PrintedRod, spline_points
from .loading import case_from_dict, load_case, with_drawing
from .materials import MATERIAL_DEFAULTS, Fabric, Rods, Segment
from .numerics import Dynamics, MeshOptions, SolverOptions
from .release import Gravity, Hang, Imperfection, Release
from .rules import RULES
from .validators import ConfigError, allowed_range, check_value, number_problem

__all__ = [
    "Fabric",
    "Rods",
    "Segment",
    "Arc",
    "PatternLine",
    "LineArray",
    "Pattern",
    "PrintedRod",
    "Release",
    "Imperfection",
    "Gravity",
    "Hang",
    "MeshOptions",
    "SolverOptions",
    "Dynamics",
    "Case",
    "ConfigError",
    "MATERIAL_DEFAULTS",
    "RULES",
    "load_case",
    "case_from_dict",
    "with_drawing",
    "spline_points",
    "allowed_range",
    "check_value",
    "number_problem",
]
