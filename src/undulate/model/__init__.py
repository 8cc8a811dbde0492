"""Model stage: what is simulated (fabric, rods, release, imperfection), validated."""

from .config import (
    Case,
    ConfigError,
    Dynamics,
    Fabric,
    Imperfection,
    MeshOptions,
    Release,
    Rods,
    Segment,
    SolverOptions,
    case_from_dict,
    load_case,
)

__all__ = [
    "Case",
    "ConfigError",
    "Dynamics",
    "Fabric",
    "Imperfection",
    "MeshOptions",
    "Release",
    "Rods",
    "Segment",
    "SolverOptions",
    "case_from_dict",
    "load_case",
]
