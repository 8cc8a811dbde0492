"""Coherence, family classification, analyse_dir and the analysis/theory CLI commands."""

from __future__ import annotations

import json

import numpy as np
import pytest
import typer
from typer.testing import CliRunner

from undulate.analysis import COHERENT_THRESHOLD, analyse_dir, analyse_run, classify, coherence
from undulate.analysis.synthetic import add_noise, arc_chain, to_xyz
from undulate.interfaces.cli_analysis import register


def _rods(n, l, R, *, flip=False, M=None, seed=0, theta_noise=1e-3):
    """Five rods at y = 0, 5, ..., each an arc chain; ``flip`` alternates their phase."""
    out = []
    for k in range(5):
        xz = arc_chain(n, l, R, M=M or 30 * n + 30, start_up=not (flip and k % 2))
        out.append(to_xyz(add_noise(xz, theta_noise * R, seed=seed + k), y=5.0 * k))
    return out


def _flat(seed=0):
    x = np.linspace(0, 100, 101)
    z = 1e-5 * np.random.default_rng(seed).normal(size=x.size)
    return np.column_stack([x, np.zeros_like(x), z])


def test_coherence_values():
    a = to_xyz(arc_chain(5, 20.0, 7.0, M=180))
    b = to_xyz(arc_chain(5, 20.0, 7.0, M=150, start_up=False), y=5.0)
    assert coherence(a, a) == pytest.approx(1.0)
    assert coherence(a, b) == pytest.approx(-1.0, abs=1e-3)
    assert coherence(a, _flat()) == pytest.approx(0.0, abs=0.2)
    flat_exact = np.column_stack([np.linspace(0, 60, 50), np.zeros(50), np.zeros(50)])
    assert coherence(a, flat_exact) == 0.0
    # a quarter-period shift is in between
    xz = arc_chain(6, 20.0, 7.0, M=200)
    shift = xz.copy()
    shift[:, 0] -= xz[-1, 0] / 12  # half a half-wave (lam / 4)
    assert abs(coherence(xz, shift)) < COHERENT_THRESHOLD


@pytest.mark.parametrize(
    ("rods", "family"),
    [
        (lambda: _rods(5, 20.0, 7.0), "coherent"),
        (lambda: _rods(5, 20.0, 7.0, flip=True), "independent"),
        (lambda: _rods(1, 40.0, 10.0), "rolls"),  # turns 4 rad > pi: lam < 2a
        (lambda: _rods(1, 40.0, 25.0), "bends"),  # turns 1.6 rad: lam > 2a
        (lambda: [_flat(k) for k in range(5)], "flat"),
        (lambda: _rods(5, 20.0, 7.0)[:1], "waves"),
        (lambda: _rods(1, 40.0, 10.0)[:1], "rolls"),
    ],
)
def test_classify_families(rods, family):
    assert classify(rods(), L=100.0) == family


def test_analyse_run_structure_and_mixed_flat():
    rods = _rods(3, 20.0, 7.0)[:3] + [_flat()]
    res = analyse_run(rods)
    assert [r["index"] for r in res["rods"]] == [0, 1, 2, 3]
    assert len(res["coherence"]) == 3
    assert res["rods"][3]["quality"] == "flat"
    assert res["family"] == "coherent"  # the flat rod's pair is ignored
    assert res["summary"]["l_mean"] == pytest.approx(20.0, rel=0.02)
    # the study table's fit-quality columns come from here (figure 1's R^2 panel, report)
    live = [r for r in res["rods"] if r["n"] > 0]
    for key in ("r2_arcs", "r2_sine"):
        assert res["summary"][f"{key}_mean"] == pytest.approx(np.mean([r[key] for r in live]))
    json.dumps(res, allow_nan=False)
    with pytest.raises(ValueError, match="rod 1"):
        analyse_run([rods[0], np.full((10, 3), np.nan)])
    with pytest.raises(ValueError, match="no centre lines"):
        analyse_run([])


