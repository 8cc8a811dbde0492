"""Screenshots of the web page (``undulate serve``) for docs/web.md.

Starts the page's server on a free local port (jobs in a temporary folder), drives headless
Chromium with Playwright as tests/test_web_browser.py does, places five parallel lines, waits
for the prediction, runs a quick simulation with the real engine, and writes

* ``web-prediction.png``: the page with the lines and their analytical prediction;
* ``web-result.png``: the prediction and results column once the simulation is done, with
  the final shape in the 3D view.

Run from the repository root (about five minutes on 2 cores, nearly all of it the quick
simulation of the five rods)::

    python docs/images/make_web_screenshots.py            # writes into docs/images/
    python docs/images/make_web_screenshots.py --out /tmp/shots --chromium /usr/bin/chromium

The PNGs are reduced to a palette of 256 colours (Pillow) so that each stays well under
300 KB.
"""

from __future__ import annotations

import argparse
import os
import shutil
import socket
import tempfile
import threading
import time
from pathlib import Path

ARGS = ["--headless=new", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
        "--disable-background-networking", "--disable-component-update", "--disable-sync",
        "--hide-scrollbars"]

#: the case shown: five parallel lines, 100 mm long, 10 mm apart (edge to edge), the default
#: rod (h = 0.3 mm) and fabric: coherent, 5 half-waves predicted
CASE = {"N": 5, "s": 10, "L": 100}


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _small_png(path: Path) -> None:
    """Rewrite ``path`` with a 256-colour palette (the page has few colours)."""
    from PIL import Image

    with Image.open(path) as im:
        q = im.convert("RGB").quantize(colors=256, method=Image.Quantize.MEDIANCUT)
    q.save(path, optimize=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path(__file__).parent)
    ap.add_argument("--chromium", default=os.environ.get("UNDULATE_CHROMIUM")
                    or shutil.which("chromium") or shutil.which("chromium-browser"))
    a = ap.parse_args()
    if not a.chromium:
        raise SystemExit("no chromium found: apt-get install chromium, or --chromium PATH")

    import uvicorn
    from playwright.sync_api import sync_playwright

    from undulate.interfaces.web.app import create_app

    a.out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        port = _free_port()
        app = create_app(Path(tmp) / "jobs", workers=1)
        srv = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=port,
                                            log_level="warning"))
        th = threading.Thread(target=srv.run, daemon=True)
        th.start()
        while not srv.started:
            time.sleep(0.05)
        try:
            with sync_playwright() as pw:
                browser = pw.chromium.launch(executable_path=a.chromium, args=ARGS,
                                             chromium_sandbox=False)
                page = browser.new_page(viewport={"width": 1440, "height": 820})
                page.goto(f"http://127.0.0.1:{port}")
                page.locator("#prediction tbody tr").first.wait_for()
                for k, v in CASE.items():
                    page.fill(f"#{k}", str(v))
                page.click("#place")
                page.wait_for_function(
                    f"document.querySelectorAll('#prediction tbody tr').length == {CASE['N']}")
                page.wait_for_function("!document.querySelector('#simulate').disabled")
                shot = a.out / "web-prediction.png"
                page.screenshot(path=shot)
                _small_png(shot)
                t0 = time.time()
                page.click("#simulate")
                page.wait_for_function(
                    "['done', 'failed'].includes("
                    "document.querySelector('#job-status').dataset.status)", timeout=900_000)
                status = page.locator("#job-status").inner_text()
                if page.locator("#job-status").get_attribute("data-status") != "done":
                    raise SystemExit(f"the simulation did not finish: {status}")
                print(f"simulated in {time.time() - t0:.0f} s")
                page.wait_for_function("document.querySelector('#pictures img')?.complete")
                page.wait_for_function(
                    "(() => { const c = document.querySelector('#view3d');"
                    " const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;"
                    " for (let i = 3; i < d.length; i += 4) if (d[i] > 0) return true;"
                    " return false; })()")
                shot = a.out / "web-result.png"
                page.locator("#prediction-panel").screenshot(path=shot)
                _small_png(shot)
                browser.close()
        finally:
            srv.should_exit = True
            th.join(20)
    for name in ("web-prediction.png", "web-result.png"):
        p = a.out / name
        print(f"{p}: {p.stat().st_size / 1000:.0f} KB")


if __name__ == "__main__":
    main()
