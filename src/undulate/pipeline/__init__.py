"""The run pipeline: one case simulated, analysed and written as a run folder.

This stage sits above the engine (model, mesh, mechanics, solve) and the analysis, and below
the studies, the design tools, the fabrication outputs and the interfaces, which all run cases
through it. :mod:`undulate.api` is its public face.
"""

from .run import ONSET_DEFLECTION, StageFn, analyse, onset, run_case, run_cases, simulate

__all__ = ["ONSET_DEFLECTION", "StageFn", "analyse", "onset", "run_case", "run_cases",
           "simulate"]
