"""The web page's API (FastAPI test client): prediction, SVG import, G-code, drawings, jobs,
the 3D shape, bad input, the body size limit, and clients that must not see each other's jobs.

The jobs run a fake worker (tests/_web_fakes.py) in real spawned processes; the browser test
(tests/test_web_browser.py) runs the real engine.
"""

from __future__ import annotations

import time
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("fastapi")
from _web_fakes import FABRIC_MARGIN, fake_job, fake_rods  # noqa: E402
from fastapi.testclient import TestClient  # noqa: E402

from undulate.interfaces.web.app import COOKIE, MAX_BODY, create_app  # noqa: E402

FAMILY = [{"id": f"r{k}", "points": [[-50.0, y], [50.0, y]]}
          for k, y in enumerate([-22.0, -11.0, 0.0, 11.0, 22.0])]


@pytest.fixture()
def client(tmp_path: Path):
    app = create_app(tmp_path / "jobs", workers=2, max_queued=3, job_target=fake_job)
    with TestClient(app) as c:
        yield c
    app.state.jobs.shutdown()


@pytest.fixture()
def other(client: TestClient):
    """A second browser on the same server: its own cookie jar, so its own client id. (Not
    entered as a context: that would run the app's lifespan, whose end stops the jobs.)"""
    c = TestClient(client.app)
    yield c
    c.close()


def _wait(client: TestClient, jid: str, until: tuple[str, ...], timeout: float = 60.0) -> dict:
    t0 = time.time()
    while time.time() - t0 < timeout:
        st = client.get(f"/api/jobs/{jid}").json()
        if st["status"] in until:
            return st
        time.sleep(0.05)
    raise AssertionError(f"job {jid} still {st['status']} after {timeout} s")


def test_page_and_defaults(client: TestClient) -> None:
    r = client.get("/")
    assert r.status_code == 200 and 'id="fabric"' in r.text
    assert client.get("/static/app.js").status_code == 200
    d = client.get("/api/defaults").json()
    assert d["values"]["h"] == 0.3 and d["values"]["E"] == 0.45
    assert d["ranges"]["h"] == "> 0, <= 20"


def test_predict_parallel_family_matches_theory(client: TestClient) -> None:
    from undulate import theory as T

    r = client.post("/api/predict", json={"lines": FAMILY, "h": 0.3, "eps0": 0.5})
    assert r.status_code == 200, r.text
    out = r.json()
    pm = T.phase_map(0.3, 10.0, eps0=0.5, L=100.0, N=5)
    assert [ln["n_alone"] for ln in out["lines"]] == [int(T.n(0.3, 0.5, 100.0))] * 5
    assert out["lines"][0]["l_alone"] == pytest.approx(float(T.l(0.3, 0.5)))
    assert [ln["n"] for ln in out["lines"]] == [int(pm["n"].item())] * 5
    assert out["lines"][0]["l"] == pytest.approx(float(pm["l"].item()))
    assert {ln["family"] for ln in out["lines"]} == {str(pm["family"].item())}
    assert out["groups"][0]["N"] == 5 and out["groups"][0]["s"] == pytest.approx(10.0)
    assert out["simulable"] is True


def test_predict_inclined_and_across_lines(client: TestClient) -> None:
    lines = [{"points": [[0.0, 0.0], [60.0, 60.0]]}, {"points": [[100.0, -60.0], [100.0, 60.0]]}]
    out = client.post("/api/predict", json={"lines": lines}).json()
    diag, across = out["lines"]
    assert 0 < diag["eps_line"] < 0.5 and diag["angle_deg"] == pytest.approx(45.0)
    assert across["eps_line"] < 0 and across["family"] == "flat" and across["n"] == 0
    assert any("45 deg" in w for w in out["warnings"])
    assert out["simulable"] is True  # inclined lines are a pattern the engine runs
    sharp = [{"id": "v", "points": [[0.0, 0.0], [25.0, 25.0], [50.0, 0.0]]}]
    out = client.post("/api/predict", json={"lines": sharp}).json()
    assert out["simulable"] is False and "line v: bends with a radius" in out["simulable_reason"]


