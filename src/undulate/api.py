"""Python API, mirroring the command line.

>>> from undulate import api
>>> case = api.demo_case()                      # small default single rod
>>> result = api.simulate(case)                 # final rest state (SimResult)
>>> metrics = api.analyse(result)               # l, lam, a, R, n, fits, family
>>> api.run_case(case, out="runs/demo")         # simulate + analyse + write files

Units: mm, MPa, N, s.
"""

from __future__ import annotations

from .fileio import OutputError
from .model import Case, ConfigError, case_from_dict, load_case
from .pipeline import ONSET_DEFLECTION, StageFn, analyse, onset, run_case, run_cases, simulate
from .solve import ConvergenceError
from .solve.release import SimResult

__all__ = [
    "Case",
    "ConfigError",
    "ConvergenceError",
    "OutputError",
    "SimResult",
    "demo_case",
    "load_case",
    "case_from_dict",
    "simulate",
    "analyse",
    "run_case",
    "run_cases",
    "onset",
    "ONSET_DEFLECTION",
    "StageFn",
]

DEMO = {
    "name": "demo",
    # the default sheet (200 mm of fabric beside the rod, unstructured graded mesh): wide
    # enough for the study's waves (on a 20 mm strip this rod lifts the whole strip into one
    # arch; see docs/model.md, "Fabric width")
    # on the reference set-up of the study presets, `study-2022` (rod modulus E_B = 1000 MPa;
    # docs/model.md, "The reference set-up"): the demo shows what the studies show
    "rods": {"h": 0.3, "L": 100.0, "E_B": 1000.0},
    "release": {"eps0": 0.5, "steps": 15},
}


def demo_case() -> Case:
    """The default single rod (h = 0.3 mm, L = 100 mm, E_B = 1000 MPa: the studies' reference
    set-up) on the default sheet, 15 release steps."""
    return case_from_dict(DEMO)
