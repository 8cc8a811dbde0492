"""Refine an analytical design with simulations: secant steps on the printable thickness.

The simulated metric (median over the rods of a group) is a monotone function of h away from
the quantization plateaus, and one simulation costs seconds to minutes, so a root finder that
needs few evaluations is the right tool: a secant on h, started from the analytical design
and its first correction by the model's proportionality (l, lam and a are proportional to h
in the model, so h_1 = h_0 x target / simulated). Every thickness tried is a multiple of the
printer's step (what can be printed is what is simulated); a step that lands on a thickness
already tried moves one printer step towards the target instead. It stops when the metric is
within ``tol`` of the target, when two neighbouring printable thicknesses bracket the target
(the best of them is the answer: nothing printable is closer), or after ``max_sims``.
A surrogate over the study tables was not chosen: they cover one pre-stretch and one rod
length, and a design asks for others.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import Any

from .inverse import Constraints, Design, DesignError, forward

__all__ = ["Refined", "refine", "case_of_design"]

SimulateFn = Callable[[dict[str, Any]], dict[str, Any]]


@dataclass
class Refined:
    """The refined design, every simulation it took, and model vs simulation side by side."""

    design: Design
    metric: str
    target: float
    h: float
    simulated: dict[str, Any]
    predicted: dict[str, Any]
    history: list[dict[str, Any]] = field(default_factory=list)
    converged: bool = False
    reason: str = ""

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["design"] = self.design.to_dict()
        return d


def case_of_design(d: Design, h: float) -> dict[str, Any]:
    """The simulation case (a dict for :func:`undulate.model.case_from_dict`) of a design at
    thickness ``h``: the case file's defaults for everything the design does not set."""
    rods: dict[str, Any] = {"h": h, "b": d.b, "L": d.L, "N": d.N}
    if d.N > 1:
        rods["s"] = d.s
    return {"name": f"design-h{h:g}", "rods": rods, "release": {"eps0": d.eps0}}


def _simulate_metrics(case: dict[str, Any]) -> dict[str, Any]:
    from ..pipeline import analyse, simulate

    result = simulate(case)
    ana = analyse(result)
    rods = ana["rods"]

    def med(key: str) -> float:
        vals = sorted(float(r[key]) for r in rods if r.get(key) is not None)
        if not vals:
            return float("nan")
        m = len(vals) // 2
        return vals[m] if len(vals) % 2 else 0.5 * (vals[m - 1] + vals[m])

    return {"l": med("l"), "lam": med("lam"), "a": med("a"), "R": med("R"),
            "n": int(round(med("n"))), "family": ana.get("family"),
            "newton_iterations": sum(h["newton_iterations"] for h in result.history)}


