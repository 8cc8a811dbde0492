"""The mixed Newton iteration's side of the assembly: carried stresses and the merit.

The stiff rods are written in strain form (energy = W(strains)); a mixed Newton iteration
(as in the MIP Newton of Magisano, Leonetti and Garcea) carries their stresses from the
strains *linearized* along the last step instead of recomputing them from the displaced
positions, so a step that rotates a nearly inextensible rod does not load it with its own
second-order stretch. This module gives an :class:`~undulate.mechanics.assemble.Assembly`
the stresses (:meth:`MixedStresses.stress`, :meth:`MixedStresses.stress_linearized`), the
merit that judges such steps (:meth:`MixedStresses.merit`), and the small cache that hands a
line search's last merit stresses to the next iteration.
"""

from __future__ import annotations

import functools

import jax.numpy as jnp
import numpy as np

from .forms import strain_form
from .pool import pool as _pool

__all__ = ["MERIT_STRESSES_KEPT", "MixedStresses"]

#: merit evaluations whose carried stresses an Assembly keeps for stress_linearized
MERIT_STRESSES_KEPT = 4


class MixedStresses:
    """Mixed-Newton methods of an assembly; the assembly provides ``groups``, ``joined``,
    ``_per_element`` and ``_merit_stresses`` (a deque of MERIT_STRESSES_KEPT entries)."""

    @functools.cached_property
    def mixed_groups(self) -> list[int]:
        """Indices of the groups written in strain form (their stresses can be carried)."""
        return [i for i, g in enumerate(self.groups) if strain_form(g.fn) is not None]

    def stress(self, x: np.ndarray) -> dict[int, np.ndarray]:
        """Consistent element stresses ``k e(x)`` of the strain-form groups."""
        xj = jnp.asarray(x)
        return {i: self._stress(i, xj) for i in self.mixed_groups}

    def _stress(self, i: int, xj: jnp.ndarray) -> np.ndarray:
        # k (e + J 0) = k e through the merit's kernel, which every mixed Newton iteration
        # loads anyway (the same numbers as the "stress" kernel)
        return self._stress_lin(i, xj, jnp.zeros_like(xj))

    def _stress_lin(self, i: int, xj: jnp.ndarray, dj: jnp.ndarray) -> np.ndarray:
        # k (e + J dx): the stress columns of the merit's kernel, so that a step's carried
        # stresses are the same numbers whether its merit was evaluated or not (a kernel of
        # their own gave other roundoff; and it is one program less to load)
        g = self.groups[i]
        return self.joined(g, g.run("merit_step", xj, dj))[:, 2:]

    def stress_linearized(self, x: np.ndarray, dx: np.ndarray) -> dict[int, np.ndarray]:
        """Stresses of the strains linearized at ``x`` and moved by ``dx``: ``k (e + J dx)``.

        A step whose merit :meth:`merit` evaluated lately (the one a line search took) has
        them already: the same numbers, from the merit's kernel.
        """
        params = self._mixed_params()
        for xm, dxm, pm, st in self._merit_stresses:
            if pm == params and np.array_equal(xm, x) and np.array_equal(dxm, dx):
                return dict(st)
        xj, dj = jnp.asarray(x), jnp.asarray(np.asarray(dx, dtype=np.float64))
        return {i: self._stress_lin(i, xj, dj) for i in self.mixed_groups}

    def _mixed_params(self) -> tuple[int, ...]:
        # which parameters the strain-form groups had (ElementGroup.set_params replaces the
        # tuple): kept stresses of other parameters are not reused
        return tuple(id(self.groups[i].params) for i in self.mixed_groups)

    def merit(self, x: np.ndarray, dx: np.ndarray) -> tuple[float, float]:
        """(merit, energy) at ``x + dx``: the merit of a mixed Newton step from ``x``.

        The merit is the energy with each strain-form group's quadratic term evaluated as the
        Hellinger-Reissner functional ``s e - s^2 / (2 k)`` at the stress ``s = k e_lin`` of
        the strains linearized at ``x`` (the stress a mixed Newton step carries), i.e. the
        energy less ``k (e - e_lin)^2 / 2``: the second-order stretch that a straight step
        gives a rotating stiff rod is not charged to the step (the next iteration removes it).
        """
        xj, dj = jnp.asarray(x), jnp.asarray(np.asarray(dx, dtype=np.float64))
        x1 = jnp.asarray(np.asarray(x) + np.asarray(dx))
        mixed = set(self.mixed_groups)

        stresses: dict[int, np.ndarray] = {}

        def one(i: int) -> tuple[float, float]:
            g = self.groups[i]
            if i in mixed:
                out = self.joined(g, g.run("merit_step", xj, dj))
                stresses[i] = out[:, 2:]
                me = out[:, :2].sum(axis=0)
                return float(me[0]), float(me[1])
            e = float(self._per_element(g, x1).sum())
            return e, e

        # groups side by side as in gradient_hessian, summed in group order
        parts = list(_pool().map(one, range(len(self.groups))))
        # the last few steps' stresses, for stress_linearized of the step a line search takes
        # (a curved search's expansion evaluates one step past the one it keeps)
        self._merit_stresses.appendleft((np.array(x, dtype=np.float64),
                                         np.array(dx, dtype=np.float64), self._mixed_params(),
                                         stresses))
        return sum(p[0] for p in parts), sum(p[1] for p in parts)
