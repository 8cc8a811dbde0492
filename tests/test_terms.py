"""The energy terms are declared once (undulate.solve.terms) and each stage takes its groups
from that list."""

from __future__ import annotations

import numpy as np
import pytest

from undulate.model import case_from_dict
from undulate.solve.release import prepare
from undulate.solve.terms import TERMS, TermState, groups

SMALL = {"rods": {"L": 30.0}, "fabric": {"margin_x": 5.0, "margin_y": 10.0},
         "mesh": {"h_far": 6.0}}


def test_each_stage_collects_the_terms_that_act_then() -> None:
    assert [t.name for t in TERMS] == ["fabric", "edge_tension", "rods", "gravity"]
    plain = prepare(case_from_dict(SMALL))
    assert [g.name for g in plain.fabric] == ["fabric_membrane", "fabric_bending"]
    x = plain.X3.copy()
    assert {g.name for g in groups(plain, ("print",), TermState(x))} == {
        "rod_stretch", "rod_bend_twist", "rod_footprint"}  # no weight: gravity is off
    loaded = prepare(case_from_dict({**SMALL, "fabric": {**SMALL["fabric"], "edge_tension": 0.1},
                                     "gravity": {"g": [0.0, 0.0, -9810.0]}}))
    assert [g.name for g in loaded.fabric][-1] == "edge_tension"
    free = np.ones(loaded.mesh.n_nodes, bool)
    free[loaded.mesh.node_sets["left"]] = False
    weight = groups(loaded, ("print",), TermState(x, free))[-1]
    assert weight.name == "gravity"
    assert weight.nodes.size == free.sum()  # the weight acts on the nodes that can move
    with pytest.raises(ValueError, match="energy term 'rods': needs the printed positions"):
        groups(plain, ("print",))
