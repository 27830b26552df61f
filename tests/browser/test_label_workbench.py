"""The annotator's workbench in real Chromium (issue 15): one walk through
everything an annotator meets, one through a reviewer's fix.

The frames are dark (for brightness and contrast), with a red object, a
thin bright bar (for the polygon) and a colourful DHG image (over which the
outlines must still show)."""

import json

import numpy as np
import pytest

from app.extensions import db
from app.models import Annotation, Frame
from app.services import labelling
from app.services.importing import FrameItem, add_frames
from app.services.labelling.masks import decode_rle
from app.services.users import find_user
from tests.browser.conftest import screenshot, sign_in
from tests.browser.test_label import WATCH_SAVE_STATE, area, click_points, drag, open_frame, settle, wait_for_save_text

pytestmark = pytest.mark.browser

H, W = 240, 320
OBJECT = (slice(70, 170), slice(100, 230))
BAR = (slice(30, 34), slice(30, 200))  # a thin object: 4 px tall
COLOURS = [(0, 180, 255), (255, 60, 170)]  # the first two objects' colours (label_state.js)


def dark_frames(live_app, n: int = 3) -> list[int]:
    rng = np.random.default_rng(7)
    items = []
    for i in range(n):
        image = (rng.integers(0, 12, (H, W, 3)) + [15, 45, 18]).astype(np.uint8)
        image[OBJECT] = (rng.integers(0, 12, (100, 130, 3)) + [70, 14, 14]).astype(np.uint8)
        image[BAR] = [90, 90, 90]
        dhg = np.zeros((H, W, 3), np.uint8)  # bands of saturated colours, as DHG images have
        dhg[..., 0] = np.linspace(0, 255, W)[None, :]
        dhg[..., 1] = np.linspace(255, 0, H)[:, None]
        dhg[..., 2] = (np.arange(W)[None, :] * 7) % 256
        items.append(FrameItem(f"dark-{i}", i, f"test {i}", rgb=image, dhg=dhg))
    with live_app.app_context():
        add_frames(activity="kitchen", sequence="s1", items=items)
        return list(db.session.execute(db.select(Frame.id).order_by(Frame.index)).scalars())


PIXEL_JS = """([x, y]) => {
  const c = document.querySelector("#canvas");
  const p = window.labelPage.clientPoint(x, y);
  const r = c.getBoundingClientRect();
  const d = window.devicePixelRatio || 1;
  return Array.from(c.getContext("2d").getImageData(Math.floor((p.x - r.left) * d), Math.floor((p.y - r.top) * d), 1, 1).data.slice(0, 3));
}"""


def pixel(page, x: float, y: float) -> list[int]:
    """The canvas's colour on screen at image point (x, y)."""
    return page.evaluate(PIXEL_JS, [x, y])


def wait_for_pixel(page, x: float, y: float, test: str, value: object) -> list[int]:
    """Wait until the canvas's colour ``px`` at image point (x, y) passes ``test`` (JavaScript, with ``value``).

    The canvas redraws on the browser's next frames; a test waits for what it asserts, never for a frame.
    """
    page.wait_for_function(f"([x, y, value]) => {{ const px = ({PIXEL_JS})([x, y]); return {test}; }}", arg=[x, y, value])
    return pixel(page, x, y)


def wait_for_colour(page, x: float, y: float, colour, *, equal: bool = True) -> None:
    """Wait until the canvas at (x, y) shows ``colour`` (or, with ``equal=False``, any other colour)."""
    same = "px.every((c, i) => c === value[i])"
    wait_for_pixel(page, x, y, same if equal else f"!({same})", [int(c) for c in colour])


def edge_point(page, k: int) -> tuple[float, float]:
    """The centre of a pixel on object k's outline: the leftmost of its middle row."""
    rle = page.evaluate(f"window.labelPage.maskRle({k})")
    mask = decode_rle(rle, tuple(rle["size"]), field="mask")
    ys, xs = np.nonzero(mask)
    y = int(np.median(ys))
    return float(np.nonzero(mask[y])[0][0]) + 0.5, y + 0.5


def header_fits(page) -> None:
    """Nothing in the bar above the canvas is cut off or outside the window."""
    report = page.evaluate("""() => {
      const bar = document.querySelector(".workspace-bar").getBoundingClientRect();
      const out = [];
      for (const el of document.querySelectorAll(".workspace-bar .where > *, .workspace-bar .bar-tools > *")) {
        if (el.hidden) continue;
        const r = el.getBoundingClientRect();
        if (r.right > Math.min(bar.right, window.innerWidth) + 0.5 || r.left < bar.left - 0.5 || el.scrollWidth > el.clientWidth + 1) out.push(el.id || el.className);
      }
      return out;
    }""")
    assert report == [], f"cut off in the header: {report}"


def image_inside_stage(page) -> bool:
    return page.evaluate("""() => {
      const s = document.querySelector("#stage").getBoundingClientRect();
      const a = window.labelPage.clientPoint(0, 0), b = window.labelPage.clientPoint(320, 240);
      return a.x >= s.left && a.y >= s.top && b.x <= s.right + 0.5 && b.y <= s.bottom + 0.5;
    }""")


