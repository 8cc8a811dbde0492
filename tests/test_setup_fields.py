"""Set-up candidates of the shape-families work: each field reaches the mechanics."""

from __future__ import annotations

import numpy as np
import pytest

from undulate.model import case_from_dict
from undulate.solve.release import prepare

SMALL = {"rods": {"h": 0.3, "L": 30.0}, "fabric": {"margin_x": 8.0, "margin_y": 8.0},
         "mesh": {"dx_rod": 1.5, "h_far": 6.0}}


def _with(table: str, **kw: object) -> dict:
    return {**SMALL, table: {**SMALL.get(table, {}), **kw}}


def _bending_k(case: dict) -> np.ndarray:
    sim = prepare(case_from_dict(case))
    g = next(g for g in sim.fabric if g.name == "fabric_bending")
    return np.asarray(g.params[0])


def test_bending_factor_scales_the_hinges() -> None:
    k1 = _bending_k(SMALL)
    k01 = _bending_k(_with("fabric", bending_factor=0.01))
    np.testing.assert_allclose(k01, 0.01 * k1, rtol=1e-12)


def test_offset_reaches_the_rod_sections() -> None:
    assert prepare(case_from_dict(SMALL)).sections[0].offset == pytest.approx(0.35)
    assert prepare(case_from_dict(_with("rods", offset=0.0))).sections[0].offset == 0.0


def test_zero_offset_keeps_the_flat_state_flat_before_the_onset() -> None:
    """With the rod on the mid-surface there is no bilayer: a partial release below the
    onset leaves rod and fabric exactly flat; with the offset the pair curls from the first
    step (an imperfect bifurcation)."""
    from undulate.api import simulate

    heights = {}
    for d in (None, 0.0):
        case = {**_with("rods", **({} if d is None else {"offset": d})),
                "release": {"eps0": 0.5, "final_strain": 0.49, "steps": 2},
                "imperfection": {"amplitude": 0.0}}
        res = simulate(case)
        heights[d] = float(np.abs(res.x_final[:, 2]).max())
    assert heights[0.0] < 1e-9 < 1e-4 < heights[None]


def test_new_fields_are_validated() -> None:
    from undulate.model.config import ConfigError

    for table, kw, field in (("fabric", {"bending_factor": 0.0}, "fabric.bending_factor"),
                             ("rods", {"offset": -1.0}, "rods.offset")):
        with pytest.raises(ConfigError, match=field):
            case_from_dict(_with(table, **kw))


def test_force_control_lets_the_edges_go_and_the_pins_carry_nothing() -> None:
    """release.control = "force": the clamps' forces become loads on free edges, taken down
    with the release; the six gauge pins remove the rigid motions and carry no force."""
    from undulate.mechanics.assemble import Assembly
    from undulate.solve.boundary import ForceControl, clamp_positions, gauge_pins
    from undulate.solve.release import run_release

    case = case_from_dict({**SMALL, "release": {"control": "force", "steps": 4}})
    sim = prepare(case)
    pins = gauge_pins(sim)
    assert pins.sum() == 6 and pins[:, 2].sum() == 3 and pins.any(axis=1).sum() == 3
    res = run_release(case)
    # the records' clamp strain is measured between the free ends, not the nominal one
    last = res.history[-1]
    assert abs(last["clamp_strain"]) > 0.02
    assert last["release_strain"] == pytest.approx(0.5 - last["clamp_strain"])
    # the edges moved off where clamps at that strain would hold them
    held = clamp_positions(sim, last["clamp_strain"], res.x_final)
    left = np.asarray(sim.mesh.node_sets["left"])
    assert np.abs(held[left] - res.x_final[left]).max() > 0.05
    # the free sample at the end: the pins carry no force (under loads, in the deformed
    # shape, they would carry the loads' small moment: the dead loads balance in the
    # printed shape only)
    from undulate.solve.newton import NewtonOptions
    from undulate.solve.release import prestretch
    from undulate.solve.terms import TermState, groups

    x_print, _ = prestretch(sim, NewtonOptions())
    fc = ForceControl(sim, sim.fabric, x_print)
    fc.place(0.0, res.x_final)
    rods = groups(sim, ("print",), TermState(x_print, ~fc.fixed.all(axis=1)))
    free = Assembly(sim.mesh.n_nodes, sim.fabric + rods + fc.groups(),
                    np.zeros_like(fc.fixed))
    g = free.gradient_full(res.x_final)
    assert np.abs(g[pins]).max() < 1e-7 * np.abs(fc.w0).max()  # 9e-5 while the footprint
    # energy measured its offset in the drawing's frame (not invariant under turns)


def test_force_control_refuses_inertia_and_hang() -> None:
    from undulate.model.config import ConfigError

    with pytest.raises(ConfigError, match="release.control"):
        case_from_dict({**SMALL, "release": {"control": "force"}, "mode": "inertial"})
    with pytest.raises(ConfigError, match="release.control"):
        case_from_dict({**SMALL, "release": {"control": "force"}, "hang": {"edges": ["top"]}})
