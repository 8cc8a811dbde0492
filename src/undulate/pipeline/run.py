"""One case through the whole pipeline: simulate (model -> mesh -> mechanics -> solve),
analyse, and write its run folder whole (:class:`undulate.fileio.StagedDir`).

Used by the study runner, the design stage and the interfaces alike; :mod:`undulate.api`
re-exports it for users. Units: mm, MPa, N, s.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from ..model import Case, case_from_dict
from ..solve.release import ProgressFn, SimResult, run_release

__all__ = ["ONSET_DEFLECTION", "StageFn", "analyse", "onset", "run_case", "run_cases",
           "simulate"]


def simulate(case: Case | dict, progress: ProgressFn | None = None) -> SimResult:
    """Stretch, print, perturb and release; raises ConvergenceError if no equilibrium is found."""
    if isinstance(case, dict):
        case = case_from_dict(case)
    return run_release(case, progress)


def analyse(result: SimResult) -> dict[str, Any]:
    """Shape analysis (docs/analysis.md) of every rod of a result."""
    from ..analysis import analyse_run

    # nominal (printed) lengths, one per rod in the order of the centre lines; the measured
    # ones are kept beside them (L_nominal, L_measured)
    paths = result.case.rod_paths()
    return analyse_run(result.centerlines, L=[p.length for p in paths],
                       along=["principal" if p.straight else "arclength" for p in paths])


def _flat_record(result: SimResult, ana: dict[str, Any]) -> dict[str, Any]:
    st = result.stats
    rec: dict[str, Any] = {
        "converged": True,
        "newton_iterations": st.get("newton_iterations"),
        "negative_curvature_steps": st.get("negative_curvature_steps"),
        "release_steps": st.get("release_steps"),
        "step_cuts": st.get("step_cuts"),
        "wall_time_s": st.get("wall_time_s"),
        "n_unknowns": st.get("n_unknowns"),
        "family": ana["family"],
        "max_height": max(float(c[:, 2].max()) - sk.offset
                          for c, sk in zip(result.centerlines, result.sections, strict=True)),
    }
    rec.update(ana["summary"])
    ns = [r["n"] for r in ana["rods"]]
    rec["n"] = int(round(rec.get("n_median") or 0))
    rec["n_mode"] = max(set(ns), key=ns.count) if ns else None
    rec["n_mean"] = sum(ns) / len(ns) if ns else None
    for key in ("l", "l_segments", "lam", "a", "R", "n", "r2_arcs", "r2_sine", "quality"):
        rec[f"rods_{key}"] = json.dumps([r.get(key) for r in ana["rods"]])
    rec["coherence"] = json.dumps(ana.get("coherence"))
    rec.update(onset(result))
    return rec


#: a rod counts as buckled once its centre line has left its printed level by this many rod
#: thicknesses (the bilayer's smooth curl before buckling stays a fraction of h)
ONSET_DEFLECTION = 1.0


def _crossing(strains: list[float], values: list[float], thr: float) -> float | None:
    """Release strain at which ``values`` first exceeds ``thr``, linear between the two
    release steps that bracket it; None if it never does."""
    for k, v in enumerate(values):
        if v > thr:
            if k == 0:
                return float(strains[0])
            e0, e1, v0 = strains[k - 1], strains[k], values[k - 1]
            return float(e0 + (e1 - e0) * (thr - v0) / (v - v0))
    return None


def onset(result: SimResult) -> dict[str, Any]:
    """When buckling began, from the release history (release strains, as fractions of 1).

    ``onset_release_strain``: where the rods first stand out of their printed level by
    ``ONSET_DEFLECTION`` x their thickness h (largest deflection up or down over all rods),
    interpolated linearly between the two release steps that bracket it. Why not a multiple
    of the imperfection: the rod sits above the fabric's mid-surface, so the sheet curls
    smoothly from the first step (default rod: 3 um per 0.0016 of release strain, 10 x the
    imperfection by 0.005), long before the deflection takes off near 0.085.
    ``rods_onset_release_strain`` (JSON list): the same rule per rod, which tells which rods
    go first. ``onset_negative_curvature_release_strain``: the first release step whose
    equilibrium needed a negative-curvature step (the previous branch had lost stability);
    None if none did (a release in small steps can follow the imperfect branch smoothly).
    Resolution: the increments before the onset, eps0 / (steps x release.onset_substeps).
    """
    hist = [h for h in result.history if h.get("stage") != "hang"]  # the release only
    hs = [sk.h for sk in result.sections]
    strains = [h["release_strain"] for h in hist]
    unstable = next((h["release_strain"] for h in hist if h.get("negative_steps", 0) > 0), None)
    per_rod = []
    for k in range(len(result.centerlines)):
        per_rod.append(_crossing(strains, [h["rod_max_deflection"][k]
                                           if len(h.get("rod_max_deflection", [])) > k
                                           else 0.0 for h in hist], ONSET_DEFLECTION * hs[k]))
    if len(set(hs)) == 1:  # one thickness: the largest deflection of any rod crosses it
        first = _crossing(strains, [h.get("max_deflection", 0.0) for h in hist],
                          ONSET_DEFLECTION * hs[0])
    else:  # lines of different thickness: the first rod to cross its own
        first = min((v for v in per_rod if v is not None), default=None)
    return {"onset_release_strain": first,
            "onset_negative_curvature_release_strain": unstable,
            "rods_onset_release_strain": json.dumps(per_rod)}


StageFn = Callable[[str], None]
"""``stage(text)``: called when a stage of :func:`run_case` begins (set-up, release, analysis,
writing); release steps themselves are reported through ``progress(fraction, record)``."""


def run_case(case: Case | dict, out: str | Path | None = None, artifacts: bool = True,
             progress: ProgressFn | None = None, *, overwrite: bool = False,
             stage: StageFn | None = None, note: StageFn | None = None) -> dict[str, Any]:
    """Simulate and analyse one case; write its files into ``out`` (if given).

    Returns a flat, JSON-serialisable record (solver statistics and mean metrics) used by the
    study runner. Raises :class:`ConvergenceError` when the release does not converge, and
    :class:`OutputError` *before simulating* when ``out`` cannot be used (a file, not
    writable, or not empty without ``overwrite``).

    ``out`` is written atomically: the files go to a hidden ``.OUT.incomplete-XXXX`` folder
    beside it, which is renamed to ``out`` only when every file is complete. An interrupted
    run leaves no ``out`` (or the previous one, untouched). With ``overwrite``, a previous
    run's files in ``out`` are replaced (anything else there is refused).

    ``note(text)``: called, once ``out`` is accepted, with a line worth keeping on the screen
    (the first run of this undulate version on the machine: that it compiles its kernels).
    """
    from ..fileio import StagedDir

    if isinstance(case, dict):
        case = case_from_dict(case)
    from ..mechanics.compiled import cold_start_notice, mark_warm

    staged = StagedDir(out, overwrite=overwrite) if out is not None else None
    try:
        if stage is not None:
            stage("set-up: mesh, pre-stretch, printing")
        notice = cold_start_notice()
        if notice is not None and note is not None:
            note(notice)
        t0 = time.perf_counter()
        first_step: list[float] = []

        def timed(frac: float, rec: dict) -> None:
            if not first_step:  # set-up and the first release step: where kernels compile
                first_step.append(time.perf_counter() - t0)
            if progress is not None:
                progress(frac, rec)

        result = simulate(case, timed)
        if notice is not None:
            mark_warm(first_step[0] if first_step else time.perf_counter() - t0)
        return _record_and_write(result, staged, artifacts, stage)
    finally:
        if staged is not None:
            staged.discard()


def run_cases(cases: Sequence[Case | dict], outs: Sequence[str | Path | None] | None = None,
              artifacts: bool = True) -> list[dict[str, Any] | Exception]:
    """:func:`run_case` for many cases that share a mesh (a study's runs over h, the moduli or
    the seed), released together: their energy evaluations are batched across runs
    (:mod:`undulate.solve.batch`), each run keeps its own solver and ends in the state a
    single run would. Returns per case its record or the exception that ended it (an
    :class:`OutputError` for an unusable ``out``, a ``ConvergenceError``, or a ValueError when
    the cases do not share a mesh)."""
    from ..fileio import StagedDir
    from ..solve.batch import release_batch

    outs = list(outs) if outs is not None else [None] * len(cases)
    if len(outs) != len(cases):
        raise ValueError(f"run_cases: {len(cases)} cases but {len(outs)} output folders")
    parsed: list[Case] = [case_from_dict(c) if isinstance(c, dict) else c for c in cases]
    staged: list[Any] = []
    out: list[dict[str, Any] | Exception | None] = [None] * len(parsed)
    try:
        for k, o in enumerate(outs):
            try:
                staged.append(StagedDir(o) if o is not None else None)
            except Exception as err:  # noqa: BLE001 - reported for this case
                staged.append(None)
                out[k] = err
        todo = [k for k in range(len(parsed)) if out[k] is None]
        for k, res in zip(todo, release_batch([parsed[k] for k in todo]), strict=True):
            if isinstance(res, Exception):
                out[k] = res
                continue
            try:
                out[k] = _record_and_write(res, staged[k], artifacts, None)
            except Exception as err:  # noqa: BLE001 - reported for this case
                out[k] = err
    finally:
        for st in staged:
            if st is not None:
                st.discard()
    return [r if r is not None else RuntimeError("no result") for r in out]


def _record_and_write(result: SimResult, staged: Any, artifacts: bool,
                      stage: StageFn | None) -> dict[str, Any]:
    """Analyse a result, write its files into ``staged`` (a StagedDir, or None) and commit
    them; return the flat record."""
    if stage is not None:
        stage("analysis: fitting sines and arc chains")
    ana = analyse(result)
    rec = _flat_record(result, ana)
    if staged is not None:
        if stage is not None:
            stage(f"writing outputs to {staged.out}")
        _write_outputs(result, ana, staged.path, artifacts)
        staged.commit()
    return rec


def _write_outputs(result: SimResult, ana: dict[str, Any], out: Path, artifacts: bool) -> None:
    from .output import write_result

    write_result(result, out, extra={"analysis": ana, "family": ana["family"]},
                 plots=artifacts, vtu=artifacts)
    _merge_rod_metrics(out, ana)
    if artifacts:
        from ..analysis import plot_fits

        for k, (cl, r) in enumerate(zip(result.centerlines, ana["rods"], strict=True)):
            plot_fits(cl, r, out / f"rod_{k}_fits.png", title=f"rod {k}")
def _merge_rod_metrics(out: Path, ana: dict[str, Any]) -> None:
    """Put the per-rod analysis keys into metrics.json's ``rods`` entries."""
    from ..fileio import atomic_write_json, jsonable

    p = out / "metrics.json"
    m = json.loads(p.read_text())
    for entry, r in zip(m["rods"], ana["rods"], strict=True):
        for key in ("l", "lam", "a", "R", "R_up", "R_down", "n", "r2_arcs", "r2_sine",
                    "quality", "L_nominal", "L_measured"):
            entry[key] = r.get(key)
    atomic_write_json(p, jsonable(m))
