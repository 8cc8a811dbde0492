"""Validation of case descriptions: one clear error naming the field and the allowed range."""

import math

import pytest

from undulate.model import Case, ConfigError, case_from_dict, load_case


def test_defaults_are_spec_defaults():
    c = Case()
    assert (c.fabric.E, c.fabric.t, c.rods.E_B, c.rods.b, c.rods.L, c.release.eps0) == (
        0.45, 0.4, 3000.0, 1.0, 100.0, 0.5)


@pytest.mark.parametrize(
    "data, field, words",
    [
        ({"rods": {"h": 0.0}}, "rods.h", "greater than 0"),
        ({"rods": {"h": -1.0}}, "rods.h", "> 0, <= 20"),
        ({"release": {"eps0": 0.0}}, "release.eps0", "greater than 0"),
        ({"release": {"eps0": math.nan}}, "release.eps0", "finite"),
        ({"fabric": {"nu": 0.5}}, "fabric.nu", ">= 0, < 0.5"),
        ({"release": {"stall_curved_steps": -1}}, "release.stall_curved_steps", ">= 0"),
        ({"rods": {"hh": 1.0}}, "rods.hh", "Extra inputs"),
        ({"bogus": 1}, "bogus", "Extra inputs"),
        ({"rods": {"N": 3, "s": 0.0}}, "rods.s", "must be > 0"),
        ({"rods": {"segments": [{"start": [0, 0], "length": 10, "direction": [0, 1]}]}},
         "rods.segments.0.direction", "only rods along +x"),
        ({"rods": {"b": 2.0, "segments": [{"start": [0, 0], "length": 10},
                                          {"start": [5, 1], "length": 10}]}},
         "rods.segments", "overlap"),
        ({"mesh": {"dx_rod": 15.0, "dx_far": 20.0}, "rods": {"L": 20}}, "mesh.dx_rod",
         "half the shortest"),
    ],
)
def test_bad_values_name_the_field(data, field, words):
    with pytest.raises(ConfigError) as err:
        case_from_dict(data)
    msg = str(err.value)
    assert msg.startswith(field) or f"\n{field}" in msg or field in msg.split(":")[0]
    assert words in msg


def test_load_case_file_errors(tmp_path):
    with pytest.raises(ConfigError, match="no such file"):
        load_case(tmp_path / "missing.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[rods\nh = 1")
    with pytest.raises(ConfigError, match="not valid TOML"):
        load_case(bad)
    ok = tmp_path / "ok.toml"
    ok.write_text("[rods]\nh = 0.5\nN = 5\ns = 2.5\n")
    c = load_case(ok)
    assert len(c.segments()) == 5
    ys = [s[1] for s in c.segments()]
    assert ys[1] - ys[0] == pytest.approx(c.rods.b + 2.5)


def test_examples_validate():
    from pathlib import Path

    for p in sorted(Path(__file__).parents[1].joinpath("examples").rglob("*.toml")):
        load_case(p)


def test_case_file_with_a_byte_order_mark_is_read(tmp_path):
    p = tmp_path / "bom.toml"
    p.write_bytes(b"\xef\xbb\xbf" + b'name = "bom"\n[rods]\nh = 0.4\n')
    case = load_case(p)
    assert case.name == "bom" and case.rods.h == 0.4


def test_material_defaults_are_set_once():
    """The analytical model, the study tables, the presets and `undulate theory` take their
    material defaults from the case file's fields (MATERIAL_DEFAULTS)."""
    import inspect

    from undulate import theory
    from undulate.interfaces.cli_analysis import _MAT
    from undulate.model import MATERIAL_DEFAULTS, case_from_dict
    from undulate.study.presets import get_preset
    from undulate.study.storage import PARAM_ALIASES

    case = case_from_dict({})
    assert MATERIAL_DEFAULTS == {"b": case.rods.b, "E_B": case.rods.E_B, "E": case.fabric.E,
                                 "t": case.fabric.t}
    assert theory.DEFAULTS == MATERIAL_DEFAULTS and _MAT is MATERIAL_DEFAULTS
    sig = inspect.signature(theory.l).parameters
    assert {k: sig[k].default for k in MATERIAL_DEFAULTS} == MATERIAL_DEFAULTS
    assert {k: PARAM_ALIASES[k][1] for k in MATERIAL_DEFAULTS} == MATERIAL_DEFAULTS
    run = get_preset("single-rod-h", setup="bare").runs[0].case
    assert (run["rods"]["b"], run["rods"]["E_B"], run["fabric"]["E"], run["fabric"]["t"]) == \
        tuple(MATERIAL_DEFAULTS[k] for k in ("b", "E_B", "E", "t"))


def test_the_default_rod_spacing_resolves_thin_rods_waves() -> None:
    """Without mesh.dx_rod a rod gets 1 mm, or 1/2, 1/3, 1/4 mm when eq. (1)'s half-wave
    would span fewer than 8 nodes; a given spacing is kept; a pattern takes its thinnest
    line."""
    from undulate.model import case_from_dict
    from undulate.model.numerics import auto_dx_rod

    def dx(**kw) -> float:
        return case_from_dict({"rods": {"E_B": 1000.0, **kw.pop("rods", {})}, **kw}).mesh.dx_rod

    assert dx(rods={"h": 0.3}) == 1.0 and dx(rods={"h": 0.15}) == 0.5
    assert dx(rods={"h": 0.08}, release={"eps0": 0.85}) == 0.25
    assert dx(rods={"h": 0.15}, mesh={"dx_rod": 1.0}) == 1.0
    thick = auto_dx_rod(0.15, 0.5, b=1.0, E_B=3000.0, E=0.45, t=0.4)
    assert thick > auto_dx_rod(0.15, 0.5, b=1.0, E_B=1000.0, E=0.45, t=0.4)
    lines = {"lines": [{"points": [[0, 0], [60, 0]], "h": 0.3},
                       {"points": [[0, 10], [60, 10]], "h": 0.1}]}
    assert dx(rods={"h": 0.3}, pattern=lines) == 0.5
