"""Boundary conditions beyond two clamps: a frame holding more edges (``release.clamps``), a
fabric of a given size (``fabric.size``) and a sheet taken off the clamps and hung up by some
edges after the release (``[hang]``)."""

from __future__ import annotations

import numpy as np
import pytest

from undulate.mechanics.assemble import Assembly
from undulate.model import ConfigError, case_from_dict
from undulate.solve.dynamics import gravity_group
from undulate.solve.newton import NewtonOptions
from undulate.solve.release import edge_nodes, prepare, prestretch, run_release

SMALL = {"rods": {"L": 30.0, "h": 0.2}, "fabric": {"margin_x": 5.0, "margin_y": 15.0},
         "release": {"steps": 6}, "mesh": {"h_far": 6.0}}


def _case(**extra: dict) -> object:
    data = {k: dict(v) for k, v in SMALL.items()}
    for k, v in extra.items():
        data[k] = {**data.get(k, {}), **v} if isinstance(v, dict) else v
    return case_from_dict(data)


@pytest.mark.parametrize("data, message", [
    ({"release": {"clamps": ["left", "top"]}}, r"release.clamps: must hold 'right'"),
    ({"release": {"clamps": ["left", "right", "left"]}}, r"each edge at most once"),
    ({"release": {"clamps": ["left", "right", "up"]}}, r"release.clamps.2: Input should be"),
    ({"hang": {"edges": []}}, r"hang.edges: List should have at least 1 item"),
    ({"fabric": {"edge_tension": 0.1},
      "release": {"clamps": ["left", "right", "bottom", "top"]}},
     r"fabric.edge_tension: pulls on the edges across the stretch that are free"),
    ({"pattern": {"arrays": [{"length": 1e6, "count": 1}]}},
     r"pattern.arrays.0.length: must be a length > 0 and <= 1e5 mm"),
    ({"pattern": {"lines": [{"id": "f0.0", "points": [[0.0, 5.0], [20.0, 5.0]]}],
                  "arrays": [{"length": 20.0, "count": 1}]}},
     r"pattern: line ids must be unique; repeated: \['f0.0'\] \(an array's lines"),
    ({"hang": {"edges": ["top"], "steps": 0}}, r"hang.steps: .*>= 1"),
    ({"fabric": {"size": [100.0, 50.0], "margin_y": 10.0}}, r"fabric.size: give either size"),
    ({"fabric": {"size": [100.0, 0.0]}}, r"fabric.size"),
    ({"fabric": {"size": [101.0, 50.0]}, "rods": {"L": 99.0}},
     r"rod 0 is only 1 mm from the clamp on the left edge"),
    ({"fabric": {"size": [100.0, 60.0]},
      "pattern": {"lines": [{"id": "a", "points": [[-40.0, 29.0], [20.0, 29.0]]}]}},
     r"line a: is only 0.5 mm from the top edge of the 100 x 60 mm fabric"),
    ({"fabric": {"size": [100.0, 60.0]},
      "pattern": {"lines": [{"id": "a", "points": [[-60.0, 0.0], [20.0, 0.0]]}]}},
     r"line a: leaves the fabric across the clamp on the left edge"),
])
def test_bad_boundary_settings_are_refused(data: dict, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        case_from_dict(data)


def test_fabric_size_sets_the_sheet() -> None:
    c = case_from_dict({"fabric": {"size": [160.0, 90.0]}})
    assert c.fabric_extent() == (-80.0, 80.0, -45.0, 45.0)


def test_a_four_edge_frame_holds_the_edges_across_the_stretch() -> None:
    """With bottom and top clamped the stretch is biaxial at the edges: they stay at their
    printed y, move with the stretch along x, and the sheet is not narrowed."""
    case = _case(release={"clamps": ["left", "right", "bottom", "top"]})
    sim = prepare(case)
    x, _ = prestretch(sim, NewtonOptions(force_scale=sim.force_scale))
    ymin, ymax = case.fabric_extent()[2:]
    top, bottom = sim.mesh.node_sets["top"], sim.mesh.node_sets["bottom"]
    assert np.allclose(x[top, 1], ymax) and np.allclose(x[bottom, 1], ymin)
    assert np.allclose(x[top, 0], sim.X3[top, 0] * (1.0 + case.release.eps0))
    # the reference mesh is as wide as the printed sheet (no lateral contraction to undo)
    assert np.ptp(sim.X3[:, 1]) == pytest.approx(ymax - ymin)


@pytest.mark.parametrize("edge", ["top", "bottom"])
def test_one_held_edge_across_the_stretch_stays_at_its_printed_place(edge: str) -> None:
    """With the frame holding one edge across the stretch, the sheet narrows towards it: that
    edge is held at its printed place, the rod is printed where it was drawn (within the
    non-uniform stretch near the clamps), and the free edge has come in."""
    # a sheet long against its width (60 mm beyond the rod's ends, 31 mm wide): next to the
    # clamps, which hold its ends unnarrowed, the lines sit off their drawn place (measured:
    # 1.6 mm with 5 mm beyond the ends, 0.4 mm with 30, 0.05 mm with 60)
    case = _case(release={"clamps": ["left", "right", edge]}, fabric={"margin_x": 60.0})
    sim = prepare(case)
    x, _ = prestretch(sim, NewtonOptions(force_scale=sim.force_scale))
    ymin, ymax = case.fabric_extent()[2:]
    held, free = (ymax, ymin) if edge == "top" else (ymin, ymax)
    assert np.allclose(x[sim.mesh.node_sets[edge], 1], held)
    rod = sim.mesh.rods[0].p
    assert np.abs(x[rod, 1]).max() < 0.15  # drawn at y = 0
    other = sim.mesh.node_sets["bottom" if edge == "top" else "top"]
    mid = other[np.abs(x[other, 0]) < 5.0]
    assert np.abs(x[mid, 1] - free).max() < 0.2  # the free edge in the middle came in


def test_hung_up_by_its_top_edge_the_top_carries_the_whole_weight() -> None:
    """Released between left and right clamps, then let go of them and held by the top edge
    only, under a strong in-plane gravity: the held edge's force on the sheet balances the
    weight of everything else (no clamp force is left over), and the let-go is recorded."""
    g = 1e6  # 100 g along -y, so the weight stands well above the solver's tolerance
    case = _case(gravity={"g": [0.0, -g, 0.0]}, hang={"edges": ["top"], "steps": 4})
    res = run_release(case)
    stages = [h.get("stage") for h in res.history]
    assert stages[-4:] == ["hang"] * 4 and "hang" not in stages[:-4]
    assert res.history[-1]["let_go"] == 1.0
    assert res.stats["hang_newton_iterations"] > 0
    sim = prepare(case)
    held = edge_nodes(sim.mesh, ["top"])
    fixed = np.zeros((sim.mesh.n_nodes, 3), bool)
    fixed[held] = True
    from undulate.mechanics.build import rod_groups

    weight = gravity_group(sim, ~held)
    W = weight.params[0].sum(axis=0)
    internal = Assembly(sim.mesh.n_nodes, sim.fabric + rod_groups(sim.mesh.rods, res.x_printed,
                                                                    sim.sections), fixed)
    # dE_int/dx at the held nodes = minus the force the sheet needs from them = -W in total
    pull = internal.gradient_full(res.x_final)[held].sum(axis=0)
    assert W[1] < 0
    assert pull == pytest.approx(-W, abs=2e-3 * abs(W[1]))
    # with the clamps gone the sides hang free: the bottom edge has moved down
    bottom = sim.mesh.node_sets["bottom"]
    assert res.x_final[bottom, 1].mean() < res.x_printed[bottom, 1].mean()


def test_letting_go_after_an_inertial_release_numbers_its_steps_on() -> None:
    case = _case(mode="inertial", dynamics={"release_time": 0.06, "settle_time": 0.02,
                                            "dt": 0.01},
                 hang={"edges": ["top"], "steps": 2})
    res = run_release(case)
    steps = [h["step"] for h in res.history]
    assert steps == sorted(set(steps))  # no step number twice
    assert [h.get("stage") for h in res.history[-2:]] == ["hang", "hang"]


def test_the_onset_of_buckling_is_read_from_the_release_only() -> None:
    """A deflection reached while the clamps are let go is no onset of buckling."""
    from types import SimpleNamespace

    from undulate.api import onset

    def rec(e: float, d: float, **kw: object) -> dict:
        return dict(release_strain=e, max_deflection=d, rod_max_deflection=[d], **kw)

    flat = [rec(0.1 * k, 1e-3) for k in range(6)]
    hung = [rec(0.5, 5.0, stage="hang", negative_steps=3)]
    res = SimpleNamespace(history=flat + hung, sections=[SimpleNamespace(h=0.3)],
                          centerlines=[np.zeros((3, 3))])
    got = onset(res)
    assert got["onset_release_strain"] is None
    assert got["onset_negative_curvature_release_strain"] is None


def test_holding_the_clamped_edges_changes_nothing() -> None:
    case = _case(hang={"edges": ["left", "right"]})
    res = run_release(case)
    assert res.stats["hang_steps"] == 0
    assert all(h.get("stage") != "hang" for h in res.history)