@pytest.mark.parametrize(("body", "needle"), [
    ({"lines": FAMILY, "h": -1.0}, "h: "),
    ({"lines": FAMILY, "h": "0.3"}, "h: "),
    ({"lines": FAMILY, "eps0": 5.0}, "eps0: "),
    ({"lines": FAMILY, "nu": 0.7}, "nu: "),
    ({"lines": []}, "lines: "),
    ({"lines": [{"points": [[0.0, 0.0]]}]}, "lines.0.points"),
    ({"lines": [{"points": [[0.0, 0.0], [0.0, 0.0]]}]}, "line 0: has zero length"),
    ({"lines": [{"points": [[-10.0, 0.0], [10.0, 0.0]]}, {"points": [[0.0, -5.0], [0.0, 5.0]]}]},
     "lines 0 and 1: cross at (0, 0)"),
    ({"lines": [{"points": [[-10.0, 0.0], [10.0, 0.0]]}, {"points": [[-10.0, 0.5], [10.0, 0.5]]}]},
     "lines 0 and 1: touch"),
    ({"lines": FAMILY, "colour": "red"}, "colour: Extra inputs"),
])
def test_bad_input_is_one_clear_line(client: TestClient, body: dict, needle: str) -> None:
    r = client.post("/api/predict", json=body)
    assert r.status_code == 422, r.text
    msg = r.json()["error"]
    assert needle in msg and "\n" not in msg and "Traceback" not in msg, msg


def test_svg_upload(client: TestClient) -> None:
    svg = ('<svg xmlns="http://www.w3.org/2000/svg" width="200mm" height="100mm" '
           'viewBox="0 0 200 100"><line id="a" x1="10" y1="20" x2="110" y2="20"/>'
           '<path id="w" d="M10 60 C 40 40, 70 80, 110 60"/></svg>')
    r = client.post("/api/pattern/svg", json={"svg": svg})
    assert r.status_code == 200, r.text
    lines = r.json()["lines"]
    assert [ln["id"] for ln in lines] == ["a", "w"]
    a = lines[0]["points"]
    w = lines[1]["points"]
    # mm from the SVG's size; y flipped (SVG's y points down): the line lies 40 mm above w
    assert a[1][0] - a[0][0] == pytest.approx(100.0, rel=1e-5)
    assert a[0][1] - w[0][1] == pytest.approx(40.0, rel=1e-5)
    bad = client.post("/api/pattern/svg", json={"svg": svg.replace("<line", "<rect x='0' "
                      "y='0' width='5' height='5'/><line")})
    assert bad.status_code == 422 and "closed rect" in bad.json()["error"]
    assert "not a readable SVG" in client.post("/api/pattern/svg",
                                               json={"svg": "<svg"}).json()["error"]


def test_gcode_download(client: TestClient) -> None:
    r = client.post("/api/gcode", json={"lines": FAMILY, "h": 0.3})
    assert r.status_code == 200, r.text
    assert "attachment" in r.headers["content-disposition"]
    assert r.text.count("G1") > 5 and "eps0" in r.text


def test_jobs_run_concurrently_queue_and_download(client: TestClient) -> None:
    ids = []
    for _ in range(3):
        r = client.post("/api/jobs", json={"lines": FAMILY, "seed": 5})  # ~1 s each
        assert r.status_code == 201, r.text
        ids.append(r.json()["id"])
    # two workers: two jobs run together while the third waits its turn
    t0 = time.time()
    while time.time() - t0 < 30:
        states = [client.get(f"/api/jobs/{j}").json() for j in ids]
        if sum(s["status"] == "running" for s in states) == 2:
            break
        time.sleep(0.02)
    else:
        raise AssertionError(states)
    assert states[2]["status"] == "queued" and states[2]["queue_position"] == 1
    done = [_wait(client, j, ("done", "failed")) for j in ids]
    assert all(s["status"] == "done" for s in done), done
    st = done[0]
    assert st["files"] == ["centerlines.npz", "final.vtu", "metrics.json"]
    assert st["metrics"]["n"] == 3
    f = client.get(f"/api/jobs/{ids[0]}/files/metrics.json")
    assert f.status_code == 200 and len(f.json()["rods"]) == 5
    assert client.get(f"/api/jobs/{ids[0]}/files/..%2Fcase.json").status_code == 404
    assert {j["id"] for j in client.get("/api/jobs").json()} == set(ids)


