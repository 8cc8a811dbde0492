"""Named set-ups shipped with the package: partial case dicts laid over a study's base case.

A *set-up* is a modelling choice tried on a whole study (``presets`` module docstring). The
named ones live as TOML files in ``undulate/study/setups/`` so that a reader can open them:

* ``study-2022`` (:data:`REFERENCE`): the reference of the study presets, chosen on the
  sentinel (docs/model.md, "The reference set-up"); today it sets ``rods.E_B = 1000`` MPa.
* ``bare``: nothing changed, the engine's defaults (the presets' set-up until 2026-12-06).

``--setup NAME`` takes either one of these names or a path to a TOML file of case tables.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path
from typing import Any

from .spec import StudyError, read_toml

__all__ = ["REFERENCE", "setup_names", "named_setup", "is_setup_name", "setup_text",
           "describe_setup"]

#: the set-up the study presets use unless told otherwise
REFERENCE = "study-2022"


def _dir() -> Path:
    return Path(str(resources.files("undulate.study") / "setups"))


def setup_names() -> list[str]:
    """The shipped set-up names, the reference first."""
    names = sorted(p.stem for p in _dir().glob("*.toml"))
    return [REFERENCE] + [n for n in names if n != REFERENCE]


def is_setup_name(text: str) -> bool:
    """True when ``text`` names a shipped set-up (not a path)."""
    return text in setup_names()


def setup_text(name: str) -> str:
    """The TOML text of a shipped set-up, comments included (they say why)."""
    if not is_setup_name(name):
        raise StudyError(f"--setup {name!r}: no such set-up; shipped: {', '.join(setup_names())} "
                         "(or a path to a TOML file)")
    return (_dir() / f"{name}.toml").read_text()


def named_setup(name: str) -> dict[str, Any]:
    """The set-up dict of a shipped name (``{}`` for ``bare``)."""
    setup_text(name)  # the one message for an unknown name
    return read_toml(_dir() / f"{name}.toml", "--setup ")


def describe_setup(setup: dict[str, Any] | None) -> str:
    """One line for reports: the shipped name a set-up equals, with its tables."""
    setup = setup or {}
    for name in setup_names():
        if named_setup(name) == setup:
            return f"{name} (`{setup}`)" if setup else f"{name} (the engine's defaults)"
    return f"`{setup}`"
