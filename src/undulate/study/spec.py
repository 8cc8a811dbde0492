"""What a study is: a base case, swept parameters (dotted paths), seeds, and the expanded runs.

A *study* is the cartesian product of a few parameter lists applied to a base case dict (the
same nested dict that :func:`undulate.model.case_from_dict` validates). Each expanded case is a
*run* with a stable id: the first 16 hex digits of the SHA-256 of its canonical JSON (sorted
keys, compact separators, normalised floats, without the cosmetic ``name``). The same parameters
therefore always give the same id, which is what makes studies resumable.
"""

from __future__ import annotations

import copy
import hashlib
import itertools
import json
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

__all__ = [
    "RunSpec",
    "Study",
    "StudyError",
    "canonical_json",
    "run_id",
    "get_path",
    "set_path",
    "frange",
    "expand_values",
    "apply_single_rod_rule",
    "build_study",
    "coarse_first",
    "load_sweep_toml",
    "merge_case",
]

SEED_PATH = "imperfection.seed"


class StudyError(ValueError):
    """A study definition is invalid (bad sweep file, bad expanded case, unknown preset)."""


@dataclass(frozen=True)
class RunSpec:
    """One run of a study: its id, the swept parameter values, the seed and the full case dict."""

    id: str
    params: dict[str, Any]
    seed: int
    case: dict[str, Any]


@dataclass
class Study:
    """An expanded study: a name, its JSON-able definition and the list of runs."""

    name: str
    kind: str  # "preset" or "sweep"
    definition: dict[str, Any]
    runs: list[RunSpec] = field(default_factory=list)
    quick: bool = False

    def meta(self) -> dict[str, Any]:
        """The JSON document stored as ``DIR/study.json``."""
        return {
            "schema": 1,
            "name": self.name,
            "kind": self.kind,
            "quick": self.quick,
            "definition": self.definition,
            "n_runs": len(self.runs),
            "runs": [{"id": r.id, "params": r.params, "seed": r.seed} for r in self.runs],
        }


