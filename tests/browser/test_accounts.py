"""An admin manages accounts on the Users page; a user changes their own password."""

import pytest

from tests.browser.conftest import screenshot, sign_in

pytestmark = pytest.mark.browser


def test_an_admin_adds_a_user_who_then_changes_their_password(live_app, live_server, page, browser):
    failed = []
    page.on("response", lambda r: failed.append(f"{r.status} {r.url}") if r.status >= 400 else None)
    sign_in(page, live_app, live_server)
    page.get_by_role("navigation").get_by_role("link", name="Users").click()
    page.fill("#new-user input[name=username]", "mia")
    page.select_option("#new-user select[name=role]", "reviewer")
    page.click("#new-user button[type=submit]")
    password = page.locator("#new-password").inner_text().strip()
    assert len(password) >= 10
    screenshot(page, "accounts-created")

    other = browser.new_context()
    mia = other.new_page()
    mia.goto(live_server + "/login")
    mia.fill("input[name=username]", "mia")
    mia.fill("input[name=password]", password)
    mia.click("button[type=submit]")
    mia.get_by_role("link", name="mia").click()  # her name in the top bar
    mia.fill("input[name=current_password]", password)
    mia.fill("input[name=new_password]", "lantern meadow quartz")
    mia.fill("input[name=repeat]", "lantern meadow quartz")
    mia.click("main button[type=submit]")
    assert "Password changed" in mia.locator(".flash").inner_text()
    other.close()

    page.get_by_role("navigation").get_by_role("link", name="Users").click()
    row = page.locator('tr[data-user="mia"]')
    assert "reviewer" in row.locator("select").input_value()
    row.get_by_role("button", name="Deactivate").click()
    assert "deactivated" in page.locator('tr[data-user="mia"]').inner_text()
    screenshot(page, "accounts-list")
    assert failed == [], "requests of these pages that failed"
