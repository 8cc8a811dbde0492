"""``undulate serve``: the local web page (docs/web.md)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

__all__ = ["register"]


def serve(
    host: Annotated[str, typer.Option("--host", help="address to listen on")] = "127.0.0.1",
    port: Annotated[int, typer.Option("--port", help="port, 1..65535")] = 8000,
    jobs: Annotated[Path, typer.Option("--jobs", help="folder for the simulations' files")]
    = Path("undulate-jobs"),
    workers: Annotated[int, typer.Option(
        "--workers", help="simulations run at once (each uses the cores it can)")] = 1,
) -> None:
    """A local web page: draw lines or upload an SVG, see the prediction, simulate, download.

    Open http://127.0.0.1:8000 after starting it. Simulations run in the background, one at
    a time unless --workers says otherwise; their files stay under --jobs.
    """
    if not 1 <= port <= 65535:
        typer.echo(f"Error: --port: must be in 1..65535; got {port}", err=True)
        raise typer.Exit(code=2)
    if not 1 <= workers <= 64:
        typer.echo(f"Error: --workers: must be in 1..64; got {workers}", err=True)
        raise typer.Exit(code=2)
    if jobs.exists() and not jobs.is_dir():
        typer.echo(f"Error: --jobs: {jobs} is a file, not a folder", err=True)
        raise typer.Exit(code=2)
    try:
        import uvicorn

        from .web.app import create_app
    except ImportError as err:
        typer.echo(f"Error: undulate serve needs the web extra ({err.name} is missing): "
                   "pip install 'undulate[web]'", err=True)
        raise typer.Exit(code=2) from None
    app = create_app(jobs, workers=workers)
    typer.echo(f"undulate: serving on http://{host}:{port} (simulations in {jobs}/); "
               "Ctrl+C stops", err=True)
    uvicorn.run(app, host=host, port=port, log_level="warning")


def register(app: typer.Typer) -> None:
    """Add the ``serve`` command to ``app``."""
    app.command("serve")(serve)
