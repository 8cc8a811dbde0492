"""Planar curves of piecewise-constant curvature (tangent-continuous chains of circular arcs).

A chain is described in its own plane (x along the rod, z out of the fabric) by a start point
``(x0, z0)``, a start tangent angle ``psi0`` (radians from +x towards +z), the signed curvature
``kappa[k]`` of each piece and the arclength positions of the junctions. The tangent angle is
then the continuous, piecewise-linear function ``psi(s)`` and the position follows in closed
form, so the chain can be evaluated at any arclength without integration error.

Sign convention: ``kappa < 0`` turns clockwise (from +z towards +x), i.e. the arc bulges to +z:
an **up** arc ("convex up", a crest). ``kappa > 0`` is a **down** arc (a trough).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["chain_points", "arc_displacement"]


def arc_displacement(
    psi: ArrayLike, kappa: ArrayLike, d: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Displacement ``(dx, dz)`` after arclength ``d`` on an arc of curvature ``kappa``.

    Exact and stable for ``kappa -> 0``: with ``u = kappa d / 2``,
    ``dx = d cos(psi + u) sinc(u)`` and ``dz = d sin(psi + u) sinc(u)``.
    """
    psi = np.asarray(psi, dtype=float)
    kappa = np.asarray(kappa, dtype=float)
    d = np.asarray(d, dtype=float)
    u = 0.5 * kappa * d
    sc = np.sinc(u / np.pi)
    return d * np.cos(psi + u) * sc, d * np.sin(psi + u) * sc


def chain_points(
    x0: float,
    z0: float,
    psi0: float,
    kappa: ArrayLike,
    knots: ArrayLike,
    s: ArrayLike,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Evaluate a tangent-continuous chain at arclengths ``s``.

    ``kappa`` has ``m`` entries, ``knots`` the ``m - 1`` interior junction arclengths (sorted
    here, so an optimiser may let them cross). The start point ``(x0, z0)`` and angle ``psi0``
    sit at ``s = 0``; the first piece extends to ``s < 0`` and the last past the last knot.
    Returns ``(x, z, psi)`` at ``s``.
    """
    kap = np.atleast_1d(np.asarray(kappa, dtype=float))
    kn = np.sort(np.atleast_1d(np.asarray(knots, dtype=float)))
    s = np.asarray(s, dtype=float)
    starts = np.concatenate([[0.0], kn])
    seg = np.diff(starts)  # lengths of pieces 0..m-2 (the last piece is open-ended)
    psi_start = psi0 + np.concatenate([[0.0], np.cumsum(kap[:-1] * seg)])
    dx, dz = arc_displacement(psi_start[:-1], kap[:-1], seg)
    xs = x0 + np.concatenate([[0.0], np.cumsum(dx)])
    zs = z0 + np.concatenate([[0.0], np.cumsum(dz)])
    idx = np.searchsorted(kn, s, side="right")
    d = s - starts[idx]
    ddx, ddz = arc_displacement(psi_start[idx], kap[idx], d)
    return xs[idx] + ddx, zs[idx] + ddz, psi_start[idx] + kap[idx] * d
