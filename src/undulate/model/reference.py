"""docs/config.md, generated from the case models of :mod:`undulate.model.config`.

    python -m undulate.model.reference docs/config.md     # rewrite the file
    python -m undulate.model.reference --check docs/config.md

Generic: every section, field, type, default, range and description is read from the pydantic
models (``Field(..., description=...)``, bounds ``gt/ge/lt/le``, ``Literal`` choices, and an
optional ``json_schema_extra={"allowed": "..."}`` for what bounds cannot say); the rules between
fields come from :data:`undulate.model.config.RULES`. Nothing here names a field.
"""

from __future__ import annotations

import sys
import types
import typing
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel
from pydantic.fields import FieldInfo
from pydantic_core import PydanticUndefined

from . import config

__all__ = ["config_markdown", "main"]

_HEADER = """# Case description (TOML)

Generated from `undulate.model.config` by `python -m undulate.model.reference docs/config.md`
(a test fails when this file is out of date). Units: mm, MPa, N, s. Rod positions are in the
*printed* (pre-stretched) configuration, origin at the fabric centre. Examples:
`examples/*.toml`.

Inputs are strict: unknown keys, NaN/inf, out-of-range values and values of the wrong type are
refused, nothing is converted (`h = "0.3"`, `N = 2.0`, `N = true`, `adaptive = "yes"` are
errors; an integer is accepted where a number is expected). Each problem is one line naming the
file and the field; every message is listed in [errors.md](errors.md).
"""


def _strip_optional(ann: Any) -> Any:
    if typing.get_origin(ann) in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(ann) if a is not type(None)]
        if len(args) == 1:
            return args[0]
    return ann


def _base(ann: Any) -> Any:
    """``Annotated[float, Strict()]`` -> ``float``."""
    while typing.get_origin(ann) is typing.Annotated:
        ann = typing.get_args(ann)[0]
    return ann


def _type_name(ann: Any) -> str:
    ann = _base(_strip_optional(ann))
    origin = typing.get_origin(ann)
    if origin in (typing.Union, types.UnionType):
        return " or ".join(_type_name(a) for a in typing.get_args(ann))
    if origin is Literal:
        return "text"
    if origin is tuple:
        return "[" + ", ".join(_type_name(a) for a in typing.get_args(ann)) + "]"
    if origin is list:
        (item,) = typing.get_args(ann)
        if isinstance(item, type) and issubclass(item, BaseModel):
            return "array of tables"
        return f"array of {_type_name(item)}"
    if isinstance(ann, type) and issubclass(ann, BaseModel):
        return "table"
    return {float: "number", int: "integer", bool: "true / false", str: "text"}.get(
        ann, getattr(ann, "__name__", str(ann))
    )


def _toml(v: Any) -> str:
    if v is None:
        return "not set"
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return f'"{v}"'
    if isinstance(v, tuple | list):
        return "[" + ", ".join(_toml(x) for x in v) + "]"
    return repr(v)


def _default(f: FieldInfo) -> str:
    if f.is_required():
        return "required"
    if f.default_factory is not None:
        value = f.default_factory()
        return "(table)" if isinstance(value, BaseModel) else f"`{_toml(value)}`"
    if f.default is PydanticUndefined:
        return "required"
    if f.default is None:
        return "not set"
    return f"`{_toml(f.default)}`"


def _allowed(model: type[BaseModel], name: str, f: FieldInfo) -> str:
    extra = f.json_schema_extra if isinstance(f.json_schema_extra, dict) else {}
    if "allowed" in extra:
        return str(extra["allowed"])
    ann = _base(_strip_optional(f.annotation))
    if typing.get_origin(ann) is Literal:
        return " / ".join(_toml(a) for a in typing.get_args(ann))
    if typing.get_origin(ann) is list:
        item = _base(typing.get_args(ann)[0])
        if typing.get_origin(item) is Literal:
            return "each of " + " / ".join(_toml(a) for a in typing.get_args(item))
    rng = config.allowed_range(model, name)
    if rng:
        return rng
    if ann is bool:
        return "true / false"
    if typing.get_origin(ann) is tuple:
        return "any"
    if ann in (float, int):
        return "any finite"
    if ann is str:
        lo = hi = None
        for m in f.metadata:
            lo = getattr(m, "min_length", lo)
            hi = getattr(m, "max_length", hi)
        if lo is not None or hi is not None:
            return f"{lo or 0} to {hi} characters"
    nested = typing.get_origin(ann) is list or (isinstance(ann, type)
                                                 and issubclass(ann, BaseModel))
    return "see below" if nested else "any"


def _table(model: type[BaseModel], title: str, out: list[str], nested: list) -> None:
    out += [f"## {title}", ""]
    doc = (model.__doc__ or "").strip().split("\n\n")[0]  # the first paragraph
    if doc:
        out += [" ".join(doc.split()), ""]
    out += ["| field | type | default | allowed | meaning |", "|---|---|---|---|---|"]
    for name, f in model.model_fields.items():
        ann = _strip_optional(f.annotation)
        if isinstance(ann, type) and issubclass(ann, BaseModel):
            nested.append((ann, f"[{title.strip('[]')}.{name}]"))  # its own section
        out.append(
            f"| `{name}` | {_type_name(f.annotation)} | {_default(f)} | "
            f"{_allowed(model, name, f)} | {f.description or ''} |"
        )
        if typing.get_origin(ann) is list:
            (item,) = typing.get_args(ann)
            if isinstance(item, type) and issubclass(item, BaseModel):
                nested.append((item, f"{title[:-1]}.{name}]]".replace("[", "[[", 1)))
    out.append("")


def config_markdown() -> str:
    """The text of docs/config.md."""
    out = [_HEADER, "## top level", ""]
    out += ["| field | type | default | allowed | meaning |", "|---|---|---|---|---|"]
    sections = []
    for name, f in config.Case.model_fields.items():
        ann = _strip_optional(f.annotation)
        if isinstance(ann, type) and issubclass(ann, BaseModel):
            sections.append((ann, f"[{name}]"))
            continue
        out.append(
            f"| `{name}` | {_type_name(f.annotation)} | {_default(f)} | "
            f"{_allowed(config.Case, name, f)} | {f.description or ''} |"
        )
    out.append("")
    for model, title in sections:
        nested: list = []
        _table(model, title, out, nested)
        for sub, subtitle in nested:  # grows while it is read: tables inside tables
            _table(sub, subtitle, out, nested)
    out += ["## Rules between fields", ""]
    out += [f"* {r}" for r in config.RULES]
    out.append("")
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    args = list(sys.argv[1:] if argv is None else argv)
    check = "--check" in args
    args = [a for a in args if a != "--check"]
    path = Path(args[0]) if args else Path("docs/config.md")
    text = config_markdown()
    if check:
        if not path.is_file() or path.read_text() != text:
            print(f"{path} is out of date: run python -m undulate.model.reference {path}")
            return 1
        return 0
    path.write_text(text)
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
