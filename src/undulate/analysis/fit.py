"""Fits of one buckled centre line: a sine ``z(x)`` and a chain of circular arcs.

Both fits work in the rod's own vertical plane: ``x`` along the rod (projected on the rod's
in-plane principal direction, oriented towards +x), ``z`` out of the fabric. See
``docs/analysis.md`` for the algorithms. Goodness of fit is reported the same way for both so
that they can be compared: ``rms`` is the root-mean-square *normal distance* of the points to
the fitted curve [mm] and ``r2 = 1 - sum(d**2) / sum((z - mean(z))**2)`` ("R^2 on z").
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.ndimage import gaussian_filter1d
from scipy.optimize import least_squares
from scipy.spatial import cKDTree

from .geometry import chain_points

__all__ = ["Centerline", "SineFit", "ArcChainFit", "prepare", "fit_sine", "fit_arcs"]

MIN_POINTS = 5
"""Fewer points than this is an error (a ValueError naming the problem)."""


@dataclass
class Centerline:
    """A centre line reduced to its vertical plane: ``x`` along the rod, ``z`` up, ``s`` the
    cumulative arclength of the ``(x, z)`` polyline (starting at 0), ``length`` its total 3-D
    polyline length."""

    x: NDArray[np.float64]
    z: NDArray[np.float64]
    s: NDArray[np.float64]
    length: float


def prepare(xyz: ArrayLike) -> Centerline:
    """Validate a centre line and project it on its vertical plane.

    Accepts an ``(M, 3)`` array of ``(x, y, z)`` points ordered along the rod, or an ``(M, 2)``
    array of ``(x, z)``. ``x`` is the coordinate along the principal in-plane direction of the
    points (oriented towards +x, so rods along x keep their own x coordinates). Consecutive
    duplicate points are dropped. Raises :class:`ValueError` naming the problem for a wrong
    shape, NaN/inf values or fewer than :data:`MIN_POINTS` points.
    """
    try:
        arr = np.asarray(xyz, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"centre line: cannot convert to a float array ({exc})") from exc
    if arr.ndim != 2 or arr.shape[1] not in (2, 3):
        raise ValueError(
            f"centre line: expected an (M, 3) array of (x, y, z) or (M, 2) of (x, z); "
            f"got shape {arr.shape}"
        )
    bad = ~np.isfinite(arr).all(axis=1)
    if bad.any():
        raise ValueError(
            f"centre line: {int(bad.sum())} point(s) contain NaN or inf "
            f"(first at row {int(np.argmax(bad))})"
        )
    if len(arr) < MIN_POINTS:
        raise ValueError(
            f"centre line: {len(arr)} point(s); need at least {MIN_POINTS} to analyse a shape"
        )
    if arr.shape[1] == 3:
        xy = arr[:, :2]
        length = float(np.sum(np.linalg.norm(np.diff(arr, axis=0), axis=1)))
        centred = xy - xy.mean(axis=0)
        _, sv, vt = np.linalg.svd(centred, full_matrices=False)
        u = vt[0] if sv[0] > 0 else np.array([1.0, 0.0])
        if u[0] < 0 or (u[0] == 0 and u[1] < 0):
            u = -u
        x = xy @ u
        z = arr[:, 2].copy()
    else:
        x = arr[:, 0].copy()
        z = arr[:, 1].copy()
        length = float(np.sum(np.hypot(np.diff(x), np.diff(z))))
    step = np.hypot(np.diff(x), np.diff(z))
    keep = np.concatenate([[True], step > 1e-12 * max(length, 1e-300)])
    x, z = x[keep], z[keep]
    if len(x) < MIN_POINTS:
        raise ValueError(
            f"centre line: {len(x)} distinct point(s); need at least {MIN_POINTS}"
        )
    s = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(x), np.diff(z)))])
    return Centerline(x=x, z=z, s=s, length=length)


def _r2(d2: NDArray[np.float64], z: NDArray[np.float64]) -> float:
    ss_tot = float(np.sum((z - z.mean()) ** 2))
    if ss_tot <= 0.0:
        return 0.0
    return float(1.0 - np.sum(d2) / ss_tot)


def _project(
    px: NDArray[np.float64],
    pz: NDArray[np.float64],
    curve: Any,
    t_lo: float,
    t_hi: float,
    n_dense: int,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Nearest-point projection of points on a parametric curve ``curve(t) -> (x, z, psi)``.

    Dense sampling + k-d tree, then one Newton step along the tangent (exact for straight
    lines and circles). Returns the parameters ``t`` and the squared normal distances.
    """
    td = np.linspace(t_lo, t_hi, n_dense)
    cx, cz, _ = curve(td)
    tree = cKDTree(np.column_stack([cx, cz]))
    _, idx = tree.query(np.column_stack([px, pz]))
    t = td[idx]
    mx, mz, psi = curve(t)
    speed = np.sqrt(np.gradient(cx, td) ** 2 + np.gradient(cz, td) ** 2)[idx]
    t = t + ((px - mx) * np.cos(psi) + (pz - mz) * np.sin(psi)) / np.maximum(speed, 1e-300)
    mx, mz, _ = curve(t)
    return t, (px - mx) ** 2 + (pz - mz) ** 2