def test_queue_limit_cancel_and_unknown_job(client: TestClient) -> None:
    ids = [client.post("/api/jobs", json={"lines": FAMILY, "seed": 50}).json()["id"]
           for _ in range(5)]  # 2 run, 3 wait: the queue is full
    r = client.post("/api/jobs", json={"lines": FAMILY, "seed": 50})
    assert r.status_code == 429 and "queue full" in r.json()["error"]
    _wait(client, ids[0], ("running",))
    assert client.delete(f"/api/jobs/{ids[0]}").json()["status"] == "cancelled"
    assert client.delete(f"/api/jobs/{ids[4]}").json()["status"] == "cancelled"
    assert client.get("/api/jobs/0123456789ab").status_code == 404
    assert "no such job" in client.get("/api/jobs/nope").json()["error"]


def test_job_refuses_what_the_engine_cannot_simulate(client: TestClient) -> None:
    r = client.post("/api/jobs", json={"lines": [{"id": "v", "points": [[0.0, 0.0], [25.0, 25.0],
                                                                    [50.0, 0.0]]}]})
    assert r.status_code == 422 and "line v: bends with a radius of" in r.json()["error"]
    r = client.post("/api/jobs", json={"lines": FAMILY, "quality": "best"})
    assert r.status_code == 422 and r.json()["error"].startswith("quality:")


def _svg_lines(text: str) -> tuple[list[np.ndarray], np.ndarray]:
    """The polylines of a drawing (SVG user units = mm) and its viewBox."""
    root = ET.fromstring(text)
    ns = {"s": "http://www.w3.org/2000/svg"}
    box = np.array([float(v) for v in root.get("viewBox").split()])
    out = [np.array([[float(v) for v in xy.split(",")] for xy in pl.get("points").split()])
           for pl in root.iterfind(".//s:polyline", ns)]
    return out, box


def test_drawing_svg_in_the_print_and_the_relaxed_frame(client: TestClient) -> None:
    from undulate.mechanics.build import lateral_stretch

    eps0, nu = 0.5, 0.3
    body = {"lines": FAMILY, "eps0": eps0, "nu": nu}
    pr = client.post("/api/drawing?frame=print", json=body)
    rl = client.post("/api/drawing?frame=relaxed", json=body)
    assert pr.status_code == 200 and rl.status_code == 200, (pr.text, rl.text)
    assert pr.headers["content-type"].startswith("image/svg+xml")
    assert 'filename="lines-print.svg"' in pr.headers["content-disposition"]
    assert 'filename="lines-relaxed.svg"' in rl.headers["content-disposition"]
    assert client.post("/api/drawing", json=body).text == pr.text  # print is the default
    p_lines, p_box = _svg_lines(pr.text)
    r_lines, r_box = _svg_lines(rl.text)
    assert len(p_lines) == len(r_lines) == 5
    lam_y = lateral_stretch(eps0, nu)
    for k, (p, r) in enumerate(zip(p_lines, r_lines, strict=True)):
        # back to fabric coordinates: the drawing is centred on the lines' (symmetric) extent,
        # SVG's y grows downwards
        pf = np.column_stack([p[:, 0] - p_box[2] / 2, p_box[3] / 2 - p[:, 1]])
        rf = np.column_stack([r[:, 0] - r_box[2] / 2, r_box[3] / 2 - r[:, 1]])
        assert pf == pytest.approx(np.array(FAMILY[k]["points"]), abs=1e-3)
        assert rf[:, 0] == pytest.approx(pf[:, 0] / (1 + eps0), abs=1e-3)
        assert rf[:, 1] == pytest.approx(pf[:, 1] / lam_y, abs=1e-3)
    # the print-frame drawing reads back as the same lines (an SVG upload of it)
    back = client.post("/api/pattern/svg", json={"svg": pr.text}).json()["lines"]
    assert [ln["id"] for ln in back] == [f"line-{k}" for k in range(5)]
    for ln, want in zip(back, FAMILY, strict=True):
        assert np.array(ln["points"]) == pytest.approx(np.array(want["points"]), abs=1e-3)
    bad = client.post("/api/drawing?frame=side", json=body)
    assert bad.status_code == 422 and bad.json()["error"].startswith("frame: "), bad.text
    bad = client.post("/api/drawing?frame=relaxed", json={"lines": FAMILY, "eps0": -2.0})
    assert bad.status_code == 422 and bad.json()["error"].startswith("eps0: "), bad.text


