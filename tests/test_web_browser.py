"""End to end in a real headless browser: the page of ``undulate serve`` with the real engine.

Playwright drives Chromium (the system's ``/usr/bin/chromium``, or ``UNDULATE_CHROMIUM``):
load the page, place lines, see the prediction, draw a line, see a clear error, refuse an
SVG over the size limit with one line, run a small simulation to the end, see its shape in the
3D view (drawn, turned by a drag, zoomed by the wheel, reset by a double-click), download its
metrics, its 3D model (.glb), the G-code and drawings (SVG, DXF); edit lines on the grid
(draw, undo, redo, select, delete, move). No script errors on the way. Skipped where no browser is
installed, unless ``UNDULATE_REQUIRE_BROWSER=1`` (CI sets it), where that is a failure.
"""

from __future__ import annotations

import json
import os
import shutil
import socket
import threading
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from undulate import theory as T

uvicorn = pytest.importorskip("uvicorn")
sync_api = pytest.importorskip("playwright.sync_api")

CHROMIUM = os.environ.get("UNDULATE_CHROMIUM") or shutil.which("chromium") or shutil.which(
    "chromium-browser")
if not CHROMIUM:
    if os.environ.get("UNDULATE_REQUIRE_BROWSER") == "1":
        raise RuntimeError("UNDULATE_REQUIRE_BROWSER=1 but no chromium found (apt-get install "
                           "chromium, or set UNDULATE_CHROMIUM)")
    pytest.skip("no chromium on this machine", allow_module_level=True)

# WebGL (the 3D view) runs on SwiftShader, Chromium's software renderer
ARGS = ["--headless=new", "--no-sandbox", "--disable-gpu", "--enable-unsafe-swiftshader",
        "--disable-quic", "--no-first-run",
        "--disable-background-networking", "--disable-component-update", "--disable-sync"]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture()
def server(tmp_path: Path):
    from undulate.interfaces.web.app import create_app

    port = _free_port()
    app = create_app(tmp_path / "jobs", workers=1)
    srv = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=port, log_level="warning"))
    th = threading.Thread(target=srv.run, daemon=True)
    th.start()
    t0 = time.time()
    while not srv.started:
        assert time.time() - t0 < 30, "server did not start"
        time.sleep(0.05)
    yield f"http://127.0.0.1:{port}"
    srv.should_exit = True
    th.join(20)


def _set(page, field: str, value: float) -> None:
    page.fill(f"#{field}", str(value))


# pixels of the 3D view (a WebGL canvas, read through its PNG): drawn (not the background
# #fbfbfb) and of the rods' orange (glTF base colour 230, 110, 40, lit)
CANVAS_PIXELS = """async () => {
  const cv = document.querySelector('#view3d');
  const url = cv.toDataURL();
  const img = new Image();
  img.src = url;
  await img.decode();
  const c2 = document.createElement('canvas');
  c2.width = cv.width;
  c2.height = cv.height;
  const g = c2.getContext('2d');
  g.drawImage(img, 0, 0);
  const d = g.getImageData(0, 0, c2.width, c2.height).data;
  let drawn = 0, rod = 0;
  for (let i = 0; i < d.length; i += 4) {
    if (Math.abs(d[i] - 251) + Math.abs(d[i + 1] - 251) + Math.abs(d[i + 2] - 251) > 12) drawn++;
    if (d[i] > d[i + 1] + 40 && d[i] > d[i + 2] + 60) rod++;
  }
  return { drawn, rod, total: cv.width * cv.height, url };
}"""


def _pixels_until(page, ok, timeout: float = 20.0) -> dict:
    """The 3D view's pixels once ``ok(pixels)`` holds (or the last ones after ``timeout``)."""
    t0 = time.time()
    while True:
        px = page.evaluate(CANVAS_PIXELS)
        if ok(px) or time.time() - t0 > timeout:
            return px
        time.sleep(0.1)


def _svg_upload(page, size: int) -> None:
    """Choose an SVG file of ``size`` bytes (a line and a long comment) in the page."""
    head = ('<svg xmlns="http://www.w3.org/2000/svg" width="100mm" height="50mm" '
            'viewBox="0 0 100 50"><line x1="10" y1="20" x2="60" y2="20"/><!-- ')
    tail = " --></svg>"
    body = head + "x" * (size - len(head) - len(tail)) + tail
    page.set_input_files("#svg-file", files=[{"name": "big.svg", "mimeType": "image/svg+xml",
                                              "buffer": body.encode()}])


