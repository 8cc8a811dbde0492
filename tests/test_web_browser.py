"""End to end in a real headless browser: the page of ``undulate serve`` with the real engine.

Playwright drives Chromium (the system's ``/usr/bin/chromium``, or ``UNDULATE_CHROMIUM``):
load the page, place lines, see the prediction, draw a line, see a clear error, run a small
simulation to the end, download its metrics and the G-code. Skipped where no browser is
installed, unless ``UNDULATE_REQUIRE_BROWSER=1`` (CI sets it), where that is a failure.
"""

from __future__ import annotations

import json
import os
import shutil
import socket
import threading
import time
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

ARGS = ["--headless=new", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
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


def test_page_end_to_end(server: str, tmp_path: Path) -> None:
    with sync_api.sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=CHROMIUM, args=ARGS,
                                     chromium_sandbox=False)
        page = browser.new_page(accept_downloads=True)
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
        pm = T.phase_map(0.3, 10.0, eps0=0.5, L=40.0, N=3)
        assert int(cells.nth(3).inner_text()) == int(pm["n"].item())
        fam = str(pm["family"].item())
        assert cells.nth(6).inner_text() == fam
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
        assert page.evaluate("document.querySelector('#pictures img').naturalWidth") > 100
        with page.expect_download() as dl:
            page.click("#files a[download='metrics.json']")
        path = tmp_path / "metrics.json"
        dl.value.save_as(path)
        metrics = json.loads(path.read_text())
        assert metrics["rods"][0]["n"] == n_sim
        with page.expect_download() as dl:
            page.click("#gcode")
        g = tmp_path / "lines.gcode"
        dl.value.save_as(g)
        text = g.read_text()
        assert text.count("\nG1 ") > 3 and "eps0" in text
        browser.close()