def _write_run(d, rods, *, L=100.0, extra_rods=True):
    np.savez(d / "centerlines.npz", **{f"rod{k}": r for k, r in enumerate(rods)})
    meta = {"case": {"rods": {"L": L, "h": 0.5}}, "solver": {"iters": 3}}
    if extra_rods:
        meta["rods"] = [{"index": k, "energy": 1.5 * k} for k in range(len(rods))]
    (d / "metrics.json").write_text(json.dumps(meta))


def test_analyse_dir_merges_metrics_and_plots(tmp_path):
    rods = _rods(5, 20.0, 7.0)[:2]
    _write_run(tmp_path, rods)
    res = analyse_dir(tmp_path)
    meta = json.loads((tmp_path / "metrics.json").read_text())
    assert meta["solver"] == {"iters": 3} and meta["case"]["rods"]["h"] == 0.5
    assert meta["family"] == res["family"] == "coherent"
    assert meta["analysis"]["rods"][0]["L_nominal"] == 100.0
    assert meta["analysis"]["rods"][0]["L_measured"] > 0
    for k, entry in enumerate(meta["rods"]):
        assert entry["energy"] == 1.5 * k and entry["index"] == k
        for key in ("l", "lam", "a", "R", "n", "r2_arcs", "r2_sine"):
            assert key in entry
        assert entry["n"] == 5
        assert (tmp_path / f"rod_{k}_fits.png").stat().st_size > 1000


def test_analyse_dir_without_metrics_json(tmp_path):
    np.savez(tmp_path / "centerlines.npz", rod1=_rods(3, 20.0, 7.0)[1], rod0=_flat())
    res = analyse_dir(tmp_path, plots=False)
    assert [r["n"] for r in res["rods"]] == [0, 3]
    meta = json.loads((tmp_path / "metrics.json").read_text())
    assert [e["index"] for e in meta["rods"]] == [0, 1]
    with pytest.raises(FileNotFoundError, match="not a directory"):
        analyse_dir(tmp_path / "missing")
    (tmp_path / "empty").mkdir()
    with pytest.raises(FileNotFoundError, match="centerlines.npz"):
        analyse_dir(tmp_path / "empty")


# ------------------------------------------------------------------------------------- CLI


@pytest.fixture()
def app():
    a = typer.Typer()
    register(a)
    return a


def test_cli_theory_table(app):
    res = CliRunner().invoke(app, ["theory", "--h", "0.5", "--eps0", "0.5", "--s", "10"])
    assert res.exit_code == 0, res.output
    for word in ("I_B", "sagitta", "s_hat", "h_bundled", "30.676", "coherent"):
        assert word in res.output


@pytest.mark.parametrize(
    ("args", "msg"),
    [(["--h", "-1"], "--h: Input should be greater than 0"), (["--eps0", "0"], "--eps0: "),
     (["--N", "0"], "--N: "), (["--s", "-2"], "--s: Input should be greater than or equal to 0")],
)
def test_cli_theory_validation(app, args, msg):
    res = CliRunner().invoke(app, ["theory", *args])
    assert res.exit_code == 2
    assert msg in res.output


def test_cli_theory_phase_map(app, tmp_path):
    out = tmp_path / "pm.png"
    res = CliRunner().invoke(app, ["theory", "--phase-map", "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert out.stat().st_size > 1000


def test_cli_analyse(app, tmp_path):
    res = CliRunner().invoke(app, ["analyse", str(tmp_path)])
    assert res.exit_code == 2 and "centerlines.npz" in res.output
    _write_run(tmp_path, _rods(3, 20.0, 7.0)[:2])
    res = CliRunner().invoke(app, ["analyse", str(tmp_path), "--no-plots"])
    assert res.exit_code == 0, res.output
    assert "family" in res.output and "coherent" in res.output and "r2_arcs" in res.output
