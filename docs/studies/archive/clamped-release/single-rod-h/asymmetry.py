"""Up against down arcs (the bilayer asymmetry) from the committed table:

    python docs/studies/single-rod-h/asymmetry.py   # -> figures/bilayer_asymmetry.png, .pdf

R_up / R_down: mean radius of the arcs bulging away from the fabric / towards it (interior
arcs only where a rod has them; docs/analysis.md). Only runs with n >= 5 have interior arcs
of both kinds; with n = 3 the one interior arc is a down arc and the up value comes from the
two end arcs, which the clamped-free ends shape, so those are marked apart.
"""

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import pandas as pd  # noqa: E402

HERE = Path(__file__).resolve().parent
t = pd.read_csv(HERE / "table.csv")
t = t[t.seed == 0].sort_values("h")
both = t[(t.n >= 5) & t.R_down_mean.notna()]
three = t[(t.n == 3) & t.R_down_mean.notna() & (t.h < 1.0)]
fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 4.0))
a1.plot(both.h, both.R_up_mean, "o", ms=4, label="R_up (away from the fabric), n >= 5")
a1.plot(both.h, both.R_down_mean, "s", ms=4, mfc="none", label="R_down (towards it), n >= 5")
a1.plot(three.h, three.R_up_mean, "o", ms=4, alpha=0.35, label="R_up, n = 3 (end arcs)")
a1.plot(three.h, three.R_down_mean, "s", ms=4, mfc="none", alpha=0.35,
        label="R_down, n = 3 (the middle arc)")
a1.set_xlabel("rod thickness h [mm]")
a1.set_ylabel("arc radius [mm]")
a1.legend(fontsize=7)
a1.set_title("up and down arcs of one rod")
a2.plot(both.h, both.R_up_mean / both.R_down_mean, "o", ms=4, label="n >= 5")
a2.plot(three.h, three.R_up_mean / three.R_down_mean, "o", ms=4, alpha=0.35,
        label="n = 3 (end arcs over the middle one)")
a2.axhline(1.0, color="k", lw=0.8)
a2.set_xlabel("rod thickness h [mm]")
a2.set_ylabel("R_up / R_down")
a2.legend(fontsize=7)
a2.set_title("bilayer asymmetry")
fig.tight_layout()
for ext in ("png", "pdf"):
    fig.savefig(HERE / "figures" / f"bilayer_asymmetry.{ext}", dpi=130)
r = both.R_up_mean / both.R_down_mean
print(f"n >= 5: {len(both)} runs, R_up/R_down {r.min():.3f}-{r.max():.3f}, "
      f"median {r.median():.3f}")
