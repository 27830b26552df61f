"""Labelling in real Chromium: GrabCut box and stroke, autosave, reload, conflicts, review."""

import time

import numpy as np
import pytest

from app.extensions import db
from app.models import Frame
from app.services.importing import FrameItem, add_frames
from tests.browser.conftest import screenshot, sign_in

pytestmark = pytest.mark.browser

H, W = 240, 320
OBJECT = (slice(70, 170), slice(100, 230))  # rows, columns of the red object


def object_frames(live_app, n: int = 2) -> list[int]:
    rng = np.random.default_rng(5)
    items = []
    for i in range(n):
        image = (rng.integers(0, 30, (H, W, 3)) + [40, 130, 50]).astype(np.uint8)
        image[OBJECT] = (rng.integers(0, 30, (100, 130, 3)) + [190, 40, 40]).astype(np.uint8)
        items.append(FrameItem(f"frame-{i}", i, f"test {i}", rgb=image))
    with live_app.app_context():
        add_frames(activity="kitchen", sequence="s1", items=items)
        return list(db.session.execute(db.select(Frame.id).order_by(Frame.index)).scalars())


def open_frame(page, base_url: str, frame_id: int) -> None:
    page.goto(f"{base_url}/label/frames/{frame_id}")
    page.wait_for_selector("#label-app[data-ready='1']")


def drag(page, points, *, steps: int = 6) -> None:
    """Press at the first image point, move through the others, release."""
    screen = [page.evaluate("([x, y]) => window.labelPage.clientPoint(x, y)", list(p)) for p in points]
    page.mouse.move(screen[0]["x"], screen[0]["y"])
    page.mouse.down()
    for s in screen[1:]:
        page.mouse.move(s["x"], s["y"], steps=steps)
    page.mouse.up()


def settle(page) -> None:
    """Wait until no GrabCut call runs and everything is saved."""
    page.wait_for_selector("#busy", state="hidden")
    page.wait_for_selector("#save-state[data-state='saved']", timeout=10_000)


def area(page) -> int:
    return page.evaluate("window.labelPage.instances()[0].area")


def test_a_box_with_no_object_in_it_says_so(live_app, live_server, page):
    frame_id, _ = object_frames(live_app)
    sign_in(page, live_app, live_server, username="ann", role="annotator")
    open_frame(page, live_server, frame_id)
    drag(page, [(5, 180), (95, 235)])  # plain background under the object
    page.wait_for_function("window.labelPage.instances().length === 1")
    page.wait_for_selector("#busy", state="hidden")
    assert area(page) == 0
    message = page.locator("#message")
    message.wait_for(state="visible")
    assert "found no object in this box" in message.inner_text()
    screenshot(page, "label-empty-box")


def test_box_and_stroke_are_saved_and_come_back_after_a_reload(live_app, live_server, page):
    frame_id, _ = object_frames(live_app)
    sign_in(page, live_app, live_server, username="ann", role="annotator")
    open_frame(page, live_server, frame_id)
    assert page.locator("#save-state").inner_text() == "All changes saved"

    drag(page, [(85, 55), (245, 185)])  # a box around the object (B is the default tool)
    page.wait_for_function("window.labelPage.instances().length === 1 && window.labelPage.instances()[0].area > 0")
    page.wait_for_selector("#busy", state="hidden")
    boxed = area(page)
    assert abs(boxed - 100 * 130) < 0.1 * 100 * 130

    page.keyboard.press("g")  # background brush through the middle of the object
    drag(page, [(110, 120), (220, 120)])
    page.wait_for_function(f"window.labelPage.instances()[0].area < {boxed}")
    changed = time.monotonic()
    settle(page)
    assert time.monotonic() - changed < 2.5, "autosave took longer than 2 s"
    saved_rle = page.evaluate("window.labelPage.maskRle(0)")
    saved_version = page.evaluate("window.labelPage.version")
    assert saved_version >= 1
    screenshot(page, "label-box-and-stroke")

    page.reload()
    page.wait_for_selector("#label-app[data-ready='1']")
    assert page.evaluate("window.labelPage.maskRle(0)") == saved_rle
    assert page.evaluate("window.labelPage.version") == saved_version
    assert page.evaluate("window.labelPage.instances()[0].hasEngine"), "the GrabCut session did not come back"
    assert page.locator("#status-badge").text_content() == "in progress"

    # The restored session takes further strokes; undo and redo go through the server too.
    page.keyboard.press("f")
    before = area(page)
    drag(page, [(150, 115), (160, 125)])
    page.wait_for_function(f"window.labelPage.instances()[0].area > {before}")
    page.wait_for_selector("#busy", state="hidden")
    page.keyboard.press("Control+z")
    page.wait_for_function(f"window.labelPage.instances()[0].area === {before}")
    page.keyboard.press("Control+Shift+z")
    page.wait_for_function(f"window.labelPage.instances()[0].area > {before}")
    settle(page)

    # Manual paint reaches the server within 2 s, with no other action.
    page.keyboard.press("p")
    painted = area(page)
    drag(page, [(20, 20), (40, 20)])
    start = time.monotonic()
    page.wait_for_function(f"window.labelPage.instances()[0].area > {painted}")
    settle(page)
    assert time.monotonic() - start < 2.5

    page.locator("#mark-done").click()
    page.wait_for_function("document.querySelector('#status-badge').textContent === 'done'")
    settle(page)
    screenshot(page, "label-done")


