"""Participants who come back, in real Chromium: a reload does not restart the reaction time, and a withdrawn
participant is told they withdrew (not to continue in their first browser)."""

import pytest

from app.extensions import db
from app.models import Activity
from app.models.studies import Participant, Study
from app.services import studies
from app.services.demo import create_demo
from app.services.users import create_user
from tests.browser.conftest import screenshot, sign_in
from tests.browser.test_study import click_frame, wait_for_trial

pytestmark = pytest.mark.browser

PROLIFIC = "?PROLIFIC_PID=5f1e2d3c4b5a69788796a5b{n}&STUDY_ID=s1&SESSION_ID=visit{n}"


def open_study(live_app) -> tuple[int, str]:
    with live_app.app_context():
        create_demo(frames_per_activity=2, unlabelled_fraction=0, seed=2, width=320, height=240)
        activity = db.session.execute(db.select(Activity).filter_by(name="cooking")).scalar_one()
        study = studies.create_study(name="returns", activity_ids=[activity.id], frames_per_activity=2, seed=1,
                                     multiple_clicks=False, open_link={"cap": 10})  # fmt: skip
        return study.id, f"/s/o/{study.open_link_token}"


def arrive(browser, live_server, link: str, n: int):
    context = browser.new_context(viewport={"width": 1280, "height": 800})
    person = context.new_page()
    person.goto(live_server + link + PROLIFIC.format(n=n))
    person.click("#open-start button[type=submit]")
    person.click("#agree")
    person.click("#start")
    wait_for_trial(person, 1)
    return context, person


def test_a_reload_does_not_restart_the_reaction_time(live_app, live_server, browser, page):
    study_id, link = open_study(live_app)
    context, person = arrive(browser, live_server, link, 1)
    person.wait_for_timeout(1500)
    person.reload()
    wait_for_trial(person, 1)
    person.wait_for_timeout(300)
    click_frame(person, 0.5, 0.5)  # one click answers (single-click study)
    wait_for_trial(person, 2)
    with live_app.app_context():
        trial = db.session.execute(db.select(Study).filter_by(id=study_id)).scalar_one().participants[0].trials[0]
        server_ms = (trial.submitted_at - trial.shown_at).total_seconds() * 1000
        # The browser's clock goes on from the first showing: rt_ms is the server's time less the network's delays,
        # not the 300 ms since the reload.
        assert trial.rt_ms >= 1800 and server_ms - 1000 < trial.rt_ms <= server_ms + 50, (trial.rt_ms, server_ms)
        assert trial.clicks[0].rt_ms == pytest.approx(trial.rt_ms, abs=100)
        assert [e.kind.value for e in trial.events].count("reload") == 1
        hit = studies.cap_summary(db.session.get(Study, study_id)).hit
    context.close()
    # The results page: mean maps without pilots, and the region cap with how many trials hit it.
    sign_in(page, live_app, live_server)
    page.goto(f"{live_server}/studies/{study_id}/frames")
    text = page.inner_text("#region-cap")
    assert "Region cap: no region over 25 % of the frame." in text and f"{hit} of 1 answered trial had a click" in text
    screenshot(page, "study-results-cap")


def test_a_withdrawn_participant_who_returns_is_told_they_withdrew(live_app, live_server, browser):
    study_id, link = open_study(live_app)
    context, person = arrive(browser, live_server, link, 2)
    with live_app.app_context():
        participant = db.session.execute(db.select(Participant).filter_by(study_id=study_id, external_id="5f1e2d3c4b5a69788796a5b2")).scalar_one()
        staff, _ = create_user("staff", "admin")
        studies.withdraw(participant, by=staff)
    for browser_page in (person, browser.new_context().new_page()):  # the first browser, and another
        browser_page.goto(live_server + link + PROLIFIC.format(n=2))
        # The page shows no sign that the id takes part (whether an id takes part never leaks, issue 32.7):
        # its Start decides, and tells the participant they withdrew.
        assert browser_page.inner_text("#start-open") == "Start"
        with browser_page.expect_navigation():
            browser_page.click("#start-open")
        heading = browser_page.inner_text("h1")
        assert heading == "You have withdrawn from this study", heading
        assert "answers were deleted" in browser_page.inner_text("main")
        assert "first browser" not in browser_page.inner_text("main")
    screenshot(person, "study-withdrawn-returns")
    context.close()
