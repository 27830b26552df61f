"""The server is the authority on study time: frozen-clock tests through the participant API."""

from datetime import UTC, datetime, timedelta

import pytest

from app.extensions import db
from app.models.studies import EndReason, EventKind, Outcome, Participant, Trial
from app.services import studies
from tests.app.access.studies import build_study

T0 = datetime(2026, 5, 4, 10, 0, 0, tzinfo=UTC)
JSON = {"Accept": "application/json"}


class Clock:
    """A clock the test moves by hand (the app's STUDY_CLOCK)."""

    def __init__(self, t: datetime):
        self.t = t

    def __call__(self) -> datetime:
        return self.t

    def advance(self, seconds: float) -> None:
        self.t += timedelta(seconds=seconds)


@pytest.fixture
def clock(app):
    app.config["STUDY_CLOCK"] = Clock(T0)
    return app.config["STUDY_CLOCK"]


def setup_study(app, tmp_path, **options):
    """A study of 4 frames and one participant; returns (participant id, code)."""
    with app.app_context():
        ids = build_study(tmp_path, frames=2, per_activity=2, participants=1, **options)
        participant = db.session.get(Participant, ids["participants"][0])
        return participant.id, participant.code


def enter_and_start(client, code):
    assert client.post("/s/", data={"code": code}).headers["Location"].endswith("/s/consent")
    assert client.post("/s/consent", data={"decision": "agree"}).headers["Location"].endswith("/s/instructions")
    assert client.post("/s/start").headers["Location"].endswith("/s/trials")


def current(client):
    response = client.get("/s/api/current", headers=JSON)
    assert response.status_code == 200, response.data
    return response.get_json()


def answer(client, trial, **body):
    body.setdefault("clicks", [{"x": 10.0, "y": 12.5, "rt_ms": 800.0}])
    return client.post(trial["submit_url"], json=body, headers=JSON)


def test_before_the_session_starts_nothing_can_be_answered(app, client, clock, tmp_path):
    participant_id, code = setup_study(app, tmp_path, time_limit_s=60)
    assert client.post("/s/", data={"code": code}).status_code == 302
    state = current(client)
    assert state["step"] == "consent" and state["trial"] is None and state["redirect"] == "/s/consent"
    with app.app_context():
        trial_id = db.session.execute(db.select(Trial.id).filter_by(participant_id=participant_id, position=1)).scalar_one()
    response = client.post(f"/s/api/trials/{trial_id}", json={"clicks": [{"x": 1, "y": 1, "rt_ms": 1}]}, headers=JSON)
    assert response.status_code == 409 and response.get_json()["reason"] == "not_started"
    assert client.get("/s/trials").headers["Location"].endswith("/s/consent")  # pages follow the steps
    assert client.post("/s/start").headers["Location"].endswith("/s/consent")  # no start before consent
    client.post("/s/consent", data={"decision": "agree"})
    assert current(client)["step"] == "instructions"
    clock.advance(300)  # reading the instructions does not use the session's time
    client.post("/s/start")
    with app.app_context():
        participant = db.session.get(Participant, participant_id)
        assert participant.started_at == T0 + timedelta(seconds=300)
        assert participant.deadline == participant.started_at + timedelta(seconds=60)
    assert client.post("/s/consent", data={"decision": "maybe"}).status_code == 400


