"""The project's class list in real Chromium: an admin fills it, the label field completes from it."""

import pytest

from tests.browser.conftest import screenshot, sign_in
from tests.browser.test_label import drag, object_frames, open_frame, saved_on_server, settle

pytestmark = pytest.mark.browser


def test_an_admin_fills_the_list_and_the_label_field_completes_from_it(live_app, live_server, browser):
    frame_id, _ = object_frames(live_app)
    admin = browser.new_context(viewport={"width": 1280, "height": 900}).new_page()
    sign_in(admin, live_app, live_server)
    admin.goto(live_server + "/label/")
    admin.click("#classes-link")
    admin.fill("textarea[name=names]", "cutting board\ncup, knife")
    admin.click("#add-classes button[type=submit]")
    assert admin.locator("#classes tbody tr").evaluate_all("rows => rows.map(r => r.dataset.class)") == [
        "cup", "cutting board", "knife"]
    screenshot(admin, "object-classes")

    page = browser.new_context(viewport={"width": 1280, "height": 900}).new_page()
    sign_in(page, live_app, live_server, username="ann", role="annotator")
    open_frame(page, live_server, frame_id)
    drag(page, [(85, 55), (245, 185)])  # a box around the object: one instance, with its label field
    page.wait_for_function("() => window.labelPage.instances().length === 1")
    field = page.locator("#instances .label").first
    offered = field.evaluate("input => [...input.list.options].map(o => o.value)")  # null list: not bound
    assert offered == ["cup", "cutting board", "knife", "hand"]
    # Chromium's completion pop-up is drawn outside the page (Playwright cannot click it): the browser
    # has bound the field to the list (input.list above); choosing a name types it, as here.
    field.fill("cutting board")
    field.press("Tab")
    settle(page)
    screenshot(page, "label-class-completed")
    with live_app.app_context():
        client = live_app.test_client()
        from app.services.users import find_user

        client.login_as(find_user("ann"))
    saved = client.get(f"/api/label/frames/{frame_id}/annotation").get_json()
    assert [i["label"] for i in saved["instances"]] == ["cutting board"]
    assert saved_on_server(live_app, frame_id)[1] > 0
