"""Shape analysis of buckled rods (docs/analysis.md).

Fit a sine and a chain of circular arcs to each rod's centre line, extract the metrics
``l, lam, a, R, R_up, R_down, kappa_up, kappa_down, n, ...``, measure the phase coherence of
neighbouring rods and classify a run into a shape family. See ``docs/analysis.md``.

Public API::

    fit_sine(xyz) -> SineFit
    fit_arcs(xyz, *, smooth=None) -> ArcChainFit
    rod_metrics(xyz, *, L=None) -> dict
    coherence(xyz_a, xyz_b) -> float
    classify(rods_xyz, *, L=None) -> str
    analyse_run(centerlines, *, L=None) -> dict
    analyse_dir(path, *, plots=True) -> dict
"""

from .fit import ArcChainFit, SineFit, fit_arcs, fit_sine, prepare
from .io import analyse_dir, load_centerlines, plot_fits
from .metrics import (
    COHERENT_THRESHOLD,
    FAMILIES,
    analyse_run,
    classify,
    coherence,
    rod_metrics,
)
from .synthetic import arc_chain, sine_curve, to_xyz

__all__ = [
    "ArcChainFit",
    "SineFit",
    "fit_arcs",
    "fit_sine",
    "prepare",
    "rod_metrics",
    "coherence",
    "classify",
    "analyse_run",
    "analyse_dir",
    "load_centerlines",
    "plot_fits",
    "arc_chain",
    "sine_curve",
    "to_xyz",
    "COHERENT_THRESHOLD",
    "FAMILIES",
]
