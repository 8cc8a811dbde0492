"""Batched evaluation of runs that share one mesh (mechanics/batched.py) against the
single-run assembly: same energy, gradient and Hessian for every run of the batch."""

from __future__ import annotations

import numpy as np
import pytest

from undulate.mechanics.assemble import Assembly
from undulate.mechanics.batched import BatchedAssembly
from undulate.model import case_from_dict
from undulate.solve.newton import NewtonOptions
from undulate.solve.release import _clamped, prepare, prestretch
from undulate.solve.terms import TermState, groups

SMALL = {"rods": {"L": 20.0}, "fabric": {"margin_x": 4.0, "margin_y": 8.0},
         "mesh": {"h_far": 4.0}}


def _assemblies(hs: list[float]) -> tuple[list[Assembly], np.ndarray]:
    out, x0 = [], None
    for h in hs:
        sim = prepare(case_from_dict({**SMALL, "rods": {**SMALL["rods"], "h": h}}))
        x, _ = prestretch(sim, NewtonOptions(force_scale=sim.force_scale))
        fixed = np.zeros((sim.mesh.n_nodes, 3), bool)
        fixed[_clamped(sim)] = True
        out.append(Assembly(sim.mesh.n_nodes, sim.fabric + groups(sim, ("print",),
                                                                    TermState(x)), fixed))
        x0 = x if x0 is None else x0
    return out, x0


def test_batched_runs_match_the_single_run_assembly() -> None:
    hs = [0.2, 0.3, 0.5]
    asms, x0 = _assemblies(hs)
    rng = np.random.default_rng(0)
    X = np.stack([x0 + 0.05 * rng.standard_normal(x0.shape) * (~asms[0].fixed)
                  for _ in hs])
    batch = BatchedAssembly(asms)
    E, G, Hv = batch.evaluate(X)
    for b, asm in enumerate(asms):
        assert E[b] == pytest.approx(asm.energy(X[b]), rel=1e-9)
        g, H = asm.gradient_hessian(X[b])
        assert np.abs(G[b] - g).max() <= 1e-9 * np.abs(g).max()
        Hb = batch.hessian(Hv[b])
        assert (Hb.indptr == H.indptr).all() and (Hb.indices == H.indices).all()
        assert np.abs(Hb.data - H.data).max() <= 1e-8 * np.abs(H.data).max()
    # the runs really differ (the rods' stiffness scales with h^3)
    assert len({round(float(e), 6) for e in E}) == 3


def test_batched_refuses_runs_of_another_mesh() -> None:
    a, _ = _assemblies([0.3])
    other = prepare(case_from_dict({**SMALL, "rods": {"L": 16.0}}))
    fixed = np.zeros((other.mesh.n_nodes, 3), bool)
    b = Assembly(other.mesh.n_nodes, other.fabric, fixed)
    with pytest.raises(ValueError, match="run 1 has other nodes or clamps"):
        BatchedAssembly([a[0], b])


# --------------------------------------------------------------------------- batched release
RELEASE = {**SMALL, "release": {"steps": 10}}


def _case(**rods: float):
    return case_from_dict({**RELEASE, "rods": {**SMALL["rods"], **rods}})