def test_during_the_session_answers_are_stamped_and_final(app, client, clock, tmp_path):
    participant_id, code = setup_study(app, tmp_path, time_limit_s=60)
    enter_and_start(client, code)
    state = current(client)
    first = state["trial"]
    assert (state["step"], first["position"], state["done"], state["total"]) == ("trials", 1, 0, 4)
    assert state["time_left_s"] == 60 and state["trial_time_left_s"] is None
    assert state["next"]["position"] == 2 and (first["width"], first["height"]) == (64, 48)
    clock.advance(5)
    response = answer(client, first, rt_ms=4200.0, events=[{"kind": "blur", "t_ms": 100}, {"kind": "focus", "t_ms": 900}])
    assert response.status_code == 200, response.data
    state = response.get_json()
    second = state["trial"]
    assert second["position"] == 2 and state["done"] == 1 and state["time_left_s"] == 55

    # A submitted trial cannot be changed; a trial not on screen cannot be answered.
    again = answer(client, first, clicks=[{"x": 1, "y": 1, "rt_ms": 1}])
    assert again.status_code == 409 and again.get_json()["reason"] == "submitted"
    with app.app_context():
        third_id = db.session.execute(db.select(Trial.id).filter_by(participant_id=participant_id, position=3)).scalar_one()
    early = client.post(f"/s/api/trials/{third_id}", json={"clicks": [{"x": 1, "y": 1, "rt_ms": 1}]}, headers=JSON)
    assert early.status_code == 409 and early.get_json()["reason"] == "not_current"

    # A reload resumes at the first unanswered trial, and is logged.
    clock.advance(3)
    state = current(client)
    assert state["trial"]["id"] == second["id"] and state["time_left_s"] == 52
    with app.app_context():
        trial = db.session.get(Trial, first["id"])
        assert (trial.outcome, trial.shown_at, trial.submitted_at, trial.rt_ms) == (Outcome.CLICKED, T0, T0 + timedelta(seconds=5), 4200.0)
        assert [(c.x, c.y, c.rt_ms, c.received_at) for c in trial.clicks] == [(10.0, 12.5, 800.0, T0 + timedelta(seconds=5))]
        assert [(e.kind, e.client_ms) for e in trial.events] == [(EventKind.BLUR, 100.0), (EventKind.FOCUS, 900.0)]
        reloaded = db.session.get(Trial, second["id"])
        assert reloaded.shown_at == T0 + timedelta(seconds=5)  # first shown, not re-stamped by the reload
        assert [(e.kind, e.client_ms, e.server_at) for e in reloaded.events] == [(EventKind.RELOAD, None, T0 + timedelta(seconds=8))]


def test_after_the_deadline_answers_are_refused_and_the_session_ends(app, client, clock, tmp_path):
    participant_id, code = setup_study(app, tmp_path, time_limit_s=60)
    enter_and_start(client, code)
    first = current(client)["trial"]
    clock.advance(60 + studies.LATE_GRACE_S - 0.5)  # late, but within the grace for the request's travel
    response = answer(client, first, timed_out=True)  # the page's own submission at its zero
    assert response.status_code == 200, response.data
    state = response.get_json()
    assert state["step"] == "done" and state["end_reason"] == "time_up" and state["redirect"] == "/s/done"
    with app.app_context():
        participant = db.session.get(Participant, participant_id)
        assert participant.end_reason is EndReason.TIME_UP and participant.finished_at == participant.deadline
        assert [t.outcome for t in participant.trials] == [Outcome.TIMED_OUT, None, None, None]


def test_an_answer_after_the_grace_is_refused(app, client, clock, tmp_path):
    participant_id, code = setup_study(app, tmp_path, time_limit_s=60)
    enter_and_start(client, code)
    first = current(client)["trial"]
    clock.advance(30)
    second = answer(client, first).get_json()["trial"]
    clock.advance(30 + studies.LATE_GRACE_S + 0.5)
    late = answer(client, second)
    assert late.status_code == 409 and late.get_json()["reason"] == "time_up"
    with app.app_context():
        participant = db.session.get(Participant, participant_id)
        assert participant.end_reason is EndReason.TIME_UP and participant.finished_at == T0 + timedelta(seconds=60)
        assert [t.outcome for t in participant.trials] == [Outcome.CLICKED, Outcome.EXPIRED, None, None]
        assert db.session.get(Trial, second["id"]).clicks == []
    state = current(client)
    assert state["step"] == "done" and state["trial"] is None
    assert client.get("/s/trials").headers["Location"].endswith("/s/done")
    done = client.get("/s/done")
    assert done.status_code == 200 and b"The time is up. You answered 1 of 4" in done.data
    assert answer(client, first).get_json()["reason"] == "submitted"


def test_the_session_ends_on_time_without_any_answer(app, client, clock, tmp_path):
    participant_id, code = setup_study(app, tmp_path, time_limit_s=60)
    enter_and_start(client, code)
    first = current(client)["trial"]
    clock.advance(59.9)
    assert current(client)["time_left_s"] == pytest.approx(0.1)
    clock.advance(0.1)  # at the deadline: nothing more is served
    state = current(client)
    assert state["step"] == "done" and state["end_reason"] == "time_up"
    late = answer(client, first)
    assert late.status_code == 409 and late.get_json()["reason"] == "time_up"
    with app.app_context():
        assert db.session.get(Trial, first["id"]).outcome is Outcome.EXPIRED


