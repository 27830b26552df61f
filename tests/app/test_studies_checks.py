"""Quality of the data: comprehension questions, practice trials, catch trials, completion codes, display and environment."""

import csv
import io
from datetime import UTC, datetime, timedelta

import pytest

from app.extensions import db
from app.models import Activity, Frame, Sequence
from app.models.studies import EndReason, FrameKind, Outcome, Participant, Study
from app.services import scoring, studies
from tests.app.access.studies import build_study

JSON = {"Accept": "application/json"}
QUESTIONS = [
    {"question": "What do you click?", "options": ["Any object", "The centre of the object the person acts on"], "answer": 1},
    {"question": "Is there always an action-object?", "options": ["Yes", "No: then I press None"], "answer": "No: then I press None"},
]
REDIRECT = "https://app.prolific.com/submissions/complete?cc={code}"


def spare_frames(activity: str) -> list[int]:
    """Frame ids of an activity the study does not draw from (for practice and catch trials)."""
    query = db.select(Frame.id).join(Sequence).join(Activity).where(Activity.name == activity).order_by(Frame.id)
    return list(db.session.execute(query).scalars())


def quality_study(tmp_path, **options) -> Study:
    """4 main frames (cooking, hotel), 1 practice frame, 2 catch trials (a box, the ground truth), 2 participants."""
    build_study(tmp_path, activities=("cooking", "hotel", "dining"), frames=3, per_activity=2, participants=0)
    spare = spare_frames("dining")
    ids = [a.id for a in db.session.execute(db.select(Activity).where(Activity.name != "dining")).scalars()]
    options.setdefault("completion", {"code": "C0MPLETE", "failed_code": "FAILED1", "redirect_url": REDIRECT})
    study = studies.create_study(
        name="checks", activity_ids=ids, frames_per_activity=2, seed=3, practice_trials=[spare[0]],
        catch_trials=[{"frame": spare[1], "position": 2, "box": [0, 0, 20, 20]}, {"frame": spare[2], "position": 99 - 94}],
        **options,
    )  # fmt: skip
    studies.add_participants(study, count=2)
    return study


def run_through(participant: Participant, *, catch_click) -> None:
    """Consent, instructions, practice (a click), start, then every trial: a click at (15, 15), catch trials at ``catch_click``."""
    studies.answer_consent(participant, agree=True)
    studies.start_session(participant)
    assert studies.step(participant) == "practice"
    state = studies.session_state(participant)
    assert (state.step, state.trial.kind, state.time_left_s, state.done, state.total) == ("practice", FrameKind.PRACTICE, None, 0, 1)
    state = studies.submit(participant, state.trial, studies.Answer(clicks=[(15.0, 15.0, 300.0)]))
    assert state.step == "ready" and state.feedback == "Well done: your click is on the action-object."
    studies.start_session(participant)
    state = studies.session_state(participant)
    while state.trial is not None:
        point = catch_click if state.trial.kind is FrameKind.CATCH else (15.0, 15.0)
        state = studies.submit(participant, state.trial, studies.Answer(clicks=[(*point, 500.0)]))


def run_through_passing(participant: Participant) -> None:
    """Practice, then every trial at (15, 15), catch trials with a box inside it at (5, 5): every check passed."""
    studies.answer_consent(participant, agree=True)
    studies.start_session(participant)
    studies.submit(participant, studies.session_state(participant).trial, studies.Answer(clicks=[(15.0, 15.0, 300.0)]))
    studies.start_session(participant)
    state = studies.session_state(participant)
    while state.trial is not None:
        inside_box = state.trial.study_frame.region is not None
        state = studies.submit(participant, state.trial, studies.Answer(clicks=[(5.0 if inside_box else 15.0, 5.0 if inside_box else 15.0, 400.0)]))


