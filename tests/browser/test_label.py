"""Labelling in real Chromium: GrabCut box and stroke, autosave, failed saves
and stale CSRF tokens, reload, conflicts, review."""

import secrets
import time

import numpy as np
import pytest

from app.extensions import db
from app.models import Frame
from app.services.importing import FrameItem, add_frames
from app.services.users import find_user
from egonet import io
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


# Where image point (x, y) is in the window, once the view fits the stage as laid out now: a
# change in the page's layout (a tool's hint on one line instead of two) resizes the stage, and
# the view refits on the next frame (a ResizeObserver), moving the image by pixels. Until then
# (the canvas keeps the stage's old size) a point read would be off where the pointer lands.
SCREEN_POINT_JS = """([x, y]) => {
  const stage = document.querySelector("#stage"), canvas = document.querySelector("#canvas");
  const fitted = canvas.style.width === `${stage.clientWidth}px` && canvas.style.height === `${stage.clientHeight}px`;
  return fitted && window.labelPage.clientPoint(x, y);
}"""


def screen_point(page, x: float, y: float) -> dict:
    return page.wait_for_function(SCREEN_POINT_JS, arg=[x, y]).json_value()


def drag(page, points, *, steps: int = 6) -> None:
    """Press at the first image point, move through the others, release."""
    screen = [screen_point(page, *p) for p in points]
    page.mouse.move(screen[0]["x"], screen[0]["y"])
    page.mouse.down()
    for s in screen[1:]:
        page.mouse.move(s["x"], s["y"], steps=steps)
    page.mouse.up()


def click_points(page, points) -> None:
    """Click at each image point in turn (the polygon tool's corners)."""
    for x, y in points:
        p = screen_point(page, x, y)
        page.mouse.click(p["x"], p["y"])


def settle(page) -> None:
    """Wait until no GrabCut call runs and everything is saved."""
    page.wait_for_selector("#busy", state="hidden")
    page.wait_for_selector("#save-state[data-state='saved']", timeout=10_000)


def area(page) -> int:
    return page.evaluate("window.labelPage.instances()[0].area")


def saved_on_server(live_app, frame_id: int, username: str = "ann") -> tuple[int, int]:
    """(version, area of the first object) of the user's annotation, as the server answers them."""
    client = live_app.test_client()
    with live_app.app_context():
        client.login_as(find_user(username))
    annotation = client.get(f"/api/label/frames/{frame_id}/annotation").get_json()
    if not annotation["instances"]:
        return annotation["version"], 0
    with client.get(annotation["instances"][0]["mask_url"]) as png:
        assert png.status_code == 200
        return annotation["version"], int(io.decode_mask(png.data).sum())


# Keep every text the save indicator shows, to check none of them lied.
WATCH_SAVE_STATE = """() => {
  const el = document.querySelector("#save-state");
  window.saveTexts = [];
  new MutationObserver(() => window.saveTexts.push(el.textContent)).observe(el, { childList: true, characterData: true, subtree: true });
}"""


def wait_for_save_text(page, start: str, timeout: int = 10_000) -> str:
    page.wait_for_function("start => document.querySelector('#save-state').textContent.startsWith(start)", arg=start, timeout=timeout)
    return page.locator("#save-state").inner_text()


def test_a_box_with_no_object_in_it_says_so(live_app, live_server, page):
    frame_id, _ = object_frames(live_app)
    sign_in(page, live_app, live_server, username="ann", role="annotator")
    open_frame(page, live_server, frame_id)
    drag(page, [(5, 180), (95, 235)])  # plain background under the object
    page.wait_for_function("() => window.labelPage.instances().length === 1")
    page.wait_for_selector("#busy", state="hidden")
    assert area(page) == 0
    message = page.locator("#message")
    message.wait_for(state="visible")
    assert "found no object in this box" in message.inner_text()
    screenshot(page, "label-empty-box")


def test_a_grabcut_call_that_fails_says_why_in_words(live_app, live_server, page):
    frame_id, _ = object_frames(live_app)
    sign_in(page, live_app, live_server, username="ann", role="annotator")
    open_frame(page, live_server, frame_id)
    page.route("**/api/label/grabcut/box", lambda route: route.abort())
    drag(page, [(85, 55), (245, 185)])
    message = page.locator("#message")
    message.wait_for(state="visible")
    assert message.inner_text() == "GrabCut did not run: the server could not be reached"
    assert page.locator("#busy").is_hidden()


def test_box_and_stroke_are_saved_and_come_back_after_a_reload(live_app, live_server, page):
    frame_id, _ = object_frames(live_app)
    sign_in(page, live_app, live_server, username="ann", role="annotator")
    open_frame(page, live_server, frame_id)
    assert page.locator("#save-state").inner_text() == "All changes saved"

    drag(page, [(85, 55), (245, 185)])  # a box around the object (B is the default tool)
    page.wait_for_function("() => window.labelPage.instances().length === 1 && window.labelPage.instances()[0].area > 0")
    page.wait_for_selector("#busy", state="hidden")
    boxed = area(page)
    assert abs(boxed - 100 * 130) < 0.1 * 100 * 130

    page.keyboard.press("g")  # background brush through the middle of the object
    drag(page, [(110, 120), (220, 120)])
    page.wait_for_function(f"() => window.labelPage.instances()[0].area < {boxed}")
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
    page.wait_for_function(f"() => window.labelPage.instances()[0].area > {before}")
    page.wait_for_selector("#busy", state="hidden")
    page.keyboard.press("Control+z")
    page.wait_for_function(f"() => window.labelPage.instances()[0].area === {before}")
    page.keyboard.press("Control+Shift+z")
    page.wait_for_function(f"() => window.labelPage.instances()[0].area > {before}")
    settle(page)

    # Manual paint reaches the server within 2 s, with no other action.
    page.keyboard.press("p")
    painted = area(page)
    drag(page, [(20, 20), (40, 20)])
    start = time.monotonic()
    page.wait_for_function(f"() => window.labelPage.instances()[0].area > {painted}")
    settle(page)
    assert time.monotonic() - start < 2.5

    page.locator("#mark-done").click()
    page.wait_for_function("() => document.querySelector('#status-badge').textContent === 'done'")
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
    annotator.wait_for_function("() => window.labelPage.instances().length === 1 && window.labelPage.instances()[0].area > 0")
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


