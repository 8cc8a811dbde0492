"""``undulate serve``: a local web page to draw lines, see the prediction, run a simulation.

Routes (JSON in and out; every bad input is a 422 with ``{"error": "<field>: <problem>"}``):

* ``GET  /``                         the page (static HTML + one script, no build step)
* ``GET  /api/defaults``             material defaults and the allowed ranges of the form
* ``POST /api/predict``              analytical prediction per line and per group (instant)
* ``POST /api/pattern/svg``          lines of an uploaded SVG (text), centred, checked
* ``POST /api/gcode``                G-code that prints the lines (a file download)
* ``POST /api/jobs``                 start a simulation in the background; returns its id
* ``GET  /api/jobs``, ``GET /api/jobs/{id}``, ``DELETE /api/jobs/{id}``
* ``GET  /api/jobs/{id}/files/{name}``  a file of a finished simulation

The simulation is the real engine (``undulate run``): straight lines along the stretch (x),
any lengths and positions. Other lines get the analytical prediction only.
"""

from __future__ import annotations

import contextlib
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any, Literal

from fastapi import FastAPI, HTTPException, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import FileResponse, JSONResponse, PlainTextResponse
from fastapi.staticfiles import StaticFiles
from pydantic import BaseModel, ConfigDict, Field

from ...model import Fabric, Release, Rods
from ...model.config import MATERIAL_DEFAULTS, ConfigError, allowed_range, check_value
from ...model.pattern import Line, PatternError, check_lines, line_from_points, read_svg
from .jobs import JobError, JobManager

__all__ = ["create_app", "case_from_lines"]

STATIC = Path(__file__).parent / "static"

#: mesh and release of the page's "quick" simulations (coarse, for trying ideas in seconds);
#: "standard" uses the case-file defaults (as ``undulate run``)
QUICK = {"mesh": {"dx_rod": 2.0, "dx_far": 6.0, "dy_far": 8.0}, "release": {"steps": 15}}


class LineIn(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True)
    id: str | None = Field(None, max_length=100)
    points: list[list[float]] = Field(min_length=2, max_length=100_000)
    h: float | None = None
    b: float | None = None


class Params(BaseModel):
    """The form: lines (print frame, mm) and the material; ranges are those of a case file."""

    model_config = ConfigDict(extra="forbid", strict=True)
    lines: list[LineIn] = Field(min_length=1, max_length=200)
    h: float = Rods.model_fields["h"].default
    b: float = MATERIAL_DEFAULTS["b"]
    eps0: float = 0.5
    E: float = MATERIAL_DEFAULTS["E"]
    t: float = MATERIAL_DEFAULTS["t"]
    E_B: float = MATERIAL_DEFAULTS["E_B"]
    nu: float = 0.3


class JobIn(Params):
    quality: Literal["quick", "standard"] = "quick"
    seed: int = Field(0, ge=0, le=2**31 - 1)
    label: str = Field("", max_length=200)


class SvgIn(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True)
    svg: str = Field(min_length=1, max_length=5_000_000)
    scale: float = 1.0
    b: float = MATERIAL_DEFAULTS["b"]


_FIELDS = {"h": (Rods, "h"), "b": (Rods, "b"), "E_B": (Rods, "E_B"), "E": (Fabric, "E"),
           "t": (Fabric, "t"), "nu": (Fabric, "nu"), "eps0": (Release, "eps0")}


def _check_params(p: Params) -> list[Line]:
    """Ranges as in a case file; lines as patterns (raises ConfigError / PatternError)."""
    for name, (model, field) in _FIELDS.items():
        check_value(model, field, getattr(p, name), name)
    lines = [line_from_points(ln.points, k, id=ln.id, h=ln.h, b=ln.b)
             for k, ln in enumerate(p.lines)]
    check_lines(lines, b=p.b)
    return lines


def case_from_lines(p: Params, lines: list[Line], *, quality: str = "quick", seed: int = 0,
                    name: str = "web") -> dict[str, Any]:
    """A case (dict, as a case file) for straight lines along x; PatternError otherwise."""
    segs = []
    for ln in lines:
        if not ln.is_straight(1e-3) or abs(ln.chord[1]) > 1e-6 * ln.length:
            raise PatternError(
                f"line {ln.id}: the simulation takes straight lines along the stretch (x) "
                f"only; this one is {'curved' if not ln.is_straight(1e-3) else 'inclined'} "
                f"({ln.angle_deg:.1f} deg). Its analytical prediction is shown instead")
        if (ln.h not in (None, p.h)) or (ln.b not in (None, p.b)):
            raise PatternError(f"line {ln.id}: the simulation takes one h and b for all lines;"
                               " remove this line's own h or b")
        x0 = float(min(ln.points[0, 0], ln.points[-1, 0]))
        segs.append({"start": [x0, float(ln.points[0, 1])], "length": ln.length})
    case: dict[str, Any] = {
        "name": name,
        "fabric": {"E": p.E, "t": p.t, "nu": p.nu},
        "rods": {"h": p.h, "b": p.b, "E_B": p.E_B, "segments": segs},
        "release": {"eps0": p.eps0},
        "imperfection": {"seed": seed},
    }
    if quality == "quick":
        case["mesh"] = dict(QUICK["mesh"])
        case["release"].update(QUICK["release"])
    return case


def _error(status: int, msg: str) -> JSONResponse:
    return JSONResponse({"error": msg}, status_code=status)


