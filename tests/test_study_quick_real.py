"""The quick presets with the real engine (slow marker; CI runs it): run, tables, figures, report.

These are the same commands a user runs (``undulate study run PRESET --quick``), with the
simulation and analysis of :func:`undulate.api.run_case`, not the fakes of the other study
tests. The assertions are about the pipeline and coarse physics that any correct engine shows
on the quick case (L = 60 mm, 2 mm rod mesh, 15 release steps).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from undulate.study import collect, get_preset, run_study
from undulate.study.derived import fit_eps0_exponents
from undulate.study.report import write_report

pytestmark = pytest.mark.slow


def _run(preset: str, out: Path) -> pd.DataFrame:
    study = get_preset(preset, quick=True)
    summary = run_study(study, out, workers=2, progress=False, artifacts=False)
    df = collect(out)
    failed = df[df["status"] != "ok"]
    assert failed.empty, failed[["run_id", "error"]].to_string()
    assert summary.ok == len(study.runs) == len(df)
    return df


def test_quick_single_rod_h(tmp_path: Path) -> None:
    df = _run("single-rod-h", tmp_path).sort_values("h")
    n = df["n"].to_numpy()
    # fewer half-waves for thicker rods. Not only odd numbers: on the physical sheet (200 mm
    # beside the rod) the change from three half-waves to one passes through n = 2 (measured
    # here at h = 0.3: n = 3, 2, 1 for h = 0.2, 0.3, 0.4; docs/model.md, "Fabric width")
    assert (n >= 1).all() and (np.diff(n) <= 0).all(), n
    # thick rods: one half-wave spanning the rod; the 0.2 mm rod still forms several
    thick = df[df["h"] >= 1.0]
    assert (thick["n"] == 1).all()
    assert np.allclose(thick["l_mean"], 60.0, rtol=0.05)
    assert int(df.loc[np.isclose(df["h"], 0.2), "n"].iloc[0]) >= 3
    assert (df["r2_arcs_mean"] > 0.9).all()
    qualities = [json.loads(q)[0] for q in df["rods_quality"]]
    assert "noisy" not in qualities and "flat" not in qualities, qualities
    assert (df["newton_iterations"] > 0).all() and (df["wall_time_s"] > 0).all()
    text = write_report(tmp_path).read_text()
    assert "![single_rod_h](figures/single_rod_h.png)" in text and "## Cost" in text
    assert (tmp_path / "figures" / "single_rod_h.png").stat().st_size > 20_000


def test_quick_single_rod_eps0(tmp_path: Path) -> None:
    df = _run("single-rod-eps0", tmp_path).sort_values("eps0")
    # more pre-strain, more shortening to take up: n never drops, and within one mode the
    # waves rise and shorten (the study's "slightly shorter wavelength, larger amplitude").
    # Measured on the reference set-up: n = 1, 3, 3, 3 for eps0 = 0.1, 0.3, 0.5, 1.0; within
    # n = 3, a = 3.04, 3.47, 4.09 mm and lam = 21.6, 17.9, 13.7 mm
    assert (np.diff(df["n"].to_numpy()) >= 0).all(), df[["eps0", "n"]]
    modes = [g for _, g in df.groupby("n") if len(g) >= 2]
    assert modes, df[["eps0", "n"]]
    for g in modes:
        assert g["a_mean"].is_monotonic_increasing, g[["eps0", "n", "a_mean"]]
        assert g["lam_mean"].is_monotonic_decreasing, g[["eps0", "n", "lam_mean"]]
    assert len(fit_eps0_exponents(df)) == 1  # quick: h = 0.3 only
    text = write_report(tmp_path).read_text()
    assert "exponent" in text and "l_vs_eps0" in text


def test_quick_parallel_phase_diagram(tmp_path: Path) -> None:
    df = _run("parallel-phase-diagram", tmp_path)
    four = {"coherent", "independent", "rolls", "bends"}
    assert set(df.loc[df["N"] == 5, "family"]) <= four
    # s = 0 is one wide rod: a single rod with several half-waves is "waves" (on the
    # reference set-up, measured: n = 3 at h = 0.2)
    assert set(df.loc[df["N"] == 1, "family"]) <= four | {"waves"}
    assert (df.loc[df["s"] == 0.0, "N"] == 1).all()  # s = 0: one rod five times as wide
    assert (df.loc[df["s"] > 0.0, "N"] == 5).all()
    # the thickest rods end in one half-wave whatever the gap
    assert (df.loc[df["h"] == df["h"].max(), "n"] == 1).all()
    text = write_report(tmp_path).read_text()
    for name in ("phase_diagram", "master_curve"):
        assert f"figures/{name}.png" in text
    assert "Bundling" in text