def test_body_over_the_limit_is_413_with_one_line(client: TestClient) -> None:
    assert client.get("/api/defaults").json()["max_body"] == MAX_BODY
    svg = ('<svg xmlns="http://www.w3.org/2000/svg" width="200mm" height="100mm" '
           'viewBox="0 0 200 100"><line id="a" x1="10" y1="20" x2="110" y2="20"/>'
           "<!-- {} --></svg>")
    # just under the limit: read as usual
    fill = MAX_BODY - len(svg) - 200
    ok = client.post("/api/pattern/svg", json={"svg": svg.format("x" * fill)})
    assert ok.status_code == 200, ok.text[:300]
    assert [ln["id"] for ln in ok.json()["lines"]] == ["a"]
    # over it: refused before the body is read (content-length), one line saying the limit
    big = client.post("/api/pattern/svg", json={"svg": svg.format("x" * MAX_BODY)})
    assert big.status_code == 413, big.text[:300]
    msg = big.json()["error"]
    assert msg.startswith("request body: ") and f"{MAX_BODY:,} bytes" in msg, msg
    assert "5 MB" in msg and "SVG" in msg and "\n" not in msg and len(msg) < 200, msg
    # without a content-length (chunked): counted as it arrives, the same answer
    payload = b'{"svg": "' + b"x" * (MAX_BODY + 10) + b'"}'
    chunks = (payload[k:k + 65536] for k in range(0, len(payload), 65536))
    r = client.post("/api/pattern/svg", content=chunks,
                    headers={"content-type": "application/json"})
    assert r.status_code == 413, r.text[:300]
    assert r.json()["error"].startswith("request body: more than ")
    # the server still answers
    assert client.post("/api/predict", json={"lines": FAMILY}).status_code == 200


def test_clients_do_not_see_each_others_jobs(client: TestClient, other: TestClient) -> None:
    jid = client.post("/api/jobs", json={"lines": FAMILY, "seed": 1}).json()["id"]
    mine = client.post("/api/jobs", json={"lines": FAMILY[:2], "seed": 1}).json()["id"]
    theirs = other.post("/api/jobs", json={"lines": FAMILY[:1], "seed": 1}).json()["id"]
    a, b = client.cookies.get(COOKIE), other.cookies.get(COOKIE)
    assert a and b and a != b and len(a) == 32
    for j in (jid, mine):
        _wait(client, j, ("done",))
    _wait(other, theirs, ("done",))
    assert [j["id"] for j in client.get("/api/jobs").json()] == [jid, mine]
    assert [j["id"] for j in other.get("/api/jobs").json()] == [theirs]
    # every route of a job: "no such job" (404) for the other client, as for an unknown id
    for path in (f"/api/jobs/{jid}", f"/api/jobs/{jid}/files/metrics.json",
                 f"/api/jobs/{jid}/files/final.vtu", f"/api/jobs/{jid}/shape"):
        r = other.get(path)
        assert r.status_code == 404 and r.json()["error"] == f"job {jid}: no such job", path
        assert client.get(path).status_code == 200, path
    r = other.delete(f"/api/jobs/{jid}")
    assert r.status_code == 404 and "no such job" in r.json()["error"]
    assert client.get(f"/api/jobs/{jid}").json()["status"] == "done"
    assert other.get(f"/api/jobs/{theirs}").json()["status"] == "done"
    assert client.get(f"/api/jobs/{theirs}").status_code == 404
    # the owner is not shown in the job's state
    assert "owner" not in client.get(f"/api/jobs/{jid}").json()
    # a browser without the cookie, or with a forged one, is a new client: sees nothing
    for forged in ("not-a-client-id", a.upper(), a[:-1]):
        stranger = TestClient(client.app)  # an empty cookie jar: the forged one is sent alone
        hdr = {"cookie": f"{COOKIE}={forged}"}
        r = stranger.get("/api/jobs", headers=hdr)
        assert r.status_code == 200 and r.json() == [], forged
        new = r.cookies.get(COOKIE)
        assert new and len(new) == 32 and new not in (a, b), (forged, new)
        assert stranger.get(f"/api/jobs/{jid}", headers=hdr).status_code == 404
        stranger.close()
    # the cookie is set once, HttpOnly and SameSite=Strict; a known client gets none again
    fresh = TestClient(client.app).get("/api/defaults").headers.get_list("set-cookie")
    assert len(fresh) == 1 and "httponly" in fresh[0].lower(), fresh
    assert "samesite=strict" in fresh[0].lower(), fresh
    assert "set-cookie" not in client.get("/api/defaults").headers


