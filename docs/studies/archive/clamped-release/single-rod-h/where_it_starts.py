"""Where along the rod buckling starts: one rod released part-way, its height envelope.

    python docs/studies/single-rod-h/where_it_starts.py 0.1 0.47,0.462,0.455,0.44

Arguments: the rod thickness h [mm] and the clamp strains to stop the release at (eps0 = 0.5,
so 0.47 is a release of 0.03). For each, the largest |z| (height above the rod's median
level) in each tenth of the rod's length is printed, from one end to the other.
"""

import sys

import numpy as np

from undulate import api


def main() -> None:
    h = float(sys.argv[1])
    for final in (float(x) for x in sys.argv[2].split(",")):
        result = api.simulate({"rods": {"h": h}, "release": {"final_strain": final}})
        c = np.asarray(result.centerlines[0])
        x, z = c[:, 0] - c[:, 0].min(), c[:, 2] - np.median(c[:, 2])
        edges = np.linspace(0.0, x.max(), 11)
        env = [np.max(np.abs(z[(x >= a) & (x <= b)])) for a, b in zip(edges[:-1], edges[1:],
                                                                       strict=True)]
        print(f"h = {h} mm, release {0.5 - final:.3f}: max |z| per tenth of the rod [mm]: "
              + " ".join(f"{e:.3f}" for e in env), flush=True)


if __name__ == "__main__":
    main()
