"""The default sheet is wide enough: doubling its width changes neither n nor l (by < 2 %).

Checked for the default rod (h = 0.3) and for h = 0.5, on the default 200 mm of fabric beside
the rod against 400 mm. (On the former default of 100 mm, h = 0.5 ended with n = 3 where 200,
300 and 400 mm all give n = 2; see docs/model.md, "Fabric width".)
"""

import json
import os

import pytest

from undulate import api


@pytest.mark.slow
@pytest.mark.parametrize("h", [0.3, 0.5])
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
