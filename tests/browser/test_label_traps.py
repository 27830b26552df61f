"""The labelling workflow's traps (issue 36, part 4), each in real Chromium:
strokes on a mask GrabCut never made, "Mark done" clicked twice, an export
with images on one machine with no worker command, a GrabCut step the server
refuses, a drag inside the selected object's box, and the page's words."""

import pytest

from app.extensions import db
from app.models import Annotation, Frame
from app.services import labelling
from app.services.users import create_user, find_user
from tests.app.test_labelling import rle
from tests.browser.conftest import screenshot, sign_in
from tests.browser.test_label import WATCH_SAVE_STATE, area, drag, open_frame, settle
from tests.browser.test_label_workbench import H, OBJECT, W, dark_frames, wait_for_pixel

pytestmark = pytest.mark.browser


def instances(page) -> list[dict]:
    return page.evaluate("window.labelPage.instances()")


def test_a_stroke_corrects_a_mask_painted_by_hand_and_stays_in_sight(live_app, live_server, page):
    f0, *_ = dark_frames(live_app)
    sign_in(page, live_app, live_server, username="ann", role="annotator")
    open_frame(page, live_server, f0)
    strokes = []
    page.on("request", lambda r: strokes.append(r.post_data_json) if r.url.endswith("/grabcut/stroke") else None)
    # Painted by hand over the red object and the green around it (no box: GrabCut has no session).
    page.keyboard.press("p")
    for _ in range(4):
        page.keyboard.press("]")
    for y in range(80, 170, 12):
        drag(page, [(95, y), (250, y)])
    settle(page)
    painted = area(page)
    assert not instances(page)[0]["hasEngine"] and painted > 0
    before = wait_for_pixel(page, 240, 120, "true", None)

    # A background stroke down the green strip right of the object: GrabCut starts from the painted mask.
    page.keyboard.press("g")
    drag(page, [(240, 85), (240, 160)])
    settle(page)
    assert strokes[-1]["start"] is not None and strokes[-1]["start"]["size"] == [H, W]
    after = instances(page)[0]
    assert after["hasEngine"] and after["area"] < painted
    assert "painted by hand" not in page.locator("#message").inner_text()
    mask = labelling.decode_rle(page.evaluate("window.labelPage.maskRle(0)"), (H, W), field="mask")
    assert not mask[85:160, 236:244].any() and mask[OBJECT].mean() > 0.9
    # The stroke stays on the canvas, faintly red, where the mask no longer is.
    wait_for_pixel(page, 240, 120, "px[0] > value[0] + 20 && px[1] < value[1] + 10", before)
    screenshot(page, "traps-1-stroke-on-a-painted-mask")
    # A second stroke continues the session: no mask sent again.
    drag(page, [(96, 165), (96, 100)])
    settle(page)
    assert "start" not in strokes[-1] and len(strokes) == 2


def test_a_reviewer_corrects_someone_elses_mask_with_a_stroke(live_app, live_server, page):
    frame_id, *_ = dark_frames(live_app, n=1)
    with live_app.app_context():
        ann, _ = create_user("ann", "annotator", "browser-test-password")
        mask = labelling.empty_mask(db.session.get(Frame, frame_id))
        mask[70:170, 100:250] = True  # the object and 20 columns of green right of it
        done = labelling.save_annotation(db.session.get(Frame, frame_id), ann, {
            "version": 0, "instances": [{"key": "a", "kind": None, "label": None, "mask": rle(mask)}],
            "no_action_object": False, "status": "done", "time_spent_delta_s": 0.0}).id
    sign_in(page, live_app, live_server, username="rev", role="reviewer")
    page.goto(f"{live_server}/label/annotations/{done}/review")
    page.wait_for_selector("#label-app[data-ready='1']")
    page.click("#fix")
    page.keyboard.press("g")
    before = area(page)
    drag(page, [(240, 80), (240, 160)])  # background, through the green the author took in
    settle(page)
    fixed = labelling.decode_rle(page.evaluate("window.labelPage.maskRle(0)"), (H, W), field="mask")
    assert area(page) < before and not fixed[80:160, 236:244].any() and fixed[OBJECT].mean() > 0.9
    with live_app.app_context():
        saved = db.session.get(Annotation, done)
        assert saved.fixed_by.username == "rev" and saved.status.value == "done"


