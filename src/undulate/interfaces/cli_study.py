"""``undulate study ...``: run resumable parametric studies, inspect them, plot and report.

Mounted by :mod:`undulate.interfaces.cli` as ``undulate study``.
"""

from __future__ import annotations

import os
import statistics
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer
from rich.console import Console
from rich.table import Table

from undulate.study.named_setups import REFERENCE, setup_names
from undulate.study.presets import preset_names, resolve_study, setup_from
from undulate.study.spec import Study, StudyError

if TYPE_CHECKING:
    from undulate.study.runner import RunSummary

study_app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    help="Parametric studies: presets (" + ", ".join(preset_names()) + ") or a SWEEP.toml; "
    "resumable, local processes or dask.",
)

_out = Console()
_err = Console(stderr=True)


def _fail(msg: str, code: int = 2) -> None:
    _err.print(f"[red]error:[/] {msg}", highlight=False, soft_wrap=True)
    raise typer.Exit(code)


#: ``--set`` and ``--setup``, shared by ``study run`` and ``study sentinel``
SetOption = Annotated[
    list[str] | None,
    typer.Option("--set", help="set-up: PATH=VALUE laid over every run's case (after --setup), "
                 "e.g. rods.E_B=10000 or 'release.clamps=[\"left\",\"right\",\"top\"]' "
                 "(repeat for more)"),
]
SetupOption = Annotated[
    str | None,
    typer.Option("--setup", help="set-up laid over every run's case: a shipped name ("
                 + ", ".join(setup_names()) + f") or a TOML file of case tables \\[presets: "
                 f"{REFERENCE}; a SWEEP.toml: none]"),
]
WorkersOption = Annotated[
    int | None,
    typer.Option("--workers", "-j", min=1, help="local processes \\[default: cpu count]"),
]
RunnerOption = Annotated[
    str | None, typer.Option("--runner", hidden=True, help="module:function replacing run_case")
]
Quick60Option = Annotated[
    bool, typer.Option("--quick", help="coarse, cheap variant (L = 60 mm)")
]


@study_app.command("run")
def run_cmd(
    target: Annotated[str, typer.Argument(help="preset name or path to a SWEEP.toml")],
    out: Annotated[Path, typer.Option("--out", "-o", help="study directory")],
    quick: Annotated[bool, typer.Option("--quick", help="coarse, cheap variant")] = False,
    workers: WorkersOption = None,
    dask: Annotated[
        str | None, typer.Option("--dask", help="dask.distributed scheduler address")
    ] = None,
    retry_failed: Annotated[
        bool, typer.Option("--retry-failed", help="run failed runs again")
    ] = False,
    no_artifacts: Annotated[
        bool, typer.Option("--no-artifacts", help="do not keep per-run artifacts")
    ] = False,
    seeds: Annotated[
        int | None, typer.Option("--seeds", min=1, help="seeds 0..K-1 per parameter point")
    ] = None,
    batch: Annotated[
        int,
        typer.Option("--batch", min=1, max=4096,
                     help="release up to this many runs that share a mesh (runs over h, E_B, "
                          "the seed) together in one worker, their evaluations batched "
                          "(for a GPU; same states as one by one)"),
    ] = 1,
    settings: SetOption = None,
    setup_file: SetupOption = None,
    runner: RunnerOption = None,
) -> None:
    """Run (or resume) a study into OUT; finished runs are skipped."""
    try:
        setup = setup_from(settings or [], setup_file, preset=target in preset_names())
        study = resolve_study(target, quick=quick, seeds=seeds, setup=setup)
    except StudyError as err:
        _fail(str(err))
    _run(study, out, runner=runner, workers=workers, dask=dask, retry_failed=retry_failed,
         artifacts=not no_artifacts, batch=batch)


