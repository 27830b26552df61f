"""The frame viewer's 3-D view: open it, see the marked points, orbit and zoom with the mouse."""

import pytest

from app.extensions import db
from app.models import Frame
from app.services.demo import create_demo
from tests.browser.conftest import screenshot, sign_in

pytestmark = pytest.mark.browser


# Coarse content of the canvas: summed RGB of a 4 x 4 grid of blocks (changes when the view moves).
SIGNATURE_JS = """() => {
  const c = document.getElementById('view3d-canvas');
  const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
  const out = new Array(16).fill(0);
  for (let y = 0; y < c.height; y++) for (let x = 0; x < c.width; x++) {
    const k = 4 * (y * c.width + x), b = Math.floor(4 * y / c.height) * 4 + Math.floor(4 * x / c.width);
    out[b] += d[k] + d[k + 1] + d[k + 2];
  }
  return out;
}"""


def canvas_signature(page) -> list[int]:
    return page.evaluate(SIGNATURE_JS)


def wait_for_signature(page, value: list[int], *, equal: bool) -> list[int]:
    """Wait until the canvas's signature equals ``value`` (or, with ``equal=False``, differs); return it.

    The view redraws on the browser's next frames: the test waits for what it asserts, never for a time.
    """
    same = f"JSON.stringify(({SIGNATURE_JS})()) === JSON.stringify(value)"
    page.wait_for_function(f"(value) => {same if equal else f'!({same})'}", arg=value)
    return canvas_signature(page)


def green_pixels(page) -> int:
    return page.evaluate(
        """() => {
        const c = document.getElementById('view3d-canvas');
        const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
        let n = 0;
        for (let k = 0; k < d.length; k += 4) if (d[k + 1] > 120 && d[k + 1] > d[k] + 40 && d[k + 1] > d[k + 2] + 40) n++;
        return n;
    }"""
    )


def test_3d_view_orbits_the_marked_points(live_app, live_server, page):
    with live_app.app_context():
        create_demo(frames_per_activity=1, unlabelled_fraction=0, width=320, height=240)
        frame_id = db.session.execute(db.select(Frame.id).order_by(Frame.id)).scalars().first()
    sign_in(page, live_app, live_server)
    page.goto(f"{live_server}/frames/{frame_id}")
    panel = page.locator("#view3d-panel")
    assert panel.is_hidden()
    page.get_by_role("button", name="3D view").click()
    page.wait_for_selector("#view3d-canvas[data-drawn]")  # (wait_for_function would eval: CSP forbids it)
    assert int(page.get_attribute("#view3d-canvas", "data-drawn")) > 0
    points = int(page.get_attribute("#view3d-canvas", "data-points"))
    assert 0 < points <= 40_000  # 320 x 240 with depth everywhere: every other pixel
    assert "labelled" in page.inner_text("#view3d-status")
    assert green_pixels(page) > 200  # the labelled action-object, tinted green
    before = canvas_signature(page)
    screenshot(page, "frame3d-camera-view")

    box = page.locator("#view3d-canvas").bounding_box()
    cx, cy = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
    page.mouse.move(cx, cy)
    page.mouse.down()
    page.mouse.move(cx + 160, cy - 60, steps=8)
    page.mouse.up()
    turned = wait_for_signature(page, before, equal=False)
    screenshot(page, "frame3d-orbited")

    page.mouse.wheel(0, -600)  # zoom in
    wait_for_signature(page, turned, equal=False)
    page.dblclick("#view3d-canvas")  # back to the camera's view
    wait_for_signature(page, before, equal=True)
    page.get_by_role("button", name="3D view").click()
    assert panel.is_hidden()
