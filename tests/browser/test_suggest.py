"""Proposals in real Chromium: Suggest (button and S), the proposal drawn and
listed with its source, Accept and Reject; without a trained run, a depth
proposal and the hint on how to train one.

The run's checkpoint has a stored map of the frame (as training leaves for
the frames it held out): a network-like blurred copy of the object, a few
pixels off, which the suggestion reuses (tests/app/test_suggest.py trains
a real one)."""

import numpy as np
import pytest

from app.extensions import db
from app.models import Annotation, Instance
from tests.app.test_suggest import held_bag, network_like, stored_run
from tests.browser.conftest import screenshot, sign_in
from tests.browser.test_label import H, OBJECT, W, object_frames, open_frame, settle

pytestmark = pytest.mark.browser


def truth() -> np.ndarray:
    mask = np.zeros((H, W), bool)
    mask[OBJECT] = True
    return mask


def instances_on_server(live_app, frame_id: int) -> list[Instance]:
    with live_app.app_context():
        annotation = db.session.execute(db.select(Annotation).filter_by(frame_id=frame_id)).scalar_one()
        return [(i.key, i.proposed_by_run_id) for i in annotation.instances]


def test_suggest_then_accept_one_and_reject_another(live_app, live_server, page):
    first, second = object_frames(live_app)
    with live_app.app_context():
        run_id = stored_run({f: network_like(truth(), shift=(6, -6)) for f in (first, second)}, name="tiny demo run")
    sign_in(page, live_app, live_server, username="ann", role="annotator")
    open_frame(page, live_server, first)
    assert page.locator("#suggest-source option").all_inner_texts() == [
        f"Auto (run {run_id})", "Depth: this frame has none", "Handled: the colour region nearest the centre",
        "Saliency: spectral residual saliency", f"Run {run_id}: tiny demo run"]
    assert page.locator("#suggest-hint").inner_text() == f"Auto uses run {run_id}: trained on real frames like this one."
    assert "Suggest: a trained run, or depth, proposes objects" in page.locator(".shortcuts").inner_text()

    page.click("#suggest")
    page.wait_for_selector("#instances .instance.proposed")
    settle(page)
    tag = page.locator("#instances .instance.proposed .proposal-tag")
    assert tag.inner_text() == f"proposed by run {run_id}"
    assert page.locator("#suggest-result").inner_text() == (
        f"Run {run_id}: trained on real frames like this one. It proposed 1 object: accept or reject it.")
    objects = page.evaluate("window.labelPage.instances()")
    assert len(objects) == 1 and objects[0]["hasEngine"]  # GrabCut strokes can correct it at once
    assert abs(objects[0]["area"] - truth().sum()) < 0.1 * truth().sum()
    screenshot(page, "suggest-proposed")

    page.click("#instances .accept-proposal")
    page.wait_for_selector("#instances .instance.proposed", state="detached")
    settle(page)
    assert instances_on_server(live_app, first) == [(objects[0]["key"], None)]
    screenshot(page, "suggest-accepted")

    # The shortcut on the next frame, then Reject: the object goes, and the save says so.
    open_frame(page, live_server, second)
    page.locator("#canvas").click(position={"x": 5, "y": 5})  # the keyboard goes to the page, not the select
    page.keyboard.press("s")
    page.wait_for_selector("#instances .instance.proposed")
    settle(page)
    page.click("#instances .reject-proposal")
    page.wait_for_function("() => window.labelPage.instances().length === 0")
    settle(page)
    assert instances_on_server(live_app, second) == []


def test_without_a_trained_run_suggest_proposes_from_depth(live_app, live_server, page):
    frame_id, bag = held_bag(live_app)
    sign_in(page, live_app, live_server, username="ann", role="annotator")
    open_frame(page, live_server, frame_id)
    assert page.locator("#suggest-source option").first.inner_text() == "Auto (depth)"
    assert page.locator("#suggest-hint").inner_text() == (
        "Auto uses depth: this frame has depth. "
        "Train one for shop: the Training page, or flask egonet train --activities shop")
    page.click("#suggest")
    page.wait_for_selector("#instances .instance.proposed")
    settle(page)
    assert page.locator("#instances .proposal-tag").inner_text() == "proposed by depth"
    assert page.locator("#suggest-result").inner_text() == "Depth: this frame has depth. It proposed 1 object: accept or reject it."
    (proposal,) = page.evaluate("window.labelPage.instances()")
    assert abs(proposal["area"] - bag.sum()) < 0.1 * bag.sum()  # the bag the hand holds
    screenshot(page, "suggest-depth")
    page.click("#instances .accept-proposal")
    page.wait_for_selector("#instances .instance.proposed", state="detached")
    with live_app.app_context():
        annotation = db.session.execute(db.select(Annotation).filter_by(frame_id=frame_id)).scalar_one()
        assert [(i.key, i.proposal_source) for i in annotation.instances] == [(proposal["key"], None)]


def test_the_suggest_control_says_before_the_click_what_can_work_and_claims_nothing(live_app, live_server, page):
    """An RGB-only frame and a finished run that reads DHG: the run is offered disabled with the reason, Auto is
    handled and says why; a Suggest that proposes nothing says so in words and leaves the frame unclaimed."""
    first, _ = object_frames(live_app)
    with live_app.app_context():
        run_id = stored_run({}, name="needs dhg")  # no stored map: it would have to predict, and it reads DHG
    sign_in(page, live_app, live_server, username="ann", role="annotator")
    open_frame(page, live_server, first)
    options = page.locator("#suggest-source option")
    assert options.all_inner_texts() == [
        "Auto (handled)", "Depth: this frame has none", "Handled: the colour region nearest the centre",
        "Saliency: spectral residual saliency", f"Run {run_id}: needs dhg — needs depth (DHG): this frame has none"]
    assert [options.nth(i).is_disabled() for i in range(5)] == [False, True, False, False, True]
    hint = page.locator("#suggest-hint").inner_text()
    assert hint.startswith("Auto uses handled: no depth here; it proposes object-sized colour regions near the centre.")
    assert "No trained run yet" not in hint

    page.click("#suggest")
    page.wait_for_selector("#suggest-result:not([hidden])")
    # The object (a red block of 20 % of the frame) is larger than handled's colour regions: nothing proposed,
    # said in words, and nothing claimed.
    assert page.locator("#suggest-result").inner_text() == (
        "Handled: no depth here; it proposes object-sized colour regions near the centre. It found no object to "
        "propose here; choose another source, or draw a box (B).")
    settle_page = page.locator("#status-badge")
    assert settle_page.inner_text().lower() == "todo"
    screenshot(page, "suggest-rgb-only-menu")
    with live_app.app_context():
        assert db.session.execute(db.select(Annotation).filter_by(frame_id=first)).scalar_one_or_none() is None