# ----------------------------------------------------------------------------------- sine fit


@dataclass
class SineFit:
    """``z = A sin(2 pi x / lam + phi) + c`` fitted by least squares on vertical residuals.

    ``A >= 0`` and ``phi`` in ``(-pi, pi]``. ``rms`` and ``r2`` use normal distances (module doc).
    """

    A: float
    lam: float
    phi: float
    c: float
    rms: float
    r2: float

    def z(self, x: ArrayLike) -> NDArray[np.float64]:
        """Fitted ``z`` at ``x``."""
        return self.A * np.sin(2 * np.pi * np.asarray(x, float) / self.lam + self.phi) + self.c

    def to_dict(self) -> dict[str, float]:
        return {k: float(getattr(self, k)) for k in ("A", "lam", "phi", "c", "rms", "r2")}


def _sine_start(x: NDArray[np.float64], z: NDArray[np.float64], f: float) -> NDArray[np.float64]:
    """Linear least squares for amplitude/phase/offset at fixed frequency ``f``."""
    w = 2 * np.pi * f
    G = np.column_stack([np.sin(w * x), np.cos(w * x), np.ones_like(x)])
    (al, be, c), *_ = np.linalg.lstsq(G, z, rcond=None)
    return np.array([np.hypot(al, be), w, np.arctan2(be, al), c])


def fit_sine(xyz: ArrayLike) -> SineFit:
    """Fit ``z = A sin(2 pi x / lam + phi) + c`` to a centre line (see :func:`prepare`).

    Initial wavelengths come from the peak of the zero-padded FFT of ``z(x)`` resampled on a
    uniform grid and from the count of zero crossings of ``z - median(z)``; for each, the
    amplitude, phase and offset follow from linear least squares, then
    :func:`scipy.optimize.least_squares` refines all four parameters. The best candidate wins.
    """
    cl = prepare(xyz)
    order = np.argsort(cl.x, kind="stable")
    x, z = cl.x[order], cl.z[order]
    X = float(x[-1] - x[0])
    if X <= 0:
        raise ValueError("centre line: zero extent along the rod")
    nu = 1024
    xu = np.linspace(x[0], x[-1], nu)
    zu = np.interp(xu, x, z)
    zu = zu - zu.mean()
    spec = np.abs(np.fft.rfft(zu, n=16 * nu))
    freqs = np.fft.rfftfreq(16 * nu, d=xu[1] - xu[0])
    valid = freqs >= 0.4 / X
    f_fft = float(freqs[valid][np.argmax(spec[valid])]) if valid.any() else 0.5 / X
    zc = z - np.median(z)
    nz = int(np.sum(np.signbit(zc[1:]) != np.signbit(zc[:-1])))
    cands = {f_fft, max(nz, 1) / (2 * X), (nz + 1) / (2 * X), max(nz - 1, 1) / (2 * X)}
    best = None
    w_lo, w_hi = 2 * np.pi / (4 * X), np.pi * len(x) / X  # lam in [2 X / M, 4 X]
    scale = max(float(np.ptp(z)), 1e-12)
    for f in sorted(cands):
        p0 = _sine_start(x, z, f)

        def res(p: NDArray[np.float64]) -> NDArray[np.float64]:
            return p[0] * np.sin(p[1] * x + p[2]) + p[3] - z

        p0[1] = np.clip(p0[1], w_lo * 1.001, w_hi * 0.999)
        try:
            sol = least_squares(
                res, p0, x_scale=[scale, 1.0 / X, 1.0, scale],
                bounds=([-np.inf, w_lo, -np.inf, -np.inf], [np.inf, w_hi, np.inf, np.inf]),
            )
            p = sol.x
            cost = float(np.sum(sol.fun**2))
        except (ValueError, np.linalg.LinAlgError):  # pragma: no cover - defensive
            p, cost = p0, float(np.sum(res(p0) ** 2))
        if best is None or cost < best[1]:
            best = (p, cost)
    assert best is not None
    A, w, phi, c = best[0]
    if A < 0:
        A, phi = -A, phi + np.pi
    if w < 0:  # sin(-w x + phi) = sin(w x + pi - phi)
        w, phi = -w, np.pi - phi
    phi = float(np.angle(np.exp(1j * phi)))
    lam = 2 * np.pi / w if w != 0 else np.inf

    def curve(t: NDArray[np.float64]) -> tuple[Any, Any, Any]:
        zz = A * np.sin(w * t + phi) + c
        return t, zz, np.arctan(A * w * np.cos(w * t + phi))

    pad = 0.05 * X
    _, d2 = _project(x, z, curve, x[0] - pad, x[-1] + pad, max(20 * len(x), 4000))
    return SineFit(
        A=float(A), lam=float(lam), phi=phi, c=float(c),
        rms=float(np.sqrt(np.mean(d2))), r2=_r2(d2, z),
    )


