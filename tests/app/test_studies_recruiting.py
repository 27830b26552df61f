"""Recruiting online: the open link with its cap and quotas, platforms' ids, conditions, bulk codes, status."""

import csv
import html
import io
import re
import threading
from collections import Counter
from urllib.parse import urlencode, urlsplit
from xml.etree import ElementTree

import pytest

from app.extensions import db
from app.models.studies import ActivityOrder, EndReason, EntryKind, FrameKind, Participant, Study
from app.services import studies
from tests.app.access.studies import build_study

PROLIFIC = {"PROLIFIC_PID": "5f1e2d3c4b5a69788796a5b4", "STUDY_ID": "64aa00bb11cc", "SESSION_ID": "sess_01"}


def open_study(app, tmp_path, **options) -> tuple[int, str]:
    """A study of 4 frames with an open link; returns (study id, token)."""
    with app.app_context():
        options.setdefault("open_link", {})
        ids = build_study(tmp_path, frames=2, per_activity=2, participants=0, **options)
        study = db.session.get(Study, ids["study"])
        return study.id, study.open_link_token


def arrive(app, token: str, **params):
    """A newcomer in their own browser: the open link's page, then its Start (with the platform's parameters)."""
    client = app.test_client()
    page = client.get(f"/s/o/{token}", query_string=params)
    start = client.post(f"/s/o/{token}", data=params) if page.status_code == 200 else None
    return client, page, start


def without_token(page: bytes) -> bytes:
    """A page without its session's CSRF token (the rest compares between browsers)."""
    return re.sub(rb'(csrf-token" content="|name="csrf_token" value=")[^"]+', rb"\1", page)


def participants_of(app, study_id: int) -> list[tuple]:
    with app.app_context():
        study = db.session.get(Study, study_id)
        return [(p.number, p.entry, p.external_id, p.condition.name if p.condition else None) for p in study.participants]


def test_open_link_admits_up_to_the_cap_and_then_says_full(app, tmp_path):
    study_id, token = open_study(app, tmp_path, open_link={"cap": 2})
    first, page, start = arrive(app, token)
    assert page.status_code == 200 and b"Take part in a study" in page.data and b"4 photos" in page.data
    assert start.status_code == 302 and start.headers["Location"].endswith("/s/consent")
    assert first.post("/s/consent", data={"decision": "agree"}).headers["Location"].endswith("/s/instructions")
    _, _, second = arrive(app, token)
    assert second.status_code == 302
    # The third newcomer is told before consenting; nothing is made for them.
    _, full, _ = arrive(app, token)
    assert full.status_code == 409 and b"This study is full" in full.data and b"consent" not in full.data.lower()
    assert len(participants_of(app, study_id)) == 2
    # Declining frees the place.
    declined = app.test_client()
    with app.app_context():
        declined.login_as(db.session.get(Study, study_id).participants[1].user)
    declined.post("/s/consent", data={"decision": "decline"})
    _, page, third = arrive(app, token)
    assert page.status_code == 200 and third.status_code == 302
    assert [entry for _, entry, _, _ in participants_of(app, study_id)] == [EntryKind.OPEN] * 3

    # Paused: newcomers wait; closed: the link says so; those already in carry on.
    with app.app_context():
        studies.set_status(db.session.get(Study, study_id), "paused")
        studies.set_active(db.session.get(Study, study_id).participants[2], False)  # a place, but the study is paused
    _, paused, _ = arrive(app, token)
    assert paused.status_code == 409 and b"This study is paused" in paused.data
    with app.app_context():
        studies.set_status(db.session.get(Study, study_id), "closed")
    _, closed, _ = arrive(app, token)
    assert closed.status_code == 410 and b"This study is closed" in closed.data
    assert first.get("/s/instructions").status_code == 200  # already in: goes on
    assert app.test_client().get("/s/o/not-a-token").status_code == 404


def test_codes_and_links_of_a_closed_or_paused_study_say_so(app, tmp_path):
    with app.app_context():
        ids = build_study(tmp_path, participants=2, entry=EntryKind.LINK)
        study = db.session.get(Study, ids["study"])
        first, second = study.participants
        code, token, second_id = first.code, second.link_token, second.id
        studies.set_status(study, "closed")
    client = app.test_client()
    refused = client.post("/s/", data={"code": code})
    assert refused.status_code == 410 and b"This study is closed" in refused.data
    assert client.post(f"/s/l/{token}").status_code == 410
    with app.app_context():
        assert db.session.get(Participant, second_id).link_used_at is None  # not used up by the refusal
        studies.set_status(db.session.get(Study, ids["study"]), "paused")
    assert client.post("/s/", data={"code": code}).status_code == 409
    with app.app_context():
        studies.set_status(db.session.get(Study, ids["study"]), "open")
    assert client.post("/s/", data={"code": code}).headers["Location"].endswith("/s/consent")