def test_cancel_by_another_client_leaves_the_job_running(client: TestClient,
                                                         other: TestClient) -> None:
    jid = client.post("/api/jobs", json={"lines": FAMILY, "seed": 10}).json()["id"]  # ~2 s
    _wait(client, jid, ("running",))
    assert other.delete(f"/api/jobs/{jid}").status_code == 404
    assert _wait(client, jid, ("done", "cancelled", "failed"))["status"] == "done"


TWO_LINES = [{"points": [[-30.0, 6.0], [30.0, 6.0]]}, {"points": [[-20.0, -6.0], [40.0, -6.0]]}]


def _finished(client: TestClient, path: str, seed: int) -> str:
    """A fake job of TWO_LINES run to the end; ``path`` (``{jid}`` in it) answers 404 before."""
    jid = client.post("/api/jobs", json={"lines": TWO_LINES, "seed": seed}).json()["id"]
    early = client.get(path.format(jid=jid))
    assert early.status_code == 404 and "no file 'final.vtu'" in early.json()["error"]
    _wait(client, jid, ("done",))
    return jid


def test_shape_of_a_finished_job(client: TestClient) -> None:
    lines = TWO_LINES
    jid = _finished(client, "/api/jobs/{jid}/shape", seed=2)
    r = client.get(f"/api/jobs/{jid}/shape")
    assert r.status_code == 200, r.text
    shape = r.json()
    want = fake_rods({"pattern": {"lines": lines}})
    assert len(shape["rods"]) == 2  # one chain per rod, not one joined line
    for got, w in zip(shape["rods"], want, strict=True):
        assert np.array(got) == pytest.approx(w, abs=1e-3)
    pts = np.array(shape["fabric"]["points"])
    tri = np.array(shape["fabric"]["triangles"])
    assert tri.ndim == 2 and tri.shape[1] == 3 and len(tri) > 50
    assert tri.min() == 0 and tri.max() == len(pts) - 1  # every point kept is used
    # the fabric near the rods only (30 mm around them), not the whole fake sheet (40 mm)
    assert pts[:, 0].min() >= -30.0 - 30.0 - 1e-9 and pts[:, 0].max() <= 40.0 + 30.0 + 1e-9
    assert pts[:, 1].min() >= -36.0 - 1e-9 and pts[:, 1].max() <= 36.0 + 1e-9
    assert pts[:, 0].max() - pts[:, 0].min() > 60.0  # but more than the rods themselves
    assert FABRIC_MARGIN > 30.0


@pytest.mark.parametrize("fmt", ["glb", "obj", "stl"])
def test_model_of_a_finished_job(client: TestClient, other: TestClient, fmt: str,
                                 tmp_path: Path) -> None:
    import trimesh

    lines = TWO_LINES
    jid = _finished(client, "/api/jobs/{jid}/model." + fmt, seed=1)
    r = client.get(f"/api/jobs/{jid}/model.{fmt}")
    assert r.status_code == 200, r.text
    assert f'filename="undulate-{jid}.{fmt}"' in r.headers["content-disposition"]
    path = tmp_path / f"m.{fmt}"
    path.write_bytes(r.content)
    kw = {"split_objects": True, "group_material": False} if fmt == "obj" else {}
    scene = trimesh.load(path, force="scene", **kw)
    assert set(scene.geometry) == {"fabric", "rod_0", "rod_1"}
    want = fake_rods({"pattern": {"lines": lines}})
    for k, w in enumerate(want):
        lo, hi = scene.geometry[f"rod_{k}"].bounds
        assert np.all(lo <= w.min(0) + 1e-3) and np.all(hi >= w.max(0) - 1e-3)
    assert other.get(f"/api/jobs/{jid}/model.{fmt}").status_code == 404  # not its job
    assert client.get(f"/api/jobs/{jid}/model.ply").status_code in (404, 422)


