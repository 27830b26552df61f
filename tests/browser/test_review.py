"""The Label page in Chromium: the review queue shows each frame's mask over its thumbnail (with a Fix
link), and the export form says when nothing matches instead of downloading an empty zip."""

import io as bytes_io
import zipfile

import numpy as np
import pytest

from app.extensions import db
from app.models import Frame
from app.services import exchange, labelling
from app.services.importing import FrameItem, add_frames
from app.services.users import create_user
from tests.browser.conftest import screenshot, sign_in
from tests.browser.test_viewer import body

pytestmark = pytest.mark.browser

H, W = 240, 320
BOXES = [[(slice(60, 160), slice(40, 140))], [(slice(30, 90), slice(20, 120)), (slice(120, 220), slice(170, 300))]]


def done_frames(live_app) -> list[int]:
    """Three frames with a coloured object each; ann has finished the first two (one and two objects)."""
    rng = np.random.default_rng(11)
    items = []
    for i in range(3):
        rgb = (rng.integers(0, 30, (H, W, 3)) + [50, 110, 60]).astype(np.uint8)
        rgb[60:160, 40:140] = [200, 60, 40]
        items.append(FrameItem(f"frame-{i}", i, f"test {i}", rgb=rgb))
    with live_app.app_context():
        add_frames(activity="kitchen", sequence="s1", items=items)
        frames = db.session.execute(db.select(Frame).order_by(Frame.index)).scalars().all()
        ann, _ = create_user("ann", "annotator", "ann-password-123")
        for frame, boxes in zip(frames, BOXES):
            labelling.save_annotation(frame, ann, body(boxes, ["tactile"] + [None] * (len(boxes) - 1), "done"))
        return [f.id for f in frames]


def test_review_queue_thumbnails_and_the_export_form(live_app, live_server, browser):
    frame_ids = done_frames(live_app)
    context = browser.new_context(viewport={"width": 1280, "height": 800})
    page = context.new_page()
    failed = []
    page.on("response", lambda r: failed.append(f"{r.status} {r.url}") if r.status >= 400 else None)
    sign_in(page, live_app, live_server)
    page.goto(f"{live_server}/label/")
    page.wait_for_load_state("networkidle")

    tiles = page.locator("#review-queue .queue-tile")
    assert tiles.count() == 2
    for i, boxes in enumerate(BOXES):
        tile = tiles.nth(i)
        frame_img, mask_img = tile.locator(".thumb-stack img").nth(0), tile.locator(".mask-thumb")
        assert mask_img.evaluate("img => img.complete && img.naturalWidth === 240 && img.naturalHeight === 180")
        assert frame_img.bounding_box() == mask_img.bounding_box()  # the mask lies exactly over its frame
        assert f"{len(boxes)} object" in tile.inner_text()
        assert tile.locator(".fix-link").get_attribute("href").endswith("/review#fix")
        # The object's outline shows in the first instance colour where the object is.
        colour = mask_img.evaluate("""img => {
          const c = document.createElement("canvas"); c.width = 240; c.height = 180;
          const ctx = c.getContext("2d"); ctx.drawImage(img, 0, 0);
          const [r0, c0] = %s;
          return Array.from(ctx.getImageData(Math.round(c0 * 0.75), Math.round(r0 * 0.75) + 10, 1, 1).data);
        }""" % str([boxes[0][0].start, boxes[0][1].start]))
        assert colour == list(labelling.instance_colour(0)) + [255]
    tiles.first.locator(".thumb-stack").hover()
    page.wait_for_function("() => getComputedStyle(document.querySelector('#review-queue .mask-thumb')).opacity === '0'")
    page.mouse.move(5, 5)
    screenshot(page, "review-queue-1280x800")

    # Nothing matches: a message in the export card, the choices kept, no download.
    downloads = []
    page.on("download", lambda download: downloads.append(download))
    form = page.locator("#export-form")
    for status in ("done", "reviewed"):
        form.locator(f"input[name=status][value={status}]").uncheck()
    form.locator("input[name=status][value=rejected]").check()
    form.locator("input[name=annotator][value=ann]").check()
    form.locator("#export-submit").click()
    page.wait_for_selector("#export-message")
    assert page.inner_text("#export-message") == ("Nothing to export: no annotation is rejected by ann "
                                                  "(there are 2 done: choose those statuses).")
    assert page.is_checked("input[name=status][value=rejected]") and page.is_checked("input[name=annotator][value=ann]")
    assert page.locator("p.flash").count() == 1  # in the card only
    assert page.locator("#export-message").is_visible() and page.evaluate("location.hash") == "#export"
    screenshot(page, "export-nothing-1280x800")
    page.set_viewport_size({"width": 1920, "height": 1080})
    screenshot(page, "export-nothing-1920x1080")
    assert downloads == []

    # What matches downloads at once.
    page.check("input[name=status][value=done]")
    with page.expect_download() as info:
        page.click("#export-submit")
    archive = zipfile.ZipFile(bytes_io.BytesIO(info.value.path().read_bytes()))
    assert {"annotations.json", "masks/kitchen/s1/frame-0.png", "annotators/ann/kitchen/s1/frame-1.png"} <= set(
        archive.namelist())

    # With images, the worker builds it: the export's page follows its progress and then offers the zip.
    page.check("input[name=images]")
    page.click("#export-submit")
    page.wait_for_selector("#export-job[data-status='queued']")
    assert page.is_visible("#export-waiting") and not page.is_visible("#export-download")
    export_id = int(page.url.rsplit("/", 1)[1])
    with live_app.app_context():
        exchange.build_export(export_id)  # what `flask egonet worker` runs
    page.wait_for_selector("#export-job[data-status='done']", timeout=10_000)
    assert page.is_visible("#export-download") and not page.is_visible("#export-waiting")
    assert page.inner_text("#export-text").startswith("2 of 2 frames: 2 annotations, 3 action-objects")
    screenshot(page, "export-done-1920x1080")
    with page.expect_download() as info:
        page.click("#export-download")
    names = zipfile.ZipFile(bytes_io.BytesIO(info.value.path().read_bytes())).namelist()
    assert "images/kitchen/s1/frame-0.png" in names

    page.goto(f"{live_server}/label/")
    assert page.locator("#recent-exports tbody tr").count() == 1
    screenshot(page, "review-queue-1920x1080")
    assert failed == []

    # Fix opens the review page with the tools on.
    page.locator("#review-queue .fix-link").first.click()
    page.wait_for_selector("#fixing:not([hidden])")
    assert page.is_hidden("#fix")
    screenshot(page, "review-fix-1920x1080")
    context.close()
