"""``undulate analyse`` and ``undulate theory``: shape analysis and the analytical model.

Call :func:`register` on a :class:`typer.Typer` app to add both commands.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console
from rich.table import Table

from ..model.config import MATERIAL_DEFAULTS as _MAT
from .common import fail as _fail

__all__ = ["register"]


def _fmt(v: object, digits: int = 4) -> str:
    if v is None:
        return "-"
    if isinstance(v, float):
        return f"{v:.{digits}g}"
    return str(v)


#: theory option -> (case section, field): the options take the case file's ranges
_THEORY_FIELDS = {
    "--h": ("Rods", "h"), "--eps0": ("Release", "eps0"), "--b": ("Rods", "b"),
    "--E-B": ("Rods", "E_B"), "--E": ("Fabric", "E"), "--t": ("Fabric", "t"),
    "--L": ("Rods", "L"), "--N": ("Rods", "N"), "--s": ("Rods", "s"),
}


def _opt_help(text: str, option: str) -> str:
    """Help text with the allowed range from the case model; rich markup escaped ("[mm]")."""
    from rich.markup import escape

    from undulate.model import config

    section, name = _THEORY_FIELDS[option]
    rng = config.allowed_range(getattr(config, section), name)
    return escape(f"{text}; allowed {rng}" if rng else text)


def _check_theory_option(option: str, value: object) -> None:
    from undulate.model import config

    section, name = _THEORY_FIELDS[option]
    try:
        config.check_value(getattr(config, section), name, value, option)
    except config.ConfigError as err:
        raise _fail(str(err)) from None


def analyse(
    directory: Annotated[Path, typer.Argument(help="simulation output directory")],
    plots: Annotated[
        bool, typer.Option("--plots/--no-plots", help="write rod_<k>_fits.png")
    ] = True,
) -> None:
    """Fit sines and arc chains to every rod of a run; update DIR/metrics.json."""
    from undulate.analysis import analyse_dir

    if not (directory / "centerlines.npz").is_file():
        raise _fail(f"{directory}: no centerlines.npz found (is this a simulation output dir?)")
    try:
        res = analyse_dir(directory, plots=plots)
    except (ValueError, OSError) as exc:
        msg = str(exc) if str(directory) in str(exc) else f"{directory}: {exc}"
        raise _fail(msg) from None
    table = Table(title=f"{directory} - family: {res['family']}")
    cols = ("rod", "n", "l", "lam", "a", "R", "r2_arcs", "r2_sine", "quality")
    for c in cols:
        table.add_column(c, justify="right")
    for r in res["rods"]:
        table.add_row(
            str(r["index"]), str(r["n"]), *(_fmt(r[k]) for k in ("l", "lam", "a", "R")),
            _fmt(r["r2_arcs"], 5), _fmt(r["r2_sine"], 5), r["quality"],
        )
    con = Console()
    con.print(table)
    coh = ", ".join(f"{c:.3f}" for c in res["coherence"]) or "-"
    con.print(f"coherence between neighbours: {coh}")
    con.print(
        f"family: [bold]{res['family']}[/bold]  (metrics written to {directory}/metrics.json)"
    )


def theory(
    h: Annotated[float, typer.Option("--h", help=_opt_help("rod thickness [mm]", "--h"))] = 0.5,
    eps0: Annotated[
        float, typer.Option("--eps0", help=_opt_help("pre-stretch strain [-]", "--eps0"))
    ] = 0.5,
    b: Annotated[float, typer.Option("--b", help=_opt_help("rod width [mm]", "--b"))] = _MAT["b"],
    E_B: Annotated[
        float, typer.Option("--E-B", help=_opt_help("rod Young's modulus [MPa]", "--E-B"))
    ] = _MAT["E_B"],
    E: Annotated[
        float, typer.Option("--E", help=_opt_help("fabric Young's modulus [MPa]", "--E"))
    ] = _MAT["E"],
    t: Annotated[
        float, typer.Option("--t", help=_opt_help("fabric thickness [mm]", "--t"))
    ] = _MAT["t"],
    L: Annotated[float, typer.Option("--L", help=_opt_help("rod length [mm]", "--L"))] = 100.0,
    N: Annotated[int, typer.Option("--N", help=_opt_help("number of parallel rods", "--N"))] = 5,
    s: Annotated[
        float | None,
        typer.Option("--s", help=_opt_help("gap between rods [mm] (gives the family)", "--s")),
    ] = None,
    phase_map: Annotated[
        bool, typer.Option("--phase-map", help="draw the (h, s) phase map instead")
    ] = False,
    out: Annotated[Path, typer.Option("--out", help="figure file for --phase-map")] = Path(
        "phase_map.png"
    ),
) -> None:
    """Analytical predictions (docs/theory.md): l, a, R, sagitta, s_hat, n, bundling.

    Every option takes the same range as the case file (docs/config.md).
    """
    from undulate import theory as T

    for option, val in (("--h", h), ("--eps0", eps0), ("--b", b), ("--E-B", E_B), ("--E", E),
                        ("--t", t), ("--L", L), ("--N", N), ("--s", s)):
        if val is not None:
            _check_theory_option(option, val)
    mat = {"b": b, "E_B": E_B, "E": E, "t": t}
    con = Console()
    if phase_map:
        path = _draw_phase_map(out, eps0=eps0, L=L, N=N, **mat)
        con.print(f"phase map written to {path}")
        return
    p = T.predictions(h, eps0, L=L, N=N, s=s, **mat)
    rows = [
        ("I_B", "mm^4", "second moment h^3 b / 12"),
        ("l", "mm", "arc length of one segment, eq. (1)"),
        ("a_formula", "mm", "amplitude formula (equals R)"),
        ("R", "mm", "arc radius l / sqrt(24 eps0)"),
        ("sagitta", "mm", "exact height of an arc of length l, radius R"),
        ("s_hat", "mm", "spacing where fabric tension relaxes, 2 a (1 + eps0)"),
        ("n", "-", "predicted half-waves: odd integer nearest L / l"),
        ("l_n", "mm", "quantized arc length L / n"),
        ("h_bundled", "mm", f"h N^(1/3): {N} touching rods as one"),
    ]
    if "family" in p:
        rows.append(("family", "-", f"predicted shape family at s = {s} mm (N = {N})"))
    table = Table(title=f"theory: h = {h} mm, eps0 = {eps0}, L = {L} mm")
    for c in ("quantity", "value", "unit", "meaning"):
        table.add_column(c)
    for key, unit, meaning in rows:
        table.add_row(key, _fmt(p[key], 5), unit, meaning)
    con.print(table)


def _draw_phase_map(out: Path, *, eps0: float, L: float, N: int, **mat: float) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np
    from matplotlib.colors import ListedColormap

    from undulate import theory as T

    h = np.linspace(0.1, 2.0, 96)
    s = np.linspace(0.0, 50.0, 101)
    H, S = np.meshgrid(h, s)
    pm = T.phase_map(H, S, eps0=eps0, L=L, N=N, **mat)
    fig, ax = plt.subplots(figsize=(6, 4.5))
    cmap = ListedColormap(["#4c72b0", "#dd8452", "#55a868", "#c44e52"])
    ax.pcolormesh(H, S, pm["code"], cmap=cmap, vmin=-0.5, vmax=3.5, shading="auto")
    ax.plot(h, T.s_hat(h, eps0, **mat), "k-", lw=2, label="s_hat = 2 a (1 + eps0)")
    for k, fam in enumerate(T.FAMILIES):
        ax.plot([], [], "s", color=cmap(k), ms=10, label=fam)
    ax.set_xlim(h[0], h[-1])
    ax.set_ylim(s[0], s[-1])
    ax.set_xlabel("rod thickness h [mm]")
    ax.set_ylabel("gap s [mm]")
    ax.set_title(f"analytical phase map (N = {N}, eps0 = {eps0}, L = {L} mm)", fontsize=9)
    ax.legend(fontsize=7, loc="upper left", framealpha=0.9)
    fig.tight_layout()
    out = Path(out)
    try:
        fig.savefig(out, dpi=120)
    except OSError as exc:
        raise _fail(f"--out {out}: cannot write ({exc})") from exc
    finally:
        plt.close(fig)
    return out


def register(app: typer.Typer) -> None:
    """Add the ``analyse`` and ``theory`` commands to ``app``."""
    app.command("analyse")(analyse)
    app.command("theory")(theory)
