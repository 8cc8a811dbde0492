"""Shipped set-ups: the presets' reference by default, ``bare`` for the engine's defaults,
a TOML file or a name through ``--setup``, one clear line for anything else."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from undulate.interfaces.cli import app
from undulate.model.config import MATERIAL_DEFAULTS
from undulate.study import StudyError, get_preset
from undulate.study.named_setups import (
    REFERENCE,
    describe_setup,
    named_setup,
    setup_names,
    setup_text,
)
from undulate.study.presets import resolve_study, setup_from


def test_presets_use_the_reference_unless_told() -> None:
    ref = named_setup(REFERENCE)
    assert ref["rods"]["E_B"] != MATERIAL_DEFAULTS["E_B"]  # else the test could not fail
    for name in ("single-rod-h", "single-rod-eps0", "parallel-phase-diagram", "sentinel"):
        study = get_preset(name, quick=True)
        assert all(r.case["rods"]["E_B"] == ref["rods"]["E_B"] for r in study.runs), name
        assert study.definition["setup"] == ref
        bare = get_preset(name, quick=True, setup="bare")
        assert all(r.case["rods"]["E_B"] == MATERIAL_DEFAULTS["E_B"] for r in bare.runs)
        assert "setup" not in bare.definition
        assert {r.id for r in bare.runs}.isdisjoint({r.id for r in study.runs})
    assert get_preset("sentinel", setup={}).definition.get("setup") is None


def test_setup_options_for_presets_and_sweeps(tmp_path) -> None:
    ref = named_setup(REFERENCE)
    assert setup_from([], preset=True) == ref
    assert setup_from([]) == {}  # a sweep: its [base] says what it wants
    assert setup_from(["rods.E_B=700"], preset=True) == {"rods": {"E_B": 700}}
    assert setup_from(["mode=inertial"], "bare", preset=True) == {"mode": "inertial"}
    f = tmp_path / "mine.toml"
    f.write_text("[fabric]\nE = 0.9\n")
    assert setup_from([], f, preset=True) == {"fabric": {"E": 0.9}}
    with pytest.raises(StudyError, match="no such file, nor a shipped set-up"):
        setup_from([], tmp_path / "missing.toml")
    with pytest.raises(StudyError, match="no such set-up; shipped: study-2022"):
        setup_text("nope")
    sweep = tmp_path / "sweep.toml"
    sweep.write_text('name = "mine"\n[base.rods]\nE_B = 2500.0\n[sweep]\n"rods.h" = [0.2]\n')
    assert resolve_study(str(sweep)).runs[0].case["rods"]["E_B"] == 2500.0
    assert resolve_study(str(sweep), setup=REFERENCE).runs[0].case["rods"]["E_B"] == 1000.0


def test_every_shipped_setup_is_a_valid_case_overlay() -> None:
    assert setup_names()[0] == REFERENCE and "bare" in setup_names()
    for name in setup_names():
        assert setup_text(name).lstrip().startswith("#")  # it says why
        get_preset("sentinel", setup=name)  # validates every run's case
    assert describe_setup(None).startswith("bare")
    assert describe_setup(named_setup(REFERENCE)).startswith(REFERENCE)
    assert describe_setup({"rods": {"E_B": 5.0}}) == "`{'rods': {'E_B': 5.0}}`"


def test_cli_lists_and_shows_setups() -> None:
    runner = CliRunner()
    res = runner.invoke(app, ["study", "setups"])
    assert res.exit_code == 0 and REFERENCE in res.output and "bare" in res.output
    res = runner.invoke(app, ["study", "setups", REFERENCE])
    assert res.exit_code == 0 and "E_B" in res.output
    res = runner.invoke(app, ["study", "setups", "nope"])
    assert res.exit_code == 2 and "no such set-up" in res.output
