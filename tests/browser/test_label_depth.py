"""Labelling a real RGB-D frame in Chromium with the "Use depth" toggle: the
shared rgbd-primesense frames imported as a user would, a box around the
chair with depth on (its white backrest comes in) and, as a new object, off
(colour alone cannot tell it from the white wall)."""

import json

import numpy as np
import pytest

from app.extensions import db
from app.models import Frame
from app.services.importing import import_path
from app.services.labelling.masks import decode_rle
from tests.browser.conftest import screenshot, sign_in
from tests.browser.test_label import drag, open_frame
from tests.realdata import BACKREST, PRIMESENSE, chair_truth
from tests.realdata import CHAIR_BOX as BOX

pytestmark = pytest.mark.browser



def iou(a: np.ndarray, b: np.ndarray) -> float:
    return float((a & b).sum() / max(1, (a | b).sum()))


def mask_of(page, k: int) -> np.ndarray:
    rle = page.evaluate(f"window.labelPage.maskRle({k})")
    return decode_rle(rle, tuple(rle["size"]), field="mask")


def box_and_wait(page, n: int) -> None:
    """Draw BOX as the n-th object and wait for GrabCut's answer."""
    drag(page, BOX)
    page.wait_for_function(f"() => window.labelPage.instances().length === {n} && window.labelPage.instances()[{n - 1}].hasEngine")
    page.wait_for_selector("#busy", state="hidden")


@pytest.mark.skipif(not PRIMESENSE.exists(), reason="shared data not present")
def test_a_box_on_a_real_rgbd_frame_with_depth_on_and_off(live_app, live_server, browser):
    with live_app.app_context():
        import_path(PRIMESENSE, activity="room")
        frame_id = db.session.execute(db.select(Frame.id).filter_by(index=1)).scalar_one()
    context = browser.new_context(viewport={"width": 1280, "height": 800})
    page = context.new_page()
    boxes = []
    page.on("request", lambda r: boxes.append(json.loads(r.post_data)) if r.url.endswith("/grabcut/box") else None)
    sign_in(page, live_app, live_server, username="ann", role="annotator")
    open_frame(page, live_server, frame_id)
    toggle = page.locator("#use-depth")
    assert toggle.is_checked() and toggle.is_enabled()

    box_and_wait(page, 1)
    with_depth = mask_of(page, 0)
    x, y = BACKREST
    assert with_depth[y, x] and with_depth.sum() > 30_000
    screenshot(page, "label-depth-chair")

    # Off, for a new object: colour alone cannot tell the white backrest from
    # the white wall (it leaves it out, or takes the wall in with it).
    toggle.uncheck()
    page.keyboard.press("n")
    box_and_wait(page, 2)
    without = mask_of(page, 1)
    truth = chair_truth()
    assert iou(without, truth) < 0.6 < iou(with_depth, truth)
    assert [b["use_depth"] for b in boxes] == [True, False]
    screenshot(page, "label-depth-chair-off")
    context.close()


def test_a_frame_without_depth_has_the_toggle_disabled_saying_why(live_app, live_server, page):
    from tests.browser.test_label import object_frames

    frame_id, _ = object_frames(live_app)
    sign_in(page, live_app, live_server, username="ann", role="annotator")
    open_frame(page, live_server, frame_id)
    toggle = page.locator("#use-depth")
    assert toggle.is_disabled() and not toggle.is_checked()
    assert "no depth" in page.locator("label:has(#use-depth)").get_attribute("title")
    boxes = []
    page.on("request", lambda r: boxes.append(json.loads(r.post_data)) if r.url.endswith("/grabcut/box") else None)
    drag(page, [(85, 55), (245, 185)])
    page.wait_for_function("() => window.labelPage.instances().length === 1 && window.labelPage.instances()[0].area > 0")
    assert boxes == [{"frame_id": frame_id, "instance": boxes[0]["instance"], "box": boxes[0]["box"], "use_depth": False}]