def test_prolific_and_mturk_parameters_are_stored_and_the_same_id_resumes(app, tmp_path):
    study_id, token = open_study(app, tmp_path)
    client, page, start = arrive(app, token, **PROLIFIC, other="ignored")
    assert start.status_code == 302
    assert f'value="{PROLIFIC["PROLIFIC_PID"]}"'.encode() in page.data  # carried to the Start button
    with app.app_context():
        person = db.session.get(Study, study_id).participants[0]
        assert (person.platform, person.external_id) == ("prolific", PROLIFIC["PROLIFIC_PID"])
        assert person.external == {"STUDY_ID": "64aa00bb11cc", "SESSION_ID": "sess_01"} and "Werkzeug" in person.user_agent
        first_id = person.id
    client.post("/s/consent", data={"decision": "agree"})
    # The same id again, in another browser: the same participant, where they stopped.
    again, page, resumed = arrive(app, token, **PROLIFIC)
    assert b"Welcome back" in page.data and resumed.headers["Location"].endswith("/s/instructions")
    assert again.get("/s/api/current", headers={"Accept": "application/json"}).get_json()["step"] == "instructions"
    assert [external for _, _, external, _ in participants_of(app, study_id)] == [PROLIFIC["PROLIFIC_PID"]]
    with app.app_context():
        assert db.session.get(Study, study_id).participants[0].id == first_id

    _, _, mturk = arrive(app, token, workerId="A1B2C3D4E5F6G7", assignmentId="3XYZ", hitId="3HIT")
    assert mturk.status_code == 302
    _, _, generic = arrive(app, token, external_id="lab-017")
    with app.app_context():
        people = db.session.get(Study, study_id).participants
        assert [(p.platform, p.external_id, p.external) for p in people[1:]] == [
            ("mturk", "A1B2C3D4E5F6G7", {"assignmentId": "3XYZ", "hitId": "3HIT"}),
            ("external", "lab-017", {}),
        ]
    # An MTurk preview shows the study but admits nobody; bad ids are refused, naming the parameter.
    _, preview, _ = arrive(app, token, workerId="A9", assignmentId="ASSIGNMENT_ID_NOT_AVAILABLE")
    assert b"Accept the HIT" in preview.data and b"start-open" not in preview.data
    # The platforms' own formats: Prolific ids are 24 hexadecimal digits, MTurk worker ids an A and capitals or digits.
    made_up = ({"PROLIFIC_PID": "x" * 24}, {"PROLIFIC_PID": "5f1e2d3c4b5a69788796a5b"}, {"workerId": "W9"}, {"workerId": "a1b2"})
    for bad in ({"PROLIFIC_PID": "<script>"}, {"PROLIFIC_PID": "x" * 65}, {"workerId": "a b"}, {"SESSION_ID": "é"}, *made_up):
        response = app.test_client().get(f"/s/o/{token}", query_string=bad, headers={"Accept": "application/json"})
        assert response.status_code == 400 and next(iter(bad)) in response.get_json()["fields"], bad
        assert app.test_client().post(f"/s/o/{token}", data=bad).status_code == 400
    assert len(participants_of(app, study_id)) == 3