def test_page_end_to_end(server: str, tmp_path: Path) -> None:
    with sync_api.sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=CHROMIUM, args=ARGS,
                                     chromium_sandbox=False)
        page = browser.new_page(accept_downloads=True, viewport={"width": 1500, "height": 1000})
        errors: list[str] = []
        page.on("pageerror", lambda e: errors.append(f"page error: {e}"))
        # (the browser logs each refused request, 4xx, as "Failed to load resource": those
        # are the bad inputs this test makes on purpose)
        page.on("console", lambda m: errors.append(f"console: {m.text}") if m.type == "error"
                and not m.text.startswith("Failed to load resource") else None)
        page.goto(server)
        rows = page.locator("#prediction tbody tr")
        rows.first.wait_for()
        # three parallel lines, 40 mm long, 10 mm apart: the analytical prediction per line
        _set(page, "N", 3)
        _set(page, "s", 10)
        _set(page, "L", 40)
        page.click("#place")
        page.wait_for_function("document.querySelectorAll('#prediction tbody tr').length == 3")
        cells = rows.nth(0).locator("td")
        page.wait_for_function("document.querySelector('#prediction tbody td:nth-child(2)')"
                               ".textContent == '40'")
        # where the group sits in the simulated phase diagram: three lines of 40 mm are
        # outside the five-rod diagram (marked dashed), and the panel says why
        page.wait_for_function("document.querySelectorAll('#atlas circle.outside').length == 1")
        assert page.locator("#atlas rect").count() > 10
        assert "outside the simulated diagram (N = 3" in page.locator("#atlas-where").inner_text()
        pm = T.phase_map(0.3, 10.0, eps0=0.5, L=40.0, N=3, E_B=1000.0)  # the page's E_B
        assert int(cells.nth(3).inner_text()) == int(pm["n"].item())
        fam = str(pm["family"].item())
        assert cells.nth(6).inner_text() == fam
        # five lines of 50 mm, 4 mm apart: the panel switches to the diagram simulated at
        # L = 50 mm, which holds them, and marks the design on it
        _set(page, "N", 5)
        _set(page, "s", 4)
        _set(page, "L", 50)
        page.click("#place")
        page.wait_for_function("document.querySelector('#atlas').dataset.atlas == "
                               "'five_rods_L50'")
        page.wait_for_function("document.querySelectorAll('#atlas circle').length == 1")
        assert "L = 50 mm" in page.locator("#atlas-where").inner_text()
        _set(page, "N", 3)
        _set(page, "s", 10)
        _set(page, "L", 40)
        page.click("#place")
        page.wait_for_function("document.querySelectorAll('#prediction tbody tr').length == 3")
        # a bad thickness: one clear line naming the field, no prediction
        _set(page, "h", -1)
        page.wait_for_function("document.querySelector('#error').textContent.startsWith('h:')")
        assert page.locator("#simulate").is_disabled()
        _set(page, "h", 0.3)
        page.wait_for_function("document.querySelector('#error').textContent == ''")
        # draw a fourth line by dragging on the fabric, far from the others
        box = page.locator("#fabric").bounding_box()
        y = box["y"] + box["height"] * 0.85
        page.mouse.move(box["x"] + box["width"] * 0.3, y)
        page.mouse.down()
        page.mouse.move(box["x"] + box["width"] * 0.5, y, steps=5)
        page.mouse.up()
        page.wait_for_function("document.querySelectorAll('#prediction tbody tr').length == 4")
        # an SVG over the size limit: one clear line, checked in the page before it is sent...
        limit = page.evaluate("fetch('/api/defaults').then((r) => r.json())")["max_body"]
        _svg_upload(page, limit + 1000)
        page.wait_for_function("document.querySelector('#error').textContent.startsWith('SVG:')")
        err = page.locator("#error").inner_text()
        assert "big.svg" in err and f"{limit / 1e6:g} MB" in err and "\n" not in err, err
        # ... and by the server when the page's own check is off (maxBody: the page's copy)
        page.evaluate("maxBody = 1e12")
        _svg_upload(page, limit + 1000)
        page.wait_for_function(
            "document.querySelector('#error').textContent.startsWith('SVG: request body')")
        err = page.locator("#error").inner_text()
        assert f"{limit:,} bytes" in err and "\n" not in err, err
        assert page.locator("#prediction tbody tr").count() == 4  # the lines are kept
        # back to one short line and simulate it with the real engine (quick mesh)
        _set(page, "N", 1)
        page.click("#place")
        page.wait_for_function("document.querySelectorAll('#prediction tbody tr').length == 1")
        page.wait_for_function("!document.querySelector('#simulate').disabled")
        page.click("#simulate")
        page.wait_for_function(
            "['done', 'failed'].includes(document.querySelector('#job-status').dataset.status)",
            timeout=400_000)
        status = page.locator("#job-status").inner_text()
        assert page.locator("#job-status").get_attribute("data-status") == "done", status
        sim = page.locator("#sim-table tbody tr")
        assert sim.count() == 1
        n_sim = int(sim.nth(0).locator("td").nth(1).inner_text())
        assert n_sim >= 1
        page.locator("#pictures img").first.wait_for()
        # the picture loads after the element appears: wait for it (a fixed read raced)
        page.wait_for_function("document.querySelector('#pictures img').complete && "
                               "document.querySelector('#pictures img').naturalWidth > 100")
        with page.expect_download() as dl:
            page.click("#files a[download='metrics.json']")
        path = tmp_path / "metrics.json"
        dl.value.save_as(path)
        metrics = json.loads(path.read_text())
        assert metrics["rods"][0]["n"] == n_sim
        # the final shape in 3D (three.js, the run's .glb): drawn, with the rod in it
        page.locator("#view3d").scroll_into_view_if_needed()
        first = _pixels_until(page, lambda p: p["rod"] > 100)
        assert first["drawn"] > 0.1 * first["total"] and first["rod"] > 100, first | {"url": ""}
        assert "drag to turn" in page.locator("#view3d-note").inner_text()
        # a drag turns it, the wheel zooms, a double-click goes back to the first view
        box = page.locator("#view3d").bounding_box()
        cx, cy = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
        page.mouse.move(cx, cy)
        page.mouse.down()
        page.mouse.move(cx + 80, cy + 40, steps=4)
        page.mouse.up()
        turned = _pixels_until(page, lambda p: p["url"] != first["url"])
        assert turned["url"] != first["url"] and turned["drawn"] > 0.05 * turned["total"]
        page.mouse.move(cx, cy)
        page.mouse.wheel(0, -400)
        zoomed = _pixels_until(page, lambda p: p["url"] != turned["url"])
        assert zoomed["rod"] > turned["rod"], (zoomed["rod"], turned["rod"])
        page.mouse.dblclick(cx, cy)
        again = _pixels_until(page, lambda p: p["url"] == first["url"])
        assert again["url"] == first["url"]
        # the drawing of the line in the relaxed fabric: L / (1 + eps0) long
        with page.expect_download() as dl:
            page.click("#svg-relaxed")
        assert dl.value.suggested_filename == "lines-relaxed.svg"
        svg = tmp_path / "lines-relaxed.svg"
        dl.value.save_as(svg)
        pls = ET.parse(svg).getroot().findall(".//{http://www.w3.org/2000/svg}polyline")
        assert len(pls) == 1
        xs = [float(p.split(",")[0]) for p in pls[0].get("points").split()]
        assert max(xs) - min(xs) == pytest.approx(40.0 / 1.5, abs=1e-3)
        # the same lines as DXF (ezdxf reads it back: one centre line L / (1 + eps0) long)
        with page.expect_download() as dl:
            page.click("#dxf-relaxed")
        assert dl.value.suggested_filename == "lines-relaxed.dxf"
        dxf = tmp_path / "lines-relaxed.dxf"
        dl.value.save_as(dxf)
        import ezdxf

        ents = [e for e in ezdxf.readfile(dxf).modelspace() if e.dxf.layer == "LINES"]
        assert len(ents) == 1
        pts = [p[:2] for p in ents[0].get_points()]
        assert max(p[0] for p in pts) - min(p[0] for p in pts) == pytest.approx(40 / 1.5,
                                                                                abs=1e-3)
        # the final state as a 3D model: a .glb that trimesh loads, the rod a closed solid
        with page.expect_download() as dl:
            page.click("#model-glb")
        glb = tmp_path / "model.glb"
        dl.value.save_as(glb)
        import trimesh

        scene = trimesh.load(glb, force="scene")
        assert set(scene.geometry) == {"fabric", "rod_0"}
        assert scene.geometry["rod_0"].is_volume
        with page.expect_download() as dl:
            page.click("#gcode")
        g = tmp_path / "lines.gcode"
        dl.value.save_as(g)
        text = g.read_text()
        assert text.count("\nG1 ") > 3 and "eps0" in text
        # a reload shows this browser's latest job again, results and 3D view included...
        page.reload()
        page.wait_for_function("document.querySelector('#job-status').dataset.status == 'done'")
        page.wait_for_function("document.querySelectorAll('#sim-table tbody tr').length == 1")
        again = page.locator("#sim-table tbody tr").nth(0).locator("td").nth(1).inner_text()
        assert int(again) == n_sim
        assert _pixels_until(page, lambda p: p["rod"] > 100)["rod"] > 100
        # ... and another browser (no cookie of this one) sees no job
        other = browser.new_context().new_page()
        other.goto(server)
        other.locator("#prediction tbody tr").first.wait_for()
        assert other.evaluate("fetch('/api/jobs').then((r) => r.json())") == []
        assert other.locator("#job").is_hidden()
        assert errors == [], errors
        browser.close()


