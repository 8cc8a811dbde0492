"""What every command of the command line shares: the one-line error."""

from __future__ import annotations

import typer


def fail(msg: str, code: int = 2) -> typer.Exit:
    """Print ``Error: msg`` (one line, no markup) on stderr; return the Exit to raise."""
    typer.echo(f"Error: {msg}", err=True)
    return typer.Exit(code=code)
