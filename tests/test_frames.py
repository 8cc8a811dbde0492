"""The rods' Hessian made through the per-node frames (mechanics/frames.py) against the
element-by-element assembly of the same groups: same gradient, same Hessian, same pattern."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from undulate.mechanics.assemble import Assembly, ElementGroup
from undulate.mechanics.frames import FrameSlots
from undulate.model import case_from_dict
from undulate.solve.newton import NewtonOptions
from undulate.solve.release import _clamped, prepare, prestretch
from undulate.solve.terms import TermState, groups

# two rods of another length each (so the layout has two chains of different size) on a small
# sheet
TWO = {"pattern": {"lines": [{"points": [[0.0, 0.0], [14.0, 0.0]]},
                             {"points": [[0.0, 4.0], [9.0, 4.0]], "h": 0.5}]},
       "fabric": {"margin_x": 4.0, "margin_y": 6.0}, "mesh": {"h_far": 4.0}}


def _setup():
    sim = prepare(case_from_dict(TWO))
    x, _ = prestretch(sim, NewtonOptions(force_scale=sim.force_scale))
    fixed = np.zeros((sim.mesh.n_nodes, 3), bool)
    fixed[_clamped(sim)] = True
    gs = sim.fabric + groups(sim, ("print",), TermState(x))
    return sim, x, fixed, gs


def test_frames_hessian_equals_the_element_by_element_one() -> None:
    sim, x0, fixed, gs = _setup()
    fused = Assembly(sim.mesh.n_nodes, gs, fixed)
    plain = Assembly(sim.mesh.n_nodes, [dataclasses.replace(g, frames=None) for g in gs],
                     fixed)
    names = [g.name for g in fused.groups]
    assert [sorted(names[i] for i in f.indices) for f in fused.fused] == \
        [["rod_bend_twist", "rod_stretch"]]
    assert plain.fused == []
    rng = np.random.default_rng(3)
    x = x0 + 0.2 * rng.standard_normal(x0.shape) * ~fixed
    carried = {i: s * (1.0 + 0.3 * rng.standard_normal(s.shape))
               for i, s in fused.stress(x).items()}
    for stress in (None, carried):
        g1, H1 = fused.gradient_hessian(x, stress)
        g0, H0 = plain.gradient_hessian(x, stress)
        assert np.array_equal(H1.indptr, H0.indptr) and np.array_equal(H1.indices, H0.indices)
        assert np.abs(g1 - g0).max() <= 1e-12 * np.abs(g0).max()
        assert np.abs(H1.data - H0.data).max() <= 1e-12 * np.abs(H0.data).max()
    # the carried stresses change the Hessian (so the comparison above can fail)
    _, Hc = fused.gradient_hessian(x, carried)
    _, He = fused.gradient_hessian(x)
    assert np.abs(Hc.data - He.data).max() > 1e-6 * np.abs(He.data).max()


def test_frames_refuse_elements_that_are_not_the_layouts_blocks() -> None:
    sim, _, fixed, gs = _setup()
    i = next(k for k, g in enumerate(gs) if g.name == "rod_stretch")
    g = gs[i]
    shifted = FrameSlots(g.frames.layout, g.frames.first + 1)
    bad = list(gs)
    bad[i] = dataclasses.replace(g, frames=shifted)
    with pytest.raises(ValueError, match="rod_stretch: its elements are not the layout's"):
        Assembly(sim.mesh.n_nodes, bad, fixed)


def test_a_group_alone_on_its_layout_is_fused_too() -> None:
    sim, x0, fixed, gs = _setup()
    only = [g for g in gs if g.name != "rod_bend_twist"]
    fused = Assembly(sim.mesh.n_nodes, only, fixed)
    plain = Assembly(sim.mesh.n_nodes, [dataclasses.replace(g, frames=None) for g in only],
                     fixed)
    assert len(fused.fused) == 1
    x = x0 + 0.1 * np.random.default_rng(0).standard_normal(x0.shape) * ~fixed
    g1, H1 = fused.gradient_hessian(x)
    g0, H0 = plain.gradient_hessian(x)
    assert np.abs(H1.data - H0.data).max() <= 1e-12 * np.abs(H0.data).max()
    assert np.abs(g1 - g0).max() <= 1e-12 * np.abs(g0).max()
    assert isinstance(only[0], ElementGroup)


@pytest.mark.parametrize("n", [1, 7, 8, 9, 16, 17, 23])
def test_chunked_vmap_is_vmap(n: int) -> None:
    """One batch up to two chunks, a loop of chunks beyond (the last one filled up with copies
    of the last row): the same numbers as a plain vmap either way."""
    import jax
    import jax.numpy as jnp

    from undulate.mechanics.frames import chunked_vmap

    def f(a, b):
        return jnp.sin(a) * b[0], jnp.outer(a, b)

    rng = np.random.default_rng(n)
    a, b = rng.standard_normal((n, 3)), rng.standard_normal((n, 2))
    got = jax.jit(chunked_vmap(f, 4))(a, b)
    ref = jax.vmap(f)(a, b)
    for g, r in zip(got, ref, strict=True):
        assert g.shape == r.shape
        assert np.allclose(np.asarray(g), np.asarray(r), rtol=1e-15, atol=0)
