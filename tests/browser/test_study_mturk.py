"""An MTurk ExternalQuestion HIT in real Chromium: preview, accept, the session in its own tab, the POST to externalSubmit.

A local server stands in for MTurk: it frames the ExternalURL copied from the
study page's ExternalQuestion as MTurk's HIT page does (the URL as given, with
MTurk's own parameters appended) and records what its ``/mturk/externalSubmit``
receives. The study lets that server in only through the test's ``MTURK_SUBMIT_HOSTS``.
"""

import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from urllib.parse import parse_qs, urlencode
from xml.etree import ElementTree

import pytest

from app.extensions import db
from app.models import Activity
from app.models.studies import EndReason, Study
from app.services import studies
from app.services.studies.recruiting import MTURK_SUBMIT_HOSTS
from app.services.demo import create_demo
from tests.app.test_studies_recruiting import mturk_calls
from tests.browser.conftest import screenshot, sign_in
from tests.browser.test_study import click_frame, wait_for_trial

pytestmark = pytest.mark.browser


class StandIn(BaseHTTPRequestHandler):
    """MTurk's part: ``/hit?src=URL`` frames the question; a POST to ``/mturk/externalSubmit`` is recorded."""

    received: list[dict[str, list[str]]] = []

    def do_GET(self):
        src = parse_qs(self.path.partition("?")[2])["src"][0]
        self._reply(f'<title>HIT</title><iframe id="question" src="{src}" width="900" height="700"></iframe>')

    def do_POST(self):
        body = self.rfile.read(int(self.headers["Content-Length"])).decode()
        self.received.append({"path": [self.path], **parse_qs(body)})
        self._reply("<p>MTurk: HIT submitted</p>")

    def _reply(self, html: str) -> None:
        data = html.encode()
        self.send_response(200)
        self.send_header("Content-Type", "text/html")
        self.send_header("Content-Length", str(len(data)))
        self.end_headers()
        self.wfile.write(data)

    def log_message(self, *args):
        pass


@pytest.fixture
def mturk():
    server = ThreadingHTTPServer(("127.0.0.1", 0), StandIn)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    StandIn.received.clear()
    yield f"http://127.0.0.1:{server.server_port}"
    server.shutdown()
    server.server_close()


def test_an_mturk_hit_from_preview_to_external_submit(live_app, live_server, browser, mturk):
    live_app.config["MTURK_SUBMIT_HOSTS"] = (*MTURK_SUBMIT_HOSTS, mturk)  # test configuration only
    with live_app.app_context():
        create_demo(frames_per_activity=1, unlabelled_fraction=0, seed=5, width=320, height=240)
        names = {a.name: a.id for a in db.session.execute(db.select(Activity)).scalars()}
        study = studies.create_study(name="hit", activity_ids=[names["cooking"], names["hotel"]], frames_per_activity=1,
                                     seed=2, multiple_clicks=False, open_link={}, completion={"code": "MTURK42"})  # fmt: skip
        study_id = study.id
    # The researcher copies the ExternalQuestion from the study page's Recruiting card.
    staff = browser.new_context()
    admin = staff.new_page()
    sign_in(admin, live_app, live_server)
    admin.goto(f"{live_server}/studies/{study_id}")
    question = ElementTree.fromstring(admin.input_value("#mturk-question"))
    ns = "{http://mechanicalturk.amazonaws.com/AWSMechanicalTurkDataSchemas/2006-07-14/ExternalQuestion.xsd}"
    link = question.find(f"{ns}ExternalURL").text
    assert link == admin.input_value("#open-link") and int(question.find(f"{ns}FrameHeight").text) > 0
    admin.locator("#recruiting").screenshot(path=str(screenshot(admin, "mturk-recruiting").with_name("mturk-recruiting-card.png")))
    staff.close()
    context = browser.new_context(viewport={"width": 1280, "height": 900})
    hit = context.new_page()

    # Preview: MTurk frames the question with ASSIGNMENT_ID_NOT_AVAILABLE. Instructions and an example, nobody admitted.
    preview = {"assignmentId": "ASSIGNMENT_ID_NOT_AVAILABLE", "hitId": "3HITPREVIEW", "turkSubmitTo": mturk}
    hit.goto(f"{mturk}/hit?" + urlencode({"src": mturk_calls(link, preview)}))
    question = hit.frame_locator("#question")
    assert "Accept the HIT" in question.locator("#open-start").inner_text()
    assert question.locator("#preview-instructions p").count() >= 1 and question.locator("#start-open").count() == 0
    hit.frame(url=lambda url: "/s/o/" in url).wait_for_function("() => document.getElementById('preview-example').naturalWidth > 0")
    screenshot(hit, "mturk-preview")
    with live_app.app_context():
        assert db.session.get(Study, study_id).participants == []

    # Accepted: MTurk frames it again with the worker's ids; the study opens in its own tab.
    accepted = {"assignmentId": "3ASSIGN", "hitId": "3HITPREVIEW", "turkSubmitTo": mturk, "workerId": "A3WORKER"}
    hit.goto(f"{mturk}/hit?" + urlencode({"src": mturk_calls(link, accepted)}))
    with context.expect_page() as opened:
        hit.frame_locator("#question").locator("#open-tab").click()
    tab = opened.value
    tab.wait_for_load_state()
    tab.click("#start-open")
    tab.click("#agree")
    tab.click("#start")
    for position in (1, 2):
        wait_for_trial(tab, position)
        click_frame(tab, 0.4, 0.5)
    tab.wait_for_url("**/s/done")
    assert tab.inner_text("#completion-code") == "MTURK42"
    screenshot(tab, "mturk-done")
    tab.wait_for_url(f"{mturk}/mturk/externalSubmit", timeout=10_000)  # posted by itself after 3 s
    assert "HIT submitted" in tab.inner_text("body")
    assert StandIn.received == [{"path": ["/mturk/externalSubmit"], "assignmentId": ["3ASSIGN"], "completion_code": ["MTURK42"]}]
    with live_app.app_context():
        (person,) = db.session.get(Study, study_id).participants
        assert (person.platform, person.external_id, person.end_reason) == ("mturk", "A3WORKER", EndReason.COMPLETED)

    # Review: a refusal was not frameable, so a worker saw a blocked frame. Now the frame says the study is full.
    with live_app.app_context():
        db.session.get(Study, study_id).cap = 1
        db.session.commit()
    late = {"workerId": "A4LATE", "assignmentId": "4ASSIGN", "hitId": "3HITPREVIEW", "turkSubmitTo": mturk}
    hit.goto(f"{mturk}/hit?" + urlencode({"src": f"{link}?{urlencode(late)}"}))
    assert "This study is full" in hit.frame_locator("#question").locator("h1").inner_text()
    screenshot(hit, "mturk-full")
    context.close()
