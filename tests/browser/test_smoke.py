"""A person opens the app: activities, a frame grid, the frame viewer."""

import pytest

from app.services.demo import create_demo
from tests.browser.conftest import screenshot, sign_in

pytestmark = pytest.mark.browser

LOADED = "img => img.complete && img.naturalWidth > 0"


def test_grid_and_viewer_show_real_images(live_app, live_server, page):
    with live_app.app_context():
        create_demo(frames_per_activity=3, seed=1, width=160, height=120)

    failed = []
    page.on("response", lambda r: failed.append(f"{r.status} {r.url}") if r.status >= 400 else None)
    page.goto(live_server + "/")
    assert "/login" in page.url
    screenshot(page, "smoke-login")
    sign_in(page, live_app, live_server)
    assert page.locator(".activity-card").count() == 7
    screenshot(page, "smoke-index")

    page.get_by_role("link", name="cooking").first.click()
    page.wait_for_load_state("networkidle")
    tiles = page.locator(".frame-tile img")
    assert tiles.count() == 3
    for i in range(3):
        assert tiles.nth(i).evaluate(LOADED), f"thumbnail {i} did not load"
    # The quick start's demo leaves the last quarter of each activity to label: here 1 of 3.
    assert page.locator(".frame-tile .status-reviewed").count() == 2
    assert page.locator(".frame-tile").nth(2).locator(".status-todo").count() == 1
    assert page.inner_text(".labelling-progress .left-to-label") == "1 of 3 left to label"
    screenshot(page, "smoke-grid")

    tiles.first.click()
    page.wait_for_load_state("networkidle")
    for view in ("#view-rgb", "#view-depth", "#view-dhg"):
        assert page.locator(view).evaluate(LOADED), f"{view} did not load"
    assert page.locator(".meta").inner_text().count("cooking") >= 1
    screenshot(page, "smoke-viewer")

    first_url = page.url
    page.keyboard.press("ArrowRight")
    page.wait_for_function(f"() => location.href !== {first_url!r}")
    page.wait_for_load_state("networkidle")
    assert page.locator("#view-rgb").evaluate(LOADED)
    assert failed == [], "requests of these pages that failed"


def test_the_activity_page_says_how_many_are_left_and_leads_to_them(live_app, live_server, browser):
    with live_app.app_context():
        create_demo(frames_per_activity=8, seed=1, width=160, height=120)
    context = browser.new_context(viewport={"width": 1280, "height": 800})
    page = context.new_page()
    sign_in(page, live_app, live_server)
    cards = page.locator(".activity-card .left-to-label")
    assert cards.count() == 7 and set(cards.all_inner_texts()) == {"2 of 8 left to label"}
    screenshot(page, "demo-activities-left-to-label")

    page.get_by_role("link", name="dining").first.click()
    page.wait_for_load_state("networkidle")
    assert page.inner_text(".labelling-progress .left-to-label") == "2 of 8 left to label"
    bar = page.locator(".labelling-progress progress")
    assert bar.get_attribute("value") == "6" and bar.get_attribute("max") == "8"
    statuses = page.locator(".frame-tile .status").evaluate_all("badges => badges.map(b => b.className)")
    assert statuses == ["status status-reviewed"] * 6 + ["status status-todo"] * 2
    screenshot(page, "demo-activity-left-to-label")

    todo_ids = page.locator(".frame-tile").evaluate_all("tiles => tiles.slice(6).map(t => t.dataset.frameId)")
    page.click("#label-next")
    page.wait_for_selector("#label-app[data-ready='1']")
    assert page.url.endswith(f"/label/frames/{todo_ids[0]}")
    context.close()
