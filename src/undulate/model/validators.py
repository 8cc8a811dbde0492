"""Shared pieces of the case file's validation: the strict base model, the error type, and
the helpers that state a field's allowed range in one line (used by the case's tables, the
pattern reader, design and fabrication options alike)."""

from __future__ import annotations

import math
from typing import Annotated, Any, Literal

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    ValidationError,
)


class _Strict(BaseModel):
    model_config = ConfigDict(
        extra="forbid", allow_inf_nan=False, validate_assignment=True, strict=True
    )


PosFloat = Annotated[float, Field(gt=0.0)]
#: the fabric's four edges in the stretch frame: left/right are its ends along the stretch
Edge = Literal["left", "right", "bottom", "top"]



class ConfigError(ValueError):
    """A case description is invalid. The message names each bad field and its allowed range."""



_BOUND_SYMBOLS = {"gt": ">", "ge": ">=", "lt": "<", "le": "<="}


def allowed_range(model: type[BaseModel], name: str) -> str:
    """The range of a numeric field as text, e.g. ``"> 0, <= 3"`` ("" if unbounded)."""
    parts = []
    for meta in model.model_fields[name].metadata:
        for key, sym in _BOUND_SYMBOLS.items():
            v = getattr(meta, key, None)
            if v is not None:
                parts.append(f"{sym} {v:g}")
    return ", ".join(parts)


def check_value(model: type[BaseModel], name: str, value: object, label: str) -> None:
    """Validate one field value exactly as a case file would; raise :class:`ConfigError`
    (one line starting with ``label``). Lets other interfaces share the case's ranges."""
    try:
        model.__pydantic_validator__.validate_assignment(
            model.model_construct(), name, value
        )
    except ValidationError as err:
        e = err.errors()[0]
        msg = e["msg"].removeprefix("Value error, ")
        rng = allowed_range(model, name)
        raise ConfigError(
            f"{label}: {msg}" + (f" (allowed: {rng})" if rng else "") + f"; got {value!r}"
        ) from None


def number_problem(name: str, value: object, *, above: float = 0.0,
                   inclusive: bool = False) -> str | None:
    """``None`` if ``value`` is a finite number > ``above`` (>= with ``inclusive``), else the
    one-line message ``"name: must be a number > above (got value)"``. Shared by the options
    checks of design, fabrication and patterns, each raising its own error type."""
    ok = (isinstance(value, int | float) and not isinstance(value, bool)
          and math.isfinite(value) and (value >= above if inclusive else value > above))
    if ok:
        return None
    return f"{name}: must be a number {'>=' if inclusive else '>'} {above:g} (got {value!r})"


def _default(model: type[BaseModel], name: str) -> Any:
    return model.model_fields[name].default
