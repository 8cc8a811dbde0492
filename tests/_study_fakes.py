"""Fake run functions for the study tests: cheap, deterministic, theory-shaped metrics.

They mimic :func:`undulate.api.run_case` (``(case, out, artifacts=True) -> flat dict``) using
eq. (1) with quantization ``l = L/n`` (n odd), bundling of parallel rods at small spacing, and
a family classification, so the figures and report have something realistic to show.
"""

from __future__ import annotations

import json
import math
import os
import random
import time
from pathlib import Path
from typing import Any

FAIL_H = {0.42, 1.3}  # fake_run raises for these rod thicknesses


def _l_eq1(h: float, eps0: float, b: float, E_B: float, E: float, t: float) -> float:
    I_B = h**3 * b / 12.0
    return (24.0 * math.sqrt(6.0) * E_B * I_B / (E * t)) ** (1.0 / 3.0) * eps0**-0.5


def _a_formula(h: float, eps0: float, b: float, E_B: float, E: float, t: float) -> float:
    return (1.0 / (2.0 * eps0)) * ((E_B * b) / (3.0 * E * t)) ** (1.0 / 3.0) * h


def metrics(case: Any) -> dict[str, Any]:
    """Theory-shaped fake metrics for a validated Case."""
    r, f, eps0 = case.rods, case.fabric, case.release.eps0
    rng = random.Random(hash((round(r.h, 9), round(r.s, 9), r.N, eps0, case.imperfection.seed)))
    a_theory = _a_formula(r.h, eps0, r.b, r.E_B, f.E, f.t)
    s_hat = 2.0 * a_theory * (1.0 + eps0)
    h_eff = r.h
    if r.N > 1:  # bundling: close rods behave like one wider rod
        h_eff = r.h * (1.0 + (r.N ** (1 / 3) - 1.0) * math.exp(-r.s / max(s_hat, 1e-9)))
    l_free = _l_eq1(h_eff, eps0, r.b, r.E_B, f.E, f.t)
    x = r.L / l_free
    n = max(1, 2 * int(round((x - 1.0) / 2.0)) + 1)  # nearest odd integer
    if abs(x - n) > 0.8 and rng.random() < 0.3:  # runs disagree near transitions
        n = max(1, n + (2 if x > n else -2))
    l_q = r.L / n
    l_val = l_q if n <= 9 else l_free
    flatten = min(1.0, l_free / l_q) if n <= 9 else 1.0
    a = l_val / math.sqrt(24 * eps0) * flatten
    lam = 2.0 * l_val / (1.0 + eps0) / flatten**0.5 if n > 1 else r.L / (1.0 + eps0)
    if n == 1:
        family = "rolls" if r.s < s_hat and r.N > 1 else "bends"
    elif r.N > 1 and r.s > s_hat and r.h < 0.4:
        family = "independent"
    else:
        family = "coherent"
    noise = 1.0 + 0.02 * rng.uniform(-1, 1)
    # onset: thicker rods later; the outer rods of a group first (more fabric pulls on them)
    onset0 = 0.05 * (r.h / 0.3) ** 0.5
    rods_onset = [onset0 * (1.0 if k in (0, r.N - 1) else 1.1) for k in range(r.N)]
    l_rods = [l_val * (1 + 0.03 * rng.uniform(-1, 1)) for _ in range(r.N)]
    return {
        "converged": True,
        "newton_iterations": 100 + rng.randint(0, 50),
        "wall_time_s": 0.0,
        "l_mean": sum(l_rods) / len(l_rods),
        "l_std": (sum((x - sum(l_rods) / len(l_rods)) ** 2 for x in l_rods) / len(l_rods)) ** 0.5,
        "lam_mean": lam * noise,
        "a_mean": a * noise,
        "R_mean": l_val / math.sqrt(24 * eps0) * noise,
        "n_mean": float(n),
        "n_mode": n,
        "family": family,
        "r2_arcs_mean": 0.99 - 0.01 * rng.random(),
        "r2_sine_mean": 0.95 + 0.045 * rng.random(),
        "l_rods": json.dumps(l_rods),
        "onset_release_strain": min(rods_onset),
        "rods_onset_release_strain": json.dumps(rods_onset),
    }


def fake_run(case: Any, out: Path | None, artifacts: bool = True) -> dict[str, Any]:
    """Instant fake; raises RuntimeError for h in FAIL_H; writes a small artifact if asked."""
    if round(case.rods.h, 6) in FAIL_H:
        raise RuntimeError(f"fake divergence at h={case.rods.h}")
    rec = metrics(case)
    if out is not None:
        (Path(out) / "shape.txt").write_text(f"{case.name}\n")
    return rec


def slow_run(case: Any, out: Path | None, artifacts: bool = True) -> dict[str, Any]:
    """Sleeps ``UNDULATE_FAKE_SLEEP`` s (default 0.25) and logs completions to
    ``UNDULATE_FAKE_LOG`` as '<tag> <h>' lines (tag from ``UNDULATE_FAKE_TAG``); with
    ``UNDULATE_FAKE_STARTS`` set, first appends '<h>' to that file (the run has begun)."""
    starts = os.environ.get("UNDULATE_FAKE_STARTS")
    if starts:
        fd = os.open(starts, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
        try:
            os.write(fd, f"{case.rods.h!r}\n".encode())
        finally:
            os.close(fd)
    time.sleep(float(os.environ.get("UNDULATE_FAKE_SLEEP", "0.25")))
    rec = metrics(case)
    log = os.environ.get("UNDULATE_FAKE_LOG")
    if log:
        line = f"{os.environ.get('UNDULATE_FAKE_TAG', '-')} {case.rods.h!r}\n"
        fd = os.open(log, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
        try:
            os.write(fd, line.encode())
        finally:
            os.close(fd)
    return rec


def crash_run(case: Any, out: Path | None, artifacts: bool = True) -> dict[str, Any]:
    """Kills its worker process for h == 0.5 (tests worker-crash handling); the other runs
    take a moment, so that they are in flight in the same pool when it dies."""
    if round(case.rods.h, 6) == 0.5:
        time.sleep(0.2)
        os._exit(3)
    time.sleep(1.0)
    return metrics(case)


def threads_run(case: Any, out: Path | None, artifacts: bool = True) -> dict[str, Any]:
    """Records the PARDISO thread count its process was given (``UNDULATE_PARDISO_THREADS``)."""
    rec = metrics(case)
    rec["pardiso_threads_env"] = os.environ.get("UNDULATE_PARDISO_THREADS")
    return rec


def pid_run(case: Any, out: Path | None, artifacts: bool = True) -> dict[str, Any]:
    """Records the id of the process that made the run."""
    rec = metrics(case)
    rec["pid"] = os.getpid()
    return rec
