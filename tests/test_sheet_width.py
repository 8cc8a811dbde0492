"""The default sheet is wide enough: doubling its width changes neither n nor l (by < 2 %).

Checked for the default rod (h = 0.3). For h = 0.5 the check does not hold yet: on 100 mm
the rod ends with n = 3 (l = 26.4 mm), on 200 mm with n = 2 (l = 49.0 mm); see docs/model.md,
"Fabric width".
"""

import json
import os

import pytest

from undulate import api


@pytest.mark.slow
@pytest.mark.parametrize("h", [0.3])
def test_doubling_the_sheet_width_changes_neither_n_nor_l(h):
    base = api.case_from_dict({"name": f"width-{h}", "rods": {"h": h}})
    wide = base.model_copy(deep=True)
    wide.fabric.margin_y = 2 * base.fabric.margin_y
    out = {}
    for name, case in (("default", base), ("double", wide)):
        m = api.analyse(api.simulate(case))
        rod = m["rods"][0]
        out[name] = dict(margin_y=case.fabric.margin_y, n=rod["n"], l=rod["l"], a=rod["a"])
    if os.environ.get("UNDULATE_REPORT"):
        print(json.dumps({"h": h, **out}))
    assert out["default"]["n"] == out["double"]["n"]
    assert out["default"]["l"] == pytest.approx(out["double"]["l"], rel=0.02)
