"""Transitions of the quantized states, located by bisection in h (finer than a sweep's grid).

For N = 5 parallel rods at gap s, the transition ``"n+2->n"`` happens at h*_n(s), the smallest
rod thickness whose final state has at most n half-waves (the phase diagram's definition,
:func:`.derived.hstar`). A sweep on a 0.1 mm grid knows h* to +-0.05 mm; here each
(transition, s) is bracketed on a coarse grid and then halved until the bracket is at most
2 x ``tol`` wide:

    lo = the largest simulated h below hi whose n is above the target (n > n)
    hi = the smallest simulated h whose n is at most the target
    h_star = (lo + hi) / 2, known to +-(hi - lo) / 2

All transitions at one s share their runs (a run at (h, s) tells every transition its n), and
each round of bisection runs the next midpoints of every open bracket together, so two worker
processes stay busy. The runs are an ordinary study directory (``name = "transitions"``): an
interrupted search resumes where it stopped, since the same brackets give the same midpoints
and finished runs are skipped. A run that fails is left out; its bracket tries a point a
quarter of the way in instead, and is reported as unresolved if those fail too.

Where n(h) is not monotone (a state that comes back at larger h), the bracket is the first
crossing from above: the smallest h at or below the target and the largest h above it below
that.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pandas as pd

from .spec import RunSpec, Study, StudyError, build_study

__all__ = ["TRANSITIONS", "COARSE_H", "Bracket", "parse_transition", "transitions_study",
           "find_transitions", "bundling_ratios", "plot_transitions"]

#: the transitions of the study: name -> target n (h* = smallest h with n <= target)
TRANSITIONS: dict[str, int] = {"3->1": 1, "5->3": 3, "7->5": 5}
#: the coarse grid every gap starts from [mm] (the phase diagram's h range, 0.1-2.0 mm)
COARSE_H = (0.1, 0.2, 0.3, 0.5, 0.8, 1.2, 2.0)
#: the study's gaps [mm]
DEFAULT_S = (0.0, 10.0, 25.0, 50.0)
N_RODS = 5
MAX_ROUNDS = 14
H_DIGITS = 4  # h rounded to 0.1 um: the same bracket always asks for the same run


def parse_transition(text: str) -> tuple[str, int]:
    """``"3->1"`` -> ``("3->1", 1)``; the two odd numbers must differ by 2."""
    a, sep, b = text.replace(" ", "").partition("->")
    try:
        hi_n, lo_n = int(a), int(b)
    except ValueError:
        hi_n = lo_n = -1
    if not sep or lo_n < 1 or hi_n != lo_n + 2 or lo_n % 2 == 0:
        raise StudyError(f"--transition {text!r}: give two odd numbers of half-waves that differ "
                         "by 2, e.g. 3->1, 5->3, 7->5")
    return f"{hi_n}->{lo_n}", lo_n


@dataclass
class Bracket:
    """The state of one (transition, s) search."""

    transition: str
    target: int
    s: float
    lo: float | None = None
    hi: float | None = None
    n_lo: int | None = None
    n_hi: int | None = None
    status: str = "open"
    tried_failed: set[float] = field(default_factory=set)

    def update(self, points: dict[float, int], tol: float, h_range: tuple[float, float]) -> None:
        """Re-derive lo/hi from the simulated points at this s and set the status."""
        self.lo = self.hi = self.n_lo = self.n_hi = None
        at_or_below = sorted(h for h, n in points.items() if n <= self.target)
        if not at_or_below:
            self.status = f"n > {self.target} up to h = {max(points, default=h_range[1]):g} mm"
            return
        self.hi = at_or_below[0]
        self.n_hi = points[self.hi]
        above = [h for h, n in points.items() if n > self.target and h < self.hi]
        if not above:
            self.status = f"n <= {self.target} already at h = {self.hi:g} mm"
            return
        self.lo = max(above)
        self.n_lo = points[self.lo]
        self.status = "ok" if self.hi - self.lo <= 2 * tol + 1e-12 else "open"

    def next_h(self) -> float | None:
        """The next thickness to simulate (None when closed or stuck)."""
        if self.status != "open" or self.lo is None or self.hi is None:
            return None
        for frac in (0.5, 0.25, 0.75):
            h = round(self.lo + frac * (self.hi - self.lo), H_DIGITS)
            if self.lo < h < self.hi and h not in self.tried_failed:
                return h
        self.status = "unresolved: the runs inside the bracket failed"
        return None

    @property
    def h_star(self) -> float:
        if self.status != "ok" or self.lo is None or self.hi is None:
            return math.nan
        return 0.5 * (self.lo + self.hi)


def transitions_study(points: list[tuple[float, float]], *, quick: bool = False,
                      setup: dict[str, Any] | None = None) -> Study:
    """The study of five-rod runs at ``points`` [(s, h), ...]: the parallel-phase-diagram's base
    case (its set-up, s = 0 as one rod 5 b wide), one run per point, sorted."""
    from .presets import _base, _setup_definition

    base = _base(quick, {"N": N_RODS, "h": 0.3, "s": 10.0}, {"eps0": 0.5}, setup)
    runs: list[RunSpec] = []
    for s, h in sorted(set(points)):
        runs += build_study("transitions", base, {"rods.h": [h], "rods.s": [s]},
                            kind="preset", quick=quick).runs
    definition = {"base": base, "N_nominal": N_RODS, **_setup_definition(setup)}
    return Study(name="transitions", kind="preset", definition=definition, runs=runs,
                 quick=quick)


RunRound = Callable[[Study], None]


def _n_of(rec: dict[str, Any]) -> int | None:
    if rec.get("status") != "ok":
        return None
    r = rec.get("record") or {}
    n = r.get("n_mode", r.get("n"))
    if n is None and r.get("n_mean") is not None:
        n = round(float(r["n_mean"]))
    return None if n is None else int(n)


def find_transitions(
    out: str | Path,
    run_round: RunRound,
    *,
    s_values: tuple[float, ...] | list[float] = DEFAULT_S,
    transitions: dict[str, int] | None = None,
    tol: float = 0.01,
    quick: bool = False,
    setup: dict[str, Any] | None = None,
    known: pd.DataFrame | None = None,
    say: Callable[[str], None] | None = None,
) -> pd.DataFrame:
    """Bisect every (transition, s) to +-``tol`` mm; the table (one row per pair).

    ``run_round(study)`` runs a study into ``out`` (finished runs skipped), e.g.
    :func:`.runner.run_study` with its options bound. ``known``: a phase-diagram table on the
    same set-up (columns s, h, n or n_mode, status), whose runs count as simulated points.
    Columns of the result: transition, s, h_star, h_lo, h_hi, n_lo, n_hi, runs (runs
    simulated at that s, shared by its transitions), status.
    """
    from .storage import scan_runs

    out = Path(out)
    transitions = dict(TRANSITIONS if transitions is None else transitions)
    if not (0 < tol <= 0.5):
        raise StudyError(f"--tol: must be in (0, 0.5] mm (got {tol:g})")
    if not transitions or not s_values:
        raise StudyError("give at least one transition and one gap s")
    for s in s_values:
        if not (0 <= s <= 1000):
            raise StudyError(f"--s: each gap must be in [0, 1000] mm (got {s:g})")
    say = say or (lambda _t: None)
    s_values = sorted({float(s) for s in s_values})
    h_range = (min(COARSE_H), max(COARSE_H))
    table_pts: dict[float, dict[float, int]] = {s: {} for s in s_values}
    if known is not None and not known.empty:
        from .derived import n_values, ok_rows

        d = ok_rows(known)
        d = d.assign(_n=n_values(d))
        for s in s_values:
            for h, grp in d[(d["s"] - s).abs() < 1e-9].groupby("h"):
                table_pts[s][round(float(h), H_DIGITS)] = int(grp["_n"].median())
    asked: set[tuple[float, float]] = set()
    for s in s_values:
        if len(table_pts[s]) < 5:
            asked |= {(s, h) for h in COARSE_H if h not in table_pts[s]}
    brackets = [Bracket(name, target, s) for s in s_values for name, target in
                transitions.items()]
    for rnd in range(MAX_ROUNDS + 1):
        study = transitions_study(sorted(asked), quick=quick, setup=setup)
        if study.runs:
            say(f"transitions: round {rnd}, {len(study.runs)} runs in all")
            run_round(study)
        records = scan_runs(out).records
        sim_pts: dict[float, dict[float, int]] = {s: {} for s in s_values}
        failed: dict[float, set[float]] = {s: set() for s in s_values}
        for r in study.runs:
            s, h = float(r.params["rods.s"]), float(r.params["rods.h"])
            rec = records.get(r.id)
            n = _n_of(rec) if rec is not None else None
            if n is not None:
                sim_pts[s][h] = n
            elif rec is not None:
                failed[s].add(h)
        new: set[tuple[float, float]] = set()
        for b in brackets:
            pts = {**table_pts[b.s], **sim_pts[b.s]}
            b.tried_failed = failed[b.s]
            b.update(pts, tol, h_range)
            h = b.next_h()
            if h is not None:
                new.add((b.s, h))
        if not new - asked:
            break
        asked |= new
    else:
        for b in brackets:
            if b.status == "open":
                b.status = f"unresolved after {MAX_ROUNDS} rounds"
    counts = {s: sum(1 for (ss, _h) in asked if ss == s) for s in s_values}
    rows = [{"transition": b.transition, "s": b.s, "h_star": b.h_star, "h_lo": b.lo,
             "h_hi": b.hi, "n_lo": b.n_lo, "n_hi": b.n_hi, "runs": counts[b.s],
             "status": b.status} for b in brackets]
    return pd.DataFrame(rows)


def bundling_ratios(table: pd.DataFrame) -> pd.DataFrame:
    """h*(smallest s) / h*(largest s) per transition, beside N^(1/3) (the bundling estimate)."""
    rows = []
    for name, grp in table.groupby("transition", sort=False):
        g = grp.dropna(subset=["h_star"]).sort_values("s")
        if len(g) < 2:
            continue
        rows.append({"transition": name, "s_small": float(g["s"].iloc[0]),
                     "s_large": float(g["s"].iloc[-1]),
                     "ratio": float(g["h_star"].iloc[0] / g["h_star"].iloc[-1]),
                     "N_cbrt": N_RODS ** (1 / 3)})
    return pd.DataFrame(rows)


def plot_transitions(table: pd.DataFrame, path: str | Path) -> list[Path]:
    """h* against s for each transition, with the bracket as error bar; PNG and PDF."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.0, 4.2))
    for name, grp in table.groupby("transition", sort=False):
        g = grp.dropna(subset=["h_star"]).sort_values("s")
        if g.empty:
            continue
        err = 0.5 * (g["h_hi"] - g["h_lo"])
        ax.errorbar(g["s"], g["h_star"], yerr=err, marker="o", capsize=3, label=name)
    ratios = bundling_ratios(table)
    text = ", ".join(f"{r.transition}: {r.ratio:.2f}" for r in ratios.itertuples())
    ax.set_xlabel("gap between rods s [mm]")
    ax.set_ylabel("transition thickness h* [mm]")
    title = "Transitions n+2 -> n (N = 5 rods), by bisection"
    if text:
        title += f"\nh*(s min)/h*(s max): {text}; N^(1/3) = {N_RODS ** (1 / 3):.2f}"
    ax.set_title(title, fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(title="transition")
    fig.tight_layout()
    path = Path(path)
    outs = [path.with_suffix(".png"), path.with_suffix(".pdf")]
    for p in outs:
        fig.savefig(p, dpi=150)
    plt.close(fig)
    return outs