def _validation_line(err: RequestValidationError) -> str:
    e = err.errors()[0]
    loc = [str(x) for x in e.get("loc", ()) if x != "body"]
    where = ".".join(loc) or "body"
    got = e.get("input")
    shown = "" if isinstance(got, dict | list) or got is None else f"; got {got!r}"
    return f"{where}: {e.get('msg', 'invalid')}{shown}"


def create_app(jobs_dir: str | Path = "undulate-jobs", workers: int = 1,
               max_queued: int = 16, job_target: Any = None) -> FastAPI:
    """The web application; simulations go under ``jobs_dir``, ``workers`` at a time."""
    kw = {} if job_target is None else {"target": job_target}
    jobs = JobManager(Path(jobs_dir), workers=workers, max_queued=max_queued, **kw)

    @contextlib.asynccontextmanager
    async def lifespan(_: FastAPI) -> AsyncIterator[None]:
        yield
        jobs.shutdown()  # running simulations are stopped and marked interrupted

    app = FastAPI(title="undulate", description="Rods printed on a pre-stretched textile: "
                  "draw, predict, simulate. Units: mm, MPa.", lifespan=lifespan)
    app.state.jobs = jobs

    @app.exception_handler(RequestValidationError)
    async def _bad_request(_: Request, err: RequestValidationError) -> JSONResponse:
        return _error(422, _validation_line(err))

    @app.exception_handler(ConfigError)
    async def _bad_config(_: Request, err: ConfigError) -> JSONResponse:
        return _error(422, str(err))

    @app.exception_handler(PatternError)
    async def _bad_pattern(_: Request, err: PatternError) -> JSONResponse:
        return _error(422, str(err))

    @app.exception_handler(JobError)
    async def _bad_job(_: Request, err: JobError) -> JSONResponse:
        return _error(404 if "no such job" in str(err) else 429, str(err))

    @app.get("/", include_in_schema=False)
    def index() -> FileResponse:
        return FileResponse(STATIC / "index.html")

    app.mount("/static", StaticFiles(directory=STATIC), name="static")

    @app.get("/api/defaults")
    def defaults() -> dict[str, Any]:
        rng = {name: allowed_range(m, f) for name, (m, f) in _FIELDS.items()}
        return {"values": Params.model_construct(lines=[]).model_dump(exclude={"lines"}),
                "ranges": rng, "units": {"length": "mm", "modulus": "MPa"}}

    @app.post("/api/predict")
    def predict(p: Params) -> dict[str, Any]:
        from ...theory.lines import predict_lines

        lines = _check_params(p)
        out = predict_lines(lines, h=p.h, eps0=p.eps0, b=p.b, E_B=p.E_B, E=p.E, t=p.t,
                            nu=p.nu)
        try:
            case_from_lines(p, lines)
            out["simulable"], out["simulable_reason"] = True, ""
        except PatternError as err:
            out["simulable"], out["simulable_reason"] = False, str(err)
        return out

    @app.post("/api/pattern/svg")
    def pattern_svg(body: SvgIn) -> dict[str, Any]:
        check_value(Rods, "b", body.b, "b")
        lines = read_svg(body.svg, scale=body.scale)
        check_lines(lines, b=body.b)
        return {"lines": [ln.to_dict() for ln in lines]}

    @app.post("/api/gcode")
    def gcode(p: Params) -> PlainTextResponse:
        import numpy as np

        from ...fabrication import GcodeError, PrintLine, PrintSettings, make_gcode

        lines = _check_params(p)
        plines = [PrintLine(k, np.asarray(ln.points), ln.h or p.h, ln.b or p.b)
                  for k, ln in enumerate(lines)]
        allp = np.vstack([ln.points for ln in lines])
        lo, hi = allp.min(axis=0), allp.max(axis=0)
        st = PrintSettings(bed_x=max(220.0, float(hi[0] - lo[0]) + 20.0),
                           bed_y=max(220.0, float(hi[1] - lo[1]) + 20.0))
        try:
            text, _ = make_gcode(plines, st, eps0=p.eps0, fabric_t=p.t, name="web")
        except GcodeError as err:
            raise PatternError(str(err)) from None
        return PlainTextResponse(text, headers={
            "Content-Disposition": 'attachment; filename="undulate.gcode"'})

    @app.post("/api/jobs", status_code=201)
    def submit(p: JobIn) -> dict[str, Any]:
        from ...model import case_from_dict

        lines = _check_params(p)
        case = case_from_lines(p, lines, quality=p.quality, seed=p.seed)
        case_from_dict(case)  # every rule of a case file (raises ConfigError, one line)
        jid = jobs.submit(case, label=p.label)
        return jobs.state(jid)

    @app.get("/api/jobs")
    def list_jobs() -> list[dict[str, Any]]:
        return jobs.list()

    @app.get("/api/jobs/{jid}")
    def job(jid: str) -> dict[str, Any]:
        return jobs.state(jid)

    @app.delete("/api/jobs/{jid}")
    def cancel(jid: str) -> dict[str, Any]:
        return jobs.cancel(jid)

    @app.get("/api/jobs/{jid}/files/{name}")
    def job_file(jid: str, name: str) -> FileResponse:
        st = jobs.state(jid)
        if name not in st["files"]:
            raise HTTPException(404, f"job {jid}: no file {name!r} (files: "
                                f"{', '.join(st['files']) or 'none yet'})")
        return FileResponse(jobs.folder(jid) / "result" / name, filename=name)

    @app.exception_handler(HTTPException)
    async def _http(_: Request, err: HTTPException) -> JSONResponse:
        return _error(err.status_code, str(err.detail))

    return app