def _run(study: Study, out: Path, *, runner: str | None, workers: int | None,
         dask: str | None, retry_failed: bool, artifacts: bool, batch: int) -> RunSummary:
    """Run a built study with progress on stderr; the run summary, or exit on an error."""
    from undulate.study.runner import RUNNER_ENV, run_study

    _err.print(f"study [bold]{study.name}[/]: {len(study.runs)} runs -> {out}", highlight=False,
               soft_wrap=True)
    try:
        summary = run_study(
            study,
            out,
            run_fn=runner or os.environ.get(RUNNER_ENV) or None,
            workers=workers,
            dask_address=dask,
            retry_failed=retry_failed,
            artifacts=artifacts,
            progress=True,
            console=_err,
            batch=batch,
        )
    except StudyError as err:
        _fail(str(err))
    except KeyboardInterrupt:
        _err.print("interrupted: finished runs are saved; run the same command to resume")
        _exit_now(130)
    _err.print(
        f"ran {summary.ran} ({summary.ok} ok, {summary.failed} failed) in {summary.wall_s:.1f} s;"
        f" skipped {summary.skipped_ok} done"
        + (f" ({summary.stale} finished runs run again: their rod spacing is not today's "
           "default)" if summary.stale else "")
        + (f", {summary.skipped_failed} failed (use --retry-failed)" if summary.skipped_failed
           else "")
        + (f"; table: {summary.table}" if summary.table else ""),
        highlight=False,
        soft_wrap=True,
    )
    if summary.invalid_files:
        _err.print(f"[yellow]ignored {len(summary.invalid_files)} invalid record file(s)[/]")
    return summary


@study_app.command("sentinel")
def sentinel_cmd(
    out: Annotated[Path, typer.Option("--out", "-o", help="study directory")],
    settings: SetOption = None,
    setup_file: SetupOption = None,
    quick: Quick60Option = False,
    workers: WorkersOption = None,
    retry_failed: Annotated[
        bool, typer.Option("--retry-failed", help="run failed runs again")
    ] = False,
    runner: RunnerOption = None,
) -> None:
    """Judge a modelling set-up against the study in minutes: 12 runs (single rods across h,
    five rods in each corner of the (h, s) plane), then per case n, family, onset and
    R_up/R_down beside what the study says there (also written to OUT/sentinel.md)."""
    from undulate.study import sentinel
    from undulate.study.storage import collect

    try:
        setup = setup_from(settings or [], setup_file, preset=True)
        study = resolve_study("sentinel", quick=quick, setup=setup)
    except StudyError as err:
        _fail(str(err))
    _run(study, out, runner=runner, workers=workers, dask=None, retry_failed=retry_failed,
         artifacts=False, batch=1)
    rows = sentinel.judge(collect(out))
    text = sentinel.markdown(rows, setup)
    (out / "sentinel.md").write_text(text)
    _print_sentinel(rows, sentinel.summary(rows))
    _out.print(str(out / "sentinel.md"), highlight=False, soft_wrap=True)


@study_app.command("transitions")
def transitions_cmd(
    out: Annotated[Path, typer.Option("--out", "-o", help="study directory (resumable)")],
    gaps: Annotated[
        list[float] | None,
        typer.Option("--s", help="gap between the five rods [mm] (repeat) \\[default: 0, 10, "
                     "25, 50]"),
    ] = None,
    names: Annotated[
        list[str] | None,
        typer.Option("--transition", help="e.g. 3->1 (repeat) \\[default: 3->1, 5->3, 7->5]"),
    ] = None,
    tol: Annotated[float, typer.Option("--tol", help="half-width of the final bracket [mm]")]
    = 0.01,
    known: Annotated[
        Path | None,
        typer.Option("--from", help="a phase-diagram table.csv on the same set-up: its runs "
                     "count as simulated points (fewer runs)"),
    ] = None,
    settings: SetOption = None,
    setup_file: SetupOption = None,
    quick: Quick60Option = False,
    workers: WorkersOption = None,
    runner: RunnerOption = None,
) -> None:
    """Locate the transitions n+2 -> n of five parallel rods by bisection in h: h* at each gap
    to +-TOL mm (OUT/table.csv, OUT/transitions.png), rounds of runs in parallel."""
    import pandas as pd

    from undulate.study import transitions as tr

    try:
        setup = setup_from(settings or [], setup_file, preset=True)
        chosen = dict(tr.parse_transition(t) for t in names) if names else None
        table = pd.read_csv(known) if known is not None else None
    except StudyError as err:
        _fail(str(err))
    except (OSError, pd.errors.ParserError) as err:
        _fail(f"--from {known}: {err}")

    def run_round(study: Study) -> None:
        summary = _run(study, out, runner=runner, workers=workers, dask=None,
                       retry_failed=False, artifacts=False, batch=1)
        del summary

    try:
        result = tr.find_transitions(out, run_round, s_values=gaps or tr.DEFAULT_S,
                                     transitions=chosen, tol=tol, quick=quick,
                                     setup=setup or None, known=table,
                                     say=lambda t: _err.print(t, highlight=False))
    except StudyError as err:
        _fail(str(err))
    result.to_csv(out / "table.csv", index=False)
    tr.plot_transitions(result, out / "transitions.png")
    _out.print(result.to_string(index=False), highlight=False, markup=False)
    ratios = tr.bundling_ratios(result)
    if not ratios.empty:
        _out.print(ratios.to_string(index=False), highlight=False, markup=False)
    _out.print(str(out / "table.csv"), highlight=False, soft_wrap=True)


