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
* ``GET  /api/jobs/{id}/shape``      the final shape for the 3D view (rods, fabric near them)
* ``POST /api/drawing?frame=print|relaxed``  SVG drawing of the lines

Each browser gets a random client id (cookie ``undulate_client``): it sees only its own jobs.
Request bodies are limited to :data:`MAX_BODY` bytes.

The simulation is the real engine (``undulate run``) on the drawn lines as a pattern: any
angle, curved too, any lengths and positions, each line's own h and b. Lines the rods' mesh
cannot follow (a bend tighter than the case file allows) get the analytical prediction only,
with the reason.
"""

from __future__ import annotations

import contextlib
import uuid
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any, Literal

from fastapi import FastAPI, HTTPException, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import FileResponse, JSONResponse, PlainTextResponse, Response
from fastapi.staticfiles import StaticFiles
from pydantic import BaseModel, ConfigDict, Field
from starlette.exceptions import HTTPException as StarletteHTTPException

from ...model import Fabric, Release, Rods
from ...model.config import MATERIAL_DEFAULTS, ConfigError, allowed_range, check_value
from ...model.pattern import Line, PatternError, check_lines, line_from_points, read_svg
from .jobs import JobError, JobManager

__all__ = ["create_app", "case_from_lines"]

STATIC = Path(__file__).parent / "static"

#: largest request body accepted (an uploaded SVG travels as text in JSON) [bytes]
MAX_BODY = 5_000_000
COOKIE = "undulate_client"

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
    svg: str = Field(min_length=1, max_length=MAX_BODY)
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
    """A case (dict, as a case file) whose pattern is the drawn lines: straight or curved, at
    any angle, each with its own h and b if given. The case's own rules (bends the rods can
    follow, lines long enough for the mesh) are checked when it is validated
    (``case_from_dict``)."""
    pattern = [ln.to_dict() for ln in lines]
    case: dict[str, Any] = {
        "name": name,
        "fabric": {"E": p.E, "t": p.t, "nu": p.nu},
        "rods": {"h": p.h, "b": p.b, "E_B": p.E_B},
        "pattern": {"lines": pattern},
        "release": {"eps0": p.eps0},
        "imperfection": {"seed": seed},
    }
    if quality == "quick":
        case["mesh"] = dict(QUICK["mesh"])
        case["release"].update(QUICK["release"])
    return case


def final_shape(vtu: Path, margin: float = 30.0) -> dict[str, Any]:
    """Rod centre lines and the fabric's triangles within ``margin`` mm of the rods (x, y) from
    a run's ``final.vtu``, rounded to 1 um: the data of the page's 3D view.

    ``{"rods": [[[x, y, z], ...], ...], "fabric": {"points": [[x, y, z], ...],
    "triangles": [[i, j, k], ...]}}``; each rod is one chain of the file's line cells (the
    output writes every rod's centre line as its own run of points)."""
    import meshio
    import numpy as np

    m = meshio.read(vtu)
    pts = np.asarray(m.points, float)
    tri_cells = [c.data for c in m.cells if c.type == "triangle"]
    tris = np.concatenate(tri_cells) if tri_cells else np.zeros((0, 3), int)
    segs = [c.data for c in m.cells if c.type == "line"]
    rods: list[list[list[float]]] = []
    if segs:
        edges = np.concatenate(segs)
        # chains of consecutive line cells are the rods
        start = 0
        for k in range(1, len(edges) + 1):
            if k == len(edges) or edges[k, 0] != edges[k - 1, 1]:
                idx = np.r_[edges[start:k, 0], edges[k - 1, 1]]
                rods.append(pts[idx].round(3).tolist())
                start = k
    rp = np.vstack([np.asarray(r) for r in rods]) if rods else pts
    lo, hi = rp[:, :2].min(axis=0) - margin, rp[:, :2].max(axis=0) + margin
    inside = np.all((pts[:, :2] >= lo) & (pts[:, :2] <= hi), axis=1)
    keep = inside[tris].all(axis=1) if len(tris) else np.zeros(0, bool)
    used = np.unique(tris[keep])
    new = -np.ones(len(pts), int)
    new[used] = np.arange(len(used))
    return {"rods": rods, "fabric": {"points": pts[used].round(3).tolist(),
                                     "triangles": new[tris[keep]].tolist()}}


def too_large(size: int | None, limit: int = MAX_BODY) -> str:
    """The one line of a refused request body (``size`` bytes, None when not known)."""
    got = "more" if size is None else f"{size:,} bytes, more"
    return (f"request body: {got} than the {limit:,} bytes ({limit / 1e6:g} MB) the page "
            "takes; an uploaded SVG must be smaller")


