"""Synthetic centre lines with known geometry: arc chains and sines (for tests and users).

>>> from undulate.analysis.synthetic import arc_chain
>>> xz = arc_chain(5, l=20.0, R_up=7.0)      # 5 half-waves, arcs of 20 mm, radius 7 mm
>>> xz.shape[1]
2
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from .geometry import chain_points

__all__ = ["arc_chain", "sine_curve", "to_xyz", "add_noise"]


def arc_chain(
    n: int,
    l: float,
    R_up: float,
    R_down: float | None = None,
    *,
    M: int | None = None,
    start_up: bool = True,
    flat_ends: float = 0.0,
) -> NDArray[np.float64]:
    """Points ``(x, z)`` of ``n`` circular arcs of alternating curvature joined tangentially.

    Every arc turns the same angle ``theta = 2 l / (R_up + R_down)`` (so the chain is periodic
    and its mean line is straight); up arcs (crests, bulging to +z) have radius ``R_up`` and
    length ``theta R_up``, down arcs (troughs) radius ``R_down`` (default ``R_up``) and length
    ``theta R_down``; the mean arc length of an up/down pair is ``l``. The chain starts at the
    origin with tangent angle ``+theta/2`` (up first) or ``-theta/2`` (``start_up=False``), so
    all junctions lie on ``z = 0`` and the crests reach ``R_up (1 - cos(theta/2))``.

    ``flat_ends`` adds a straight (zero-curvature) piece of that length at each end, continuing
    the end tangent. ``M`` points are spaced uniformly in arclength (default: 60 per arc, at
    least 200). Returns an ``(M, 2)`` array; see :func:`to_xyz` for ``(M, 3)``.
    """
    if n < 1:
        raise ValueError(f"arc_chain: n must be >= 1 (got {n})")
    if l <= 0 or R_up <= 0 or (R_down is not None and R_down <= 0) or flat_ends < 0:
        raise ValueError("arc_chain: l, R_up, R_down must be > 0 and flat_ends >= 0")
    rd = R_up if R_down is None else R_down
    theta = 2.0 * l / (R_up + rd)
    sign = 1.0 if start_up else -1.0
    kappas, lengths = [], []
    if flat_ends > 0:
        kappas.append(0.0)
        lengths.append(flat_ends)
    for k in range(n):
        up = (k % 2 == 0) == start_up
        kappas.append(-1.0 / R_up if up else 1.0 / rd)
        lengths.append(theta * (R_up if up else rd))
    if flat_ends > 0:
        kappas.append(0.0)
        lengths.append(flat_ends)
    total = float(np.sum(lengths))
    if M is None:
        M = max(200, 60 * n)
    s = np.linspace(0.0, total, int(M))
    knots = np.cumsum(lengths)[:-1]
    x, z, _ = chain_points(0.0, 0.0, sign * theta / 2.0, kappas, knots, s)
    return np.column_stack([x, z])


def sine_curve(
    A: float, lam: float, length: float, *, phi: float = 0.0, c: float = 0.0, M: int = 400
) -> NDArray[np.float64]:
    """Points ``(x, z)`` of ``z = A sin(2 pi x / lam + phi) + c`` for ``x`` in ``[0, length]``
    (``M`` points uniform in x). Returns an ``(M, 2)`` array."""
    x = np.linspace(0.0, length, int(M))
    return np.column_stack([x, A * np.sin(2.0 * np.pi * x / lam + phi) + c])


def to_xyz(xz: NDArray[np.float64], y: float = 0.0) -> NDArray[np.float64]:
    """Lift an ``(M, 2)`` curve ``(x, z)`` to an ``(M, 3)`` centre line at constant ``y``."""
    xz = np.asarray(xz, dtype=float)
    return np.column_stack([xz[:, 0], np.full(len(xz), float(y)), xz[:, 1]])


def add_noise(
    pts: NDArray[np.float64], sigma: float, seed: int = 0
) -> NDArray[np.float64]:
    """Return ``pts`` plus isotropic Gaussian noise of standard deviation ``sigma`` [mm]."""
    rng = np.random.default_rng(seed)
    return np.asarray(pts, dtype=float) + rng.normal(0.0, sigma, np.shape(pts))
