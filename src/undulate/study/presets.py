"""Named studies (docs/studies.md), each with a ``quick`` variant.

=========================  =====================================  ==============================
preset                     full                                   quick
=========================  =====================================  ==============================
single-rod-h               h = 0.08..2.0 step 0.02 (97), N = 1,   h = 0.2..2.0 step 0.1 (19)
                           eps0 = 0.5; seeds 1, 2 also at every
                           5th h (40 more): 137 runs
single-rod-eps0            eps0 = 0.1..1.0 step 0.1 (10) x        eps0 in [0.1, 0.3, 0.5, 1.0],
                           h in [0.2, 0.3, 0.5]: 30 runs          h = 0.3
parallel-phase-diagram     N = 5, h = 0.1..2.0 step 0.1 (20),     h = 0.2..2.0 step 0.6 (4),
                           s = 0..50 step 2.5 (21): 420 runs      s in [0, 10, 50]: 12
=========================  =====================================  ==============================

Quick variants also use a coarser, cheaper case: rods L = 60 mm, ``mesh.dx_rod = 2.0``,
``mesh.dx_far = 6.0``, ``mesh.dy_far = 8.0``, ``release.steps = 15``.
Quick results are for smoke tests and the pipeline, not for physics (shorter rods shift the
quantization plateaus). The quick thickness sweep starts at h = 0.2: eq. (1) gives l ~ 6 mm at
h = 0.1, three nodes per arc on the 2 mm mesh, and the arc fit fails there (measured R^2 0.11).
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from pathlib import Path
from typing import Any

from ..model.config import MATERIAL_DEFAULTS
from .spec import Study, StudyError, build_study, frange, load_sweep_toml

__all__ = ["PRESETS", "preset_names", "get_preset", "resolve_study", "QUICK_OVERRIDES"]

#: Changes applied to the base case of every preset in ``--quick`` mode.
QUICK_OVERRIDES: dict[str, Any] = {
    "rods": {"L": 60.0},
    "mesh": {"dx_rod": 2.0, "dx_far": 6.0, "dy_far": 8.0},
    "release": {"steps": 15},
}


def _merge(base: dict[str, Any], over: dict[str, Any]) -> dict[str, Any]:
    out = copy.deepcopy(base)
    for k, v in over.items():
        if isinstance(v, dict) and isinstance(out.get(k), dict):
            out[k] = _merge(out[k], v)
        else:
            out[k] = copy.deepcopy(v)
    return out


def _base(quick: bool, rods: dict[str, Any], release: dict[str, Any]) -> dict[str, Any]:
    base: dict[str, Any] = {
        "fabric": {"E": MATERIAL_DEFAULTS["E"], "t": MATERIAL_DEFAULTS["t"]},
        "rods": {"b": MATERIAL_DEFAULTS["b"], "L": 100.0, "E_B": MATERIAL_DEFAULTS["E_B"],
                 **rods},
        "release": {"eps0": 0.5, **release},
        "imperfection": {"seed": 0},
        "mode": "quasi-static",
    }
    return _merge(base, QUICK_OVERRIDES) if quick else base


#: seeds of the spread sub-grid of ``single-rod-h`` (every SPREAD_EVERY-th thickness)
SPREAD_SEEDS = (0, 1, 2)
SPREAD_EVERY = 5


def _single_rod_h(quick: bool, seeds: int | None) -> Study:
    hs = frange(0.2, 2.0, 0.1) if quick else frange(0.08, 2.0, 0.02)
    base = _base(quick, {"N": 1, "h": 0.3}, {"eps0": 0.5})
    study = build_study("single-rod-h", base, {"rods.h": hs}, kind="preset", seeds=seeds,
                        quick=quick)
    if seeds is not None or quick:
        return study
    # the spread: seeds 0, 1, 2 at every 5th thickness (seed 0 is already in the grid)
    spread = build_study("single-rod-h", base, {"rods.h": hs[::SPREAD_EVERY]},
                         kind="preset", seeds=list(SPREAD_SEEDS), quick=quick)
    known = {r.id for r in study.runs}
    study.runs.extend(r for r in spread.runs if r.id not in known)
    study.definition["spread"] = {"rods.h": hs[::SPREAD_EVERY],
                                  "imperfection.seed": list(SPREAD_SEEDS)}
    return study


def _single_rod_eps0(quick: bool, seeds: int | None) -> Study:
    eps = [0.1, 0.3, 0.5, 1.0] if quick else frange(0.1, 1.0, 0.1)
    hs = [0.3] if quick else [0.2, 0.3, 0.5]
    return build_study(
        "single-rod-eps0",
        _base(quick, {"N": 1, "h": 0.3}, {}),
        {"rods.h": hs, "release.eps0": eps},
        kind="preset",
        seeds=seeds,
        quick=quick,
    )


def _parallel(quick: bool, seeds: int | None) -> Study:
    # quick: 12 runs of five rods, ~1 min each on 2 cores with the real engine
    hs = frange(0.2, 2.0, 0.6) if quick else frange(0.1, 2.0, 0.1)
    ss = [0.0, 10.0, 50.0] if quick else frange(0.0, 50.0, 2.5)
    return build_study(
        "parallel-phase-diagram",
        _base(quick, {"N": 5, "h": 0.3, "s": 10.0}, {"eps0": 0.5}),
        {"rods.h": hs, "rods.s": ss},
        kind="preset",
        seeds=seeds,
        quick=quick,
        single_rod_rule=True,
        extra_definition={"N_nominal": 5},
    )


#: name -> builder(quick, seeds) -> Study
PRESETS: dict[str, Callable[[bool, int | None], Study]] = {
    "single-rod-h": _single_rod_h,
    "single-rod-eps0": _single_rod_eps0,
    "parallel-phase-diagram": _parallel,
}


def preset_names() -> list[str]:
    """The valid preset names."""
    return list(PRESETS)


def get_preset(name: str, *, quick: bool = False, seeds: int | None = None) -> Study:
    """Build a preset study; unknown names raise StudyError listing the valid ones."""
    try:
        builder = PRESETS[name]
    except KeyError:
        raise StudyError(
            f"unknown preset {name!r}; valid presets: {', '.join(preset_names())} "
            "(or a path to a SWEEP.toml)"
        ) from None
    return builder(quick, seeds)


def resolve_study(target: str, *, quick: bool = False, seeds: int | None = None) -> Study:
    """A preset name, or a path to a SWEEP.toml (anything ending in .toml or an existing file)."""
    if target in PRESETS:
        return get_preset(target, quick=quick, seeds=seeds)
    p = Path(target)
    if target.endswith(".toml") or p.is_file():
        return load_sweep_toml(p, seeds=seeds, quick=quick)
    return get_preset(target, quick=quick, seeds=seeds)