class BodyLimit:
    """ASGI middleware: request bodies of at most ``max_body`` bytes, else ``413`` with one
    line. A declared ``content-length`` is checked before anything is read; a body without
    one (chunked) is counted as it arrives and refused once it passes the limit."""

    def __init__(self, app: Any, max_body: int = MAX_BODY) -> None:
        self.app = app
        self.max_body = max_body

    async def __call__(self, scope: dict, receive: Any, send: Any) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        size = dict(scope.get("headers") or ()).get(b"content-length")
        if size is not None and (not size.isdigit() or int(size) > self.max_body):
            known = int(size) if size.isdigit() else None
            await _error(413, too_large(known, self.max_body))(scope, receive, send)
            return
        seen = 0

        async def counted() -> dict:
            nonlocal seen
            msg = await receive()
            if msg["type"] == "http.request":
                seen += len(msg.get("body", b""))
                if seen > self.max_body:
                    # FastAPI passes an HTTPException raised while it reads the body on to
                    # the app's handler: a 413 with the one line
                    raise HTTPException(413, too_large(None, self.max_body))
            return msg

        await self.app(scope, counted, send)


class ClientId:
    """ASGI middleware: the browser's client id, from the cookie :data:`COOKIE` (a random
    32-digit hex string, ``HttpOnly``, ``SameSite=Strict``), or a new one, set in the answer.
    Jobs belong to the client that started them; the id is ``scope[COOKIE]``."""

    def __init__(self, app: Any) -> None:
        self.app = app

    async def __call__(self, scope: dict, receive: Any, send: Any) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        cid = Request(scope).cookies.get(COOKIE, "")
        fresh = not (len(cid) == 32 and all(c in "0123456789abcdef" for c in cid))
        if fresh:
            cid = uuid.uuid4().hex
        scope[COOKIE] = cid

        async def send_cookie(msg: dict) -> None:
            if fresh and msg["type"] == "http.response.start":
                r = Response()
                r.set_cookie(COOKIE, cid, httponly=True, samesite="strict")
                msg = {**msg, "headers": [*msg.get("headers", []),
                                          *(h for h in r.raw_headers if h[0] == b"set-cookie")]}
            await send(msg)

        await self.app(scope, receive, send_cookie)


def _client(request: Request) -> str:
    return request.scope[COOKIE]


def _error(status: int, msg: str) -> JSONResponse:
    return JSONResponse({"error": msg}, status_code=status)


def _validation_line(err: RequestValidationError) -> str:
    e = err.errors()[0]
    loc = [str(x) for x in e.get("loc", ()) if x not in ("body", "query")]
    where = ".".join(loc) or "body"
    got = e.get("input")
    shown = "" if isinstance(got, dict | list) or got is None else f"; got {got!r}"
    return f"{where}: {e.get('msg', 'invalid')}{shown}"