@pytest.mark.parametrize("device_scatter", [False, True])
def test_batched_release_ends_in_the_single_run_states(device_scatter: bool,
                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    """Three thicknesses released together take the single-run engine's path: same Newton
    iterations, same final positions (to roundoff), same n and l; with the element Hessians
    scattered on the host (the CPU's way) or on the device (an accelerator's)."""
    from undulate import api
    from undulate.mechanics.batched import RunBatch
    from undulate.solve.batch import release_batch

    monkeypatch.setattr(RunBatch, "DEVICE_SCATTER", device_scatter)

    cases = [_case(h=h) for h in (0.2, 0.3, 0.5)]
    stats: dict = {}
    seen: set[int] = set()
    batch = release_batch(cases, progress=lambda b, frac, rec: seen.add(b), stats=stats)
    assert seen == {0, 1, 2}
    # the runs met: far fewer rendezvous than the runs' evaluations added up
    assert 0 < stats["rendezvous"] <= stats["batched_calls"]
    energies = []
    for case, res in zip(cases, batch, strict=True):
        assert not isinstance(res, BaseException), res
        one = api.simulate(case)
        assert res.stats["newton_iterations"] == one.stats["newton_iterations"]
        assert np.abs(res.x_final - one.x_final).max() <= 1e-8
        ma, mb = api.analyse(one)["rods"][0], api.analyse(res)["rods"][0]
        assert ma["n"] == mb["n"]
        assert mb["l"] == pytest.approx(ma["l"], rel=1e-2)
        energies.append(sum(res.energies.values()))
    assert len({round(e, 6) for e in energies}) == 3  # three different runs, not one copied


@pytest.mark.parametrize(("max_iter", "where"), [(2, "pre-stretch"), (4, "release step 1")])
def test_batched_release_reports_each_runs_failure_and_finishes_the_others(
        max_iter: int, where: str) -> None:
    """A run that cannot converge (before it joins the batch: in the pre-stretch; or inside
    the release) ends with its ConvergenceError (step, residual); the other runs of the batch
    are not held up by it."""
    from undulate.solve.batch import release_batch
    from undulate.solve.newton import ConvergenceError

    bad = case_from_dict({**RELEASE, "rods": {**SMALL["rods"], "h": 0.3},
                          "release": {"steps": 1, "adaptive": False},
                          "solver": {"max_iter": max_iter}})
    res = release_batch([_case(h=0.3), bad])
    assert not isinstance(res[0], BaseException)
    assert isinstance(res[1], ConvergenceError)
    assert str(res[1]).startswith(where)
    assert res[1].step is not None and res[1].residual is not None


def test_batched_release_of_runs_that_all_fail_early_returns_their_errors(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """Every run fails before the batch is built: their errors come back, and no thread
    dies of an exception of its own (the last one to leave has nothing to build from)."""
    import threading

    from undulate.solve.batch import release_batch
    from undulate.solve.newton import ConvergenceError

    died: list = []
    monkeypatch.setattr(threading, "excepthook", died.append)
    bad = case_from_dict({**RELEASE, "solver": {"max_iter": 1}})
    res = release_batch([bad, bad])
    assert all(isinstance(r, ConvergenceError) and str(r).startswith("pre-stretch")
               for r in res)
    assert died == []


def test_batched_release_refuses_runs_of_another_mesh() -> None:
    from undulate.solve.batch import release_batch

    res = release_batch([_case(h=0.3), _case(h=0.3, L=16.0)])
    assert all(isinstance(r, ValueError) and "other nodes" in str(r) for r in res)


@pytest.mark.slow
def test_study_runs_a_batch_in_one_worker_with_the_single_run_results(tmp_path) -> None:
    """``run_study(batch=...)``: runs that share a mesh (three thicknesses, two sheets) go to
    workers as batches of that topology; the records equal those of runs made one by one."""
    import json

    from undulate import api
    from undulate.study import run_study
    from undulate.study.runner import batch_runs
    from undulate.study.spec import build_study

    study = build_study("batched", RELEASE, {"fabric.margin_y": [8.0, 10.0],
                                             "rods.h": [0.2, 0.3, 0.5]}, kind="sweep")
    tasks = batch_runs(study.runs, 4)
    assert sorted(len(t) for t in tasks) == [3, 3]  # by sheet, not by h
    assert all(len({r.case["fabric"]["margin_y"] for r in t}) == 1 for t in tasks)
    summary = run_study(study, tmp_path, workers=1, progress=False, artifacts=False, batch=4)
    assert summary.ok == 6 and summary.failed == 0
    for r in study.runs:
        rec = json.loads((tmp_path / "runs" / f"{r.id}.json").read_text())
        assert rec["batch"] == 3
        one = api.run_case(r.case, artifacts=False)
        assert rec["record"]["newton_iterations"] == one["newton_iterations"]
        assert rec["record"]["n"] == one["n"]
        assert rec["record"]["l_mean"] == pytest.approx(one["l_mean"], rel=1e-2)