def test_per_trial_limit_closes_only_that_trial(app, client, clock, tmp_path):
    participant_id, code = setup_study(app, tmp_path, time_limit_s=600, trial_limit_s=10)
    enter_and_start(client, code)
    state = current(client)
    assert state["trial_time_left_s"] == 10
    clock.advance(10 + studies.LATE_GRACE_S - 1)  # within the grace
    state = answer(client, state["trial"]).get_json()
    second = state["trial"]
    assert second["position"] == 2 and state["trial_time_left_s"] == 10
    clock.advance(10 + studies.LATE_GRACE_S + 1)
    late = answer(client, second)
    assert late.status_code == 409 and late.get_json()["reason"] == "trial_time_up"
    state = current(client)  # the session goes on with the next trial
    assert state["step"] == "trials" and state["trial"]["position"] == 3 and state["trial_time_left_s"] == 10
    clock.advance(30)  # nobody answers: a reload closes it and serves the next
    state = current(client)
    assert state["trial"]["position"] == 4
    state = answer(client, state["trial"], clicks=[], none=True).get_json()
    assert state["step"] == "done" and state["end_reason"] == "completed"
    with app.app_context():
        participant = db.session.get(Participant, participant_id)
        assert [t.outcome for t in participant.trials] == [Outcome.CLICKED, Outcome.EXPIRED, Outcome.EXPIRED, Outcome.NONE]
        assert participant.finished_at == clock.t and participant.end_reason is EndReason.COMPLETED


def test_completing_every_trial_finishes_the_session(app, client, clock, tmp_path):
    participant_id, code = setup_study(app, tmp_path, time_limit_s=60, multiple_clicks=False)
    enter_and_start(client, code)
    state = current(client)
    for _ in range(4):
        clock.advance(2)
        state = answer(client, state["trial"]).get_json()
    assert state["step"] == "done" and state["end_reason"] == "completed" and state["done"] == 4
    done = client.get("/s/done")
    assert b"You answered all 4 photos" in done.data
    # Time passing afterwards changes nothing.
    clock.advance(3600)
    assert current(client)["end_reason"] == "completed"


def test_answers_are_validated_naming_the_field(app, client, clock, tmp_path):
    participant_id, code = setup_study(app, tmp_path, time_limit_s=60, multiple_clicks=False)
    enter_and_start(client, code)
    trial = current(client)["trial"]
    cases = [
        (dict(clicks=[{"x": 64.0, "y": 3, "rt_ms": 1}]), "clicks[0]"),
        (dict(clicks=[{"x": 1, "y": 1, "rt_ms": 1}, {"x": 2, "y": 2, "rt_ms": 2}]), "clicks"),
        (dict(clicks=[]), "clicks"),
        (dict(clicks=[{"x": 1, "y": 1, "rt_ms": 1}], none=True), "none"),
        (dict(clicks=[], none=True, timed_out=True), "timed_out"),
        (dict(clicks=[{"x": "a", "y": 1, "rt_ms": -1}]), "clicks[0].x"),
        (dict(clicks=[], none=True, events=[{"kind": "reload", "t_ms": 1}]), "events[0].kind"),
        (dict(clicks=[], none=True, window={"width": 10}), "window.height"),
        (dict(clicks=[], none=True, colour="red"), "colour"),
    ]
    for body, field in cases:
        response = client.post(trial["submit_url"], json=body, headers=JSON)
        assert response.status_code == 400, (body, response.data)
        assert field in response.get_json()["fields"], (body, response.get_json())
    bad_json = client.post(trial["submit_url"], data="{", content_type="application/json", headers=JSON)
    assert bad_json.status_code == 400
    # Nothing was recorded by the refused answers.
    response = client.post(trial["submit_url"], json={"clicks": [{"x": -0.5, "y": 47.5, "rt_ms": 10}]}, headers=JSON)
    assert response.status_code == 200
    with app.app_context():
        assert [(c.x, c.y) for c in db.session.get(Trial, trial["id"]).clicks] == [(-0.5, 47.5)]