def server_annotation(live_app, frame_id: int, username: str = "ann") -> dict:
    with live_app.app_context():
        annotation = db.session.execute(
            db.select(Annotation).filter_by(frame_id=frame_id, author_id=find_user(username).id)
        ).scalar_one_or_none()
        if annotation is None:
            return {"version": 0}
        return {"version": annotation.version, "status": annotation.status.value, "instances": len(annotation.instances),
                "fixed_by": annotation.fixed_by.username if annotation.fixed_by else None}


def test_an_annotators_walk_through_the_workbench(live_app, live_server, browser):
    f0, f1, f2 = dark_frames(live_app)
    context = browser.new_context(viewport={"width": 1280, "height": 800})
    page = context.new_page()
    boxes = []
    page.on("request", lambda r: boxes.append(json.loads(r.post_data)["box"]) if r.url.endswith("/grabcut/box") else None)
    sign_in(page, live_app, live_server, username="ann", role="annotator")
    open_frame(page, live_server, f0)
    header_fits(page)
    assert image_inside_stage(page)

    # "Mark done" on an untouched frame asks; keeping on labelling saves nothing.
    page.click("#mark-done")
    page.wait_for_selector("#confirm-empty[open]")
    screenshot(page, "workbench-1-nothing-drawn-1280")
    page.click("#confirm-keep")
    page.wait_for_selector("#confirm-empty", state="hidden")
    assert server_annotation(live_app, f0) == {"version": 0}

    # A box, then its handle dragged: the object is cut again from the edited box.
    drag(page, [(85, 55), (245, 185)])
    page.wait_for_function("() => window.labelPage.instances().length === 1 && window.labelPage.instances()[0].area > 0")
    settle(page)
    drag(page, [(245, 185), (236, 180)])
    page.wait_for_function("() => window.labelPage.instances()[0].box[2] === 236")
    settle(page)
    first, edited = boxes  # the pointer lands within a pixel of each point
    assert edited[:2] == first[:2] and edited[2] == 236 and abs(edited[3] - 180) <= 1 and first[2] == 245
    assert page.evaluate("window.labelPage.instances().length") == 1

    # A polygon around the thin bar, as a new object.
    page.keyboard.press("n")
    page.keyboard.press("l")
    corners = [(28, 28), (202, 28), (202, 36), (28, 36)]
    click_points(page, corners + corners[:1])  # the polygon's hint fits one line: the view refits first
    page.wait_for_function("() => window.labelPage.instances().length === 2 && window.labelPage.instances()[1].area > 0")
    bar = page.evaluate("window.labelPage.maskRle(1)")
    bar_mask = decode_rle(bar, (H, W), field="mask")
    assert bar_mask[BAR].all() and bar_mask.sum() < 2 * 176 * 9
    settle(page)

    # Every object outlined in its own colour, over the DHG too; one hidden, then shown again.
    page.keyboard.press("d")
    page.wait_for_selector("#canvas[data-shown='dhg']")
    for k in (0, 1):
        wait_for_colour(page, *edge_point(page, k), COLOURS[k])  # object k + 1 outlined in its own colour
    screenshot(page, "workbench-2-outlines-over-dhg-1280")
    page.locator("#instances .instance").nth(1).locator(".visibility").click()
    wait_for_colour(page, *edge_point(page, 1), COLOURS[1], equal=False)
    page.keyboard.press("2")
    page.keyboard.press("v")
    wait_for_colour(page, *edge_point(page, 1), COLOURS[1])

    # Brightness and contrast are for the eyes only.
    page.keyboard.press("d")
    page.wait_for_selector("#canvas[data-shown='rgb']")
    version = page.evaluate("window.labelPage.version")
    before = sum(pixel(page, 20, 200))
    page.locator("#brightness").fill("250")
    page.keyboard.press("Escape")  # the keyboard back to the page
    assert sum(wait_for_pixel(page, 20, 200, "px[0] + px[1] + px[2] > 2 * value", before)) > 2 * before
    assert page.evaluate("window.labelPage.version") == version and page.evaluate("window.labelPage.saveState") == "saved"
    screenshot(page, "workbench-3-brighter-1280")

    # A GrabCut stroke that fails is not covered by "All changes saved": it waits for Retry.
    page.keyboard.press("1")
    page.evaluate(WATCH_SAVE_STATE)
    page.route("**/api/label/grabcut/stroke", lambda route: route.abort())
    page.keyboard.press("g")
    object_area = area(page)
    drag(page, [(110, 120), (220, 120)])  # background through the object's middle
    text = wait_for_save_text(page, "Not applied: ")
    assert text == "Not applied: your GrabCut stroke (background) — the server could not be reached"
    assert page.locator("#save-state").get_attribute("data-state") == "error" and page.locator("#retry-op").is_visible()
    screenshot(page, "workbench-4-stroke-not-applied-1280")
    page.unroute("**/api/label/grabcut/stroke")
    page.click("#retry-op")
    wait_for_save_text(page, "All changes saved")
    texts = page.evaluate("window.saveTexts")
    assert "All changes saved" not in texts[: texts.index(text)], texts
    stroked = area(page)
    assert stroked < object_area

    # The undo history comes back after a reload: Ctrl+Z takes the stroke back, GrabCut follows.
    steps = page.evaluate("window.labelPage.undoSteps")
    page.reload()
    page.wait_for_selector("#label-app[data-ready='1']")
    assert page.evaluate("window.labelPage.undoSteps") == steps >= 4
    page.keyboard.press("Control+z")
    page.wait_for_function(f"() => window.labelPage.instances()[0].area === {object_area}")
    page.keyboard.press("Control+Shift+z")
    page.wait_for_function(f"() => window.labelPage.instances()[0].area === {stroked}")
    settle(page)

    # Done: read-only, the view refitted under the banner; a stray drag and Ctrl+Z change nothing.
    page.click("#mark-done")
    page.wait_for_selector("#locked", state="visible")
    assert "Edit puts the frame back in progress" in page.locator("#locked").inner_text()
    assert image_inside_stage(page)
    header_fits(page)
    done = server_annotation(live_app, f0)
    assert done["status"] == "done"
    count = len(boxes)
    page.keyboard.press("b")
    drag(page, [(10, 10), (60, 60)])
    page.keyboard.press("Control+z")
    page.wait_for_function("() => document.querySelector('#message').textContent.includes('read-only')")
    assert len(boxes) == count and server_annotation(live_app, f0) == done
    screenshot(page, "workbench-5-done-read-only-1280")
    page.click("#edit")
    page.wait_for_selector("#locked", state="hidden")
    assert page.evaluate("window.labelPage.status") == "in_progress" and page.evaluate("window.labelPage.editable")

    # Someone else opening the frame is told; their "next unlabelled" skips what ann holds or has open.
    other_tab = context.new_page()
    open_frame(other_tab, live_server, f1)  # ann has f1 open too, with nothing saved
    bob = browser.new_context(viewport={"width": 1920, "height": 1080}).new_page()
    sign_in(bob, live_app, live_server, username="bob", role="annotator")
    open_frame(bob, live_server, f0)
    bob.wait_for_selector("#presence", state="visible")
    assert "ann has this frame in progress since" in bob.locator("#presence").inner_text()
    header_fits(bob)
    assert image_inside_stage(bob)
    screenshot(bob, "workbench-6-someone-else-1920")
    bob.keyboard.press("u")
    bob.wait_for_url(f"**/label/frames/{f2}")
    bob.context.close()
    context.close()