def test_a_platform_id_alone_does_not_resume_a_session(app, admin_client, tmp_path):
    """A worker id is no credential: the first browser, the platform's same visit id, or staff's release resumes."""
    study_id, token = open_study(app, tmp_path)
    worker = {"workerId": "A1WORKER", "hitId": "3HIT"}
    first, _, start = arrive(app, token, **worker, assignmentId="ASG1")
    assert start.status_code == 302 and first.post("/s/consent", data={"decision": "agree"}).status_code == 302
    thief, page, taken = arrive(app, token, **worker)  # the id alone, or with another assignment, in a fresh browser
    # Its GET answers as to a newcomer (who takes part does not show); only the Start is refused.
    stranger = app.test_client().get(f"/s/o/{token}", query_string={"workerId": "A1STRANGER", "hitId": "3HIT"})
    assert page.status_code == stranger.status_code == 200 and without_token(page.data).replace(b"A1WORKER", b"A1STRANGER") == without_token(stranger.data)
    assert taken.status_code == 409 and b"continue in your first browser" in taken.data
    assert thief.post(f"/s/o/{token}", data={**worker, "assignmentId": "ASG9"}).status_code == 409
    assert thief.get("/s/api/current", headers={"Accept": "application/json"}).status_code == 401
    _, _, same_visit = arrive(app, token, **worker, assignmentId="ASG1")  # the same assignment, a new browser
    assert same_visit.headers["Location"].endswith("/s/instructions")
    assert arrive(app, token, **worker, assignmentId="ASG2")[2].status_code == 409
    again = first.post(f"/s/o/{token}", data={**worker, "assignmentId": "ASG2"})  # returned the HIT, took another
    assert again.headers["Location"].endswith("/s/instructions")
    with app.app_context():
        (person,) = db.session.get(Study, study_id).participants
        assert person.external == {"assignmentId": "ASG2", "hitId": "3HIT"}

    # Someone took a worker's id before the worker came: staff release it to the worker's browser.
    early, _, _ = arrive(app, token, workerId="A2", assignmentId="X")
    real, _, refused = arrive(app, token, workerId="A2", assignmentId="Y")
    assert refused.status_code == 409
    with app.app_context():
        taken_id = studies.by_external_id(db.session.get(Study, study_id), "A2").id
    assert b"Release to a new browser" in admin_client.get(f"/studies/{study_id}").data
    assert admin_client.post(f"/studies/{study_id}/participants/{taken_id}/release").status_code == 302
    assert real.post(f"/s/o/{token}", data={"workerId": "A2", "assignmentId": "Y"}).headers["Location"].endswith("/s/consent")
    assert early.get("/s/api/current", headers={"Accept": "application/json"}).status_code == 401  # signed out
    assert early.post(f"/s/o/{token}", data={"workerId": "A2", "assignmentId": "X"}).status_code == 409
    with app.app_context():
        assert db.session.get(Participant, taken_id).external == {"assignmentId": "Y"}


def test_an_mturk_hit_previews_without_admitting_and_submits_to_mturk_only(app, tmp_path):
    study_id, token = open_study(app, tmp_path, completion={"code": "MT0001"})
    preview = {"assignmentId": "ASSIGNMENT_ID_NOT_AVAILABLE", "hitId": "3HIT", "turkSubmitTo": "https://workersandbox.mturk.com"}
    browser = app.test_client()
    page = browser.get(f"/s/o/{token}", query_string=preview, headers={"Sec-Fetch-Dest": "iframe"})
    assert page.status_code == 200 and b'id="preview-instructions"' in page.data and b"start-open" not in page.data
    policy = page.headers["Content-Security-Policy"]
    assert "frame-ancestors https://workersandbox.mturk.com https://www.mturk.com" in policy and "frame-ancestors 'none'" not in policy
    with browser.get(f"/s/o/{token}/example") as example:
        assert example.status_code == 200 and example.mimetype.startswith("image/")
    assert participants_of(app, study_id) == []  # nobody admitted, no clock started
    for host in ("https://evil.example", "https://www.mturk.com.evil.example", "javascript:alert(1)"):
        bad = browser.get(f"/s/o/{token}", query_string={**preview, "turkSubmitTo": host}, headers={"Accept": "application/json"})
        assert bad.status_code == 400 and "turkSubmitTo" in bad.get_json()["fields"]
    accepted = {"workerId": "A2W", "assignmentId": "3ASG", "hitId": "3HIT", "turkSubmitTo": "https://www.mturk.com"}
    framed = browser.get(f"/s/o/{token}", query_string=accepted, headers={"Sec-Fetch-Dest": "iframe"})
    assert b'id="open-tab"' in framed.data and b'target="_blank"' in framed.data  # the session runs in its own tab
    assert browser.post(f"/s/o/{token}", data=accepted).status_code == 302
    with app.app_context():
        person = db.session.get(Study, study_id).participants[0]
        assert studies.mturk_submit_url(person) == "https://www.mturk.com/mturk/externalSubmit"
        person.completion_code, person.end_reason, person.finished_at = "MT0001", EndReason.COMPLETED, studies.now()
        db.session.commit()
    done = browser.get("/s/done")
    assert b'action="https://www.mturk.com/mturk/externalSubmit"' in done.data and b'value="3ASG"' in done.data
    assert "form-action 'self' https://www.mturk.com/mturk/externalSubmit" in done.headers["Content-Security-Policy"]