def test_catch_trials_are_judged_exported_and_excluded_by_the_scorer(ctx, tmp_path):
    study = quality_study(tmp_path)
    good, careless = study.participants
    kinds = [t.kind.value for t in good.trials]
    assert kinds == ["practice", "main", "catch", "main", "main", "catch", "main"]  # catch trials at places 2 and 5
    run_through(good, catch_click=(5.0, 5.0))  # in the box, and on the second one's ground truth? no: (5, 5) is off its mask
    run_through(careless, catch_click=(60.0, 40.0))
    db.session.expire_all()
    assert [t.hit for t in good.trials if t.kind is FrameKind.CATCH] == [True, False]
    # The second catch frame's answer is its ground truth (rows 10-19, columns 7-29 of this frame): (5, 5) misses it.
    results = studies.checks_of(study.participants)
    assert results[good.id].catch_passed == 1 and results[good.id].passed is False
    assert results[careless.id].as_dict() == {
        "passed": False, "comprehension": "none", "catch_trials": {"total": 2, "passed": 0, "failed": 2}
    }  # fmt: skip

    # A participant who clicks every catch trial right passes.
    third = studies.add_participants(study, count=1)[0]
    run_through_passing(third)
    assert studies.checks_of([third])[third.id].passed is True
    assert third.completion_code == "C0MPLETE" and good.completion_code == "FAILED1"

    # Exports: every trial says its kind and whether it hit; practice and catch trials are never data.
    rows = list(csv.DictReader(io.StringIO(studies.export_csv(study, "trials"))))
    mine = [r for r in rows if r["participant"] == "P01"]
    assert [r["kind"] for r in mine] == kinds and [r["hit"] for r in mine] == ["True", "True", "True", "True", "True", "False", "True"]
    people = {r["participant"]: r for r in csv.DictReader(io.StringIO(studies.export_csv(study, "participants")))}
    assert (people["P01"]["checks_passed"], people["P01"]["catch_passed"], people["P03"]["checks_passed"]) == ("False", "1", "True")
    assert [f for f, _ in studies.participant_soft_masks(good)] == [t.frame for t in good.trials if t.kind is FrameKind.MAIN]
    report = scoring.build_report(run_ids=[], study_ids=[study.id], baselines=False)
    assert [r.name for r in report.rows] == ["P01", "P02", "P03"] and all(r.overall.n_frames == 4 for r in report.rows)
    kept = scoring.build_report(run_ids=[], study_ids=[study.id], baselines=False, exclude_failed_checks=True)
    assert [r.name for r in kept.rows] == ["P03"] and "2 participants who failed a check left out." in kept.notes
    assert [p.id for p in studies.study_participants([study.id], exclude_failed_checks=True)] == [third.id]


def test_comprehension_questions_gate_the_timed_part_with_retries(app, client, tmp_path):
    with app.app_context():
        ids = build_study(tmp_path, participants=2, comprehension={"questions": QUESTIONS, "max_attempts": 2},
                          completion={"code": "OK1", "failed_code": "SCREENED"})  # fmt: skip
        first, second = (db.session.get(Participant, pid) for pid in ids["participants"])
        codes = first.code, second.code
    client.post("/s/", data={"code": codes[0]})
    client.post("/s/consent", data={"decision": "agree"})
    page = client.get("/s/instructions")
    assert b"Check your understanding" in page.data and b'name="q1"' in page.data and b'id="start"' not in page.data
    assert client.post("/s/start").headers["Location"].endswith("/s/instructions")  # no way round the questions
    wrong = client.post("/s/comprehension", data={"q0": "1", "q1": "0"})
    assert wrong.status_code == 400 and b"Some answers are not right" in wrong.data and b"1 try left" in wrong.data
    right = client.post("/s/comprehension", data={"q0": "1", "q1": "1"})
    assert right.headers["Location"].endswith("/s/ready")
    assert b"Your answers were right" in client.get("/s/ready").data
    assert client.post("/s/start").headers["Location"].endswith("/s/trials")
    bounded = client.post("/s/comprehension", data={"q0": "1", "q77": "1"})
    assert bounded.status_code == 302  # past the questions: nothing more to grade

    other = client.application.test_client()
    other.post("/s/", data={"code": codes[1]})
    other.post("/s/consent", data={"decision": "agree"})
    assert other.post("/s/comprehension", data={"q0": "1", "q1": "1", "q5": "0"}).status_code == 400  # no such question
    assert other.post("/s/comprehension", data={"q0": "0"}).status_code == 400
    out = other.post("/s/comprehension", data={"q0": "0", "q1": "0"})
    assert out.headers["Location"].endswith("/s/done")
    done = other.get("/s/done")
    assert b"not right, so the study ends here" in done.data and b"SCREENED" in done.data
    with app.app_context():
        first, second = (db.session.get(Participant, pid) for pid in ids["participants"])
        assert (first.comprehension_attempts, first.comprehension_passed_at is not None) == (2, True)
        assert (second.comprehension_attempts, second.end_reason) == (2, EndReason.SCREENED_OUT)
        assert studies.checks_of([first, second]) == {first.id: studies.Checks("passed"), second.id: studies.Checks("failed")}


