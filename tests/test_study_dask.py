"""The dask.distributed path, on a LocalCluster with two worker processes."""

from __future__ import annotations

from pathlib import Path

import _study_fakes as fakes
import cloudpickle
import pytest

from undulate.study import build_study, run_study, scan_runs

distributed = pytest.importorskip("distributed")


def test_dask_local_cluster(tmp_path: Path) -> None:
    # the fakes module is not importable on the workers: ship its functions by value
    cloudpickle.register_pickle_by_value(fakes)
    try:
        study = build_study(
            "dask", {"rods": {"N": 1, "L": 60.0}, "mesh": {"dx_rod": 2.0, "dx_far": 6.0}},
            {"rods.h": [0.1, 0.2, 0.3, 0.42, 0.5, 0.6]}, kind="sweep",
        )
        with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                      dashboard_address=None) as cluster:
            s = run_study(study, tmp_path, run_fn=fakes.fake_run,
                          dask_address=cluster.scheduler_address, progress=False,
                          artifacts=False)
            assert (s.ran, s.ok, s.failed) == (6, 5, 1)
            recs = scan_runs(tmp_path).records
            assert len(recs) == 6
            pids = {r["pid"] for r in recs.values()}
            assert len(pids) >= 1 and all(p is not None for p in pids)
            bad = [r for r in recs.values() if r["status"] == "failed"]
            assert bad[0]["params"]["rods.h"] == 0.42 and "fake divergence" in bad[0]["error"]
            # resume on dask: nothing to do
            s2 = run_study(study, tmp_path, run_fn=fakes.fake_run,
                           dask_address=cluster.scheduler_address, progress=False)
            assert (s2.ran, s2.skipped_ok, s2.skipped_failed) == (0, 5, 1)
    finally:
        cloudpickle.unregister_pickle_by_value(fakes)