@study_app.command("setups")
def setups_cmd(
    name: Annotated[str | None, typer.Argument(help="print this set-up's TOML (with why)")]
    = None,
) -> None:
    """The shipped set-ups (--setup NAME): their names, or one's TOML text, comments included."""
    from undulate.study.named_setups import describe_setup, named_setup, setup_text

    try:
        if name is not None:
            _out.print(setup_text(name), highlight=False, soft_wrap=True, markup=False)
            return
        for n in setup_names():
            mark = "  (the presets' reference)" if n == REFERENCE else ""
            _out.print(f"{describe_setup(named_setup(n))}{mark}", highlight=False,
                       soft_wrap=True, markup=False)
    except StudyError as err:
        _fail(str(err))


@study_app.command("compare")
def compare_cmd(
    directories: Annotated[list[Path], typer.Argument(help="sentinel study directories")],
    out: Annotated[Path | None, typer.Option("--out", help="also write the table here")]
    = None,
) -> None:
    """Candidate set-ups side by side: several sentinel directories judged against the study,
    one row each (scores, then each case's family and n)."""
    from undulate.study import sentinel
    from undulate.study.storage import collect, read_study

    entries = []
    for d in directories:
        meta = read_study(d)
        if meta is None or meta.get("name") != "sentinel":
            _fail(f"{d}: not a sentinel study directory (run: undulate study sentinel --out {d})")
        setup = (meta.get("definition") or {}).get("setup")
        entries.append((d.name, setup, sentinel.judge(collect(d))))
    text = sentinel.compare_markdown(entries)
    if out is not None:
        out.write_text(text)
    _out.print(text, highlight=False, soft_wrap=True, markup=False)


def _print_sentinel(rows: list[dict], s: dict) -> None:
    from undulate.study.sentinel import ONSET_SPREAD_MAX

    def mark(ok: object, what: str) -> str:
        return "" if ok is None else (f"[green]{what}[/]" if ok else f"[red]{what}![/]")

    t = Table(title="sentinel: this set-up against the study (! = MISMATCH)")
    for col in ("case", "study: family, n", "here: family, n", "onset", "Rup/Rdn", "verdict"):
        t.add_column(col)
    for r in rows:
        if r.get("status") != "ok":
            t.add_row(r["case"], r["expect_family"], str(r.get("status")), "", "",
                      r.get("error", ""))
            continue
        lo, hi = r["expect_n"]
        ratio = r["R_up_over_down"]
        t.add_row(r["case"], f"{r['expect_family']}, {lo if lo == hi else f'{lo}-{hi}'}",
                  f"{r['family']}, {r['n']}",
                  f"{r['onset']:.4f}" if r["onset"] == r["onset"] else "-",
                  f"{ratio:.3f}" if ratio == ratio else "-",
                  " ".join(m for m in (mark(r["family_ok"], "family"), mark(r["n_ok"], "n"),
                                       mark(r["updown_ok"], "up/down")) if m))
    _out.print(t)
    spread = s["onset_spread"]
    _out.print(
        f"families {s['family_match']}/{s['ok']}, n {s['n_match']}/{s['ok']}, up more curved "
        f"{s['updown_match']}/{s['updown_judged']}; single rods' onset max/min "
        + (f"{spread:.2f}" if spread == spread else "-")
        + f" (one critical strain: <= {ONSET_SPREAD_MAX:g}): "
        + ("-" if s["onset_ok"] is None else "MATCH" if s["onset_ok"] else "MISMATCH"),
        highlight=False, soft_wrap=True)