def _normalise(value: Any) -> Any:
    """Make floats that are mathematically equal serialise identically (e.g. 0.1*3)."""
    if isinstance(value, bool) or value is None:
        return value
    if isinstance(value, float):
        if value.is_integer():
            return float(value)
        return float(f"{value:.12g}")
    if isinstance(value, dict):
        return {str(k): _normalise(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_normalise(v) for v in value]
    return value


def canonical_json(obj: Any) -> str:
    """Canonical JSON text of a case dict: sorted keys, compact, normalised floats."""
    return json.dumps(_normalise(obj), sort_keys=True, separators=(",", ":"), allow_nan=False)


def run_id(case: dict[str, Any]) -> str:
    """Stable id of a run: 16 hex digits of the SHA-256 of the canonical case JSON.

    The cosmetic ``name`` is left out, so the id depends only on what is simulated (a seeded
    study's seed-0 runs are the unseeded study's runs).
    """
    physics = {k: v for k, v in case.items() if k != "name"}
    return hashlib.sha256(canonical_json(physics).encode()).hexdigest()[:16]


def get_path(d: dict[str, Any], path: str, default: Any = None) -> Any:
    """Value at a dotted path in a nested dict (``default`` when absent)."""
    cur: Any = d
    for part in path.split("."):
        if not isinstance(cur, dict) or part not in cur:
            return default
        cur = cur[part]
    return cur


def set_path(d: dict[str, Any], path: str, value: Any) -> None:
    """Set a dotted path in a nested dict in place, creating intermediate tables."""
    parts = path.split(".")
    if not all(parts):
        raise StudyError(f"{path!r}: not a valid dotted path")
    cur = d
    for part in parts[:-1]:
        nxt = cur.setdefault(part, {})
        if not isinstance(nxt, dict):
            raise StudyError(f"{path}: {part!r} is a value, not a table")
        cur = nxt
    cur[parts[-1]] = value


def frange(start: float, stop: float, step: float) -> list[float]:
    """Inclusive float range ``start, start+step, ..., <= stop`` with round-off protection."""
    if step <= 0 or not all(math.isfinite(x) for x in (start, stop, step)):
        raise StudyError(f"range: need finite start/stop and step > 0; got {start}, {stop}, {step}")
    n = int(math.floor((stop - start) / step + 1e-9)) + 1
    if n < 1:
        raise StudyError(f"range: empty (start {start} > stop {stop})")
    return [float(f"{start + i * step:.12g}") for i in range(n)]


def expand_values(path: str, spec: Any) -> list[Any]:
    """A sweep entry (list, ``{start, stop, step}`` or ``{start, stop, num}``) as a list."""
    if isinstance(spec, list):
        if not spec:
            raise StudyError(f"sweep.{path}: empty list")
        return list(spec)
    if isinstance(spec, dict):
        keys = set(spec)
        try:
            if keys == {"start", "stop", "step"}:
                return frange(float(spec["start"]), float(spec["stop"]), float(spec["step"]))
            if keys == {"start", "stop", "num"}:
                num = int(spec["num"])
                if num < 1:
                    raise StudyError(f"sweep.{path}: num must be >= 1")
                a, b = float(spec["start"]), float(spec["stop"])
                if num == 1:
                    return [a]
                return [float(f"{a + i * (b - a) / (num - 1):.12g}") for i in range(num)]
        except (TypeError, ValueError) as err:
            if isinstance(err, StudyError):
                raise StudyError(f"sweep.{path}: {err}") from None
            raise StudyError(f"sweep.{path}: numbers expected ({err})") from None
        raise StudyError(
            f"sweep.{path}: a range must be {{start, stop, step}} or {{start, stop, num}}; "
            f"got keys {sorted(keys)}"
        )
    return [spec]


def apply_single_rod_rule(case: dict[str, Any]) -> dict[str, Any]:
    """Parallel-rod rule: ``s = 0`` with ``N > 1`` means one rod ``N*b`` wide (N = 1, b = N*b)."""
    rods = case.get("rods")
    if not isinstance(rods, dict) or rods.get("segments") is not None:
        return case
    n = rods.get("N", 1)
    if rods.get("s", 10.0) == 0 and isinstance(n, int) and n > 1:
        rods["b"] = float(f"{n * float(rods.get('b', 1.0)):.12g}")
        rods["N"] = 1
    return case


def _short(v: Any) -> str:
    return f"{v:g}" if isinstance(v, float) else str(v)


def coarse_first(runs: list[RunSpec]) -> list[RunSpec]:
    """The runs reordered so that every prefix covers the swept grid as evenly as it can.

    Along each swept axis a value's index i has the level "how often 2 divides i" (the first
    value the highest); a run's level is the lowest of its axes' levels. Runs are taken by
    level, highest first, in their listed order within a level: first every 16th value of
    each axis, then every 8th, 4th, 2nd, then the rest. An interrupted sweep therefore leaves
    a coarse picture of the whole plane instead of a finished strip of it. Runs without
    parameters keep their order.
    """
    axes: dict[str, dict[str, int]] = {}
    for r in runs:
        for p, v in r.params.items():
            index = axes.setdefault(p, {})
            index.setdefault(canonical_json(v), len(index))

    def level(r: RunSpec) -> int:
        levels = [_two_adic(axes[p][canonical_json(v)]) for p, v in r.params.items()]
        return min(levels, default=0)

    return sorted(runs, key=lambda r: -level(r))


def _two_adic(i: int) -> int:
    """How many times 2 divides i (a large number for 0, the first value of an axis)."""
    return 64 if i == 0 else (i & -i).bit_length() - 1


def build_study(
    name: str,
    base: dict[str, Any],
    sweep: dict[str, list[Any]],
    *,
    kind: str,
    seeds: int | list[int] | None = None,
    single_rod_rule: bool = True,
    quick: bool = False,
    extra_definition: dict[str, Any] | None = None,
    validate: bool = True,
) -> Study:
    """Expand a base case and swept lists (cartesian product, in the given order) into a Study.

    ``seeds`` (a count K meaning seeds 0..K-1, or an explicit list) adds ``imperfection.seed``
    as the last axis; without it each run uses the base seed (default 0), written explicitly
    into every case so that ids do not change when seeds are added later. With ``validate`` each
    expanded case goes through :func:`undulate.model.case_from_dict`; the first bad one raises
    :class:`StudyError` with a single line naming the run and the field.
    """
    sweep = {k: list(v) for k, v in sweep.items()}
    if seeds is not None:
        if SEED_PATH in sweep:
            raise StudyError(f"seeds: {SEED_PATH} is already swept; do not also give seeds")
        seed_list = list(range(seeds)) if isinstance(seeds, int) else [int(s) for s in seeds]
        if not seed_list:
            raise StudyError("seeds: must be >= 1")
        sweep[SEED_PATH] = seed_list
    base = copy.deepcopy(base)
    if get_path(base, SEED_PATH) is None:
        set_path(base, SEED_PATH, 0)
    paths = list(sweep)
    runs: list[RunSpec] = []
    seen: set[str] = set()
    for combo in itertools.product(*(sweep[p] for p in paths)):
        case = copy.deepcopy(base)
        params = dict(zip(paths, combo, strict=True))
        for p, v in params.items():
            set_path(case, p, v)
        label = ",".join(f"{p.rsplit('.', 1)[-1]}={_short(v)}" for p, v in params.items())
        case["name"] = f"{name}[{label}]" if label else name
        if single_rod_rule:
            apply_single_rod_rule(case)
        case = _normalise(case)
        rid = run_id(case)
        if rid in seen:
            continue
        seen.add(rid)
        seed = get_path(case, SEED_PATH, 0)
        runs.append(RunSpec(id=rid, params=_normalise(params), seed=int(seed), case=case))
    if validate:
        validate_runs(runs)
    definition = {
        "base": base,
        "sweep": sweep,
        "single_rod_rule": single_rod_rule,
        **(extra_definition or {}),
    }
    return Study(name=name, kind=kind, definition=_normalise(definition), runs=runs, quick=quick)


def validate_runs(runs: list[RunSpec]) -> None:
    """Validate every run's case; raise StudyError naming the first bad run and field."""
    from undulate.model import ConfigError, case_from_dict

    for i, r in enumerate(runs):
        try:
            case_from_dict(r.case)
        except ConfigError as err:
            first = str(err).splitlines()[0] if str(err) else "invalid case"
            label = ", ".join(f"{k}={v!r}" for k, v in r.params.items()) or "base case"
            raise StudyError(f"run {i + 1}/{len(runs)} ({label}): {first}") from None


def merge_case(base: dict[str, Any], over: dict[str, Any]) -> dict[str, Any]:
    """``over`` laid over ``base``, table by table (neither is changed)."""
    out = copy.deepcopy(base)
    for k, v in over.items():
        if isinstance(v, dict) and isinstance(out.get(k), dict):
            out[k] = merge_case(out[k], v)
        else:
            out[k] = copy.deepcopy(v)
    return out


def _flatten_sweep(table: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    """``{"rods": {"h": [..]}}`` and ``{"rods.h": [..]}`` both give ``{"rods.h": [..]}``."""
    out: dict[str, Any] = {}
    for k, v in table.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict) and not ({"start", "stop"} <= set(v)):
            out.update(_flatten_sweep(v, key + "."))
        else:
            out[key] = v
    return out


def read_toml(p: Path, label: str = "") -> dict[str, Any]:
    """The tables of TOML file ``p``; a StudyError naming it (after ``label``, e.g. an
    option) when it is missing or not valid TOML."""
    if not p.is_file():
        raise StudyError(f"{label}{p}: no such file")
    try:
        return tomllib.loads(p.read_text())
    except tomllib.TOMLDecodeError as err:
        raise StudyError(f"{label}{p}: not valid TOML: {err}") from None


def load_sweep_toml(
    path: str | Path, *, seeds: int | None = None, quick: bool = False, validate: bool = True,
    setup: dict[str, Any] | None = None,
) -> Study:
    """Read a SWEEP.toml: ``[base]`` (a case dict), ``[sweep]`` (dotted path -> list or range).

    Optional top-level ``name = "..."`` and ``[options]`` with ``seeds`` (int or list) and
    ``single_rod_rule`` (bool, default true: ``s = 0`` with ``N > 1`` means one rod ``N*b``
    wide). ``quick`` is recorded but does not change a user sweep. ``setup`` (a partial case
    dict) is laid over ``[base]``.
    """
    p = Path(path)
    data = read_toml(p)
    unknown = set(data) - {"name", "base", "sweep", "options"}
    if unknown:
        raise StudyError(f"{p}: unknown top-level keys {sorted(unknown)} (allowed: name, base, "
                         "sweep, options)")
    base = data.get("base", {})
    if not isinstance(base, dict):
        raise StudyError(f"{p}: [base] must be a table")
    if setup:
        base = merge_case(base, setup)
    raw = data.get("sweep")
    if not isinstance(raw, dict) or not raw:
        raise StudyError(f"{p}: a non-empty [sweep] table is required")
    sweep = {k: expand_values(k, v) for k, v in _flatten_sweep(raw).items()}
    opts = data.get("options", {})
    unknown = set(opts) - {"seeds", "single_rod_rule"}
    if unknown:
        raise StudyError(f"{p}: unknown [options] keys {sorted(unknown)}")
    n_seeds = seeds if seeds is not None else opts.get("seeds")
    name = str(data.get("name", p.stem))
    return build_study(
        name,
        base,
        sweep,
        kind="sweep",
        seeds=n_seeds,
        single_rod_rule=bool(opts.get("single_rod_rule", True)),
        quick=quick,
        extra_definition={"source": str(p), **({"setup": setup} if setup else {})},
        validate=validate,
    )
