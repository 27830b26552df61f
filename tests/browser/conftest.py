"""A live server and Debian's Chromium driven by Playwright.

The server is the real WSGI app served by Werkzeug in a background thread,
on a migrated SQLite database in a temporary folder. Chromium comes from
Debian (``apt-get install -y chromium``); Playwright's own browser download
cannot work offline. ``find_chromium`` says where it is; without Chromium
these tests skip, unless ``EGONET_REQUIRE_BROWSER=1`` (set by .ci/run) makes
that a failure.

Every browser context (the ``page`` fixture's and those a test opens with
``browser.new_context``) records Content Security Policy violations, and a
test with any fails: the app's pages must run with no inline script or style.
Give ``wait_for_function`` a function (``"() => ..."``): Playwright runs a bare
expression through ``eval`` in the page, which that policy refuses.
"""

import os
import shutil
import threading
from pathlib import Path

import pytest
from flask_migrate import upgrade
from werkzeug.serving import make_server

from app.extensions import db
from tests.app.conftest import demo_frames_rendered_once, make_app  # noqa: F401 (autouse here too)

CHROMIUM_ARGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--disable-dev-shm-usage",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]
ARTIFACTS = Path(__file__).resolve().parents[2] / "test-results"

# Runs in every document before its own scripts (not subject to the page's CSP).
REPORT_CSP_VIOLATIONS = """
document.addEventListener("securitypolicyviolation", (event) => {
  window.reportCspViolation(`${event.effectiveDirective} blocked ${event.blockedURI || "inline"}`
    + ` on ${location.pathname} (${event.sourceFile || "page"}:${event.lineNumber})`);
}, true);
"""
csp_violations: list[str] = []


def watch_csp(context) -> None:
    """Record the CSP violations of every page in ``context`` (the DOM event and the console's report)."""

    def on_violation(text: str) -> None:
        csp_violations.append(text)

    def on_console(message) -> None:
        if "Content Security Policy" in message.text:
            csp_violations.append(message.text)

    context.expose_function("reportCspViolation", on_violation)
    context.add_init_script(REPORT_CSP_VIOLATIONS)
    context.on("console", on_console)


@pytest.fixture(autouse=True)
def no_csp_violations():
    csp_violations.clear()
    yield
    assert not csp_violations, "Content Security Policy violations:\n" + "\n".join(csp_violations)


@pytest.fixture(scope="session")
def migrated_sqlite(tmp_path_factory) -> Path:
    """An empty SQLite database, migrated once a session: each live app starts on a copy."""
    folder = tmp_path_factory.mktemp("migrated")
    app = make_app(f"sqlite:///{folder / 'live.sqlite3'}", folder)
    with app.app_context():
        upgrade()
        db.engine.dispose()
    return folder / "live.sqlite3"


@pytest.fixture
def live_app(request, tmp_path, migrated_sqlite):
    """The app on a copy of the migrated database; settings of a test's own come by
    ``@pytest.mark.parametrize("live_app", [{"NAME": value}], indirect=True)``."""
    shutil.copyfile(migrated_sqlite, tmp_path / "live.sqlite3")
    app = make_app(f"sqlite:///{tmp_path / 'live.sqlite3'}", tmp_path, **getattr(request, "param", {}))
    yield app
    app.extensions["egonet.queue"].stop_consumer()  # the in-process one, when a test turned it on


@pytest.fixture
def live_server(live_app):
    """Serve ``live_app`` on a free loopback port; yield its base URL."""
    server = make_server("127.0.0.1", 0, live_app, threaded=True)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    yield f"http://127.0.0.1:{server.server_port}"
    server.shutdown()
    thread.join(timeout=5)
    server.server_close()


def find_chromium(environ=os.environ) -> str:
    """Chromium's path: ``$PLAYWRIGHT_CHROMIUM`` or ``$CHROMIUM`` (a path or a
    command) when set, else ``chromium`` or ``chromium-browser`` on ``PATH``.

    Without one it skips the test with one line naming the install command,
    or fails it when ``EGONET_REQUIRE_BROWSER=1``.
    """
    named = environ.get("PLAYWRIGHT_CHROMIUM") or environ.get("CHROMIUM")
    for command in [named] if named else ["chromium", "chromium-browser"]:
        if found := shutil.which(command, path=environ.get("PATH", os.defpath)):
            return found
    where = repr(named) if named else "chromium or chromium-browser on PATH"
    problem = f"no Chromium ({where}); install it: apt-get install -y chromium"
    if environ.get("EGONET_REQUIRE_BROWSER") == "1":
        pytest.fail(problem + " (EGONET_REQUIRE_BROWSER=1)", pytrace=False)
    pytest.skip(problem)


@pytest.fixture(scope="session")
def browser():
    chromium = find_chromium()
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=chromium, headless=True, args=CHROMIUM_ARGS)
        new_context = browser.new_context

        def new_watched_context(**options):
            context = new_context(**options)
            watch_csp(context)
            return context

        browser.new_context = new_watched_context
        yield browser
        browser.close()


@pytest.fixture
def page(browser):
    context = browser.new_context(viewport={"width": 1280, "height": 900})
    page = context.new_page()
    yield page
    context.close()


PASSWORD = "browser-test-password"


def sign_in(page, live_app, base_url: str, *, username: str = "admin", role: str = "admin") -> None:
    """Create a staff user and sign in through the real log-in form."""
    from app.services.users import create_user, find_user

    with live_app.app_context():
        if find_user(username) is None:
            create_user(username, role, PASSWORD)
    page.goto(base_url + "/login")
    page.fill("input[name=username]", username)
    page.fill("input[name=password]", PASSWORD)
    page.click("button[type=submit]")
    page.wait_for_selector("form.whoami")  # the page after signing in names the user (no 500 ms of network silence)


def screenshot(page, name: str) -> Path:
    """Save a full-page screenshot under test-results/ for a person to look at."""
    ARTIFACTS.mkdir(exist_ok=True)
    path = ARTIFACTS / f"{name}.png"
    page.screenshot(path=str(path), full_page=True)
    return path
