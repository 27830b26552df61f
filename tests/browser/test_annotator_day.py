"""An annotator's whole day on the real RGB-D frames, then a reviewer's and an
export's, as one walk in Chromium (issue 26).

ann, before any run is trained, accepts the chair that depth proposes on
rgbd-primesense 00000 and takes the suggestion back, labels the chair
herself (a box with depth, an object and a background stroke, a polygon),
undoes twice, reloads, redoes, propagates to 00001, accepts a model's
proposal of the cabinet there and marks it done; rev opens the review queue from the navigation bar, fixes
the chair and accepts; the COCO export (with images) holds exactly the masks
the review page showed. The run "trained" for the proposal is a stored one
(tests/app/test_suggest.py): its checkpoint's map of 00001 is reused, no
model is trained. Screenshots of every step go to the test's tmp folder.
"""

import io as bytes_io
import itertools
import json
import re
import zipfile

import numpy as np
import pytest
from pycocotools.coco import COCO

from app.extensions import db
from app.models import Frame
from app.services import exchange
from app.services.importing import import_path
from egonet import io
from tests.app.test_suggest import network_like, stored_run
from tests.browser.conftest import sign_in
from tests.browser.test_label import click_points, drag, open_frame, settle
from tests.browser.test_label_depth import iou, mask_of
from tests.browser.test_label_workbench import COLOURS, edge_point, server_annotation, wait_for_colour
from tests.browser.test_propagate import wait_for_frame
from tests.realdata import BACKREST, PRIMESENSE, chair_truth
from tests.realdata import CHAIR_BOX as BOX

pytestmark = [pytest.mark.browser, pytest.mark.skipif(not PRIMESENSE.exists(), reason="shared data not present")]

CABINET = (slice(212, 350), slice(602, 640))  # the wooden cabinet at the right edge of 00001
FG_STROKE = [(392, 300), (392, 360)]  # down the chair's left leg
BG_STROKE = [(505, 125), (560, 125)]  # the wall above the right armrest, inside the box
FOOT = [(336, 350), (362, 360), (380, 372), (376, 384), (354, 372), (332, 358)]  # the left foot, as a polygon
RAW_STATUS = re.compile(r"\b[45]\d\d\b|Bad Request|Conflict|Forbidden")


def wait_for_area(page, k: int, mask: np.ndarray) -> None:
    page.wait_for_function(f"() => window.labelPage.instances()[{k}]?.area === {int(mask.sum())}")
    settle(page)
    assert (mask_of(page, k) == mask).all()


def said_in_words(page, words: str) -> None:
    """Wait for the page's message to say ``words``; it must not be a bare HTTP status."""
    page.wait_for_function("s => document.querySelector('#message').textContent.includes(s)", arg=words)
    text = page.locator("#message").inner_text()
    assert not RAW_STATUS.search(text), text