@study_app.command("status")
def status_cmd(
    directory: Annotated[Path, typer.Argument(help="study directory")],
) -> None:
    """Summarise a study: done / failed / pending, run times, first error lines."""
    from undulate.study.storage import read_study, scan_runs, write_table

    meta = read_study(directory)
    scan = scan_runs(directory)
    if meta is None and not scan.records:
        _fail(f"{directory}: not a study directory (no study.json, no runs/)")
    meta = meta or {}
    expected = [r["id"] for r in meta.get("runs", [])] or list(scan.records)
    recs = [scan.records[i] for i in expected if i in scan.records]
    ok = [r for r in recs if r["status"] == "ok"]
    failed = [r for r in recs if r["status"] == "failed"]
    t = Table(title=f"study {meta.get('name', '?')}" + (" (quick)" if meta.get("quick") else ""))
    t.add_column("item")
    t.add_column("value", justify="right")
    t.add_row("total", str(len(expected)))
    t.add_row("done (ok)", str(len(ok)))
    t.add_row("failed", str(len(failed)))
    t.add_row("pending", str(len(expected) - len(recs)))
    times = [float(r["elapsed_s"]) for r in ok if r.get("elapsed_s") is not None]
    if times:
        t.add_row("run time min / median / max \\[s]",
                  f"{min(times):.3g} / {statistics.median(times):.3g} / {max(times):.3g}")
        t.add_row("run time total \\[s]", f"{sum(times):.4g}")
    if scan.invalid or scan.tmp:
        t.add_row("ignored files (invalid / tmp)", f"{len(scan.invalid)} / {len(scan.tmp)}")
    _out.print(t)
    if failed:
        _out.print("[bold]failures[/] (first error line):")
        for r in failed[:20]:
            first = (r.get("error") or "?").splitlines()[0]
            _out.print(f"  {r['id']} {r.get('params')}: {first}", highlight=False, soft_wrap=True)
        if len(failed) > 20:
            _out.print(f"  ... and {len(failed) - 20} more")
    for p in scan.invalid:
        _out.print(f"[yellow]invalid record ignored:[/] {p}", highlight=False, soft_wrap=True)
    if recs:
        write_table(directory)


@study_app.command("table")
def table_cmd(
    directory: Annotated[Path, typer.Argument(help="study directory")],
    out: Annotated[Path | None, typer.Option("--out", help="CSV file (default DIR/table.csv)")]
    = None,
) -> None:
    """Write the study's table as CSV, one row per run: inputs, status, cost, mean metrics,
    onset of buckling and per-rod lists (JSON) first, then every other recorded field."""
    from undulate.study.storage import write_csv

    if not (directory / "runs").is_dir():
        _fail(f"{directory}: not a study directory (no runs/)")
    if out is not None and out.is_dir():
        _fail(f"--out {out}: is a folder; give a file name such as {out / 'table.csv'}")
    _out.print(str(write_csv(directory, out)), highlight=False, soft_wrap=True)


@study_app.command("figures")
def figures_cmd(directory: Annotated[Path, typer.Argument(help="study directory")]) -> None:
    """Make the figures the study's data support (PNG + PDF in DIR/figures)."""
    from undulate.study.figures import make_figures

    if not (directory / "runs").is_dir():
        _fail(f"{directory}: not a study directory (no runs/)")
    made = make_figures(directory)
    if not made:
        _err.print("no figure: not enough successful runs with the needed metrics")
    for _name, paths in made.items():
        for p in paths:
            _out.print(str(p), highlight=False, soft_wrap=True)


@study_app.command("report")
def report_cmd(directory: Annotated[Path, typer.Argument(help="study directory")]) -> None:
    """Write DIR/report.md (figures, fitted slopes/exponents vs theory, bundling ratios)."""
    from undulate.study.report import write_report

    if not (directory / "runs").is_dir():
        _fail(f"{directory}: not a study directory (no runs/)")
    _out.print(str(write_report(directory)), highlight=False, soft_wrap=True)


def _exit_now(code: int) -> None:
    """Stop this process and its worker processes at once. A normal exit would first wait for
    the worker pool's threads, i.e. for the runs in flight (measured: an interrupted study
    kept running until they ended); their results are lost either way, finished runs are
    already on disk."""
    import multiprocessing
    import os
    import sys

    for child in multiprocessing.active_children():
        child.terminate()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


# `study atlas` lives in its own module (this one is long enough)
from .cli_study_atlas import atlas_cmd  # noqa: E402

study_app.command("atlas")(atlas_cmd)
