"""Parametric studies: presets and sweeps, resumable local/dask runner, storage, figures, report.

Typical use::

    from undulate.study import get_preset, run_study, collect
    study = get_preset("single-rod-h", quick=True)
    run_study(study, "out/single-rod-h")
    df = collect("out/single-rod-h")
"""

from .presets import PRESETS, get_preset, preset_names, resolve_study
from .runner import RunSummary, execute_run, resolve_runner, run_study
from .spec import RunSpec, Study, StudyError, build_study, load_sweep_toml, run_id
from .storage import collect, read_study, scan_runs, write_table

__all__ = [
    "PRESETS",
    "RunSpec",
    "RunSummary",
    "Study",
    "StudyError",
    "build_study",
    "collect",
    "execute_run",
    "get_preset",
    "load_sweep_toml",
    "preset_names",
    "read_study",
    "resolve_runner",
    "resolve_study",
    "run_id",
    "run_study",
    "scan_runs",
    "write_table",
]