@pytest.mark.filterwarnings("ignore:__array__ implementation:DeprecationWarning")  # pycocotools predates numpy 2
def test_an_annotators_day_then_review_and_export(live_app, live_server, browser, tmp_path):
    with live_app.app_context():
        import_path(PRIMESENSE, activity="room")
        f0, f1, _ = db.session.execute(db.select(Frame.id).order_by(Frame.index)).scalars()
    shots = itertools.count(1)

    def shot(page, name: str) -> None:
        page.screenshot(path=tmp_path / f"{next(shots):02d}-{name}.png")

    context = browser.new_context(viewport={"width": 1280, "height": 800})
    page = context.new_page()
    boxes = []
    page.on("request", lambda r: boxes.append(json.loads(r.post_data)) if r.url.endswith("/grabcut/box") else None)
    sign_in(page, live_app, live_server, username="ann", role="annotator")
    open_frame(page, live_server, f0)

    # Morning: "Mark done" on the untouched frame asks. No run is trained yet: Suggest proposes the
    # chair from depth, tagged with its source; accepted, then the suggestion taken back (Ctrl+Z).
    page.click("#mark-done")
    page.wait_for_selector("#confirm-empty[open]")
    shot(page, "untouched-mark-done-asks")
    page.click("#confirm-keep")
    page.wait_for_selector("#confirm-empty", state="hidden")
    assert server_annotation(live_app, f0) == {"version": 0}
    assert page.locator("#suggest-hint").inner_text().startswith("Auto uses depth: this frame has depth.")
    page.click("#suggest")
    page.wait_for_selector("#instances .instance.proposed")
    settle(page)
    assert page.locator("#instances .proposal-tag").inner_text() == "proposed by depth"
    # Measured 0.42: the seat and the arms; the back, further and higher, scores under the threshold here
    # (on 00001 it joins them: 0.86, bench/bench_suggest.py).
    assert iou(mask_of(page, 0), chair_truth()) > 0.3
    shot(page, "suggest-depth-without-a-run")
    page.click("#instances .accept-proposal")
    page.wait_for_selector("#instances .instance.proposed", state="detached")
    settle(page)
    assert server_annotation(live_app, f0)["instances"] == 1
    page.keyboard.press("Control+z")
    page.wait_for_function("() => window.labelPage.instances().length === 0")
    settle(page)
    page.wait_for_function("() => window.labelPage.undoSteps === 0")

    # A box with depth: the white backrest before the white wall comes in.
    drag(page, BOX)
    page.wait_for_function("() => window.labelPage.instances().length === 1 && window.labelPage.instances()[0].hasEngine")
    settle(page)
    boxed = mask_of(page, 0)
    assert boxes[0]["use_depth"] is True and boxed[BACKREST[1], BACKREST[0]] and iou(boxed, chair_truth()) > 0.6
    shot(page, "box-with-depth")

    # An object stroke and a background stroke (hard constraints), then the polygon fixes the foot.
    states = [boxed]
    for key, stroke, inside in (("f", FG_STROKE, True), ("g", BG_STROKE, False)):
        page.keyboard.press(key)
        drag(page, stroke)
        page.wait_for_function(f"() => window.labelPage.undoSteps === {len(states) + 1}")
        settle(page)
        states.append(mask_of(page, 0))
        assert all(states[-1][y, x] == inside for x, y in stroke), key
    page.keyboard.press("l")
    click_points(page, FOOT + FOOT[:1])
    page.wait_for_function("() => window.labelPage.undoSteps === 4")
    settle(page)
    states.append(mask_of(page, 0))
    assert states[3][370, 360] and states[3].sum() > states[2].sum()
    shot(page, "strokes-and-polygon")

    # Undo twice, reload: the history is still there, and redo brings both steps back.
    for _ in range(2):
        page.keyboard.press("Control+z")
    wait_for_area(page, 0, states[1])
    page.reload()
    page.wait_for_selector("#label-app[data-ready='1']")
    assert page.evaluate("window.labelPage.undoSteps") == 2
    wait_for_area(page, 0, states[1])
    page.keyboard.press("Control+Shift+z")
    wait_for_area(page, 0, states[2])
    page.keyboard.press("Control+Shift+z")
    wait_for_area(page, 0, states[3])
    shot(page, "redone-after-reload")

    # Propagate: 00001 opens with the chair carried there (and still the chair).
    with live_app.app_context():
        cabinet = np.zeros(states[0].shape, bool)
        cabinet[CABINET] = True
        run_id = stored_run({f1: network_like(cabinet)}, name="room run", activities=("room",))  # trained on real frames: Auto's
    page.click("#propagate-next")
    wait_for_frame(page, live_server, f1)
    carried = mask_of(page, 0)
    assert page.evaluate("window.labelPage.instances().length") == 1 and iou(carried, chair_truth()) > 0.6
    shot(page, "propagated")

    # Someone else opening 00001 is told ann has it in progress.
    bob = browser.new_context(viewport={"width": 1280, "height": 800}).new_page()
    sign_in(bob, live_app, live_server, username="bob", role="annotator")
    open_frame(bob, live_server, f1)
    bob.wait_for_selector("#presence", state="visible")
    assert "ann has this frame in progress since" in bob.locator("#presence").inner_text()
    shot(bob, "bob-sees-ann-in-progress")
    bob.context.close()

    # A proposal of the cabinet, accepted; both objects outlined in their colours.
    page.click("#suggest")
    page.wait_for_selector("#instances .instance.proposed")
    settle(page)
    assert page.locator("#instances .proposal-tag").inner_text() == f"proposed by run {run_id}"
    shot(page, "proposal")
    page.click("#instances .accept-proposal")
    page.wait_for_selector("#instances .instance.proposed", state="detached")
    settle(page)
    assert iou(mask_of(page, 1), cabinet) > 0.7
    for k in (0, 1):
        wait_for_colour(page, *edge_point(page, k), COLOURS[k])  # object k + 1 outlined in its own colour

    # Done: read-only; a stray box and Ctrl+Z change nothing.
    page.click("#mark-done")
    page.wait_for_selector("#locked", state="visible")
    done = server_annotation(live_app, f1)
    assert (done["status"], done["instances"]) == ("done", 2)
    count = len(boxes)
    page.keyboard.press("b")
    drag(page, [(40, 40), (200, 200)])
    page.keyboard.press("Control+z")
    said_in_words(page, "read-only")
    assert len(boxes) == count and server_annotation(live_app, f1) == done
    shot(page, "done-read-only")
    context.close()

    # The reviewer: the Label link in the navigation bar, the queue's Fix, an erased stray, Accept.
    rev = browser.new_context(viewport={"width": 1280, "height": 800}).new_page()
    sign_in(rev, live_app, live_server, username="rev", role="reviewer")
    rev.locator("header.topbar nav a", has_text="Label").click()
    rev.wait_for_selector("#review-queue .queue-tile")
    assert rev.locator("#review-queue .queue-tile").count() == 1 and "2 objects" in rev.inner_text("#review-queue")
    rev.wait_for_function("() => document.querySelector('#review-queue .mask-thumb').complete")
    shot(rev, "review-queue")
    rev.locator("#review-queue .fix-link").click()
    rev.wait_for_selector("#label-app[data-ready='1']")
    rev.wait_for_selector("#fixing:not([hidden])")
    before = mask_of(rev, 0)
    rev.keyboard.press("1")
    rev.keyboard.press("e")
    drag(rev, [(515, 322), (575, 322)])  # the wall seen through the right armrest's loop is no chair
    rev.wait_for_function(f"() => window.labelPage.instances()[0].area < {int(before.sum())}")
    settle(rev)
    assert iou(mask_of(rev, 0), chair_truth()) > iou(before, chair_truth())
    assert server_annotation(live_app, f1)["fixed_by"] == "rev"
    shown = [mask_of(rev, k) for k in (0, 1)]
    api = rev.evaluate("async () => (await fetch(JSON.parse(document.querySelector('#label-config').textContent).urls.annotation)).json()")
    served = [io.decode_mask(rev.request.get(live_server + i["mask_url"]).body()).astype(bool) for i in api["instances"]]
    assert len(served) == 2 and all((a == b).all() for a, b in zip(shown, served))
    shot(rev, "reviewer-fixed")
    rev.click("#accept")
    rev.wait_for_url("**/label/")
    assert server_annotation(live_app, f1)["status"] == "reviewed"

    # Export COCO with the images through the Label page's form; the worker builds it.
    rev.select_option("#export-form select[name=format]", "coco")
    rev.check("#export-form input[name=images]")
    rev.click("#export-submit")
    rev.wait_for_selector("#export-job[data-status='queued']")
    with live_app.app_context():
        exchange.build_export(int(rev.url.rsplit("/", 1)[1]))
    rev.wait_for_selector("#export-job[data-status='done']")
    assert rev.inner_text("nav a.active") == "Label"  # an export is the Label area's page
    shot(rev, "export-done")
    with rev.expect_download() as info:
        rev.click("#export-download")
    archive = zipfile.ZipFile(bytes_io.BytesIO(info.value.path().read_bytes()))
    archive.extractall(tmp_path / "export")
    coco = COCO(str(tmp_path / "export" / "annotations.json"))
    (image,) = coco.dataset["images"]
    assert (tmp_path / "export" / "images" / image["file_name"]).is_file()
    exported = coco.loadAnns(coco.getAnnIds(imgIds=image["id"]))
    assert [a["attributes"]["status"] for a in exported] == ["reviewed", "reviewed"]
    assert all((coco.annToMask(a).astype(bool) == m).all() for a, m in zip(exported, shown))
    rev.context.close()
