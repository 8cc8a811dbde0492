"""Where along a single rod buckling starts, and how curved its end arcs end up.

    python docs/studies/onset/spread.py 0.2 0.3 0.42      # rod thicknesses h [mm]

For each h: the rod (L = 100 mm) on the reference set-up (E_B = 1000 MPa), eps0 = 0.5,
released in 40 equal nominal steps. At each of the first release steps it prints the largest
height of the rod's centre line above or below its printed level in the middle third of the
rod and in its two outer sixths; then the final arcs (length, radius R, crest or trough) as
the arc-chain fit of the analysis finds them. Reads the release's equilibria through its
history hook (`undulate.solve.release._record`), so it needs the source tree of this commit.
"""

from __future__ import annotations

import sys

import numpy as np

import undulate.solve.release as release
from undulate import api
from undulate.analysis.metrics import _split_flat_ends, fit_arcs
from undulate.mechanics.build import rod_centrelines


def spread(h: float, steps_shown: int = 12) -> None:
    snaps = []
    record = release._record

    def keep(sim, bd, w, res, eps0):
        rec = record(sim, bd, w, res, eps0)
        cl = rod_centrelines(sim.mesh.rods, w.x, sim.sections)[0]
        snaps.append((rec["release_strain"], cl.copy(), sim.sections[0].offset))
        return rec

    release._record = keep
    try:
        case = api.case_from_dict({"rods": {"h": h, "L": 100.0, "E_B": 1000.0},
                                   "release": {"eps0": 0.5, "steps": 40}})
        r = release.run_release(case)
    finally:
        release._record = record
    print(f"h = {h:g} mm: release strain, max |z - printed level| [mm] in the middle third "
          "and in the outer sixths")
    for e, cl, off in snaps[:steps_shown]:
        xs = cl[:, 0] - cl[:, 0].mean()
        span = np.ptp(cl[:, 0])
        dz = np.abs(cl[:, 2] - off)
        print(f"  {e:.4f}  {dz[np.abs(xs) < span / 6].max():6.3f}  "
              f"{dz[np.abs(xs) > span / 3].max():6.3f}")
    arcs, _ = _split_flat_ends(fit_arcs(r.centerlines[0]).arcs())
    print("  final arcs (length [mm], R [mm], crest):",
          [(round(p["length"], 1), round(p["R"], 2) if p["R"] else None, p["up"])
           for p in arcs])


if __name__ == "__main__":
    for arg in sys.argv[1:] or ["0.3"]:
        spread(float(arg))
