"""Release increments: nominal up to the onset and through every hard step, growing on the
smooth post-buckling branch (``release.max_step_factor``)."""

from types import SimpleNamespace

import pytest
from test_engine import SMALL as _SMALL  # tests/ is on sys.path under pytest

from undulate import api
from undulate.model import case_from_dict
from undulate.solve.release import EASY_STEP_ITERATIONS, _next_increment

SMALL = {**_SMALL, "release": {**_SMALL["release"], "steps": 20}}


def _res(iterations: int, negative_steps: int = 0) -> SimpleNamespace:
    return SimpleNamespace(iterations=iterations, negative_steps=negative_steps)


def test_increment_stays_nominal_before_buckling():
    assert _next_increment(1.0, 1.0, 4.0, False, _res(2)) == 1.0


def test_increment_doubles_on_easy_steps_after_buckling_up_to_the_cap():
    de = 1.0
    seen = []
    for _ in range(4):
        de = _next_increment(de, 1.0, 4.0, True, _res(EASY_STEP_ITERATIONS))
        seen.append(de)
    assert seen == [2.0, 4.0, 4.0, 4.0]
    # max_step_factor = 1: equal increments, as before the option existed
    assert _next_increment(1.0, 1.0, 1.0, True, _res(2)) == 1.0


@pytest.mark.parametrize("res", [_res(EASY_STEP_ITERATIONS + 1), _res(3, negative_steps=1)])
def test_hard_step_returns_to_the_nominal_increment(res):
    assert _next_increment(4.0, 1.0, 4.0, True, res) == 1.0


def test_cut_increment_grows_back_to_nominal_only():
    # after a failed step was halved: back towards nominal, however easy the step was, until
    # the rods have buckled
    assert _next_increment(0.25, 1.0, 4.0, False, _res(2)) == 0.5
    assert _next_increment(0.25, 1.0, 4.0, True, _res(9)) == 0.5


def test_growing_increments_reach_the_end_in_fewer_steps():
    """The small case buckles early; with growth it needs fewer release steps, every step no
    longer than max_step_factor x nominal, and ends at full release."""
    data = SMALL
    grown = api.simulate(case_from_dict(data))
    equal = api.simulate(case_from_dict(
        {**data, "release": {**data["release"], "max_step_factor": 1.0}}))
    s_g = [h["release_strain"] for h in grown.history]
    s_e = [h["release_strain"] for h in equal.history]
    assert len(s_e) == 21
    assert len(s_g) < len(s_e)
    assert s_g[-1] == pytest.approx(0.5)
    nominal = 0.5 / 20
    assert max(b - a for a, b in zip(s_g, s_g[1:], strict=False)) <= 4 * nominal * (1 + 1e-9)