def box_the_object(page) -> None:
    """A box around the frame's object, cut and saved."""
    drag(page, [(85, 55), (245, 185)])
    page.wait_for_function("() => window.labelPage.instances()[0]?.area > 0")
    settle(page)


def test_mark_done_clicked_twice_marks_the_frame_done_once(live_app, live_server, page):
    f0, *_ = dark_frames(live_app)
    sign_in(page, live_app, live_server, username="ann", role="annotator")
    open_frame(page, live_server, f0)
    box_the_object(page)
    saves = []
    page.on("request", lambda r: saves.append(r.post_data_json) if r.method == "PUT" and r.url.endswith("/annotation") else None)
    page.dblclick("#mark-done")
    page.wait_for_selector("#locked", state="visible")
    settle(page)
    assert page.evaluate("window.labelPage.status") == "done"
    assert "elsewhere" not in page.locator("#message").inner_text()
    assert [s["status"] for s in saves] == ["done"]
    assert page.is_enabled("#edit")


@pytest.mark.parametrize("live_app", [{"QUEUE_IN_PROCESS": True}], indirect=True)
def test_an_export_with_images_finishes_with_no_worker_command(live_app, live_server, page):
    """The quick start's setup (SQLite queue in the instance folder): the app runs the queue itself."""
    f0, f1, _ = dark_frames(live_app)
    with live_app.app_context():
        ann, _ = create_user("ann", "annotator", "browser-test-password")
        mask = labelling.empty_mask(db.session.get(Frame, f0))
        mask[OBJECT] = True
        for frame_id in (f0, f1):
            labelling.save_annotation(db.session.get(Frame, frame_id), ann, {
                "version": 0, "instances": [{"key": "a", "kind": None, "label": None, "mask": rle(mask)}],
                "no_action_object": False, "status": "done", "time_spent_delta_s": 0.0})
    sign_in(page, live_app, live_server, username="boss", role="admin")
    page.goto(live_server + "/label/")
    page.check("input[name=status][value=done]")
    page.check("input[name=images]")
    page.click("#export-submit")
    page.wait_for_selector("#export-job")
    assert "(2 frames) is queued" in page.locator("p.flash").first.inner_text()
    page.wait_for_selector("#export-job[data-status='done']", timeout=30_000)
    assert page.is_visible("#export-download") and page.locator("#no-worker").count() == 0
    assert page.inner_text("#export-text").startswith("2 of 2 frames: 2 annotations, 2 action-objects")
    screenshot(page, "traps-2-export-done-without-a-worker")


def test_a_refused_box_says_why_and_leaves_nothing_behind(live_app, live_server, page):
    f0, *_ = dark_frames(live_app)
    sign_in(page, live_app, live_server, username="ann", role="annotator")
    open_frame(page, live_server, f0)
    page.evaluate(WATCH_SAVE_STATE)
    drag(page, [(-4, -4), (W + 4, H + 4)])  # the whole frame
    page.wait_for_function("() => document.querySelector('#message').textContent.includes('covers the whole frame')")
    page.wait_for_selector("#busy", state="hidden")
    assert page.locator("#message").inner_text() == (
        "GrabCut did not run: the box covers the whole frame; leave some background around the object")
    assert instances(page) == [] and page.evaluate("window.labelPage.dropped") is None
    assert page.locator("#save-state").get_attribute("data-state") != "error" and page.is_hidden("#retry-op")
    screenshot(page, "traps-3-refused-box")
    # An object already there stays selected and whole.
    box_the_object(page)
    whole = instances(page)
    drag(page, [(-4, -4), (W + 4, H + 4)])
    page.wait_for_function("() => document.querySelector('#message').textContent.includes('covers the whole frame')")
    page.wait_for_selector("#busy", state="hidden")
    assert instances(page) == whole and page.evaluate("window.labelPage.selected") == whole[0]["key"]


