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
sentinel                   6 single rods across h and 6 five-rod  the same 12 places
                           places of the (h, s) plane: 12 runs    (:mod:`.sentinel`)
=========================  =====================================  ==============================

Every preset takes a *set-up*: a partial case dict (the same tables as a case file) laid over
the preset's base case before its swept values, e.g. ``{"rods": {"E_B": 10000.0}}`` or
``{"release": {"clamps": ["left", "right", "bottom", "top"]}}``. It is how a modelling choice
is tried on a whole study (``undulate study run PRESET --set rods.E_B=10000``); the set-up is
recorded in the study's definition and is part of every run's id. Unless told otherwise a
preset runs on the reference set-up, ``study-2022`` (:mod:`.named_setups`: E_B = 1000 MPa,
chosen on the sentinel); ``setup="bare"`` runs it on the engine's defaults.

Quick variants also use a coarser, cheaper case: rods L = 60 mm, ``mesh.dx_rod = 2.0``,
``mesh.dx_far = 6.0``, ``mesh.dy_far = 8.0``, ``release.steps = 15``.
Quick results are for smoke tests and the pipeline, not for physics (shorter rods shift the
quantization plateaus). The quick thickness sweep starts at h = 0.2: eq. (1) gives l ~ 6 mm at
h = 0.1, three nodes per arc on the 2 mm mesh, and the arc fit fails there (measured R^2 0.11).
"""

from __future__ import annotations

import copy
import re
import tomllib
from collections.abc import Callable
from pathlib import Path
from typing import Any

from ..model.config import MATERIAL_DEFAULTS
from .named_setups import REFERENCE, is_setup_name, named_setup, setup_names
from .sentinel import SENTINEL_CASES
from .spec import (
    RunSpec,
    Study,
    StudyError,
    build_study,
    frange,
    load_sweep_toml,
    merge_case,
    read_toml,
    set_path,
    validate_runs,
)

__all__ = ["PRESETS", "preset_names", "get_preset", "resolve_study", "QUICK_OVERRIDES",
           "parse_setting", "setup_from"]

#: Changes applied to the base case of every preset in ``--quick`` mode.
QUICK_OVERRIDES: dict[str, Any] = {
    "rods": {"L": 60.0},
    "mesh": {"dx_rod": 2.0, "dx_far": 6.0, "dy_far": 8.0},
    "release": {"steps": 15},
}


def _base(quick: bool, rods: dict[str, Any], release: dict[str, Any],
          setup: dict[str, Any] | None = None) -> dict[str, Any]:
    base: dict[str, Any] = {
        "fabric": {"E": MATERIAL_DEFAULTS["E"], "t": MATERIAL_DEFAULTS["t"]},
        "rods": {"b": MATERIAL_DEFAULTS["b"], "L": 100.0, "E_B": MATERIAL_DEFAULTS["E_B"],
                 **rods},
        "release": {"eps0": 0.5, **release},
        "imperfection": {"seed": 0},
        "mode": "quasi-static",
    }
    if setup:
        base = merge_case(base, setup)
    return merge_case(base, QUICK_OVERRIDES) if quick else base


def _setup_definition(setup: dict[str, Any] | None) -> dict[str, Any]:
    return {"setup": copy.deepcopy(setup)} if setup else {}


#: seeds of the spread sub-grid of ``single-rod-h`` (every SPREAD_EVERY-th thickness)
SPREAD_SEEDS = (0, 1, 2)
SPREAD_EVERY = 5


def _single_rod_h(quick: bool, seeds: int | None, setup: dict[str, Any] | None) -> Study:
    hs = frange(0.2, 2.0, 0.1) if quick else frange(0.08, 2.0, 0.02)
    base = _base(quick, {"N": 1, "h": 0.3}, {"eps0": 0.5}, setup)
    study = build_study("single-rod-h", base, {"rods.h": hs}, kind="preset", seeds=seeds,
                        quick=quick, extra_definition=_setup_definition(setup))
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


def _single_rod_eps0(quick: bool, seeds: int | None, setup: dict[str, Any] | None) -> Study:
    eps = [0.1, 0.3, 0.5, 1.0] if quick else frange(0.1, 1.0, 0.1)
    hs = [0.3] if quick else [0.2, 0.3, 0.5]
    return build_study(
        "single-rod-eps0",
        _base(quick, {"N": 1, "h": 0.3}, {}, setup),
        {"rods.h": hs, "release.eps0": eps},
        kind="preset",
        seeds=seeds,
        quick=quick,
        extra_definition=_setup_definition(setup),
    )


def _parallel(quick: bool, seeds: int | None, setup: dict[str, Any] | None) -> Study:
    # quick: 12 runs of five rods, ~1 min each on 2 cores with the real engine
    hs = frange(0.2, 2.0, 0.6) if quick else frange(0.1, 2.0, 0.1)
    ss = [0.0, 10.0, 50.0] if quick else frange(0.0, 50.0, 2.5)
    return build_study(
        "parallel-phase-diagram",
        _base(quick, {"N": 5, "h": 0.3, "s": 10.0}, {"eps0": 0.5}, setup),
        {"rods.h": hs, "rods.s": ss},
        kind="preset",
        seeds=seeds,
        quick=quick,
        single_rod_rule=True,
        extra_definition={"N_nominal": 5, **_setup_definition(setup)},
    )


def _sentinel(quick: bool, seeds: int | None, setup: dict[str, Any] | None) -> Study:
    """The twelve places of :data:`.sentinel.SENTINEL_CASES`, one run each (per seed)."""
    base = _base(quick, {"N": 1, "h": 0.3, "s": 10.0}, {"eps0": 0.5}, setup)
    runs: list[RunSpec] = []
    definition: dict[str, Any] = {}
    for c in SENTINEL_CASES:
        one = build_study("sentinel", base, {k: [v] for k, v in c.params().items()},
                          kind="preset", seeds=seeds, quick=quick, single_rod_rule=False,
                          validate=False)
        runs.extend(one.runs)
        definition = one.definition
    study = Study(name="sentinel", kind="preset", definition=definition, runs=runs, quick=quick)
    study.definition.pop("sweep", None)
    study.definition.update(cases=[c.label for c in SENTINEL_CASES], **_setup_definition(setup))
    validate_runs(runs)
    return study


#: name -> builder(quick, seeds, setup) -> Study
PRESETS: dict[str, Callable[[bool, int | None, dict[str, Any] | None], Study]] = {
    "single-rod-h": _single_rod_h,
    "single-rod-eps0": _single_rod_eps0,
    "parallel-phase-diagram": _parallel,
    "sentinel": _sentinel,
}


def preset_names() -> list[str]:
    """The valid preset names."""
    return list(PRESETS)


def get_preset(name: str, *, quick: bool = False, seeds: int | None = None,
               setup: dict[str, Any] | str | None = None) -> Study:
    """Build a preset study with a set-up laid over its base case (module docstring):
    ``None`` for the reference set-up (:data:`.named_setups.REFERENCE`), a shipped name such as
    ``"bare"`` (the engine's defaults), or a set-up dict (``{}``: bare). Unknown names raise
    StudyError listing the valid ones."""
    try:
        builder = PRESETS[name]
    except KeyError:
        raise StudyError(
            f"unknown preset {name!r}; valid presets: {', '.join(preset_names())} "
            "(or a path to a SWEEP.toml)"
        ) from None
    if setup is None:
        setup = REFERENCE
    if isinstance(setup, str):
        setup = named_setup(setup)
    return builder(quick, seeds, setup or None)


def resolve_study(target: str, *, quick: bool = False, seeds: int | None = None,
                  setup: dict[str, Any] | str | None = None) -> Study:
    """A preset name, or a path to a SWEEP.toml (anything ending in .toml or an existing file);
    ``setup`` (a dict or a shipped name) is laid over a preset's base case or a sweep's
    ``[base]``. ``None``: the target's default, the reference set-up for a preset and nothing
    for a sweep (its ``[base]`` says what it wants)."""
    p = Path(target)
    if target not in PRESETS and (target.endswith(".toml") or p.is_file()):
        if isinstance(setup, str):
            setup = named_setup(setup)
        return load_sweep_toml(p, seeds=seeds, quick=quick, setup=setup or None)
    return get_preset(target, quick=quick, seeds=seeds, setup=setup)


_BARE_WORD = re.compile(r"[A-Za-z_][A-Za-z0-9_-]*")


def parse_setting(text: str) -> tuple[str, Any]:
    """``"rods.E_B=10000"`` -> ``("rods.E_B", 10000)``: a dotted path and a TOML value
    (numbers, true/false, "strings", [lists]); a bare word such as ``inertial`` is a string."""
    path, sep, raw = text.partition("=")
    path, raw = path.strip(), raw.strip()
    if not sep or not path or not raw:
        raise StudyError(f"--set {text!r}: give PATH=VALUE, e.g. rods.E_B=10000")
    if not all(_BARE_WORD.fullmatch(part) for part in path.split(".")):
        raise StudyError(f"--set {text!r}: {path!r} is not a dotted path such as rods.E_B")
    try:
        value = tomllib.loads(f"v = {raw}")["v"]
    except tomllib.TOMLDecodeError:
        if not _BARE_WORD.fullmatch(raw):
            raise StudyError(f"--set {text!r}: {raw!r} is not a TOML value (numbers, true/false, "
                             '"text", [lists])') from None
        value = raw
    return path, value


def setup_from(settings: list[str], file: str | Path | None = None, *,
               preset: bool = False) -> dict[str, Any]:
    """The set-up dict of the ``--setup`` and ``--set`` options: ``file`` is a shipped name
    (``study-2022``, ``bare``) or a TOML file of case tables; without it a preset starts from
    the reference set-up and a sweep from nothing. ``PATH=VALUE`` settings are laid over it.
    ``{}`` is the bare engine defaults."""
    if file is not None:
        name = str(file)
        if is_setup_name(name):
            setup = named_setup(name)
        elif not Path(file).is_file():
            raise StudyError(f"--setup {name}: no such file, nor a shipped set-up ("
                             f"{', '.join(setup_names())})")
        else:
            setup = read_toml(Path(file), "--setup ")
    else:
        setup = named_setup(REFERENCE) if preset else {}
    for text in settings:
        path, value = parse_setting(text)
        set_path(setup, path, value)
    return setup