def _drag(page, x0: float, y0: float, x1: float, y1: float) -> None:
    page.mouse.move(x0, y0)
    page.mouse.down()
    page.mouse.move(x1, y1, steps=6)
    page.mouse.up()


def _points(page) -> list[list[tuple[float, float]]]:
    return page.evaluate("""() => [...document.querySelectorAll('#lines-layer polyline')]
        .map((p) => p.getAttribute('points').trim().split(/\\s+/)
        .map((q) => q.split(',').map(Number)))""")


def test_editing_lines_grid_select_move_delete_undo(server: str) -> None:
    """Draw two lines on the 5 mm grid, undo and redo, select, delete and move one; each
    line shows its length and angle in mm and degrees."""
    with sync_api.sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=CHROMIUM, args=ARGS,
                                     chromium_sandbox=False)
        page = browser.new_page(viewport={"width": 1500, "height": 1000})
        errors: list[str] = []
        page.on("pageerror", lambda e: errors.append(f"page error: {e}"))
        page.goto(server)
        rows = page.locator("#prediction tbody tr")
        rows.first.wait_for()
        assert page.locator("#undo").is_disabled()  # the page's start is not a change
        page.click("#clear")
        page.wait_for_function("document.querySelectorAll('#prediction tbody tr').length == 0")
        assert page.locator("#grid-layer line").count() > 50  # the 5 mm grid is drawn
        box = page.locator("#fabric").bounding_box()
        x0, x1 = box["x"] + box["width"] * 0.3, box["x"] + box["width"] * 0.6
        _drag(page, x0, box["y"] + box["height"] * 0.3, x1, box["y"] + box["height"] * 0.3)
        _drag(page, x0, box["y"] + box["height"] * 0.7, x1, box["y"] + box["height"] * 0.7)
        page.wait_for_function("document.querySelectorAll('#prediction tbody tr').length == 2")
        pts = _points(page)
        assert len(pts) == 2
        for line in pts:  # snapped to the grid
            for x, y in line:
                assert x % 5 == 0 and y % 5 == 0, line
        labels = page.locator("#lines-layer text").all_text_contents()
        length = pts[0][1][0] - pts[0][0][0]
        assert labels[0] == f"{length:g} mm, 0°", labels
        # undo the second line, redo it, undo it again (keyboard)
        page.keyboard.press("Control+z")
        page.wait_for_function("document.querySelectorAll('#prediction tbody tr').length == 1")
        page.keyboard.press("Control+Shift+z")
        page.wait_for_function("document.querySelectorAll('#prediction tbody tr').length == 2")
        page.keyboard.press("Control+z")
        page.wait_for_function("document.querySelectorAll('#prediction tbody tr').length == 1")
        # select the remaining line by clicking it; Delete removes it; undo brings it back
        line = page.locator("#lines-layer polyline").first
        lb = line.bounding_box()
        page.mouse.click(lb["x"] + lb["width"] / 2, lb["y"] + lb["height"] / 2)
        assert "selected" in (line.get_attribute("class") or "")
        assert page.locator("#delete").is_enabled()
        page.keyboard.press("Delete")
        page.wait_for_function("document.querySelectorAll('#prediction tbody tr').length == 0")
        page.click("#undo")
        page.wait_for_function("document.querySelectorAll('#prediction tbody tr').length == 1")
        before = _points(page)[0]
        # drag it about 20 mm to the right: it moves by whole grid steps, one undoable change
        lb = page.locator("#lines-layer polyline").first.bounding_box()
        cx, cy = lb["x"] + lb["width"] / 2, lb["y"] + lb["height"] / 2
        mm = box["width"] / 320.0  # the drawing shows 320 mm across
        _drag(page, cx, cy, cx + 21 * mm, cy)
        after = _points(page)[0]
        dx = after[0][0] - before[0][0]
        same_y = all(a[1] == b[1] for a, b in zip(after, before, strict=True))
        assert dx in (15, 20, 25) and same_y, (before, after)
        page.keyboard.press("Control+z")  # the move is undone as one change
        t0 = time.time()
        while _points(page)[0] != before and time.time() - t0 < 10:
            time.sleep(0.05)
        assert _points(page)[0] == before
        assert errors == [], errors
        browser.close()