def test_a_drag_inside_the_selected_box_draws_a_new_object(live_app, live_server, page):
    f0, *_ = dark_frames(live_app)
    sign_in(page, live_app, live_server, username="ann", role="annotator")
    open_frame(page, live_server, f0)
    box_the_object(page)
    first = instances(page)[0]
    drag(page, [(120, 90), (200, 150)])  # inside the selected object's box, away from its edges
    page.wait_for_function("() => window.labelPage.instances().length === 2")
    settle(page)
    now = instances(page)
    assert now[0] == first  # neither moved nor emptied
    assert now[1]["box"] == [120, 90, 200, 150] or abs(now[1]["box"][0] - 120) <= 1
    assert page.evaluate("window.labelPage.selected") == now[1]["key"]


def test_the_page_speaks_in_words_and_disables_what_cannot_work(live_app, live_server, browser):
    f0, f1, f2 = dark_frames(live_app)
    page = browser.new_context(viewport={"width": 1280, "height": 800}).new_page()
    sign_in(page, live_app, live_server, username="ann", role="annotator")
    open_frame(page, live_server, f0)
    # The first frame: nothing to copy from, nothing drawn to propagate.
    assert page.is_disabled("#copy-previous") and page.is_disabled("#propagate-next")
    assert "first frame" in page.get_attribute("#copy-previous", "title")
    assert "draw an object first" in page.get_attribute("#propagate-next", "title")
    page.keyboard.press("Shift+ArrowRight")
    page.wait_for_function("() => document.querySelector('#message').textContent.includes('draw an object first')")
    drag(page, [(85, 55), (245, 185)])
    page.wait_for_function("() => !document.querySelector('#propagate-next').disabled")
    assert "Carry your objects" in page.get_attribute("#propagate-next", "title")
    settle(page)
    assert page.is_disabled("#copy-previous")  # still, after the saves that set the editing controls
    # The last frame: nothing to propagate to.
    open_frame(page, live_server, f2)
    assert page.is_disabled("#propagate-next") and page.is_enabled("#copy-previous")
    assert "last frame" in page.get_attribute("#propagate-next", "title")
    # "Go to frame" a number the sequence does not have: said in words, no field name.
    page.fill("#jump-to", "999")
    page.press("#jump-to", "Enter")
    page.wait_for_function("() => document.querySelector('#message').textContent.includes('no frame 999')")
    assert page.locator("#message").inner_text() == "the sequence has no frame 999"
    page.context.close()

    # A reviewer deciding on an annotation someone else accepted already: no "(status: is reviewed)".
    with live_app.app_context():
        ann = find_user("ann")
        mask = labelling.empty_mask(db.session.get(Frame, f1))
        mask[OBJECT] = True
        done = labelling.save_annotation(db.session.get(Frame, f1), ann, {
            "version": 0, "instances": [{"key": "a", "kind": None, "label": None, "mask": rle(mask)}],
            "no_action_object": False, "status": "done", "time_spent_delta_s": 0.0})
        other, _ = create_user("rev2", "reviewer", "browser-test-password")
        labelling.review_annotation(done, other, version=done.version, decision="accept", comment=None)
        annotation_id = done.id
    page = browser.new_context(viewport={"width": 1280, "height": 800}).new_page()
    sign_in(page, live_app, live_server, username="rev", role="reviewer")
    page.goto(f"{live_server}/label/annotations/{annotation_id}/review")
    page.wait_for_selector("#label-app[data-ready='1']")
    page.click("#accept")
    page.wait_for_function("() => document.querySelector('#message').textContent.includes('accepted already')")
    text = page.locator("#message").inner_text()
    assert text == "only done annotations can be reviewed; this one was accepted already", text
    screenshot(page, "traps-4-review-words")
    page.context.close()
