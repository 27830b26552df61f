"""The frame viewer in Chromium: every annotation's objects outlined in their colours over RGB, depth
and DHG, toggled; the heat map's colour bar and its display-only stretch."""

import numpy as np
import pycocotools.mask as coco_mask
import pytest

from app.extensions import db
from app.models import Frame
from app.models.training import Prediction
from app.services import labelling, media
from app.services.importing import FrameItem, add_frames
from app.services.users import create_user
from egonet import io
from tests.app.access.training import make_prediction_fixture
from tests.browser.conftest import screenshot, sign_in

pytestmark = pytest.mark.browser

H, W = 240, 320
# (rows, columns) of the objects: anna's two, bert's one (bert's lies inside anna's second, drawn over it).
ANNA = [(slice(40, 110), slice(30, 130)), (slice(130, 210), slice(180, 300))]
BERT = [(slice(140, 200), slice(200, 280))]


def box(rows, cols) -> np.ndarray:
    mask = np.zeros((H, W), bool)
    mask[rows, cols] = True
    return mask


def rle(mask):
    encoded = coco_mask.encode(np.asfortranarray(mask.astype(np.uint8)))
    return {"size": [int(v) for v in encoded["size"]], "counts": encoded["counts"].decode()}


def body(boxes, kinds, status):
    return {"version": 0, "status": status, "no_action_object": False, "time_spent_delta_s": 0.0,
            "instances": [{"key": f"k{i}", "kind": k, "label": None, "mask": rle(box(*b))}
                          for i, (b, k) in enumerate(zip(boxes, kinds))]}


def annotated_frame(live_app) -> int:
    rng = np.random.default_rng(3)
    rgb = (rng.integers(0, 40, (H, W, 3)) + [60, 90, 120]).astype(np.uint8)
    depth = np.linspace(0.8, 3.0, H * W, dtype=np.float32).reshape(H, W)
    dhg = rng.integers(0, 255, (H, W, 3), dtype=np.uint8)
    with live_app.app_context():
        add_frames(activity="kitchen", sequence="s1",
                   items=[FrameItem("f0", 0, "test", rgb=rgb, depth_m=depth, dhg=dhg)])
        frame = db.session.execute(db.select(Frame)).scalar_one()
        anna, _ = create_user("anna", "annotator", "anna-password-123")
        bert, _ = create_user("bert", "annotator", "bert-password-123")
        labelling.save_annotation(frame, bert, body(BERT, [None], "done"))
        labelling.save_annotation(frame, anna, body(ANNA, ["tactile", "visual"], "done"))  # the later: listed first
        ids = make_prediction_fixture(frame)
        faint = (np.linspace(0.01, 0.06, H * W).reshape(H, W) * 65535).round().astype(np.uint16)
        db.session.get(Prediction, ids["prediction_id"]).path = media.store(io.encode_png(faint), ".png")
        db.session.commit()
        return frame.id


PIXEL = """([selector, x, y]) => {
  const canvas = document.querySelectorAll("canvas.outlines")[selector];
  return Array.from(canvas.getContext("2d").getImageData(x, y, 1, 1).data);
}"""


def test_outlines_toggles_and_the_colour_bar(live_app, live_server, browser):
    frame_id = annotated_frame(live_app)
    context = browser.new_context(viewport={"width": 1280, "height": 800})
    page = context.new_page()
    failed = []
    page.on("response", lambda r: failed.append(f"{r.status} {r.url}") if r.status >= 400 else None)
    sign_in(page, live_app, live_server)
    page.goto(f"{live_server}/frames/{frame_id}")
    page.wait_for_selector("#views[data-ready='1']")
    assert page.locator("canvas.outlines").count() == 3
    assert page.get_attribute("#views", "data-outlines") == "3"
    colours = [list(labelling.instance_colour(i)) for i in range(3)]

    # Each object's edge in its own colour on every view, its inside left clear.
    left_edge = (30, 75)  # anna's first object, left side, mid-height
    for view in range(3):
        assert page.evaluate(PIXEL, [view, *left_edge]) == colours[0] + [255]
        assert page.evaluate(PIXEL, [view, 80, 75])[3] == 0
        assert page.evaluate(PIXEL, [view, 200, 170]) == colours[2] + [255]  # bert's, painted last
    assert page.evaluate(PIXEL, [0, 299, 150]) == colours[1] + [255]  # anna's second, right edge
    swatch = page.locator(".swatch").first.evaluate("el => getComputedStyle(el).backgroundColor")
    assert swatch == f"rgb({', '.join(map(str, colours[0]))})"
    legend = page.inner_text("#annotations")
    assert "anna" in legend and "bert" in legend and "object 1 · tactile" in legend
    screenshot(page, "viewer-outlines-1280x800")

    # One object off, one annotation off, everything off with O and back.
    page.locator(".show-instance").first.uncheck()
    assert page.evaluate(PIXEL, [1, *left_edge])[3] == 0 and page.get_attribute("#views", "data-outlines") == "2"
    page.locator(".show-annotation").nth(1).uncheck()  # bert
    assert page.get_attribute("#views", "data-outlines") == "1"
    assert page.evaluate(PIXEL, [0, 200, 170])[3] == 0
    page.keyboard.press("o")  # the focus is still on the box just unticked
    assert page.get_attribute("#views", "data-outlines") == "0" and not page.is_checked("#show-outlines")
    page.keyboard.press("o")
    assert page.get_attribute("#views", "data-outlines") == "1"

    # The heat map's scale, then stretched to this map's range (for the eye only).
    assert page.locator("#heat-ticks span").all_inner_texts() == ["0", "0.25", "0.5", "0.75", "1"]
    assert page.locator(".colour-bar img").evaluate("img => img.complete && img.naturalWidth === 256")
    assert not page.is_visible("#view-prediction")
    page.check("#normalise-prediction")
    page.wait_for_function("() => document.querySelector('#view-prediction').src.endsWith('/normalised.png')")
    page.wait_for_function("() => document.querySelector('#view-prediction').complete")
    assert page.is_visible("#view-prediction") and page.is_checked("#show-prediction")
    assert page.locator("#heat-ticks span").all_inner_texts() == ["0.00999", "0.0225", "0.035", "0.0475", "0.06"]  # 16-bit codes
    assert "display only" in page.inner_text("#heat-caption")
    page.uncheck("#normalise-prediction")
    assert page.locator("#heat-ticks span").all_inner_texts()[-1] == "1"
    page.check("#normalise-prediction")

    page.set_viewport_size({"width": 1920, "height": 1080})
    # The outlines follow the new size (on the next frames): wait for the edge's colour.
    page.wait_for_function(f"([at, colour]) => ({PIXEL})(at).every((c, i) => c === colour[i])",
                           arg=[[0, 299, 150], colours[1] + [255]])
    screenshot(page, "viewer-stretched-1920x1080")
    assert failed == []
    context.close()
