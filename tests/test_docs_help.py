"""Help and docs a newcomer reads: generated config reference, honest help texts."""

from __future__ import annotations

import re
from pathlib import Path

from typer.testing import CliRunner

from undulate.interfaces.cli import app
from undulate.model.reference import config_markdown

ROOT = Path(__file__).parents[1]


def _help(*args: str) -> str:
    res = CliRunner().invoke(app, [*args, "--help"], env={"COLUMNS": "200"})
    assert res.exit_code == 0, res.output
    return res.output


def test_config_doc_is_generated_and_complete() -> None:
    text = config_markdown()
    assert (ROOT / "docs" / "config.md").read_text() == text, (
        "docs/config.md is out of date: python -m undulate.model.reference docs/config.md")
    assert "PydanticUndefined" not in text
    for rule in ("dx_far >= mesh.dx_rod", "half the shortest rod", "overlap",
                 "must then be left out"):
        assert rule in text
    # every table row has an allowed column that is not blank
    for row in text.splitlines():
        if row.startswith("| `"):
            cells = [c.strip() for c in row.strip("|").split("|")]
            assert cells[3], row
    assert "[1, 0] only" in text  # the allowed direction


def test_demo_help_states_the_demo_case() -> None:
    from undulate.api import demo_case

    text = _help("demo")
    assert f"L = {demo_case().rods.L:g} mm" in text
    assert "L = 60" not in text
    assert f"E_B = {demo_case().rods.E_B:g} MPa" in text


def test_demo_is_on_the_reference_setup() -> None:
    """The demo shows what the study presets show: every value the reference set-up sets."""
    from undulate.api import DEMO
    from undulate.study.named_setups import REFERENCE, named_setup
    from undulate.study.spec import merge_case

    assert merge_case(DEMO, named_setup(REFERENCE)) == DEMO


def test_theory_help_keeps_units() -> None:
    text = _help("theory")
    for unit in ("rod thickness [mm]", "rod width [mm]", "fabric thickness [mm]",
                 "rod length [mm]", "gap between rods [mm]", "[MPa]", "[-]"):
        assert unit in text, unit
    assert "<= 3" in text  # the case file's range for eps0


def test_no_reference_to_an_unshipped_spec() -> None:
    texts = [_help(), _help("demo"), _help("run"), _help("theory"), _help("analyse")]
    files = [*ROOT.joinpath("docs").glob("*.md"), ROOT / "README.md",
             *ROOT.joinpath("examples").glob("*.toml"), *ROOT.joinpath("src").rglob("*.py")]
    texts += [p.read_text() for p in files]
    for t in texts:
        assert not re.search(r"\bSPEC\b", t)