def test_quotas_per_condition_and_balanced_assignment(app, tmp_path):
    conditions = [{"name": "fast", "trial_limit_seconds": 5}, {"name": "slow", "trial_limit_seconds": 20}]
    study_id, token = open_study(app, tmp_path, conditions=conditions, open_link={"quotas": {"fast": 1, "slow": 2}})
    for _ in range(3):
        assert arrive(app, token)[2].status_code == 302
    _, full, _ = arrive(app, token)
    assert full.status_code == 409 and b"full" in full.data
    assert [c for *_, c in participants_of(app, study_id)] == ["fast", "slow", "slow"]
    with app.app_context():
        people = db.session.get(Study, study_id).participants
        assert [studies.settings_of(p).trial_limit_s for p in people] == [5, 20, 20]


def test_conditions_stay_balanced_over_40_participants(ctx, tmp_path):
    conditions = [{"name": "a"}, {"name": "b"}, {"name": "c", "activities": ["hotel"]}]
    ids = build_study(tmp_path, frames=3, per_activity=3, participants=0, conditions=conditions, open_link={},
                      activity_order="counterbalanced")  # fmt: skip
    study = db.session.get(Study, ids["study"])
    admitted = []
    for i in range(40):
        person = studies.admit(study, studies.Arrival(platform="prolific", external_id=f"P{i:03d}"))
        admitted.append(person)
        if i % 7 == 3:  # some decline: their places (and their condition's) are freed
            studies.answer_consent(person, agree=False)
        if i % 11 == 5:
            studies.set_active(person, False)
    holding = [p for p in admitted if p.user.active and p.end_reason is None]
    counts = Counter(p.condition.name for p in holding)
    assert sum(counts.values()) == len(holding) and max(counts.values()) - min(counts.values()) <= 1, counts
    assert studies.places_taken(study) == len(holding)
    # Condition c shows only hotel; a and b both activities, in counterbalanced activity blocks.
    for person in admitted:
        activities = [t.frame.sequence.activity.name for t in person.trials]
        if person.condition.name == "c":
            assert activities == ["hotel"] * 3
        else:
            assert len(activities) == 6 and activities[:3] == [activities[0]] * 3 and activities[3:] == [activities[3]] * 3
    firsts = Counter(p.trials[0].frame.sequence.activity.name for p in admitted if p.condition.name == "a")
    assert abs(firsts["cooking"] - firsts["hotel"]) <= 1  # each block order equally often
    assert studies.recruiting.balanced_latin_square(4) == [[0, 1, 3, 2], [1, 2, 0, 3], [2, 3, 1, 0], [3, 0, 2, 1]]
    assert len(studies.recruiting.balanced_latin_square(3)) == 6
    assert study.activity_order is ActivityOrder.COUNTERBALANCED


