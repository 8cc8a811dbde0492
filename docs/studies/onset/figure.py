"""Figure of docs/studies/onset/README.md from the committed tables:

    python docs/studies/onset/figure.py     # -> docs/studies/onset/onset.png and .pdf
"""

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

HERE = Path(__file__).resolve().parent
single = pd.read_csv(HERE.parent / "single-rod-h" / "table.csv")
single = single[single.seed == 0]
sweep = pd.read_csv(HERE / "table.csv")
stiff = pd.read_csv(HERE / "table_stiffness.csv")

fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 4.2))
a1.loglog(single.h, single.onset_release_strain, "o", ms=3, label="rod stands out by h")
nc = single.onset_negative_curvature_release_strain
a1.loglog(single.h, nc.where(nc > 0), "x", ms=4, label="first negative-curvature step")
sel = single[single.h <= 0.5]
p = np.polyfit(np.log(sel.h), np.log(sel.onset_release_strain), 1)
hh = np.linspace(0.08, 0.5, 20)
a1.loglog(hh, np.exp(p[1]) * hh ** p[0], "k-", lw=1,
          label=f"fit h <= 0.5: {np.exp(p[1]):.3f} h^{p[0]:.2f}")
for (my, amp), g in sweep.groupby(["margin_y", "imperfection.amplitude"]):
    if amp == 0.001:
        a1.loglog(g["rods.h"], g.onset_release_strain, "s" if my == 50 else "D", mfc="none",
                  ms=7, label=f"onset sweep, {my:g} mm of fabric beside the rod")
a1.set_xlabel("rod thickness h [mm]")
a1.set_ylabel("release strain at the onset [-]")
a1.set_title("onset of buckling vs h (single rod, eps0 = 0.5)")
a1.legend(fontsize=7)
ratio = stiff.E_B / stiff.E
a2.semilogx(ratio, stiff.onset_release_strain, "o", label="rod stands out by h")
q = np.polyfit(np.log(ratio), np.log(stiff.onset_release_strain), 1)
rr = np.geomspace(ratio.min(), ratio.max(), 20)
a2.semilogx(rr, np.exp(q[1]) * rr ** q[0], "k-", lw=1, label=f"fit: (E_B/E)^{q[0]:.3f}")
a2.set_xlabel("E_B / E (rod modulus over fabric modulus)")
a2.set_ylabel("release strain at the onset [-]")
a2.set_title("h = 0.3 mm: only the ratio matters")
a2.legend(fontsize=7)
fig.tight_layout()
for ext in ("png", "pdf"):
    fig.savefig(HERE / f"onset.{ext}", dpi=130)
print(f"h exponent {p[0]:.3f}, E_B/E exponent {q[0]:.3f}")