# ------------------------------------------------------------------------------ arc-chain fit


@dataclass
class ArcChainFit:
    """A tangent-continuous chain of circular arcs fitted to a centre line.

    ``kappa[k]`` is the signed curvature of piece ``k`` (< 0: up arc/crest, > 0: down
    arc/trough, ~0: straight), ``bounds`` the ``m + 1`` arclength limits of the pieces over the
    data (first and last are the data's ends), ``(x0, z0, psi0)`` the chain's start at
    arclength 0. ``s`` holds each data point's arclength on the fitted chain.
    """

    x0: float
    z0: float
    psi0: float
    kappa: NDArray[np.float64]
    bounds: NDArray[np.float64]
    s: NDArray[np.float64]
    x: NDArray[np.float64]
    z: NDArray[np.float64]
    rms: float
    r2: float
    extra: dict[str, Any] = field(default_factory=dict)

    def evaluate(self, s: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Points ``(x, z)`` of the fitted chain at arclengths ``s``."""
        x, z, _ = chain_points(self.x0, self.z0, self.psi0, self.kappa, self.bounds[1:-1], s)
        return x, z

    def arcs(self) -> list[dict[str, Any]]:
        """One dict per piece: ``s_start``, ``s_end``, ``length``, ``kappa``, ``R`` (None if
        straight), ``up`` (kappa < 0), ``turning`` (|kappa| * length, rad), end points,
        projected ``dx`` (|x_end - x_start|) and ``height`` (largest |z - chord z| inside the
        piece, measured along z from the line through its end points)."""
        out = []
        for k, kap in enumerate(self.kappa):
            s0, s1 = float(self.bounds[k]), float(self.bounds[k + 1])
            ss = np.linspace(s0, s1, 81)
            xx, zz = self.evaluate(ss)
            xr = xx[-1] - xx[0]
            if abs(xr) > 1e-12:
                chord = zz[0] + (zz[-1] - zz[0]) * (xx - xx[0]) / xr
            else:
                chord = np.full_like(zz, 0.5 * (zz[0] + zz[-1]))
            height = float(np.max(np.abs(zz - chord)))
            out.append({
                "s_start": s0, "s_end": s1, "length": s1 - s0, "kappa": float(kap),
                "R": float(1.0 / abs(kap)) if kap != 0 else None, "up": bool(kap < 0),
                "turning": float(abs(kap) * (s1 - s0)),
                "start": [float(xx[0]), float(zz[0])], "end": [float(xx[-1]), float(zz[-1])],
                "dx": float(abs(xr)), "height": height,
                "z_extreme": float(zz.max() if kap < 0 else zz.min()),
            })
        return out


def _smooth_odd(v: NDArray[np.float64], sigma: float) -> NDArray[np.float64]:
    """Gaussian smoothing with odd (point) reflection at both ends, which keeps the end
    tangents instead of flattening them."""
    p = int(min(max(4 * sigma, 2), len(v) - 2))
    left = 2 * v[0] - v[1 : p + 1][::-1]
    right = 2 * v[-1] - v[-p - 1 : -1][::-1]
    out = gaussian_filter1d(np.concatenate([left, v, right]), sigma, mode="nearest")
    return out[p : p + len(v)]


def _runs(labels: NDArray[np.int_]) -> list[list[int]]:
    """Runs of equal labels as [label, start, stop) lists."""
    edges = np.flatnonzero(np.diff(labels)) + 1
    starts = np.concatenate([[0], edges])
    stops = np.concatenate([edges, [len(labels)]])
    return [[int(labels[a]), int(a), int(b)] for a, b in zip(starts, stops, strict=True)]


def _segment(
    cl: Centerline, smooth: float | None
) -> tuple[list[float], list[float], float, dict[str, Any]]:
    """Initial guess: junctions at sign changes of the smoothed curvature.

    Returns ``(knots, kappas, psi0, info)``.
    """
    S = float(cl.s[-1])
    nu = int(np.clip(4 * len(cl.s), 400, 4000))
    su = np.linspace(0.0, S, nu)
    du = su[1]
    xu = np.interp(su, cl.s, cl.x)
    zu = np.interp(su, cl.s, cl.z)
    spacing = S / (len(cl.s) - 1)
    sig_len = float(smooth) if smooth else max(S / 150.0, 2.0 * spacing)
    sig = sig_len / du
    xs, zs = _smooth_odd(xu, sig), _smooth_odd(zu, sig)
    psi = np.unwrap(np.arctan2(np.gradient(zs), np.gradient(xs)))
    kap = np.gradient(psi, du)
    kmax = float(np.percentile(np.abs(kap), 95))
    info = {"sigma": sig_len, "kappa_max": kmax}
    if kmax * S < 1e-3:
        return [], [float((psi[-1] - psi[0]) / S)], float(psi[0]), info
    lab = np.where(kap > 0.15 * kmax, 1, np.where(kap < -0.15 * kmax, -1, 0))
    min_run = max(2.0 * sig_len, S / 200.0) / du
    # drop short non-zero runs (noise blips), then merge same-sign runs across zero gaps
    for r in _runs(lab):
        if r[0] != 0 and r[2] - r[1] < min_run:
            lab[r[1] : r[2]] = 0
    runs = [r for r in _runs(lab) if r[0] != 0]
    if not runs:
        return [], [float((psi[-1] - psi[0]) / S)], float(psi[0]), info
    merged = [runs[0]]
    for r in runs[1:]:
        if r[0] == merged[-1][0]:
            merged[-1][2] = r[2]
        else:
            merged.append(r)
    knots: list[float] = []
    for r0, r1 in zip(merged[:-1], merged[1:], strict=True):
        a, b = r0[2] - 1, r1[1] + 1  # zero crossing of kappa inside [a, b]
        seg = kap[a:b]
        cross = np.flatnonzero(np.signbit(seg[1:]) != np.signbit(seg[:-1]))
        j = a + int(cross[len(cross) // 2]) if len(cross) else (a + b) // 2
        # linear interpolation of the crossing between samples j and j+1
        k0, k1 = kap[j], kap[min(j + 1, nu - 1)]
        frac = k0 / (k0 - k1) if k0 != k1 else 0.5
        knots.append(float(su[j] + np.clip(frac, 0, 1) * du))
    # straight end pieces where a long zero-labelled stretch remains at an end
    end_len = 3.0 * sig_len
    if merged[0][1] * du > end_len:
        knots.insert(0, float(su[merged[0][1]]))
    if (nu - merged[-1][2]) * du > end_len:
        knots.append(float(su[merged[-1][2] - 1]))
    bounds = np.concatenate([[0.0], knots, [S]])
    psi_b = np.interp(bounds, su, psi)
    kappas = [float((psi_b[k + 1] - psi_b[k]) / max(bounds[k + 1] - bounds[k], 1e-12))
              for k in range(len(bounds) - 1)]
    return knots, kappas, float(psi[0]), info


def _denoised_arclength(cl: Centerline) -> Centerline:
    """Arclength of the polyline after a light Gaussian smoothing (2 points wide).

    Noise lengthens a polyline (each step gains ~ noise**2 / spacing); smoothing first keeps the
    initial arclength close to the true one. The orthogonal refinement removes what is left.
    """
    xs, zs = _smooth_odd(cl.x, 2.0), _smooth_odd(cl.z, 2.0)
    s = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(xs), np.diff(zs)))])
    return Centerline(x=cl.x, z=cl.z, s=s, length=cl.length)


def fit_arcs(
    xyz: ArrayLike, *, smooth: float | None = None, max_nfev: int = 40
) -> ArcChainFit:
    """Fit a tangent-continuous chain of circular arcs to a centre line (see :func:`prepare`).

    1. **Segmentation** (initial guess): resample ``(x, z)`` uniformly in arclength, smooth
       with a Gaussian of width ``smooth`` [mm] (default ``max(S/150, 2 * point spacing)``),
       compute the tangent angle ``psi(s)`` and curvature ``kappa = dpsi/ds``; label samples
       +1/-1/0 by comparing ``kappa`` with 15 % of its 95th percentile; drop runs shorter
       than ``max(2 smooth, S/200)``, merge same-sign runs; junctions go at the zero crossing
       of ``kappa`` between opposite-sign runs; long zero stretches at the ends become
       straight end pieces. Initial curvatures are turning angle / length of each piece.
    2. **Least squares** (:func:`scipy.optimize.least_squares`) on the ``(x, z)`` residuals at
       matched arclength over start point, start angle, curvatures and junction positions
       (at most ``max_nfev`` evaluations per solve; a clean chain needs < 20).
    3. **Orthogonal refinement**: each point's arclength is replaced by that of its nearest
       point on the fitted chain and the fit is repeated on *normal* distances, re-projecting
       the points inside every residual evaluation (variable projection). This removes the
       bias of the noisy polyline arclength (noise lengthens a polyline).
    """
    cl = prepare(xyz)
    cl = _denoised_arclength(cl)
    S = float(cl.s[-1])
    knots, kappas, psi0, info = _segment(cl, smooth)
    m = len(kappas)
    p0 = np.concatenate([[cl.x[0], cl.z[0], psi0], kappas, knots])
    lo = np.full(p0.shape, -np.inf)
    hi = np.full(p0.shape, np.inf)
    lo[3 + m :] = 0.0
    hi[3 + m :] = S
    p0 = np.clip(p0, lo + 1e-12 * S, hi - 1e-12 * S) if m > 1 else p0
    kscale = max(float(np.max(np.abs(kappas))), 1.0 / S)
    xscale = np.concatenate([[S / 100, S / 100, 0.1], np.full(m, kscale), np.full(m - 1, S / 100)])
    x, z = cl.x, cl.z
    ext = 3.0 * S / (len(x) - 1)  # how far the end pieces may extend beyond the data
    s_lo, s_hi = -ext, S + ext
    n_dense = max(20 * len(x), 4000)

    def curve_of(q: NDArray[np.float64]) -> Any:
        def curve(t: NDArray[np.float64]) -> tuple[Any, Any, Any]:
            return chain_points(q[0], q[1], q[2], q[3 : 3 + m], q[3 + m :], t)

        return curve

    def solve(
        p: NDArray[np.float64], s_ref: NDArray[np.float64], normal: bool
    ) -> NDArray[np.float64]:
        """``normal=False``: (x, z) residuals at the fixed arclengths ``s_ref``.
        ``normal=True``: signed normal distances, each point re-projected on the chain by
        two tangential Newton steps from ``s_ref`` (variable projection)."""

        def res(q: NDArray[np.float64]) -> NDArray[np.float64]:
            sq = s_ref
            mx, mz, psi = chain_points(q[0], q[1], q[2], q[3 : 3 + m], q[3 + m :], sq)
            if not normal:
                return np.concatenate([mx - x, mz - z])
            for _ in range(2):
                sq = np.clip(sq + (x - mx) * np.cos(psi) + (z - mz) * np.sin(psi), s_lo, s_hi)
                mx, mz, psi = chain_points(q[0], q[1], q[2], q[3 : 3 + m], q[3 + m :], sq)
            return (z - mz) * np.cos(psi) - (x - mx) * np.sin(psi)

        return least_squares(
            res, p, bounds=(lo, hi), x_scale=xscale, method="trf", max_nfev=max_nfev
        ).x

    p = solve(p0, cl.s, normal=False)
    for _ in range(2):
        s, _ = _project(x, z, curve_of(p), s_lo, s_hi, n_dense)
        p = solve(p, s, normal=True)
    s, d2 = _project(x, z, curve_of(p), s_lo, s_hi, n_dense)
    kap = p[3 : 3 + m]
    kn = np.sort(p[3 + m :])
    bounds = np.concatenate([[float(s.min())], np.clip(kn, s.min(), s.max()), [float(s.max())]])
    return ArcChainFit(
        x0=float(p[0]), z0=float(p[1]), psi0=float(p[2]), kappa=np.asarray(kap, float),
        bounds=bounds, s=s, x=x, z=z, rms=float(np.sqrt(np.mean(d2))), r2=_r2(d2, z),
        extra=info,
    )
