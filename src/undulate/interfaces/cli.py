"""The ``undulate`` command line (typer).

    undulate demo --out DIR          default single rod (small), all outputs
    undulate run CASE.toml --out DIR any case described in TOML
    undulate analyse DIR             shape analysis of a run directory
    undulate theory --h 0.5          analytical model (SPEC section 3)
    undulate study run PRESET ...    parametric studies
"""

from __future__ import annotations

from pathlib import Path

import typer
from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    help="Rods printed on a pre-stretched textile: simulate, analyse, study. Units: mm, MPa, N, s.",
)
console = Console()


def _simulate_and_report(case, out: Path) -> None:
    from .. import api

    with Progress(
        TextColumn("[bold]release"), BarColumn(), TextColumn("{task.percentage:>3.0f}%"),
        TextColumn("{task.fields[info]}"), TimeElapsedColumn(), console=console,
        transient=False, disable=not console.is_terminal,
    ) as prog:
        task = prog.add_task("release", total=1.0, info="")

        def progress(frac: float, rec: dict) -> None:
            prog.update(task, completed=frac, info=(
                f"strain {rec['release_strain']:.3f}  max z {rec['max_height']:.2f} mm  "
                f"Newton {rec['newton_iterations']}"))

        try:
            rec = api.run_case(case, out, progress=progress)
        except api.ConvergenceError as err:
            console.print(f"[red]no equilibrium found:[/red] {err}")
            raise typer.Exit(code=3) from None
    t = Table(title=f"{case.name}: {out}")
    for col in ("quantity", "value"):
        t.add_column(col)
    for key in ("family", "n", "l_mean", "lam_mean", "a_mean", "R_mean", "r2_arcs_mean",
                "r2_sine_mean", "max_height", "newton_iterations", "wall_time_s"):
        v = rec.get(key)
        t.add_row(key, f"{v:.4g}" if isinstance(v, float) else str(v))
    console.print(t)
    console.print(f"wrote {out}/final.vtu, metrics.json, centerlines.npz, "
                  "rod_*_side.png, rod_*_fits.png")


@app.command()
def demo(out: Path = typer.Option(Path("undulate-demo"), "--out", help="output folder")) -> None:
    """Simulate the default single rod (SPEC defaults, L = 60 mm) and write all outputs."""
    from ..api import demo_case

    _simulate_and_report(demo_case(), out)


@app.command()
def run(
    config: Path = typer.Argument(..., help="case description (TOML)"),
    out: Path = typer.Option(..., "--out", help="output folder"),
) -> None:
    """Run the case described in CONFIG (TOML); see docs/config.md for every field."""
    from ..model import ConfigError, load_case

    try:
        case = load_case(config)
    except ConfigError as err:
        console.print(f"[red]invalid case {config}:[/red]\n{err}")
        raise typer.Exit(code=2) from None
    _simulate_and_report(case, out)


def _register_subcommands() -> None:
    from .cli_analysis import register as register_analysis
    from .cli_study import study_app

    register_analysis(app)
    app.add_typer(study_app, name="study")


_register_subcommands()


def main() -> None:
    app()
