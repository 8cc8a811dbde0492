"""Model stage: what is simulated (fabric, rods, release, imperfection), validated."""

from .config import (
    MATERIAL_DEFAULTS,
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
    "MATERIAL_DEFAULTS",
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
