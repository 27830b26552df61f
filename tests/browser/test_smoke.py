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
    assert page.locator(".frame-tile .status-reviewed").count() == 3
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