def refine(d: Design, *, metric: str | None = None, tol: float = 0.03, max_sims: int = 4,
           simulate: SimulateFn | None = None,
           progress: Callable[[str], None] | None = None) -> Refined:
    """Simulate the design and correct its h until ``metric`` is within ``tol`` (relative)
    of its target. ``metric``: the design's size target (l, lam, a; n is met when equal).
    ``simulate(case_dict) -> metrics`` defaults to the real engine."""
    sim = simulate or _simulate_metrics
    size = [k for k in ("n", "l", "lam", "a") if k in d.targets]
    metric = metric or (size[0] if size else None)
    if metric is None or metric not in d.targets:
        raise DesignError("refine: the design has no l, lam, a or n target to refine")
    if not (0 < tol < 1) or max_sims < 1:
        raise DesignError("refine: needs 0 < tol < 1 and max_sims >= 1")
    target = float(d.targets[metric])  # type: ignore[arg-type]
    c = Constraints(L=d.L, N=d.N, b=d.b, eps0=d.eps0, s=d.s, h_step=d.h_step)
    step = c.h_step
    tried: dict[float, dict[str, Any]] = {}

    def run(h: float) -> dict[str, Any]:
        h = float(f"{h:.10g}")
        if progress:
            progress(f"simulation {len(tried) + 1}/{max_sims}: h = {h:g} mm")
        m = sim(case_of_design(d, h))
        tried[h] = m
        if progress:
            progress(f"  {metric} = {m[metric]:.4g} (target {target:g}), n = {m['n']}")
        return m

    def err(m: dict[str, Any]) -> float:
        if metric == "n":
            return float(m["n"] - target)  # n falls as h grows
        return float(m[metric]) / target - 1.0

    def snap(h: float) -> float:
        return float(f"{max(round(h / step), 1) * step:.10g}")

    h = snap(d.h)
    reason = f"{max_sims} simulations"
    converged = False
    while len(tried) < max_sims:
        m = run(h)
        e = err(m)
        if (metric == "n" and e == 0) or (metric != "n" and abs(e) <= tol):
            converged, reason = True, ("n met" if metric == "n" else f"within {tol:g}")
            break
        lo_h = max((x for x in tried if x < h and _sign(err(tried[x])) != _sign(e)),
                   default=None)
        hi_h = min((x for x in tried if x > h and _sign(err(tried[x])) != _sign(e)),
                   default=None)
        if any(x is not None and abs(x - h) <= step * 1.0001 for x in (lo_h, hi_h)):
            reason = "bracketed by neighbouring printable thicknesses"
            break
        h_new = _next_h(h, m, tried, metric, target, err, step)
        h_new = snap(h_new)
        if h_new in tried or h_new == h:
            h_new = snap(h + step * (_direction(metric, e)))
        if h_new in tried:
            reason = "no printable thickness left to try"
            break
        h = h_new
    best_h = min(tried, key=lambda x: abs(err(tried[x])))
    pred = forward(best_h, d.eps0, c, s=d.s)
    return Refined(design=d, metric=metric, target=target, h=best_h, simulated=tried[best_h],
                   predicted={k: pred[k] for k in ("l", "lam", "a", "n", "family")},
                   history=[{"h": x, **tried[x]} for x in tried], converged=converged,
                   reason=reason)


def _sign(x: float) -> int:
    return (x > 0) - (x < 0)


def _direction(metric: str, e: float) -> int:
    """+1: thicker. A too-long wave (e > 0) wants a thinner rod; too many half-waves a
    thicker one."""
    if metric == "n":
        return 1 if e > 0 else -1
    return -1 if e > 0 else 1


def _next_h(h: float, m: dict[str, Any], tried: dict[float, dict[str, Any]], metric: str,
            target: float, err: Callable[[dict[str, Any]], float], step: float) -> float:
    """The next thickness: false position inside a bracket of the target when the tries
    have one, else the secant through the two nearest tries (the model's proportionality
    after the first), never more than MAX_FACTOR from h (a quantization plateau makes the
    secant shoot off)."""
    if metric == "n":
        return h + _direction(metric, err(m)) * step
    below = [x for x in tried if err(tried[x]) < 0]
    above = [x for x in tried if err(tried[x]) > 0]
    if below and above:
        # the metric grows with h: the bracket is (largest h below, smallest h above)
        a_h = max(x for x in below if x < min(above)) if any(x < min(above) for x in below) \
            else None
        b_h = min(above)
        if a_h is not None:
            ma, mb = float(tried[a_h][metric]), float(tried[b_h][metric])
            return a_h + (target - ma) * (b_h - a_h) / (mb - ma)
    others = [x for x in tried if x != h]
    m1 = float(m[metric])
    if not others:
        h_new = h * target / m1  # the model's proportionality
    else:
        h0 = min(others, key=lambda x: abs(x - h))
        m0 = float(tried[h0][metric])
        h_new = h * target / m1 if m1 == m0 else h + (target - m1) * (h - h0) / (m1 - m0)
    return min(max(h_new, h / MAX_FACTOR), h * MAX_FACTOR)


#: a refinement step changes h by at most this factor
MAX_FACTOR = 1.3