def test_completion_code_and_redirect_prolific_style(app, client, tmp_path):
    app.config["STUDY_CLOCK"] = clock = Clock(datetime(2026, 6, 1, 12, tzinfo=UTC))
    with app.app_context():
        ids = build_study(tmp_path, participants=3, time_limit_s=60, multiple_clicks=False, open_link={"cap": 10},
                          completion={"code": "ABC123", "failed_code": "LATE99", "redirect_url": REDIRECT})  # fmt: skip
        codes = [db.session.get(Participant, pid).code for pid in ids["participants"]]
        token = db.session.get(Study, ids["study"]).open_link_token

    def answer_every_trial(browser):
        browser.post("/s/consent", data={"decision": "agree"})
        browser.post("/s/start")
        state = browser.get("/s/api/current", headers=JSON).get_json()
        while state["trial"]:
            state = browser.post(state["trial"]["submit_url"], json={"clicks": [{"x": 3, "y": 3, "rt_ms": 100}]}, headers=JSON).get_json()
        assert state["redirect"] == "/s/done"
        return browser.get("/s/done")

    # A Prolific arrival through the open link is sent back to Prolific with the code.
    prolific = app.test_client()
    assert prolific.post(f"/s/o/{token}", data={"PROLIFIC_PID": "5f1e2d3c4b5a69788796a5b1", "STUDY_ID": "s1", "SESSION_ID": "v1"}).status_code == 302
    done = answer_every_trial(prolific)
    assert b'id="completion-code">ABC123<' in done.data
    assert b'data-redirect="https://app.prolific.com/submissions/complete?cc=ABC123"' in done.data and b"study_done.js" in done.data
    # A lab code gets the code and stays on the page: it did not come from Prolific.
    client.post("/s/", data={"code": codes[0]})
    done = answer_every_trial(client)
    assert b'id="completion-code">ABC123<' in done.data and b"data-redirect" not in done.data

    late = app.test_client()
    assert late.post(f"/s/o/{token}", data={"PROLIFIC_PID": "5f1e2d3c4b5a69788796a5b2", "STUDY_ID": "s1", "SESSION_ID": "v2"}).status_code == 302
    late.post("/s/consent", data={"decision": "agree"})
    late.post("/s/start")
    clock.advance(61 + studies.LATE_GRACE_S)
    assert b"LATE99" in late.get("/s/done").data and b"cc=LATE99" in late.get("/s/done").data
    late_code = app.test_client()
    late_code.post("/s/", data={"code": codes[1]})
    late_code.post("/s/consent", data={"decision": "agree"})
    late_code.post("/s/start")
    clock.advance(61 + studies.LATE_GRACE_S)
    assert b"LATE99" in late_code.get("/s/done").data and b"cc=LATE99" not in late_code.get("/s/done").data

    declined = app.test_client()
    declined.post("/s/", data={"code": codes[2]})
    declined.post("/s/consent", data={"decision": "decline"})
    page = declined.get("/s/done")
    assert b"completion-code" not in page.data and b"data-redirect" not in page.data and b"return the study" in page.data
    with app.app_context():
        assert [db.session.get(Participant, pid).completion_code for pid in ids["participants"]] == ["ABC123", "LATE99", None]
        assert [p.completion_code for p in db.session.get(Study, ids["study"]).participants if p.external_id] == ["ABC123", "LATE99"]