def test_a_failed_save_says_why_and_goes_through_once_the_server_answers(live_app, live_server, page):
    frame_id, _ = object_frames(live_app)
    page.set_viewport_size({"width": 1280, "height": 800})
    sign_in(page, live_app, live_server, username="ann", role="annotator")
    open_frame(page, live_server, frame_id)
    page.evaluate(WATCH_SAVE_STATE)
    answer = {"saves": "abort"}

    def saves(route):
        if route.request.method != "PUT":
            route.continue_()
        elif answer["saves"] == "abort":
            route.abort()
        else:
            route.fulfill(status=500, json={"error": "internal_server_error", "message": "boom", "fields": {}})

    page.route("**/api/label/frames/*/annotation", saves)
    page.keyboard.press("p")
    drag(page, [(20, 20), (60, 20)])
    text = wait_for_save_text(page, "Not saved: the server could not be reached; retrying in ")
    assert page.locator("#save-state").get_attribute("data-state") == "error"
    assert page.locator("#save-state").is_visible()
    screenshot(page, "label-not-saved-network")

    answer["saves"] = "500"
    text = wait_for_save_text(page, "Not saved: the server failed (HTTP 500); retrying in ")
    screenshot(page, "label-not-saved-500")
    assert saved_on_server(live_app, frame_id) == (0, 0)

    page.unroute("**/api/label/frames/*/annotation")
    wait_for_save_text(page, "All changes saved", timeout=15_000)
    texts = page.evaluate("window.saveTexts")
    assert texts.index("All changes saved") == len(texts) - 1, f"said saved before the server had it: {texts}"
    assert any(t.startswith("Not saved: the server could not be reached") for t in texts), texts
    assert saved_on_server(live_app, frame_id) == (page.evaluate("window.labelPage.version"), area(page))
    assert area(page) > 0 and page.evaluate("window.labelPage.version") == 1

    # Unsaved work holds the page: leaving asks first.
    page.route("**/api/label/frames/*/annotation", lambda route: route.abort() if route.request.method == "PUT" else route.continue_())
    drag(page, [(20, 40), (60, 40)])
    wait_for_save_text(page, "Not saved: ")
    with page.expect_event("dialog") as dialog:
        page.close(run_before_unload=True)
    assert dialog.value.type == "beforeunload"
    dialog.value.accept()


def test_a_stale_csrf_token_is_replaced_and_the_save_goes_through(live_app, live_server, page):
    frame_id, _ = object_frames(live_app)
    sign_in(page, live_app, live_server, username="ann", role="annotator")
    open_frame(page, live_server, frame_id)
    token_requests = []
    page.on("request", lambda r: r.url.endswith("/api/csrf-token") and token_requests.append(r.url))
    page.keyboard.press("p")

    # The page's token is garbage.
    page.evaluate("document.querySelector('meta[name=csrf-token]').content = 'garbage'")
    drag(page, [(20, 20), (60, 20)])
    settle(page)
    assert len(token_requests) == 1
    assert page.evaluate("document.querySelector('meta[name=csrf-token]').content") != "garbage"
    assert saved_on_server(live_app, frame_id) == (1, area(page))

    # The session's token changed under the page (as after signing out and in again in another tab).
    context = page.context
    cookie = next(c for c in context.cookies() if c["name"] == live_app.config["SESSION_COOKIE_NAME"])
    serializer = live_app.session_interface.get_signing_serializer(live_app)
    session = serializer.loads(cookie["value"])
    session["csrf_token"] = secrets.token_hex(20)
    context.add_cookies([{**cookie, "value": serializer.dumps(session)}])
    drag(page, [(20, 40), (60, 40)])
    settle(page)
    assert len(token_requests) == 2
    assert saved_on_server(live_app, frame_id) == (2, area(page))


def test_signed_out_in_another_tab_the_page_says_so_and_saves_once_signed_in_again(live_app, live_server, page):
    frame_id, _ = object_frames(live_app)
    page.set_viewport_size({"width": 1280, "height": 800})
    sign_in(page, live_app, live_server, username="ann", role="annotator")
    open_frame(page, live_server, frame_id)
    other = page.context.new_page()
    other.goto(live_server + "/")
    other.locator("form.whoami button[type=submit]").click()
    other.wait_for_url("**/login")

    page.keyboard.press("p")
    drag(page, [(20, 20), (60, 20)])
    wait_for_save_text(page, "Not saved: you are signed out — sign in again in another tab")
    screenshot(page, "label-not-saved-signed-out")

    sign_in(other, live_app, live_server, username="ann", role="annotator")
    wait_for_save_text(page, "All changes saved", timeout=15_000)
    assert saved_on_server(live_app, frame_id) == (1, area(page))