def _locate_groups(out: dict[str, Any], p: Params) -> None:
    """Each group of parallel lines placed on the shipped phase diagrams (``atlas``: where it
    sits, and the name of the diagram that answers, as ``undulate predict`` chooses it)."""
    from ...design.predict import place

    by_id = {r["id"]: r for r in out["lines"]}
    for g in out["groups"]:
        members = [by_id[i] for i in g["lines"]]
        live = [r for r in members if r.get("n")]
        if not live:
            continue
        if g.get("s") is None:  # one line alone: the diagrams are of several lines
            g["atlas"] = {"inside": False, "confidence": "outside", "summary": (
                "one line alone: the simulated diagrams are of parallel lines")}
            continue
        r0 = live[0]
        L = sum(r["L"] for r in live) / len(live)
        mat = {"E_B": p.E_B, "E": p.E, "t": p.t, "b": r0["b"]}
        best, scaled = place(h=r0["h"], s=g["s"], N=g["N"], L=L, eps0=r0["eps_line"], **mat)
        if best is None:
            continue
        if best.loc.inside or scaled is None:
            g["atlas"] = best.loc.to_dict() | {"design_h": r0["h"], "design_s": g["s"],
                                               "atlas": best.name}
            continue
        # another L or eps0: the design drawn where it sits on that diagram once scaled
        sc = scaled.scaled or {}
        g["atlas"] = scaled.loc.to_dict() | {
            "design_h": sc["h"], "design_s": sc["s"], "scaled": sc, "atlas": scaled.name,
            "confidence": scaled.confidence, "summary": scaled.summary()}


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
                "ranges": rng, "units": {"length": "mm", "modulus": "MPa"},
                "max_body": MAX_BODY}

    @app.post("/api/predict")
    def predict(p: Params) -> dict[str, Any]:
        from ...theory.lines import predict_lines

        lines = _check_params(p)
        out = predict_lines(lines, h=p.h, eps0=p.eps0, b=p.b, E_B=p.E_B, E=p.E, t=p.t,
                            nu=p.nu)
        _locate_groups(out, p)
        from ...model import ConfigError, case_from_dict

        try:
            case_from_dict(case_from_lines(p, lines))
            out["simulable"], out["simulable_reason"] = True, ""
        except (PatternError, ConfigError) as err:
            out["simulable"], out["simulable_reason"] = False, str(err)
        return out

    @app.get("/api/atlas")
    def atlas(name: str = "phase_diagram") -> dict[str, Any]:
        """A simulated phase diagram shipped with undulate (undulate.design.atlas), by the
        name a placed group gives (default: the five-rod diagram at L = 100 mm)."""
        from ...design.predict import atlas_named

        try:
            found = atlas_named(name)
        except KeyError as err:
            raise HTTPException(404, str(err.args[0])) from None
        return found.to_dict() | {"name": name}

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
    def submit(p: JobIn, request: Request) -> dict[str, Any]:
        from ...model import case_from_dict

        lines = _check_params(p)
        case = case_from_lines(p, lines, quality=p.quality, seed=p.seed)
        case_from_dict(case)  # every rule of a case file (raises ConfigError, one line)
        jid = jobs.submit(case, label=p.label, owner=_client(request))
        return jobs.state(jid)

    @app.get("/api/jobs")
    def list_jobs(request: Request) -> list[dict[str, Any]]:
        return jobs.list(_client(request))

    @app.get("/api/jobs/{jid}")
    def job(jid: str, request: Request) -> dict[str, Any]:
        return jobs.state(jid, _client(request))

    @app.delete("/api/jobs/{jid}")
    def cancel(jid: str, request: Request) -> dict[str, Any]:
        return jobs.cancel(jid, _client(request))

    def _done_file(jid: str, name: str, request: Request) -> Path:
        st = jobs.state(jid, _client(request))
        if name not in st["files"]:
            raise HTTPException(404, f"job {jid}: no file {name!r} (files: "
                                f"{', '.join(st['files']) or 'none yet'})")
        return jobs.folder(jid) / "result" / name

    @app.get("/api/jobs/{jid}/files/{name}")
    def job_file(jid: str, name: str, request: Request) -> FileResponse:
        return FileResponse(_done_file(jid, name, request), filename=name)

    @app.get("/api/jobs/{jid}/model.{fmt}")
    def job_model(jid: str, fmt: Literal["glb", "obj", "stl"], request: Request) -> Response:
        """The job's final state as a 3D model (`undulate export`): glb, obj or stl, in mm."""
        import tempfile

        from ...fabrication.model3d import ExportError, export_run

        run = _done_file(jid, "final.vtu", request).parent
        with tempfile.TemporaryDirectory() as tmp:
            try:
                data = export_run(run, Path(tmp) / f"model.{fmt}").read_bytes()
            except ExportError as err:
                raise HTTPException(404, f"job {jid}: {err}") from None
        media = {"glb": "model/gltf-binary", "obj": "model/obj", "stl": "model/stl"}[fmt]
        return Response(data, media_type=media, headers={
            "Content-Disposition": f'attachment; filename="undulate-{jid}.{fmt}"'})

    @app.get("/api/jobs/{jid}/shape")
    def job_shape(jid: str, request: Request) -> dict[str, Any]:
        return final_shape(_done_file(jid, "final.vtu", request))

    @app.post("/api/drawing")
    def drawing(p: Params, frame: Literal["print", "relaxed"] = "print",
                fmt: Literal["svg", "dxf"] = "svg") -> Response:
        import tempfile

        import numpy as np

        from ...fabrication import GcodeError, PrintLine
        from ...fabrication.drawing import write_drawing

        lines = _check_params(p)
        plines = [PrintLine(k, np.asarray(ln.points), ln.h or p.h, ln.b or p.b)
                  for k, ln in enumerate(lines)]
        with tempfile.TemporaryDirectory() as tmp:
            try:
                paths = write_drawing(plines, Path(tmp) / f"lines.{fmt}", eps0=p.eps0,
                                      nu=p.nu, name="undulate")
            except GcodeError as err:
                raise PatternError(str(err)) from None
            data = paths[0 if frame == "print" else 1].read_bytes()
        media = "image/svg+xml" if fmt == "svg" else "image/vnd.dxf"
        return Response(data, media_type=media, headers={
            "Content-Disposition": f'attachment; filename="lines-{frame}.{fmt}"'})

    @app.exception_handler(StarletteHTTPException)  # also the router's 404 and 405
    async def _http(_: Request, err: StarletteHTTPException) -> JSONResponse:
        return JSONResponse({"error": str(err.detail)}, status_code=err.status_code,
                            headers=err.headers)

    app.add_middleware(ClientId)
    app.add_middleware(BodyLimit, max_body=MAX_BODY)  # outermost: before anything reads
    return app