def test_a_reviewer_fixes_the_mask_then_accepts(live_app, live_server, browser):
    frame_id, *_ = dark_frames(live_app, n=1)
    with live_app.app_context():
        from app.services.users import create_user

        ann, _ = create_user("ann", "annotator", "browser-test-password")
        mask = np.zeros((H, W), bool)
        mask[70:150, 100:230] = True  # a mask short of the object's bottom 20 rows
        from tests.app.test_labelling import rle

        labelling.save_annotation(db.session.get(Frame, frame_id), ann, {
            "version": 0, "instances": [{"key": "a", "kind": "tactile", "label": "pan", "mask": rle(mask)}],
            "no_action_object": False, "status": "done", "time_spent_delta_s": 42.0})
    page = browser.new_context(viewport={"width": 1920, "height": 1080}).new_page()
    sign_in(page, live_app, live_server, username="rev", role="reviewer")
    page.goto(live_server + "/label/")
    page.click("#start-review")
    page.wait_for_selector("#label-app[data-ready='1']")
    assert not page.evaluate("window.labelPage.editable")
    page.keyboard.press("p")  # a drag pans; an editing tool says why not
    page.wait_for_function("() => document.querySelector('#message').textContent.includes('Fix the mask')")

    page.click("#fix")
    page.keyboard.press("p")
    page.keyboard.press("]")
    page.keyboard.press("]")
    before = area(page)
    drag(page, [(110, 160), (220, 160)])
    settle(page)
    assert area(page) > before
    fixed = server_annotation(live_app, frame_id)
    assert (fixed["status"], fixed["fixed_by"], fixed["instances"]) == ("done", "rev", 1)
    header_fits(page)
    screenshot(page, "workbench-7-reviewer-fixing-1920")
    page.click("#accept")
    page.wait_for_url("**/label/")
    assert server_annotation(live_app, frame_id)["status"] == "reviewed"
    page.context.close()

    # The author finds it accepted, read-only, and fixed by the reviewer.
    author = browser.new_context(viewport={"width": 1280, "height": 800}).new_page()
    sign_in(author, live_app, live_server, username="ann", role="annotator")
    open_frame(author, live_server, frame_id)
    locked = author.locator("#locked")
    locked.wait_for(state="visible")
    assert "Accepted by rev" in locked.inner_text() and "Edit withdraws the acceptance" in locked.inner_text()
    assert "Fixed in review by rev" in author.locator("#review-note").inner_text()
    author.keyboard.press("?")
    author.wait_for_selector("#help", state="visible")
    screenshot(author, "workbench-8-accepted-with-shortcuts-1280")
    author.keyboard.press("Escape")
    author.wait_for_selector("#help", state="hidden")
    author.context.close()