def test_concurrent_arrivals_hold_the_cap_and_the_balance(app, tmp_path):
    """Arrivals in parallel threads (their own connections): the cap and the conditions' balance hold."""
    study_id, token = open_study(app, tmp_path, conditions=[{"name": "a"}, {"name": "b"}], open_link={"cap": 6})
    barrier = threading.Barrier(10)
    outcomes: list[str] = []

    def arrive_now(i: int) -> None:
        with app.app_context():
            study = db.session.get(Study, study_id)
            barrier.wait()
            try:
                studies.admit(study, studies.Arrival(platform="external", external_id=f"t{i}"))
                outcomes.append("admitted")
            except studies.StudyProblem as exc:
                outcomes.append(exc.extra.get("reason"))
            finally:
                db.session.remove()

    threads = [threading.Thread(target=arrive_now, args=(i,)) for i in range(10)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(timeout=60)
    assert Counter(outcomes) == {"admitted": 6, "full": 4}
    people = participants_of(app, study_id)
    assert sorted(n for n, *_ in people) == list(range(1, 7))
    assert Counter(c for *_, c in people) == {"a": 3, "b": 3}


def test_the_same_id_arriving_twice_at_once_is_one_participant(app, tmp_path):
    study_id, _ = open_study(app, tmp_path)
    barrier = threading.Barrier(4)
    got: list[int] = []

    def arrive_now() -> None:
        with app.app_context():
            barrier.wait()
            got.append(studies.admit(db.session.get(Study, study_id), studies.Arrival(platform="prolific", external_id="SAME1", external={"SESSION_ID": "s1"})).id)
            db.session.remove()

    threads = [threading.Thread(target=arrive_now) for _ in range(4)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(timeout=60)
    assert len(got) == 4 and len(set(got)) == 1 and len(participants_of(app, study_id)) == 1


def test_bulk_codes_download_and_deactivate(app, admin_client, tmp_path):
    with app.app_context():
        ids = build_study(tmp_path, participants=0, conditions=[{"name": "x"}, {"name": "y"}])
    response = admin_client.post(f"/studies/{ids['study']}/participants", data={"count": "5", "entry": "code"})
    assert response.status_code == 302
    rows = list(csv.DictReader(io.StringIO(admin_client.get(f"/studies/{ids['study']}/export/participants.csv").get_data(as_text=True))))
    # codes in the one form shown to people and on the study page, with their dash
    assert len(rows) == 5 and all(len(r["code"]) == 9 and r["code"][4] == "-" for r in rows) and Counter(r["condition"] for r in rows) == {"x": 3, "y": 2}
    assert {r["status"] for r in rows} == {"not started"} and {r["entry"] for r in rows} == {"code"}
    with app.app_context():
        person = db.session.get(Study, ids["study"]).participants[0]
        person_id, code = person.id, person.code
    stranger = app.test_client()
    assert stranger.post("/s/", data={"code": code}).status_code == 302
    assert admin_client.post(f"/studies/{ids['study']}/participants/{person_id}/active", data={"active": "0"}).status_code == 302
    assert stranger.get("/s/consent").status_code == 302  # their session ended: back to the entry
    assert app.test_client().post("/s/", data={"code": code}).status_code == 403
    with app.app_context():
        study = db.session.get(Study, ids["study"])
        # lab codes take no place of the open link's, deactivated or not
        assert studies.places_taken(study) == 0 and studies.progress(study.participants[0]).status == "deactivated"
    assert admin_client.post(f"/studies/{ids['study']}/participants/{person_id}/active", data={"active": "2"}).status_code == 400
    assert admin_client.post(f"/studies/{ids['study']}/participants/{person_id}/active", data={"active": "1"}).status_code == 302
    assert app.test_client().post("/s/", data={"code": code}).status_code == 302
    detail = admin_client.get(f"/studies/{ids['study']}")
    assert detail.data.count(b"Deactivate") == 5 and b"participants.csv" in detail.data


def test_phones_are_told_before_anything_when_the_study_needs_a_computer(app, tmp_path):
    _, token = open_study(app, tmp_path, display={"allow_phones": False})
    iphone = "Mozilla/5.0 (iPhone; CPU iPhone OS 17_0 like Mac OS X) AppleWebKit/605.1.15 Mobile/15E148"
    client = app.test_client()
    page = client.get(f"/s/o/{token}", headers={"User-Agent": iphone})
    assert page.status_code == 403 and b"needs a computer" in page.data
    assert client.post(f"/s/o/{token}", headers={"User-Agent": iphone}).status_code == 403
    desktop = client.get(f"/s/o/{token}", headers={"User-Agent": "Mozilla/5.0 (X11; Linux x86_64) Chrome/120"})
    assert desktop.status_code == 200


@pytest.mark.parametrize("entry", ["open"])
def test_staff_cannot_make_open_link_participants_by_hand(ctx, tmp_path, entry):
    ids = build_study(tmp_path, participants=0)
    with pytest.raises(studies.StudyProblem, match="arrive by themselves"):
        studies.add_participants(db.session.get(Study, ids["study"]), count=1, entry=entry)
    assert not db.session.get(Study, ids["study"]).frames_of(FrameKind.PRACTICE)


def test_the_open_link_s_pages_and_refusals_may_be_framed_by_mturk_only(app, app_with, tmp_path):
    """Review: "This study is full" was not frameable, so an MTurk worker saw a blocked frame. Every answer of the open
    link may be framed by MTurk's sites (and no X-Frame-Options contradicts it); every other page by nobody."""
    # (``app`` too: its teardown empties the tables this test's app fills.)
    app = app_with(RATELIMIT_OPEN_ADMISSIONS=1)
    study_id, token = open_study(app, tmp_path, open_link={"cap": 2})
    mturk = "frame-ancestors https://workersandbox.mturk.com https://www.mturk.com"
    browser = app.test_client()
    answers = {
        "page": browser.get(f"/s/o/{token}"),
        "bad id": browser.get(f"/s/o/{token}", query_string={"workerId": "W1"}),
        "admitted": browser.post(f"/s/o/{token}"),
        "counted": app.test_client().post(f"/s/o/{token}"),  # the one past the budget sets a wait
        "wait": app.test_client().post(f"/s/o/{token}"),
        "full": app.test_client().get(f"/s/o/{token}"),
    }
    with app.app_context():
        studies.set_status(db.session.get(Study, study_id), "closed")
    answers["closed"] = app.test_client().get(f"/s/o/{token}")
    assert {k: r.status_code for k, r in answers.items()} == {
        "page": 200, "bad id": 400, "admitted": 302, "counted": 302, "wait": 429, "full": 409, "closed": 410}
    assert b"This study is full" in answers["full"].data
    for name, response in answers.items():
        policy = response.headers["Content-Security-Policy"]
        assert mturk in policy and "frame-ancestors 'none'" not in policy and "X-Frame-Options" not in response.headers, name
    for other in (browser.get("/s/consent"), app.test_client().get("/s/"), app.test_client().get("/login")):
        assert "frame-ancestors 'none'" in other.headers["Content-Security-Policy"] and other.headers["X-Frame-Options"] == "DENY"


def mturk_calls(url: str, params: dict) -> str:
    """The URL MTurk opens for an ExternalURL: the URL as given with MTurk's own parameters appended (it fills no placeholders)."""
    return url + ("&" if "?" in url else "?") + urlencode(params)


def test_the_study_page_gives_mturk_the_bare_open_link_and_an_external_question_that_works(app, admin_client, tmp_path):
    """The URL and XML copied from the Recruiting card, called as MTurk calls them: preview, then accepted."""
    study_id, token = open_study(app, tmp_path, completion={"code": "MT0002"})
    page = admin_client.get(f"/studies/{study_id}").get_data(as_text=True)

    def field(name: str) -> str:
        return html.unescape(re.search(rf'value="([^"]+)" id="{name}"', page).group(1))

    open_link = field("open-link")
    assert open_link.endswith(f"/s/o/{token}") and field("mturk-url") == open_link
    xml = html.unescape(re.search(r'<textarea[^>]*id="mturk-question">(.*?)</textarea>', page, re.S).group(1))
    question = ElementTree.fromstring(xml)
    ns = "{http://mechanicalturk.amazonaws.com/AWSMechanicalTurkDataSchemas/2006-07-14/ExternalQuestion.xsd}"
    assert question.tag == f"{ns}ExternalQuestion" and int(question.find(f"{ns}FrameHeight").text) > 0
    external_url = question.find(f"{ns}ExternalURL").text
    assert external_url == open_link
    # An open link with a query string is escaped in the XML (a raw & would not parse).
    assert "&amp;" in studies.platform_urls("https://a.example/s/o/T?x=1&y=2")["mturk_question"]
    assert field("prolific-url") == f"{open_link}?PROLIFIC_PID={{{{%PROLIFIC_PID%}}}}&STUDY_ID={{{{%STUDY_ID%}}}}&SESSION_ID={{{{%SESSION_ID%}}}}"

    path = urlsplit(external_url).path
    preview = {"assignmentId": "ASSIGNMENT_ID_NOT_AVAILABLE", "hitId": "3HIT", "turkSubmitTo": "https://workersandbox.mturk.com"}
    worker = app.test_client()
    shown = worker.get(mturk_calls(path, preview), headers={"Sec-Fetch-Dest": "iframe"})
    assert shown.status_code == 200 and b'id="preview-instructions"' in shown.data
    assert participants_of(app, study_id) == []
    accepted = {"assignmentId": "3ASG", "hitId": "3HIT", "turkSubmitTo": "https://workersandbox.mturk.com", "workerId": "A2WORKER"}
    framed = worker.get(mturk_calls(path, accepted), headers={"Sec-Fetch-Dest": "iframe"})
    assert framed.status_code == 200 and b'id="open-tab"' in framed.data
    assert worker.post(path, data=accepted).headers["Location"].endswith("/s/consent")
    with app.app_context():
        (person,) = db.session.get(Study, study_id).participants
        assert (person.platform, person.external_id) == ("mturk", "A2WORKER")
        assert studies.mturk_submit_url(person) == "https://workersandbox.mturk.com/mturk/externalSubmit"
    # What the page used to offer: MTurk appends to "?workerId=${workerId}&..." and every visit is refused.
    old = mturk_calls(path + "?workerId=${workerId}&assignmentId=${assignmentId}&hitId=${hitId}", preview)
    assert app.test_client().get(old, headers={"Accept": "application/json"}).status_code == 400