def test_a_conflicting_save_shows_a_banner_and_keeps_local_work(live_app, live_server, browser):
    frame_id, _ = object_frames(live_app)
    pages = []
    for _ in range(2):
        context = browser.new_context(viewport={"width": 1280, "height": 860})
        pages.append(context.new_page())
    first, second = pages
    sign_in(first, live_app, live_server, username="ann", role="annotator")
    sign_in(second, live_app, live_server, username="ann", role="annotator")
    open_frame(first, live_server, frame_id)
    open_frame(second, live_server, frame_id)

    first.keyboard.press("p")
    drag(first, [(30, 30), (60, 30)])
    settle(first)
    second.keyboard.press("p")
    drag(second, [(200, 200), (260, 200)])
    second.wait_for_selector("#conflict", state="visible")
    assert second.locator("#save-state").get_attribute("data-state") == "conflict"
    assert "version 1" in second.locator("#conflict").inner_text()
    screenshot(second, "label-conflict")
    mine = second.evaluate("window.labelPage.maskRle(0)")

    second.locator("#reload-theirs").click()
    second.wait_for_selector("#conflict", state="hidden")
    theirs = first.evaluate("window.labelPage.maskRle(0)")
    assert second.evaluate("window.labelPage.maskRle(0)") == theirs
    second.keyboard.press("Control+z")  # my version is one undo away
    second.wait_for_function("rle => JSON.stringify(window.labelPage.maskRle(0)) === JSON.stringify(rle)", arg=mine)
    settle(second)
    assert second.evaluate("window.labelPage.version") == 2
    for p in pages:
        p.context.close()


def test_a_reviewer_rejects_and_the_annotator_sees_the_comment(live_app, live_server, browser):
    frame_id, _ = object_frames(live_app)
    annotator = browser.new_context(viewport={"width": 1280, "height": 860}).new_page()
    sign_in(annotator, live_app, live_server, username="ann", role="annotator")
    open_frame(annotator, live_server, frame_id)
    drag(annotator, [(85, 55), (245, 185)])
    annotator.wait_for_function("window.labelPage.instances().length === 1 && window.labelPage.instances()[0].area > 0")
    annotator.locator("#done-next").click()
    annotator.wait_for_url(f"**/label/frames/{frame_id + 1}")

    reviewer = browser.new_context(viewport={"width": 1280, "height": 860}).new_page()
    sign_in(reviewer, live_app, live_server, username="rev", role="reviewer")
    reviewer.goto(live_server + "/label/")
    reviewer.locator("#start-review").click()
    reviewer.wait_for_selector("#label-app[data-ready='1']")
    assert reviewer.evaluate("window.labelPage.instances()[0].area") > 0
    screenshot(reviewer, "label-review")
    reviewer.fill("#review-comment", "Follow the rim more closely.")
    reviewer.locator("#reject").click()
    reviewer.wait_for_url("**/label/")

    annotator.goto(live_server + "/label/")
    assert "Follow the rim more closely." in annotator.locator(".queue").inner_text()
    open_frame(annotator, live_server, frame_id)
    assert "Follow the rim more closely." in annotator.locator("#review-note").inner_text()
    assert annotator.locator("#status-badge").text_content() == "rejected"
    screenshot(annotator, "label-rejected")
    annotator.context.close()
    reviewer.context.close()
