"""``undulate design`` and ``undulate predict``: what to print for a wanted wave (analytical
inverse), and what a case gives without simulating it (docs/design.md)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console
from rich.table import Table

from ..model.config import MATERIAL_DEFAULTS as _MAT

__all__ = ["register"]


def design(
    target: Annotated[list[str], typer.Option(
        "--target", help="wanted metric KEY=VALUE, repeatable: l, lam, a (mm), n (odd)")],
    L: Annotated[float, typer.Option("--L", help="line length, mm")] = 100.0,
    N: Annotated[int, typer.Option("--N", help="parallel rods in the group")] = 1,
    b: Annotated[float, typer.Option("--b", help="rod width, mm")] = _MAT["b"],
    eps0: Annotated[float, typer.Option("--eps0", help="pre-stretch, when not free")] = 0.5,
    eps0_min: Annotated[float | None, typer.Option(
        "--eps0-min", help="allowed pre-stretch range (with two targets)")] = None,
    eps0_max: Annotated[float | None, typer.Option("--eps0-max")] = None,
    h_min: Annotated[float, typer.Option("--h-min", help="thinnest printable rod, mm")] = 0.08,
    h_max: Annotated[float, typer.Option("--h-max", help="thickest printable rod, mm")] = 2.0,
    h_step: Annotated[float, typer.Option("--h-step", help="printable thickness step, mm")]
    = 0.02,
    h_tol: Annotated[float, typer.Option("--h-tol", help="printer's thickness tolerance, mm")]
    = 0.02,
    s: Annotated[float | None, typer.Option("--s", help="gap between rods, if fixed, mm")]
    = None,
    s_min: Annotated[float, typer.Option("--s-min", help="smallest allowed gap, mm")] = 0.0,
    s_max: Annotated[float, typer.Option("--s-max", help="largest allowed gap, mm")] = 50.0,
    family: Annotated[str | None, typer.Option(
        "--family", "--phase",
        help="the group's wanted family: coherent or independent (N >= 2; --phase: its "
        "former name)")] = None,
    do_refine: Annotated[bool, typer.Option(
        "--refine", help="correct h with simulations (the real engine, seconds to minutes "
        "each)")] = False,
    max_sims: Annotated[int, typer.Option("--max-sims", help="simulations for --refine")] = 4,
    tol: Annotated[float, typer.Option(
        "--tol", help="relative tolerance on the target for --refine")] = 0.03,
    as_json: Annotated[bool, typer.Option("--json", help="print one JSON object")] = False,
) -> None:
    """Printable h (and s, eps0) for a wanted arc length, wavelength, amplitude or n.

    Inverts the analytical model (eq. (1), the amplitude formula, the odd-n rule, s_hat and
    bundling); h is rounded to --h-step and the metrics are given for the rounded value,
    with how far they move for +- --h-tol. Example: undulate design --target l=20 --L 100
    """
    from ..design import Constraints, DesignError, inverse, parse_targets, refine

    try:
        targets = parse_targets(target)
        c = Constraints(L=L, N=N, b=b, h_min=h_min, h_max=h_max, h_step=h_step, h_tol=h_tol,
                        eps0=eps0, eps0_min=eps0_min, eps0_max=eps0_max, s=s, s_min=s_min,
                        s_max=s_max, family=family)
        d = inverse(targets, c)
        if do_refine and (max_sims < 1 or not 0 < tol < 1):
            raise DesignError("--max-sims, --tol: need --max-sims >= 1 and 0 < --tol < 1")
    except DesignError as err:
        typer.echo(f"Error: {err}", err=True)
        raise typer.Exit(code=2) from None
    refined = None
    if do_refine:
        from ..solve.newton import ConvergenceError

        try:
            refined = refine(d, tol=tol, max_sims=max_sims,
                             progress=lambda text: typer.echo(f"refine: {text}", err=True))
        except ConvergenceError as err:
            typer.echo(f"Error: refine: no equilibrium found: {err}", err=True)
            raise typer.Exit(code=3) from None
    if as_json:
        out = d.to_dict()
        if refined is not None:
            out["refined"] = {k: v for k, v in refined.to_dict().items() if k != "design"}
        typer.echo(json.dumps(out, indent=2))
        return
    con = Console()
    p = d.predicted
    con.print(f"print: h = {d.h:g} mm, b = {d.b:g} mm, line length L = {d.L:g} mm, "
              f"stretch eps0 = {d.eps0:.4g}"
              + (f", N = {d.N} rods at gap s = {d.s:.4g} mm" if d.N > 1 else ""))
    table = Table(title="predicted (analytical model)")
    for col in ("metric", "target", "predicted", f"h - {h_tol:g}",
                f"h + {h_tol:g}"):
        table.add_column(col)
    for k in ("l", "lam", "a", "n"):
        tgt = d.targets.get(k)
        sen = d.sensitivity[k]
        table.add_row(k, "" if tgt is None else f"{tgt:g}", f"{p[k]:.4g}",
                      f"{sen['h_minus_tol']:.4g}", f"{sen['h_plus_tol']:.4g}")
    table.add_row("family", str(d.targets.get("family", "")), str(p["family"]), "", "")
    con.print(table)
    for note in d.notes:
        con.print(f"note: {note}")
    if refined is not None:
        r = refined
        t2 = Table(title=f"refined with {len(r.history)} simulation(s): h = {r.h:g} mm "
                         f"({r.reason})")
        for col in ("metric", "target", "model at h", "simulated at h"):
            t2.add_column(col)
        for k in ("l", "lam", "a", "n"):
            tgt = d.targets.get(k)
            t2.add_row(k, "" if tgt is None else f"{tgt:g}", f"{r.predicted[k]:.4g}",
                       f"{r.simulated[k]:.4g}")
        con.print(t2)


def predict(
    config: Annotated[Path, typer.Argument(help="case description (TOML), as for 'run'")],
    as_json: Annotated[bool, typer.Option("--json", help="print JSON instead of a table")]
    = False,
    source: Annotated[str, typer.Option(
        "--source", help="auto (simulated data where the case is inside them, else theory), "
        "simulation (the nearest simulated point even outside) or theory (eq. (1))")]
    = "auto",
) -> None:
    """What 'undulate run CASE' would give, at once: the family and per rod n, l, lam, a, from
    the simulated results shipped with undulate where the case is inside them, else theory.

    Example: undulate predict examples/single_rod.toml --json
    """
    from ..design.predict import SOURCES, predict_case
    from ..model import ConfigError, load_case
    from .common import fail as _fail

    if source not in SOURCES:
        raise _fail(f"--source: must be one of {', '.join(SOURCES)} (got {source!r})")
    try:
        case = load_case(config)
    except ConfigError as err:
        line = (str(err).splitlines() or ["invalid case"])[0]
        raise _fail(line if line.startswith(str(config)) else f"{config}: {line}") from None
    res = predict_case(case, source)
    if as_json:
        typer.echo(json.dumps(res, indent=2))
        return
    con = Console()
    t = Table(title=f"{case.name}: {res['summary']}")
    for col in ("rod", "n", "l [mm]", "lam [mm]", "a [mm]"):
        t.add_column(col, justify="right")
    for r in res["rods"]:
        t.add_row(str(r["index"]), str(r["n"]), *(f"{r[k]:.4g}" if r[k] is not None else "-"
                                                  for k in ("l", "lam", "a")))
    con.print(t)
    typer.echo(f"family: {res['family']} ({res['source']}, {res['confidence']})")
    for w in res["warnings"]:
        typer.echo(f"Warning: {w}", err=True)


def register(app: typer.Typer) -> None:
    """Add the ``design`` and ``predict`` commands to ``app``."""
    app.command("design")(design)
    app.command("predict")(predict)
