"""A fake job worker for the web tests: no simulation, a few states over about a second.

It is the worker body of :class:`undulate.interfaces.web.jobs.JobManager` (the job folder as
a string), so the queue, progress, cancel and downloads are tested without the engine. It
writes ``metrics.json``, ``centerlines.npz`` and a small ``final.vtu`` laid out as the real
output's (fabric triangles first, then each rod's centre line as its own run of points joined
by line cells, ``is_rod`` telling them apart):
each rod a sine of 3 half-waves, 2 mm high, 0.5 mm above a flat fabric grid that reaches
:data:`FABRIC_MARGIN` mm beyond the rods.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from undulate.interfaces.web.jobs import _write_state, read_state

FABRIC_MARGIN = 40.0  # the fake fabric grid reaches this far beyond the rods [mm]
ROD_POINTS = 31


def fake_rods(case: dict) -> list[np.ndarray]:
    """The rods' centre lines of the fake final.vtu: (ROD_POINTS, 3) per line of the case's
    pattern (sampled along its polyline, three half-waves)."""
    out = []
    for line in case["pattern"]["lines"]:
        pts = np.asarray(line["points"], dtype=float)
        s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
        t = np.linspace(0.0, s[-1], ROD_POINTS)
        xy = np.column_stack([np.interp(t, s, pts[:, 0]), np.interp(t, s, pts[:, 1])])
        z = 0.5 + 2.0 * np.sin(3 * np.pi * t / s[-1])
        out.append(np.column_stack([xy, z]))
    return out


def write_fake_vtu(path: Path, case: dict) -> None:
    import meshio

    rods = fake_rods(case)
    allp = np.vstack(rods)
    lo = allp[:, :2].min(axis=0) - FABRIC_MARGIN
    hi = allp[:, :2].max(axis=0) + FABRIC_MARGIN
    gx, gy = np.linspace(lo[0], hi[0], 25), np.linspace(lo[1], hi[1], 17)
    X, Y = np.meshgrid(gx, gy, indexing="ij")
    pts = [np.column_stack([X.ravel(), Y.ravel(), np.zeros(X.size)])]
    idx = np.arange(X.size).reshape(X.shape)
    a, b = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel()
    c, d = idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    tris = np.concatenate([np.column_stack([a, b, c]), np.column_stack([a, c, d])])
    off, lines = X.size, []
    for r in rods:
        pts.append(r)
        lines.append(np.column_stack([np.arange(off, off + len(r) - 1),
                                      np.arange(off + 1, off + len(r))]))
        off += len(r)
    is_rod = np.r_[np.zeros(X.size), np.ones(off - X.size)]
    meshio.write(str(path), meshio.Mesh(np.vstack(pts), [("triangle", tris),
                                                         ("line", np.concatenate(lines))],
                                        point_data={"is_rod": is_rod}))
    np.savez(path.parent / "centerlines.npz", **{f"rod{k}": r for k, r in enumerate(rods)})


def fake_job(folder: str) -> None:
    f = Path(folder)
    case = json.loads((f / "case.json").read_text())
    st = read_state(f)
    seconds = 0.2 * case["imperfection"]["seed"]  # the tests set the run time through seed
    st.update(status="running", started=time.time(), stage="fake")
    _write_state(f, st)
    for k in range(5):
        time.sleep(seconds / 5)
        st["progress"] = (k + 1) / 5
        _write_state(f, st)
    res = f / "result"
    res.mkdir()
    rods = [{"index": k, "h": 0.3, "b": 1.0, "n": 3} for k in range(len(case["pattern"]["lines"]))]
    (res / "metrics.json").write_text(json.dumps({"n": 3, "rods": rods}))
    write_fake_vtu(res / "final.vtu", case)
    st.update(status="done", finished=time.time(), metrics={"n": 3, "family": "waves"})
    _write_state(f, st)