@pytest.mark.parametrize(
    ("completion", "field"),
    [
        ({"code": "X", "redirect_url": "javascript:alert(1)"}, "completion.redirect_url"),
        ({"code": "X", "redirect_url": "https://example.org/a b"}, "completion.redirect_url"),
        ({"code": "X", "redirect_url": "//example.org/{code}"}, "completion.redirect_url"),
        ({"redirect_url": "https://example.org/?cc={code}"}, "completion.code"),
        ({"code": "has space"}, "completion.code"),
        ({"code": "X", "colour": "red"}, "completion.colour"),
    ],
)
def test_completion_settings_are_checked(ctx, tmp_path, completion, field):
    with pytest.raises(studies.StudyProblem) as info:
        build_study(tmp_path, participants=0, completion=completion)
    assert info.value.field == field


def test_display_size_and_the_browser_are_recorded(app, client, tmp_path):
    with app.app_context():
        ids = build_study(tmp_path, participants=1, display={"width_px": 640, "min_window": [1024, 700], "fullscreen": True})
        code = db.session.get(Participant, ids["participants"][0]).code
        assert db.session.get(Study, ids["study"]).display == {"width_px": 640, "fullscreen": True, "min_window": {"width": 1024, "height": 700}}
    client.post("/s/", data={"code": code}, headers={"User-Agent": "TestBrowser/1.0"})
    client.post("/s/consent", data={"decision": "agree"})
    client.post("/s/start")
    page = client.get("/s/trials")
    assert b"data-display=" in page.data and b"&#34;width_px&#34;: 640" in page.data
    environment = {"screen": {"width": 1920, "height": 1080}, "window": {"width": 1280, "height": 800}, "pixel_ratio": 2.0,
                   "time_zone": "Europe/Berlin", "touch": False}  # fmt: skip
    response = client.post("/s/api/environment", json=environment, headers={**JSON, "User-Agent": "TestBrowser/2.0"})
    assert response.status_code == 200
    for bad, field in (({"time_zone": "<b>"}, "time_zone"), ({"screen": {"width": 10**9, "height": 1}}, "screen.width"),
                       ({"window": {"width": 5}}, "window.height"), ({"time_zone": "x" * 65}, "time_zone"), ({"gpu": "x"}, "gpu")):  # fmt: skip
        refused = client.post("/s/api/environment", json=bad, headers=JSON)
        assert refused.status_code == 400 and field in refused.get_json()["fields"], bad
    trial = client.get("/s/api/current", headers=JSON).get_json()["trial"]
    body = {"clicks": [{"x": 3, "y": 3, "rt_ms": 100}], "window": {"width": 1280, "height": 800}, "display": {"width": 640, "height": 480},
            "pixel_ratio": 2.0, "events": [{"kind": "resize", "t_ms": 50, "width": 1200, "height": 790},
                                            {"kind": "fullscreen", "t_ms": 60, "state": "exited"}]}  # fmt: skip
    assert client.post(trial["submit_url"], json=body, headers=JSON).status_code == 200
    with app.app_context():
        study = db.session.get(Study, ids["study"])
        people = {r["participant"]: r for r in csv.DictReader(io.StringIO(studies.export_csv(study, "participants")))}
        trials = list(csv.DictReader(io.StringIO(studies.export_csv(study, "trials"))))
        events = list(csv.DictReader(io.StringIO(studies.export_csv(study, "events"))))
    row = people["P01"]
    assert (row["screen_width"], row["window_height"], row["pixel_ratio"], row["time_zone"], row["user_agent"]) == (
        "1920", "800", "2.0", "Europe/Berlin", "TestBrowser/2.0")  # fmt: skip
    assert (trials[0]["display_width"], trials[0]["display_height"], trials[0]["pixel_ratio"]) == ("640.0", "480.0", "2.0")
    assert [e["kind"] for e in events] == ["resize", "fullscreen"]


