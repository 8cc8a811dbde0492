"""The ``undulate`` command line (typer)."""

from __future__ import annotations

import typer

app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    help="Rods printed on a pre-stretched textile: simulate, analyse, study. Units: mm, MPa, N, s.",
)


def _register_optional() -> None:
    """Attach sub-commands that live in their own modules."""
    try:
        from .cli_analysis import register as register_analysis
    except ImportError:  # pragma: no cover - module not written yet
        pass
    else:
        register_analysis(app)
    try:
        from .cli_study import study_app
    except ImportError:  # pragma: no cover
        pass
    else:
        app.add_typer(study_app, name="study")


_register_optional()


def main() -> None:
    app()
