"""Bad inputs and the one line each gets: shared by tests/test_errors_doc.py (which runs every
case through the real command line and checks the message) and docs/errors.md (the table is
generated from the same runs, so it cannot drift from what users see).

Each case builds its files in an empty working folder (paths in messages are relative to it)
and returns the command-line arguments.

    UNDULATE_WRITE_DOCS=1 python -m pytest tests/test_errors_doc.py    # rewrite docs/errors.md
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

TINY = """name = "tiny"
[rods]
L = 20.0
[fabric]
margin_x = 4.0
margin_y = 4.0
[release]
steps = 3
[mesh]
dx_rod = 2.0
dx_far = 4.0
"""


_PAT = "Patterns (`undulate run --pattern`, `[pattern]`)"


def _gcode_args(d: Path, *opts: str) -> list[str]:
    (d / "case.toml").write_text(TINY)
    return ["gcode", "case.toml", "--out", "case.gcode", *opts]


@dataclass(frozen=True)
class ErrorCase:
    id: str
    group: str
    what: str  # the bad input, as the table shows it
    setup: Callable[[Path], list[str]]
    expect: tuple[str, ...]  # fragments the message must contain
    env: tuple[tuple[str, str], ...] = ()  # environment settings of the command
    code: int = 2


def _case_file(text: str | bytes, name: str = "case.toml") -> Callable[[Path], list[str]]:
    def setup(d: Path) -> list[str]:
        p = d / name
        if isinstance(text, bytes):
            p.write_bytes(text)
        else:
            p.write_text(text)
        return ["run", name, "--out", "out"]

    return setup


def _tiny_to(out_setup: Callable[[Path], str], *extra: str) -> Callable[[Path], list[str]]:
    def setup(d: Path) -> list[str]:
        (d / "tiny.toml").write_text(TINY)
        return ["run", "tiny.toml", "--out", out_setup(d), *extra]

    return setup


def _dxf_with_text(path: Path) -> None:
    import ezdxf

    doc = ezdxf.new()
    doc.modelspace().add_line((0, 0), (60, 0))
    doc.modelspace().add_text("label", dxfattribs={"layer": "NOTES"})
    doc.saveas(path)


def _out_is_file(d: Path) -> str:
    (d / "result").write_text("not a folder")
    return "result"


def _out_under_file(d: Path) -> str:
    (d / "result").write_text("not a folder")
    return "result/run1"


def _out_unwritable(d: Path) -> str:
    import os

    if os.geteuid() == 0:  # root may write anywhere but in a kernel file system
        return "/sys/undulate-run"
    ro = d / "read-only"
    ro.mkdir()
    ro.chmod(0o555)
    return "read-only/run1"


def _out_nonempty(d: Path) -> str:
    o = d / "old-run"
    o.mkdir()
    for name in ("metrics.json", "centerlines.npz", "rod_3_side.png"):
        (o / name).write_text("x")
    return "old-run"


def _out_foreign(d: Path) -> str:
    o = d / "old-run"
    o.mkdir()
    (o / "metrics.json").write_text("{}")
    (o / "notes.txt").write_text("my notes")
    return "old-run"


def _run_dir(d: Path, name: str = "run1") -> Path:
    r = d / name
    r.mkdir()
    x = np.linspace(-10, 10, 41)
    z = np.sin(x / 3)
    np.savez(r / "centerlines.npz", rod0=np.stack([x, 0 * x, z], 1))
    (r / "metrics.json").write_text(json.dumps({"case": {"rods": {"L": 20.0}}, "rods": []}))
    return r


def _analyse(damage: Callable[[Path], None], name: str = "run1") -> Callable[[Path], list[str]]:
    def setup(d: Path) -> list[str]:
        damage(_run_dir(d, name))
        return ["analyse", name, "--no-plots"]

    return setup


def _truncate_npz(r: Path) -> None:
    f = r / "centerlines.npz"
    f.write_bytes(f.read_bytes()[:200])


def _garbage_npz(r: Path) -> None:
    (r / "centerlines.npz").write_bytes(bytes(range(256)) * 3)


def _pickled_npz(r: Path) -> None:
    with open(r / "centerlines.npz", "wb") as fh:
        np.save(fh, np.array([{"rod0": 1}], dtype=object), allow_pickle=True)


def _truncate_json(r: Path) -> None:
    f = r / "metrics.json"
    f.write_text(f.read_text()[:20])


def _no_npz(r: Path) -> None:
    (r / "centerlines.npz").unlink()


SEG = '{ start = [-10.0, 0.0], length = 20.0 }'

CASES: list[ErrorCase] = [
    # ---- case files --------------------------------------------------------------------
    ErrorCase("empty", "Case file (`undulate run CASE --out DIR`)", "empty file",
              _case_file(""), ("case.toml: empty case", "undulate demo")),
    ErrorCase("comments-only", "Case file (`undulate run CASE --out DIR`)",
              "only comments", _case_file("# nothing here\n"), ("empty case",)),
    ErrorCase("binary", "Case file (`undulate run CASE --out DIR`)", "binary file",
              _case_file(b"\x00\x01\x02rods\x00"), ("case.toml: binary file",)),
    ErrorCase("latin1", "Case file (`undulate run CASE --out DIR`)",
              "not UTF-8 (Latin-1 `é`)", _case_file('name = "caf\xe9"\n'.encode("latin-1")),
              ("case.toml: not a text file in UTF-8",)),
    ErrorCase("directory", "Case file (`undulate run CASE --out DIR`)", "a directory",
              lambda d: ((d / "cases").mkdir(), ["run", "cases", "--out", "out"])[1],
              ("cases: is a directory",)),
    ErrorCase("missing", "Case file (`undulate run CASE --out DIR`)", "missing file",
              lambda d: ["run", "nope.toml", "--out", "out"], ("nope.toml: no such file",)),
    ErrorCase("bad-toml", "Case file (`undulate run CASE --out DIR`)", "`[rods` (bad TOML)",
              _case_file("[rods\nh = 1\n"), ("not valid TOML",)),
    ErrorCase("string-number", "Case file (`undulate run CASE --out DIR`)",
              '`h = "0.3"`', _case_file('[rods]\nh = "0.3"\n'),
              ("rods.h", "valid number", "without quotes")),
    ErrorCase("bool-int", "Case file (`undulate run CASE --out DIR`)", "`N = true`",
              _case_file("[rods]\nN = true\n"), ("rods.N", "valid integer")),
    ErrorCase("bool-seed", "Case file (`undulate run CASE --out DIR`)", "`seed = true`",
              _case_file("[imperfection]\nseed = true\n"), ("imperfection.seed", "integer")),
    ErrorCase("string-bool", "Case file (`undulate run CASE --out DIR`)",
              '`adaptive = "yes"`', _case_file('[release]\nadaptive = "yes"\n'),
              ("release.adaptive", "valid boolean")),
    ErrorCase("float-int", "Case file (`undulate run CASE --out DIR`)", "`N = 2.0`",
              _case_file("[rods]\nN = 2.0\n"), ("rods.N", "valid integer", "2.0")),
    ErrorCase("nan", "Case file (`undulate run CASE --out DIR`)", "`h = nan`",
              _case_file("[rods]\nh = nan\n"), ("rods.h", "finite")),
    ErrorCase("range", "Case file (`undulate run CASE --out DIR`)", "`eps0 = 5`",
              _case_file("[release]\neps0 = 5\n"), ("release.eps0", "allowed: > 0, <= 3")),
    ErrorCase("step-factor", "Case file (`undulate run CASE --out DIR`)",
              "`max_step_factor = 0.5`", _case_file("[release]\nmax_step_factor = 0.5\n"),
              ("release.max_step_factor", "allowed: >= 1, <= 100")),
    ErrorCase("unknown-key", "Case file (`undulate run CASE --out DIR`)", "`hh = 1` (typo)",
              _case_file("[rods]\nhh = 1\n"), ("rods.hh", "Extra inputs")),
    ErrorCase("segments-and-N", "Case file (`undulate run CASE --out DIR`)",
              "`N`, `s` beside `segments`",
              _case_file(f"[rods]\nN = 2\ns = 3.0\nsegments = [{SEG}]\n"),
              ("rods.segments: N, s cannot be given together with segments",)),
    ErrorCase("segments-empty", "Case file (`undulate run CASE --out DIR`)", "`segments = []`",
              _case_file("[rods]\nsegments = []\n"), ("rods.segments: give at least one rod",)),
    ErrorCase("direction", "Case file (`undulate run CASE --out DIR`)",
              "segment `direction = [0, 1]`",
              _case_file("[rods]\nsegments = [{ start = [0.0, 0.0], length = 20.0, "
                         "direction = [0.0, 1.0] }]\n"), ("only rods along +x",)),
    ErrorCase("dx-far", "Case file (`undulate run CASE --out DIR`)",
              "`dx_far = 1` below `dx_rod = 2`",
              _case_file("[mesh]\ndx_rod = 2.0\ndx_far = 1.0\n"),
              ("mesh.dx_far: must be >= dx_rod",)),
    ErrorCase("dx-rod", "Case file (`undulate run CASE --out DIR`)",
              "`dx_rod = 15` for `L = 20`",
              _case_file("[rods]\nL = 20.0\n[mesh]\ndx_rod = 15.0\ndx_far = 20.0\n"),
              ("mesh.dx_rod: must be <= half the shortest rod",)),
    ErrorCase("overlap", "Case file (`undulate run CASE --out DIR`)", "overlapping segments",
              _case_file("[rods]\nb = 2.0\nsegments = [{ start = [0.0, 0.0], length = 10.0 }, "
                         "{ start = [5.0, 1.0], length = 10.0 }]\n"), ("overlap",)),
    # ---- output folder (checked before anything is simulated) ---------------------------
    ErrorCase("out-file", "Output folder (`--out`), refused before simulating",
              "`--out` is an existing file", _tiny_to(_out_is_file),
              ("output folder result: exists and is not a folder",)),
    ErrorCase("out-under-file", "Output folder (`--out`), refused before simulating",
              "`--out` inside a file", _tiny_to(_out_under_file), ("is a file, not a folder",)),
    ErrorCase("out-unwritable", "Output folder (`--out`), refused before simulating",
              "`--out` where nothing can be written", _tiny_to(_out_unwritable),
              ("cannot write there",)),
    ErrorCase("out-nonempty", "Output folder (`--out`), refused before simulating",
              "`--out` holds an earlier run", _tiny_to(_out_nonempty),
              ("is not empty", "--overwrite")),
    ErrorCase("out-foreign", "Output folder (`--out`), refused before simulating",
              "`--overwrite`, but `--out` holds other files", _tiny_to(_out_foreign,
                                                                       "--overwrite"),
              ("replaces only a previous run's files", "notes.txt")),
    # ---- analyse ------------------------------------------------------------------------
    ErrorCase("npz-truncated", "Run folder (`undulate analyse DIR`)", "truncated centerlines.npz",
              _analyse(_truncate_npz), ("run1/centerlines.npz: not a readable",)),
    ErrorCase("npz-garbage", "Run folder (`undulate analyse DIR`)", "garbage centerlines.npz",
              _analyse(_garbage_npz), ("run1/centerlines.npz: not a readable",)),
    ErrorCase("npz-pickle", "Run folder (`undulate analyse DIR`)",
              "centerlines.npz holding pickled objects", _analyse(_pickled_npz),
              ("run1/centerlines.npz",)),
    ErrorCase("json-truncated", "Run folder (`undulate analyse DIR`)", "truncated metrics.json",
              _analyse(_truncate_json), ("run1/metrics.json: not valid JSON",)),
    ErrorCase("no-npz", "Run folder (`undulate analyse DIR`)", "not a run folder",
              _analyse(_no_npz), ("no centerlines.npz",)),
    ErrorCase("incomplete", "Run folder (`undulate analyse DIR`)",
              "the hidden folder of an interrupted run",
              _analyse(lambda r: None, ".run1.incomplete-x1y2"), ("interrupted or unfinished",)),
    # ---- environment --------------------------------------------------------------------
    ErrorCase("pardiso-threads", "Environment settings (any command)",
              "`UNDULATE_PARDISO_THREADS=two`", lambda d: ["demo", "--out", "run1"],
              ("UNDULATE_PARDISO_THREADS", "whole number from 1 to 256", "'two'"),
              env=(("UNDULATE_PARDISO_THREADS", "two"),)),
    ErrorCase("pardiso-threads-zero", "Environment settings (any command)",
              "`UNDULATE_PARDISO_THREADS=0`", lambda d: ["theory", "--h", "0.3"],
              ("UNDULATE_PARDISO_THREADS", "from 1 to 256"),
              env=(("UNDULATE_PARDISO_THREADS", "0"),)),
    ErrorCase("jax-cache-mb", "Environment settings (any command)",
              "`UNDULATE_JAX_CACHE_MB=lots`", lambda d: ["cache"],
              ("UNDULATE_JAX_CACHE_MB", "from 10 to 1000000", "'lots'"),
              env=(("UNDULATE_JAX_CACHE_MB", "lots"),)),
    # ---- patterns -----------------------------------------------------------------------
    ErrorCase("knit-half", "Case file (`undulate run CASE --out DIR`)",
              "`fabric.E_y` without `fabric.G`", _case_file('[fabric]\nE_y = 0.2\n'),
              ("fabric.E_y: an orthotropic knit needs both E_y and G",)),
    ErrorCase("knit-stretch", "Case file (`undulate run CASE --out DIR`)",
              "an orthotropic knit stretched too far",
              _case_file('[fabric]\nE_y = 0.2\nG = 0.1\n[release]\neps0 = 2.0\n'),
              ("release.eps0: 2 is too large a stretch for the orthotropic",)),
    ErrorCase("gravity-size", "Case file (`undulate run CASE --out DIR`)",
              "`gravity.g` beyond 1e6 mm/s^2",
              _case_file('[gravity]\ng = [0.0, 0.0, -2e6]\n'),
              ("gravity.g: each component must be within +-1e6 mm/s^2",)),
    ErrorCase("pattern-cross", _PAT,
              "`--pattern` with crossing lines",
              lambda d: (d / "x.svg").write_text(
                  '<svg xmlns="http://www.w3.org/2000/svg" width="100mm" height="100mm" '
                  'viewBox="0 0 100 100"><line id="a" x1="0" y1="50" x2="100" y2="50"/>'
                  '<line id="b" x1="50" y1="0" x2="50" y2="100"/></svg>')
              and ["run", "--pattern", "x.svg", "--out", "out"],
              ("x.svg: pattern: lines a and b: cross at (0, 0) mm",)),
    ErrorCase("pattern-text", _PAT,
              "a drawing with a text element",
              lambda d: (d / "x.svg").write_text(
                  '<svg xmlns="http://www.w3.org/2000/svg"><line x1="0" y1="0" x2="90" y2="0"/>'
                  '<text id="label">hi</text></svg>')
              and ["run", "--pattern", "x.svg", "--out", "out"],
              ("x.svg: svg: a text element 'label' is not a line",)),
    ErrorCase("pattern-missing", _PAT,
              "`--pattern` names no file",
              lambda d: ["run", "--pattern", "nope.svg", "--out", "out"],
              ("nope.svg: svg: cannot read",)),
    ErrorCase("pattern-self", _PAT,
              "a line that crosses itself",
              _case_file('[[pattern.lines]]\nid = "z"\n'
                         'points = [[0, 0], [30, 0], [30, 30], [15, -15]]\n'),
              ("pattern: line z: crosses itself at",)),
    ErrorCase("pattern-gap", _PAT,
              "two lines closer than `min_gap`",
              _case_file('[pattern]\nmin_gap = 3.0\nlines = [\n'
                         '  { id = "a", points = [[-20, 0], [20, 0]] },\n'
                         '  { id = "b", points = [[-20, 3], [20, 3]] },\n]\n'),
              ("pattern: lines a and b: 2 mm apart edge to edge", "minimum gap 3 mm")),
    ErrorCase("pattern-bend", _PAT,
              "a bend too tight for the rod",
              _case_file('[[pattern.lines]]\nid = "v"\npoints = [[-20, 0], [0, 20], [20, 0]]\n'),
              ("pattern: line v: bends with a radius of", "max(b, 3 x mesh.dx_rod) = 3 mm")),
    ErrorCase("pattern-zero", _PAT,
              "a line of zero length",
              _case_file('[[pattern.lines]]\nid = "dot"\npoints = [[5, 5], [5, 5]]\n'),
              ("pattern: line dot: has zero length",)),
    ErrorCase("pattern-arc", _PAT,
              "an arc and points in one line",
              _case_file('[[pattern.lines]]\npoints = [[0, 0], [30, 0]]\n'
                         'arc = { centre = [0, 0], radius = 20, start = 0, end = 90 }\n'),
              ("pattern.lines.0: give exactly one of points (a polyline), arc or spline",)),
    ErrorCase("pattern-spline", _PAT,
              "a spline through a repeated point",
              _case_file('[[pattern.lines]]\nspline = [[0, 0], [10, 5], [10, 5], [30, 0]]\n'),
              ("pattern.lines.0.spline: points 1 and 2 coincide",)),
    ErrorCase("pattern-families-renamed", _PAT,
              "the old name `[[pattern.families]]`",
              _case_file('[[pattern.families]]\nlength = 40.0\ncount = 1\n'),
              ("pattern.families: renamed arrays: write [[pattern.arrays]]",)),
    ErrorCase("pattern-family", _PAT,
              "an array with both `gaps` and `count`",
              _case_file('[[pattern.arrays]]\nlength = 40.0\ncount = 3\nspacing = 4.0\n'
                         'gaps = [4.0, 6.0]\n'),
              ("pattern.arrays.0.gaps: give either gaps or count and spacing",)),
    ErrorCase("pattern-family-lengths", _PAT,
              "an array with a length list of the wrong size",
              _case_file('[[pattern.arrays]]\nlength = [40.0, 30.0]\ngaps = [4.0, 6.0]\n'),
              ("pattern.arrays.0.length: 2 lengths for 3 lines",)),
    ErrorCase("pattern-outside", _PAT,
              "a line outside the fabric (`fabric.size`)",
              _case_file('[fabric]\nsize = [100.0, 60.0]\n[[pattern.lines]]\nid = "a"\n'
                         'points = [[-60, 0], [20, 0]]\n'),
              ("pattern: line a: leaves the fabric across the clamp on the left edge",)),
    ErrorCase("pattern-clamp", _PAT,
              "a line too close to a clamp",
              _case_file('[fabric]\nsize = [100.0, 60.0]\n[[pattern.lines]]\nid = "a"\n'
                         'points = [[-49, 0], [20, 0]]\n'),
              ("pattern: line a: is only 0.5 mm from the clamp on the left edge",
               "keep at least 2 mm")),
    ErrorCase("pattern-dxf-text", _PAT,
              "a DXF drawing with a text entity",
              lambda d: (_dxf_with_text(d / "x.dxf")
                         or ["run", "--pattern", "x.dxf", "--out", "out"]),
              ("x.dxf: dxf: a TEXT entity", "layer NOTES) is not a line")),
    ErrorCase("pattern-rods", _PAT,
              "a pattern with `rods.N`",
              _case_file('[rods]\nN = 3\n[[pattern.lines]]\npoints = [[0, 0], [30, 0]]\n'),
              ("pattern: rods.N cannot be given together with a pattern",)),
    ErrorCase("pattern-structured", _PAT,
              "a pattern on the structured mesh",
              _case_file('[mesh]\nkind = "structured"\n[[pattern.lines]]\n'
                         'points = [[0, 0], [30, 0]]\n'),
              ("mesh.kind: 'structured' takes rods along x",)),
    ErrorCase("pattern-scale", _PAT,
              "`pattern.scale` without a file",
              _case_file('[pattern]\nscale = 2.0\n'),
              ("pattern.scale: only with pattern.file",)),
    ErrorCase("clamps-right", "Boundary conditions (`release.clamps`, `[hang]`)",
              "a frame without the right clamp",
              _case_file('[release]\nclamps = ["left", "top"]\n'),
              ("release.clamps: must hold 'right' (the stretch acts between left and right)",)),
    ErrorCase("hang-none", "Boundary conditions (`release.clamps`, `[hang]`)",
              "hanging by no edge",
              _case_file('[hang]\nedges = []\n'),
              ("hang.edges: List should have at least 1 item",)),
    ErrorCase("hang-edge", "Boundary conditions (`release.clamps`, `[hang]`)",
              "hanging by an edge that does not exist",
              _case_file('[hang]\nedges = ["up"]\n'),
              ("hang.edges.0: Input should be 'left', 'right', 'bottom' or 'top'",)),
    ErrorCase("size-margins", "Boundary conditions (`release.clamps`, `[hang]`)",
              "`fabric.size` together with a margin",
              _case_file('[fabric]\nsize = [100.0, 60.0]\nmargin_y = 20.0\n'),
              ("fabric.size: give either size or margin_y",)),
    # ---- gcode --------------------------------------------------------------------------
    ErrorCase("gcode-bed", "Print files (`undulate gcode`)", "a bed too small for the lines",
              lambda d: _gcode_args(d, "--bed", "15x220", "--overhang"),
              ("the print (x", "mm past the left (X 0) edge", "of the 15 x 220 mm bed")),
    ErrorCase("gcode-bed-size", "Print files (`undulate gcode`)", "`--bed 220`",
              lambda d: _gcode_args(d, "--bed", "220"), ("--bed: must be WIDTHxDEPTH",)),
    ErrorCase("gcode-fabric", "Print files (`undulate gcode`)",
              "a stretched fabric larger than the bed",
              lambda d: (d / "wide.toml").write_text('[rods]\nL = 20.0\n')
              and ["gcode", "wide.toml", "--out", "w.gcode"],
              ("the stretched fabric", "mm past the front (Y 0) edge", "--overhang")),
    ErrorCase("gcode-nozzle", "Print files (`undulate gcode`)", "`--nozzle -1`",
              lambda d: _gcode_args(d, "--nozzle", "-1"), ("nozzle: must be a number > 0",)),
    ErrorCase("gcode-width", "Print files (`undulate gcode`)", "rods narrower than the nozzle",
              lambda d: _gcode_args(d, "--nozzle", "1.5"), ("cannot be laid in passes",)),
    ErrorCase("gcode-pattern-cross", "Print files (`undulate gcode`)",
              "`--pattern` with crossing lines",
              lambda d: (d / "x.svg").write_text(
                  '<svg xmlns="http://www.w3.org/2000/svg" width="100mm" height="100mm" '
                  'viewBox="0 0 100 100"><line id="a" x1="0" y1="50" x2="100" y2="50"/>'
                  '<line id="b" x1="50" y1="0" x2="50" y2="100"/></svg>')
              and ["gcode", "--pattern", "x.svg", "--out", "x.gcode"],
              ("x.svg: lines a and b: cross at (0, 0) mm",)),
    ErrorCase("gcode-none", "Print files (`undulate gcode`)", "neither a case nor `--pattern`",
              lambda d: ["gcode", "--out", "x.gcode"], ("give a case file (CONFIG) or --pattern",)),
    # ---- export -------------------------------------------------------------------------
    ErrorCase("export-missing", "3D models (`undulate export`)", "a RUN_DIR that does not exist",
              lambda d: ["export", "nowhere", "--out", "m.glb"],
              ("RUN_DIR: nowhere is not a folder",)),
    ErrorCase("export-not-run", "3D models (`undulate export`)", "a folder that is not a run",
              lambda d: (d / "notes").mkdir() or ["export", "notes", "--out", "m.glb"],
              ("has no final.vtu, centerlines.npz, metrics.json",)),
    ErrorCase("export-format", "3D models (`undulate export`)", "`--out model.ply`",
              lambda d: (d / "r").mkdir() or ["export", "r", "--out", "model.ply"],
              ("format: must be one of glb, obj, stl",)),
    # ---- serve --------------------------------------------------------------------------
    ErrorCase("serve-port", "Web page (`undulate serve`)", "`--port 0`",
              lambda d: ["serve", "--port", "0"], ("--port: must be in 1..65535",)),
    ErrorCase("serve-workers", "Web page (`undulate serve`)", "`--workers 0`",
              lambda d: ["serve", "--workers", "0"], ("--workers: must be in 1..64",)),
    ErrorCase("serve-jobs", "Web page (`undulate serve`)", "`--jobs` is a file",
              lambda d: (d / "jobs").write_text("x") and ["serve", "--jobs", "jobs"],
              ("--jobs: jobs is a file",)),
    # ---- design -------------------------------------------------------------------------
    ErrorCase("design-key", "Inverse design (`undulate design`)", "`--target x=3`",
              lambda d: ["design", "--target", "x=3"], ("unknown key 'x'", "l, lam, a, n")),
    ErrorCase("design-even-n", "Inverse design (`undulate design`)", "`--target n=4`",
              lambda d: ["design", "--target", "n=4"], ("odd whole number",)),
    ErrorCase("design-reach", "Inverse design (`undulate design`)", "`--target l=500`",
              lambda d: ["design", "--target", "l=500"], ("out of reach", "h in [0.08, 2]")),
    ErrorCase("design-two", "Inverse design (`undulate design`)",
              "two targets, eps0 not free", lambda d: ["design", "--target", "l=20",
                                                       "--target", "a=5"],
              ("two targets need eps0 free", "--eps0-min")),
    ErrorCase("design-family", "Inverse design (`undulate design`)", "`--family wavy --N 5`",
              lambda d: ["design", "--target", "l=20", "--N", "5", "--family", "wavy"],
              ("family: must be one of coherent, independent",)),
    # ---- predict ------------------------------------------------------------------------
    ErrorCase("predict-source", "Predictions (`undulate predict`)", "`--source oracle`",
              lambda d: (d / "c.toml").write_text("[rods]\nh = 0.2\n")
              and ["predict", "c.toml", "--source", "oracle"],
              ("--source: must be one of auto, simulation, theory",)),
    ErrorCase("predict-case", "Predictions (`undulate predict`)", "a bad value in the case",
              lambda d: (d / "c.toml").write_text("[rods]\nh = -1\n")
              and ["predict", "c.toml"], ("c.toml", "h")),
    # ---- theory -------------------------------------------------------------------------
    ErrorCase("theory-eps0", "Analytical model (`undulate theory`): the case file's ranges",
              "`--eps0 50`", lambda d: ["theory", "--eps0", "50"],
              ("--eps0", "allowed: > 0, <= 3")),
    ErrorCase("theory-h", "Analytical model (`undulate theory`): the case file's ranges",
              "`--h 0`", lambda d: ["theory", "--h", "0"], ("--h", "greater than 0")),
    ErrorCase("theory-N", "Analytical model (`undulate theory`): the case file's ranges",
              "`--N 0`", lambda d: ["theory", "--N", "0"], ("--N", ">= 1")),
    ErrorCase("theory-s", "Analytical model (`undulate theory`): the case file's ranges",
              "`--s -1`", lambda d: ["theory", "--s", "-1"], ("--s", ">= 0")),
]
