"""Take docs/img/labelling.png: the labelling page on the demo data, with a
GrabCut box drawn around the first unlabelled frame's action-object.

    PYTHONPATH=. .venv/bin/python docs/img/screenshot.py

Makes the quick start's demo in a temporary folder, serves it on a free port
and drives Debian's Chromium (apt-get install -y chromium) at 1280x800.
"""

import io
import tempfile
import threading
from pathlib import Path

import numpy as np
from flask_migrate import upgrade
from PIL import Image
from playwright.sync_api import sync_playwright
from werkzeug.serving import make_server

from app import create_app
from app.extensions import db
from app.models import Frame
from app.services.demo import renderer_truth

OUT = Path(__file__).with_name("labelling.png")
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync"]
PASSWORD = "screenshot-of-the-labelling-page"

with tempfile.TemporaryDirectory() as tmp:
    app = create_app({"SQLALCHEMY_DATABASE_URI": f"sqlite:///{tmp}/egonet.sqlite3", "STORAGE_URL": str(tmp),
                      "CACHE_ROOT": f"{tmp}/cache"}, instance_path=tmp)
    with app.app_context():
        upgrade()
    for command in (["egonet", "demo"], ["egonet", "create-user", "admin", "--role", "admin", "--password", PASSWORD]):
        result = app.test_cli_runner().invoke(args=command)
        assert result.exit_code == 0, result.output
    server = make_server("127.0.0.1", 0, app, threaded=True)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    base = f"http://127.0.0.1:{server.server_port}"

    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path="/usr/bin/chromium", headless=True, args=CHROMIUM_ARGS)
        page = browser.new_page(viewport={"width": 1280, "height": 800})
        page.goto(base + "/login")
        page.fill("input[name=username]", "admin")
        page.fill("input[name=password]", PASSWORD)
        page.click("button[type=submit]")
        page.goto(base + "/label/next")
        page.wait_for_selector("#label-app[data-ready='1']")
        with app.app_context():  # the renderer's truth gives the box a person would draw
            rows, cols = np.nonzero(renderer_truth(db.session.get(Frame, int(page.url.rstrip("/").split("/")[-1]))))
        corners = [(cols.min() - 8, rows.min() - 8), (cols.max() + 8, rows.max() + 8)]
        start, end = (page.evaluate("([x, y]) => window.labelPage.clientPoint(x, y)", [int(x), int(y)]) for x, y in corners)
        page.mouse.move(start["x"], start["y"])
        page.mouse.down()
        page.mouse.move(end["x"], end["y"], steps=8)
        page.mouse.up()
        page.wait_for_selector("#busy", state="hidden")
        page.wait_for_selector("#save-state[data-state='saved']", timeout=10_000)
        png = page.screenshot()
        browser.close()
    server.shutdown()

# A 256-colour palette keeps the picture sharp and under 200 KB.
Image.open(io.BytesIO(png)).convert("RGB").quantize(256, dither=Image.Dither.NONE).save(OUT, optimize=True)
print(f"{OUT}: {OUT.stat().st_size // 1024} KB")
