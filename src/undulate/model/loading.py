"""Reading a case: TOML files and plain dicts validated into a :class:`Case`, with every
problem reported as one line naming the field and its allowed range."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

from pydantic import (
    BaseModel,
    ValidationError,
)

from .case import Case
from .lines import Pattern
from .validators import _BOUND_SYMBOLS, ConfigError, _default, allowed_range, number_problem

_TYPE_HINTS = {
    "float_type": " (a number, written without quotes)",
    "int_type": " (a whole number, without quotes or decimal point)",
    "bool_type": " (true or false, without quotes)",
    "string_type": " (text in quotes)",
}


def _show(v: object) -> str:
    """A value as it is written in TOML (true, "text", 2.0)."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return '"' + v.replace('"', '\\"') + '"'
    if isinstance(v, list | tuple):
        return "[" + ", ".join(_show(x) for x in v) + "]"
    return repr(v)


def _field_range(loc: tuple) -> str:
    """The allowed range of the field at ``loc`` (e.g. ("rods", "h")), "" if none."""
    model: type[BaseModel] = Case
    for i, part in enumerate(loc):
        if not isinstance(part, str) or part not in model.model_fields:
            return ""
        if i == len(loc) - 1:
            return allowed_range(model, part)
        ann = model.model_fields[part].annotation
        if isinstance(ann, type) and issubclass(ann, BaseModel):
            model = ann
        else:
            return ""
    return ""


def _format_validation_error(err: ValidationError) -> str:
    lines = []
    for e in err.errors():
        loc = ".".join(str(p) for p in e["loc"])
        msg = e["msg"].removeprefix("Value error, ")
        # a rule between fields says which field it is about: "dx_far: must be ..."
        named = re.match(r"([A-Za-z_][\w.]*): (.*)", msg, re.S)
        if e["type"] == "value_error" and named:
            loc = f"{loc}.{named[1]}" if loc else named[1]
            msg = named[2]
        loc = loc or "case"
        rng = _field_range(e["loc"]) if e.get("ctx") else ""
        if not rng:
            ctx = e.get("ctx") or {}
            rng = ", ".join(f"{_BOUND_SYMBOLS[k]} {v:g}" for k, v in ctx.items()
                            if k in _BOUND_SYMBOLS and isinstance(v, int | float))
        extra = f" (allowed: {rng})" if rng else ""
        hint = _TYPE_HINTS.get(e["type"], "")
        got = e.get("input")
        got_s = f"; got {_show(got)}" if got is not None and not isinstance(got, dict) else ""
        if e["type"] == "value_error":
            got_s = ""  # the rule's own message says what was wrong
        lines.append(f"{loc}: {msg}{hint}{extra}{got_s}")
    return "\n".join(lines)


def case_from_dict(data: dict) -> Case:
    """Validate a plain dict (e.g. parsed TOML) into a :class:`Case`; raise ConfigError."""
    try:
        return Case.model_validate(data)
    except ValidationError as err:
        raise ConfigError(_format_validation_error(err)) from None


def load_case(path: str | Path) -> Case:
    """Read and validate a TOML case file; raise :class:`ConfigError` with a clear message."""
    p = Path(path)
    if p.is_dir():
        raise ConfigError(f"{p}: is a directory, not a case file (give a .toml file)")
    if not p.is_file():
        raise ConfigError(f"{p}: no such file")
    try:
        raw = p.read_bytes()
    except OSError as err:
        raise ConfigError(f"{p}: cannot read ({err.strerror})") from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as err:
        raise ConfigError(
            f"{p}: not a text file in UTF-8 (byte {err.start}); a case is a TOML text file"
        ) from None
    # a byte-order mark (some editors on Windows write one) is not part of the TOML
    text = text.removeprefix("\ufeff")
    if "\x00" in text:
        raise ConfigError(f"{p}: binary file (contains NUL bytes); a case is a TOML text file")
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise ConfigError(f"{p}: not valid TOML: {err}") from None
    if not data:
        raise ConfigError(
            f"{p}: empty case (no settings); write at least one setting, e.g. name = "
            '"my-case", to run the defaults, or use `undulate demo`'
        )
    pat = data.get("pattern")
    if isinstance(pat, dict) and "file" in pat:
        pat = dict(pat)
        drawing, scale = pat.pop("file"), pat.pop("scale", 1.0)
        if not isinstance(drawing, str) or not drawing:
            raise ConfigError(f"pattern.file: must be the path of an SVG or DXF drawing (got "
                              f"{drawing!r})")
        data = {**data, "pattern": pat}
        return with_drawing(data, p.parent / drawing, scale=scale)
    if isinstance(pat, dict) and "scale" in pat:
        raise ConfigError("pattern.scale: only with pattern.file (it scales a drawing)")
    return case_from_dict(data)


def with_drawing(data: dict, drawing: str | Path, *, scale: object = 1.0) -> Case:
    """The case ``data`` (a dict, as read from TOML) with the lines of an SVG or DXF
    ``drawing`` added to its pattern (after any lines it lists); ``scale`` multiplies the
    drawing's coordinates. Raises :class:`ConfigError` naming the file or the line."""
    from .pattern import PatternError, read_pattern

    problem = number_problem("pattern.scale", scale)
    if problem:
        raise ConfigError(problem)
    pat = dict(data.get("pattern") or {})
    res = pat.get("resolution", _default(Pattern, "resolution"))
    if number_problem("pattern.resolution", res) is not None:
        res = _default(Pattern, "resolution")  # reported by the validation below
    try:
        drawn = read_pattern(drawing, scale=float(scale), resolution=float(res))
    except PatternError as err:
        raise ConfigError(f"{Path(drawing).name}: {err}") from None
    pat["lines"] = list(pat.get("lines") or []) + [ln.to_dict() for ln in drawn]
    return case_from_dict({**data, "pattern": pat})
