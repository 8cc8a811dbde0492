"""The ``undulate`` command line (typer).

    undulate demo --out DIR          default single rod (L = 100 mm), all outputs
    undulate run CASE.toml --out DIR any case described in TOML (docs/config.md)
    undulate run --pattern F.svg --out DIR   the lines of a drawing (docs/patterns.md)
    undulate analyse DIR             shape analysis of a run directory (docs/analysis.md)
    undulate theory --h 0.5          analytical model (docs/theory.md)
    undulate design --target l=20    what to print for a wanted wave (docs/design.md)
    undulate gcode CASE.toml --out F G-code that prints the case's lines (docs/fabrication.md)
    undulate study run PRESET ...    parametric studies (docs/studies.md)
    undulate serve                   a local web page: draw, predict, simulate (docs/web.md)

Every refused input is one line on stderr naming the file, field or option, exit code 2;
docs/errors.md lists them.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console
from rich.markup import escape
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from .common import fail as _fail

app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    help="Rods printed on a pre-stretched textile: simulate, analyse, study. Units: mm, MPa, N, s.",
)
console = Console()


@app.callback()
def _settings() -> None:
    """Check the environment settings before any command runs (one line if one is bad)."""
    from ..mechanics.compiled import cache_limit_mb
    from ..solve.linear import SettingError, pardiso_threads

    try:
        pardiso_threads()
        cache_limit_mb()
    except (SettingError, ValueError) as err:
        raise _fail(str(err)) from None


def _step_text(rec: dict, total: float | None) -> str:
    """One release record as text; ``total``: the release strain at the end (eps0 minus
    release.final_strain), so that a run whose steps grew does not look cut short."""
    if rec.get("stage") == "hang":
        return (f"letting go of the clamps: {100 * rec['let_go']:.0f} %, Newton "
                f"{rec['newton_iterations']} iterations, max height {rec['max_height']:.2f} mm")
    k = rec.get("step", "?")
    of = f" of {total:.3f}" if total else ""
    return (f"release step {k}: release strain {rec['release_strain']:.3f}{of}, "
            f"Newton {rec['newton_iterations']} iterations, max height {rec['max_height']:.2f} mm")


class _Reporter:
    """Stage and release-step progress: a labelled bar on a terminal, else one line each."""

    def __init__(self, case) -> None:
        self.total = case.release.eps0 - case.release.final_strain
        self.live = console.is_terminal
        self._prog: Progress | None = None

    def __enter__(self) -> _Reporter:
        if self.live:
            self._prog = Progress(
                TextColumn("[bold]{task.description}"), BarColumn(),
                TextColumn("{task.percentage:>3.0f}%"), TimeElapsedColumn(),
                console=console, transient=False,
            )
            self._prog.start()
            self._task = self._prog.add_task("starting", total=1.0)
        return self

    def __exit__(self, *exc) -> None:
        if self._prog is not None:
            self._prog.stop()

    def note(self, text: str) -> None:
        """A line that stays (above the bar on a terminal)."""
        if self._prog is not None:
            self._prog.console.print(escape(text))
        else:
            print(text, flush=True)

    def stage(self, text: str) -> None:
        if self._prog is not None:
            self._prog.update(self._task, description=escape(text))
        else:
            print(text, flush=True)

    def progress(self, frac: float, rec: dict) -> None:
        text = _step_text(rec, self.total)
        if self._prog is not None:
            self._prog.update(self._task, completed=frac, description=escape(text))
        else:
            print(text, flush=True)


def _simulate_and_report(case, out: Path, overwrite: bool) -> None:
    from .. import api
    try:
        # the destination is checked (and its staging folder made) before anything runs
        with _Reporter(case) as rep:
            rec = api.run_case(case, out, progress=rep.progress, stage=rep.stage,
                               overwrite=overwrite, note=rep.note)
    except api.OutputError as err:
        raise _fail(str(err)) from None
    except api.ConvergenceError as err:
        raise _fail(f"no equilibrium found: {err}", code=3) from None
    t = Table(title=escape(f"{case.name}: {out}"))
    for col in ("quantity", "value"):
        t.add_column(col)
    for key in ("family", "n", "l_mean", "lam_mean", "a_mean", "R_mean", "r2_arcs_mean",
                "r2_sine_mean", "max_height", "newton_iterations", "wall_time_s"):
        v = rec.get(key)
        t.add_row(key, f"{v:.4g}" if isinstance(v, float) else str(v))
    console.print(t)
    typer.echo(f"wrote {out}/: final.vtu, printed.vtu, metrics.json, centerlines.npz, "
               "rod_*_side.png, rod_*_fits.png, top_view.png, view_3d.png")


_OVERWRITE_HELP = ("replace a previous run in --out (its files only); without it a non-empty "
                   "--out is refused")


def _demo_help() -> str:
    from ..api import demo_case

    c = demo_case()
    return (f"Simulate the default single rod (h = {c.rods.h:g} mm, L = {c.rods.L:g} mm, "
            f"E_B = {c.rods.E_B:g} MPa as in the studies' reference set-up, "
            f"{c.fabric.margin_y:g} mm of fabric each side, "
            f"{c.release.steps} release steps) and write all outputs.")


@app.command(help=_demo_help())
def demo(
    out: Path = typer.Option(Path("undulate-demo"), "--out", help="output folder"),
    overwrite: bool = typer.Option(False, "--overwrite", help=_OVERWRITE_HELP),
) -> None:
    from ..api import demo_case

    _simulate_and_report(demo_case(), out, overwrite)


@app.command()
def run(
    config: Path = typer.Argument(None, help="case description (TOML); optional with --pattern"),
    out: Path = typer.Option(..., "--out", help="output folder"),
    pattern: Path = typer.Option(
        None, "--pattern", help="lines to print from an SVG or DXF drawing (docs/patterns.md)"),
    scale: float = typer.Option(1.0, "--scale", help="multiplies the drawing's coordinates"),
    overwrite: bool = typer.Option(False, "--overwrite", help=_OVERWRITE_HELP),
) -> None:
    """Run the case described in CONFIG (TOML), or the lines of a drawing (--pattern) with
    the default settings or those of CONFIG; see docs/config.md and docs/patterns.md."""
    from ..model import ConfigError, load_case, with_drawing

    label = config if config is not None else pattern
    try:
        if config is None and pattern is None:
            raise ConfigError("give a case file (TOML), a drawing (--pattern), or both")
        if pattern is None:
            case = load_case(config)
        else:
            data = {} if config is None else load_case(config).model_dump(
                mode="json", exclude_unset=True)
            if config is not None and "pattern" in data:
                raise ConfigError("has a [pattern] already; give its lines there or in "
                                  "--pattern, not both")
            case = with_drawing(data, pattern, scale=scale)
    except ConfigError as err:
        lines = str(err).splitlines() or ["invalid case"]
        if not lines[0].startswith(str(label)):  # field errors: name the file on each line
            lines = [f"{label}: {line}" for line in lines]
        for line in lines[:-1]:
            typer.echo(f"Error: {line}", err=True)
        raise _fail(lines[-1]) from None
    _simulate_and_report(case, out, overwrite)


@app.command()
def cache(
    clear: Annotated[bool, typer.Option("--clear", help="remove every compiled kernel (the "
                                        "next run compiles them again)")] = False,
) -> None:
    """Where undulate keeps its compiled kernels and how large that is; --clear empties it.

    Location: ~/.cache/undulate/jax, or UNDULATE_JAX_CACHE_DIR (UNDULATE_JAX_CACHE=0: no
    cache). It is pruned to UNDULATE_JAX_CACHE_MB (default 150 MB), least recently used first.
    """
    from ..mechanics.compiled import cache_limit_mb, cache_root, cache_usage, clear_cache

    root = cache_root()
    if root is None:
        typer.echo("kernel cache: off (UNDULATE_JAX_CACHE=0)")
        return
    if clear:
        n, size = clear_cache(root)
        typer.echo(f"kernel cache: {root}: removed {n} files, {size / 2**20:.1f} MB")
        return
    n, size = cache_usage(root)
    typer.echo(f"kernel cache: {root}: {n} files, {size / 2**20:.1f} MB (kept under "
               f"{cache_limit_mb():g} MB, UNDULATE_JAX_CACHE_MB)")


def _register_subcommands() -> None:
    from .cli_analysis import register as register_analysis
    from .cli_design import register as register_design
    from .cli_fabrication import register as register_fabrication
    from .cli_serve import register as register_serve
    from .cli_study import study_app

    register_analysis(app)
    register_design(app)
    register_fabrication(app)
    register_serve(app)
    app.add_typer(study_app, name="study")


_register_subcommands()


def main() -> None:
    app()


if __name__ == "__main__":
    main()