class Clock:
    def __init__(self, t: datetime):
        self.t = t

    def __call__(self) -> datetime:
        return self.t

    def advance(self, seconds: float) -> None:
        self.t += timedelta(seconds=seconds)


def test_progress_counts_closed_trials_and_time_up_closes_the_last_one(app, admin_client, tmp_path):
    app.config["STUDY_CLOCK"] = clock = Clock(datetime(2026, 6, 1, 12, tzinfo=UTC))
    with app.app_context():
        ids = build_study(tmp_path, participants=1, time_limit_s=60, trial_limit_s=10)
        person = db.session.get(Participant, ids["participants"][0])
        studies.answer_consent(person, agree=True)
        studies.start_session(person)
        studies.session_state(person)
        clock.advance(10 + studies.LATE_GRACE_S + 1)  # the first photo closed by its limit
        state = studies.session_state(person)
        assert (state.trial.position, state.done, state.total) == (2, 1, 4)
        state = studies.submit(person, state.trial, studies.Answer(clicks=[(3.0, 3.0, 50.0)]))
        assert state.done == 2  # closed by the limit or answered: both done
    clock.advance(300)  # the participant left with photo 3 on screen; nobody asks the server
    page = admin_client.get(f"/studies/{ids['study']}")
    assert b"time up" in page.data and b'value="3"' in page.data  # three of four closed
    with app.app_context():
        person = db.session.get(Participant, ids["participants"][0])
        assert [t.outcome for t in person.trials] == [Outcome.EXPIRED, Outcome.CLICKED, Outcome.EXPIRED, None]
        assert person.end_reason is EndReason.TIME_UP and person.finished_at == person.deadline


def test_scorer_splits_people_by_condition(ctx, tmp_path):
    ids = build_study(tmp_path, participants=4, conditions=[{"name": "slow"}, {"name": "fast", "trial_limit_seconds": 9}])
    study = db.session.get(Study, ids["study"])
    for person in study.participants:
        studies.answer_consent(person, agree=True)
        studies.start_session(person)
        state = studies.session_state(person)
        while state.trial is not None:
            state = studies.submit(person, state.trial, studies.Answer(clicks=[(15.0, 15.0, 200.0)]))
    report = scoring.build_report(run_ids=[], study_ids=[study.id], baselines=False, by_condition=True)
    assert [r.name for r in report.rows] == ["P02 [fast]", "P04 [fast]", "P01 [slow]", "P03 [slow]"]
    plain = scoring.build_report(run_ids=[], study_ids=[study.id], baselines=False)
    assert [r.name for r in plain.rows] == ["P01", "P02", "P03", "P04"]
    rows = list(csv.DictReader(io.StringIO(studies.export_csv(study, "trials"))))
    assert {(r["participant"], r["condition"]) for r in rows} == {("P01", "slow"), ("P02", "fast"), ("P03", "slow"), ("P04", "fast")}


def test_the_scores_page_splits_people_by_condition_and_keeps_the_choice(app, admin_client, tmp_path):
    with app.app_context():
        ids = build_study(tmp_path, participants=2, conditions=[{"name": "slow"}, {"name": "fast", "trial_limit_seconds": 9}])
        study = db.session.get(Study, ids["study"])
        for person in study.participants:
            studies.answer_consent(person, agree=True)
            studies.start_session(person)
            state = studies.session_state(person)
            while state.trial is not None:
                state = studies.submit(person, state.trial, studies.Answer(clicks=[(15.0, 15.0, 200.0)]))
    html = admin_client.get(f"/scores/?chosen=1&studies={ids['study']}&by_condition=1&exclude_failed_checks=1").get_data(as_text=True)
    assert "P02 [fast]" in html and "P01 [slow]" in html
    assert 'name="by_condition" value="1" checked' in html and 'name="exclude_failed_checks" value="1" checked' in html
    assert "Participants who failed a check are left out." in html
    assert "by_condition=1" in html and "exclude_failed_checks=1" in html  # the downloads repeat the choice
    csv_text = admin_client.get(f"/scores/table.csv?chosen=1&studies={ids['study']}&by_condition=1").get_data(as_text=True)
    assert "P02 [fast]" in csv_text