def test_atlas_and_where_a_group_sits(client: TestClient) -> None:
    from undulate.design.atlas import load_atlas

    a = client.get("/api/atlas").json()
    shipped = load_atlas()
    assert a["meta"] == shipped.meta and len(a["points"]) == len(shipped.points)
    m = shipped.meta
    five = [{"points": [[-m["L"] / 2, y], [m["L"] / 2, y]]}
            for y in (-22.0, -11.0, 0.0, 11.0, 22.0)]  # gap 10 mm for b = 1
    body = {"lines": five, "h": 0.5, "b": m["b"], "eps0": m["eps0"], "E_B": m["E_B"],
            "E": m["E"], "t": m["t"]}
    g = client.post("/api/predict", json=body).json()["groups"][0]
    assert g["atlas"]["inside"] and g["atlas"]["design_s"] == pytest.approx(10.0)
    p = shipped.points
    near = p.iloc[((p["h"] - 0.5).abs() / m["h_step"]
                   + (p["s"] - 10.0).abs() / m["s_step"]).argmin()]
    assert g["atlas"]["family"] == near["family"] and g["atlas"]["n"] == near["n"]
    # the page's defaults differ from the diagram's modulus: outside, and it says why
    out = client.post("/api/predict", json=body | {"E_B": 3000.0}).json()["groups"][0]
    assert not out["atlas"]["inside"] and "E_B = 3000" in out["atlas"]["summary"]
    one = client.post("/api/predict", json=body | {"lines": five[:1]}).json()["groups"][0]
    assert one["atlas"]["confidence"] == "outside" and "one line alone" in one["atlas"]["summary"]
    # shorter lines: the group is drawn where it sits once scaled (h' of the same number of
    # half-waves on the rod, s' = s L_ref / L), on the diagram simulated at the nearest L
    close = (-10.0, -5.0, 0.0, 5.0, 10.0)  # gap 4 mm: thin lines still act as a group
    short = [{"points": [[-0.45 * m["L"], y], [0.45 * m["L"], y]]} for y in close]
    sc = client.post("/api/predict", json=body | {"lines": short, "h": 0.25}).json()
    at = sc["groups"][0]["atlas"]
    assert at["inside"] and at["confidence"] in ("scaled", "near a transition")
    from undulate.design.scaling import load_scaling

    k = load_scaling()  # the rods' own half-wave l0 = c0 + c1 h grows by 1/0.9: the same x
    h_eq = ((k.c0 + k.c1 * 0.25) / 0.9 - k.c0) / k.c1
    assert at["atlas"] == "phase_diagram"
    assert at["design_h"] == pytest.approx(h_eq) and at["design_s"] == pytest.approx(4 / 0.9)
    assert at["scaled"]["length_factor"] == pytest.approx(0.9)
    assert "scaled from the simulated L = 100 mm" in at["summary"]
    # half as long: the diagram simulated at L = 50 mm holds it, and the page can fetch it
    half = [{"points": [[-m["L"] / 4, y], [m["L"] / 4, y]]} for y in close]
    at = client.post("/api/predict", json=body | {"lines": half, "h": 0.25}).json()
    at = at["groups"][0]["atlas"]
    assert at["inside"] and at["atlas"] == "five_rods_L50" and "scaled" not in at
    other = client.get("/api/atlas", params={"name": at["atlas"]}).json()
    assert other["name"] == "five_rods_L50" and other["meta"]["L"] == 50.0
    assert (at["h"], at["s"], at["n"]) in {(q["h"], q["s"], q["n"]) for q in other["points"]}
    missing = client.get("/api/atlas", params={"name": "nope"})
    assert missing.status_code == 404 and "phase_diagram" in missing.text
