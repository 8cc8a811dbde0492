"""The web page's API (FastAPI test client): prediction, SVG import, G-code, jobs, bad input.

The jobs run a fake worker (tests/_web_fakes.py) in real spawned processes; the browser test
(tests/test_web_browser.py) runs the real engine.
"""

from __future__ import annotations

import time
from pathlib import Path

import pytest

pytest.importorskip("fastapi")
from _web_fakes import fake_job  # noqa: E402
from fastapi.testclient import TestClient  # noqa: E402

from undulate.interfaces.web.app import create_app  # noqa: E402

FAMILY = [{"id": f"r{k}", "points": [[-50.0, y], [50.0, y]]}
          for k, y in enumerate([-22.0, -11.0, 0.0, 11.0, 22.0])]


@pytest.fixture()
def client(tmp_path: Path):
    app = create_app(tmp_path / "jobs", workers=2, max_queued=3, job_target=fake_job)
    with TestClient(app) as c:
        yield c
    app.state.jobs.shutdown()


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
    assert out["simulable"] is False and "along the stretch" in out["simulable_reason"]


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
    assert st["files"] == ["metrics.json"] and st["metrics"]["n"] == 3
    f = client.get(f"/api/jobs/{ids[0]}/files/metrics.json")
    assert f.status_code == 200 and f.json()["rods"] == 5
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
    r = client.post("/api/jobs", json={"lines": [{"points": [[0.0, 0.0], [50.0, 20.0]]}]})
    assert r.status_code == 422 and "straight lines along the stretch" in r.json()["error"]
    r = client.post("/api/jobs", json={"lines": FAMILY, "quality": "best"})
    assert r.status_code == 422 and r.json()["error"].startswith("quality:")
