"""The analytical inverse design inverts the forward model, and says when it cannot."""

from __future__ import annotations

import json

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from undulate import theory
from undulate.design import Constraints, DesignError, inverse
from undulate.design.inverse import forward
from undulate.interfaces.cli import app

FINE = {"h_step": 1e-9, "h_min": 0.05, "h_max": 3.0}


@settings(max_examples=40, deadline=None)
@given(h=st.floats(0.1, 1.5), eps0=st.floats(0.2, 1.0), key=st.sampled_from(["l", "lam", "a"]))
def test_one_target_gives_back_the_thickness(h, eps0, key):
    c = Constraints(eps0=eps0, L=1e4, **FINE)  # a long line: the wave branch, no n = 1
    target = forward(h, eps0, c)[key]
    d = inverse({key: target}, c)
    assert d.h_exact == pytest.approx(h, rel=1e-9)
    assert d.predicted_exact[key] == pytest.approx(target, rel=1e-9)


@settings(max_examples=30, deadline=None)
@given(h=st.floats(0.1, 1.5), eps0=st.floats(0.25, 0.95),
       pair=st.sampled_from([("l", "a"), ("lam", "a"), ("l", "lam")]))
def test_two_targets_give_back_thickness_and_prestretch(h, eps0, pair):
    c = Constraints(eps0_min=0.2, eps0_max=1.0, L=1e4, **FINE)
    m = forward(h, eps0, c)
    d = inverse({k: m[k] for k in pair}, c)
    assert d.eps0 == pytest.approx(eps0, rel=1e-7)
    assert d.h_exact == pytest.approx(h, rel=1e-7)


def test_formulas_of_the_forward_model():
    c = Constraints()
    m = forward(0.3, 0.5, c)
    assert m["l"] == pytest.approx(theory.l(0.3, 0.5))
    assert m["a"] == pytest.approx(theory.a(0.3, 0.5))
    assert m["lam"] == pytest.approx(2 * m["l"] / 1.5)
    assert m["n"] == theory.n(0.3, 0.5, 100.0)


def test_n_is_met_at_the_middle_of_its_plateau_and_rounding_is_reported():
    d = inverse({"n": 5}, Constraints(L=100.0))
    assert d.predicted_exact["l"] == pytest.approx(20.0)
    assert d.predicted["n"] == 5 and d.h == pytest.approx(round(d.h_exact / 0.02) * 0.02)
    assert any("rounded" in note for note in d.notes)


def test_bundled_group_needs_thinner_rods_than_a_lone_rod():
    lone = inverse({"l": 20.0}, Constraints(L=1e4, **FINE))
    group = inverse({"l": 20.0}, Constraints(L=1e4, N=5, phase="coherent", **FINE))
    assert group.h_exact < lone.h_exact
    assert group.s == pytest.approx(0.5 * group.predicted_exact["s_hat"])
    assert group.predicted_exact["l"] == pytest.approx(20.0)
    indep = inverse({"l": 20.0}, Constraints(L=1e4, N=5, phase="independent", **FINE))
    assert indep.h_exact == pytest.approx(lone.h_exact)  # s > s_hat: the rods act alone
    assert indep.predicted["family"] == "independent"


def test_sensitivity_brackets_the_prediction():
    d = inverse({"l": 20.0}, Constraints(h_tol=0.02))
    s = d.sensitivity["l"]
    assert s["h_minus_tol"] < d.predicted["l"] < s["h_plus_tol"]


@pytest.mark.parametrize(("targets", "kw", "frag"), [
    ({"l": 500.0}, {}, "out of reach"),
    ({"n": 4}, {}, "odd whole number"),
    ({"l": 20.0, "a": 5.0}, {}, "two targets need eps0 free"),
    ({"l": 20.0, "n": 5}, {"eps0_min": 0.2, "eps0_max": 1.0}, "both set the arc length"),
    ({"l": 20.0, "a": 50.0}, {"eps0_min": 0.2, "eps0_max": 1.0}, "no eps0 in"),
    ({}, {}, "at least one"),
    ({"l": 20.0}, {"h_max": 0.01}, "h_max"),
    ({"l": 20.0}, {"phase": "coherent"}, "needs N >= 2"),
    ({"l": 20.0}, {"N": 5, "phase": "independent", "s_max": 5.0}, "outside [s_min, s_max]"),
])
def test_bad_requests_raise_one_clear_error(targets, kw, frag):
    with pytest.raises(DesignError, match=None) as err:
        inverse(targets, Constraints(**kw))
    assert frag in str(err.value) and "\n" not in str(err.value)


def test_cli_json_has_the_design_and_its_prediction():
    res = CliRunner().invoke(app, ["design", "--target", "l=20", "--L", "100", "--json"])
    assert res.exit_code == 0, res.output
    out = json.loads(res.stdout)
    assert {"h", "s", "eps0", "b", "predicted", "sensitivity"} <= set(out)
    assert out["predicted"]["n"] == 5 and out["eps0"] == 0.5
