"""Who reaches what in a study: participants see only their own session and frames, never ground truth."""

from app.extensions import db
from app.models import Annotation, User
from app.models.studies import EntryKind, Participant, Study, Trial
from app.services import media, studies
from tests.app.access.studies import build_study

JSON = {"Accept": "application/json"}


def two_studies(app, tmp_path):
    """Study A with participants a1, a2 (a2 by link) and study B with b1; every one started."""
    with app.app_context():
        a = build_study(tmp_path / "a", participants=1)
        study_a = db.session.get(Study, a["study"])
        studies.add_participants(study_a, count=1, entry=EntryKind.LINK)
        b = build_study(tmp_path / "b", activities=("dining",), participants=1)
        people = {}
        for name, pid in (("a1", study_a.participants[0].id), ("a2", study_a.participants[1].id), ("b1", b["participants"][0])):
            participant = db.session.get(Participant, pid)
            studies.answer_consent(participant, agree=True)
            studies.start_session(participant)
            trial = studies.session_state(participant).trial
            people[name] = {"id": pid, "user": participant.user_id, "trial": trial.id, "code": participant.code, "token": participant.link_token}
        gt = db.session.execute(db.select(Annotation).where(Annotation.mask_path.is_not(None))).scalars().first()
        people["gt_mask"] = gt.mask_path
        people["study_a"], people["study_b"] = study_a.id, b["study"]
        return people


def sign_in(client, app, user_id):
    with app.app_context():
        client.login_as(db.session.get(User, user_id))


def test_a_participant_reaches_only_their_own_trials(app, client, tmp_path):
    ids = two_studies(app, tmp_path)
    sign_in(client, app, ids["a1"]["user"])
    with client.get(f"/s/trials/{ids['a1']['trial']}/image") as own:
        assert own.status_code == 200 and own.mimetype == "image/png"
        assert own.headers["Cache-Control"] == "no-store"
        with app.app_context():
            assert own.data == media.read(db.session.get(Trial, ids["a1"]["trial"]).frame.rgb_path)
    for other in ("a2", "b1"):  # the same study's other participant, and another study's
        trial = ids[other]["trial"]
        with client.get(f"/s/trials/{trial}/image") as response:
            assert response.status_code == 404
        response = client.post(f"/s/api/trials/{trial}", json={"clicks": [], "none": True}, headers=JSON)
        assert response.status_code == 404 and response.get_json()["error"] == "not_found"
    with app.app_context():
        assert db.session.get(Trial, ids["a2"]["trial"]).outcome is None  # untouched
    state = client.get("/s/api/current", headers=JSON).get_json()
    assert state["trial"]["id"] == ids["a1"]["trial"]
    text = str(state)
    assert "mask" not in text and "annotation" not in text and "frame_id" not in text


def test_participants_never_reach_ground_truth_media_or_staff_pages(app, client, tmp_path):
    ids = two_studies(app, tmp_path)
    sign_in(client, app, ids["a1"]["user"])
    with client.get(f"/media/{ids['gt_mask']}") as response:
        assert response.status_code == 403
    for url in (
        "/",
        "/api/activities",
        "/studies/",
        f"/studies/{ids['study_a']}",
        f"/studies/{ids['study_a']}/export/study.json",
        f"/studies/{ids['study_a']}/trials/{ids['a1']['trial']}/overlay.png",
        f"/studies/{ids['study_a']}/participants/{ids['a2']['id']}",
    ):
        with client.get(url, headers=JSON) as response:
            assert response.status_code == 403, url


def test_staff_and_strangers_cannot_act_as_participants(app, client, make_user, tmp_path):
    ids = two_studies(app, tmp_path)
    trial = ids["a1"]["trial"]
    assert client.get("/s/trials").status_code == 302  # signed out: to the log-in page
    assert client.get("/s/api/current", headers=JSON).status_code == 401
    client.login_as(make_user("annotator"))
    assert client.get("/studies/").status_code == 403
    with client.get(f"/s/trials/{trial}/image") as response:
        assert response.status_code == 403
    client.login_as(make_user("participant", "walk-in"))  # a participant user with no enrolment
    assert client.get("/s/api/current", headers=JSON).status_code == 403
    with client.get(f"/s/trials/{trial}/image") as response:
        assert response.status_code == 403


def test_codes_and_single_use_links(app, client, tmp_path):
    ids = two_studies(app, tmp_path)
    wrong = client.post("/s/", data={"code": "ZZZZ-ZZZZ"})
    assert wrong.status_code == 401 and b"not known" in wrong.data
    link = f"/s/l/{ids['a2']['token']}"
    # Opening the link (twice: a link-preview bot, then the participant) only shows the Start button.
    for _ in range(2):
        page = client.get(link)
        assert page.status_code == 200 and b'id="start-link"' in page.data and b'name="csrf_token"' in page.data
        assert client.get("/s/api/current", headers=JSON).status_code == 401  # not signed in
    with app.app_context():
        assert db.session.get(Participant, ids["a2"]["id"]).link_used_at is None
    start = client.post(link)
    assert start.status_code == 302 and start.headers["Location"].endswith("/s/trials")
    assert client.get("/s/api/current", headers=JSON).get_json()["trial"]["id"] == ids["a2"]["trial"]
    with app.app_context():
        assert db.session.get(Participant, ids["a2"]["id"]).link_used_at is not None
    # Another browser cannot use it again, nor is it offered the button.
    other = app.test_client()
    again = other.post(link)
    assert again.status_code == 410 and b"already been used" in again.data
    assert other.get("/s/api/current", headers=JSON).status_code == 401
    used = other.get(link)
    assert used.status_code == 410 and b"already been used" in used.data and b"start-link" not in used.data
    client.post("/logout")
    assert client.get("/s/l/not-a-token").status_code == 404
    assert client.post("/s/l/not-a-token").status_code == 404
    # The code still works after the link, and brings the participant back where they were.
    back = client.post("/s/", data={"code": ids["a2"]["code"].lower()})
    assert back.headers["Location"].endswith("/s/trials")
    assert client.get("/s/").headers["Location"].endswith("/s/trials")
    # Signing in with another code switches to that participant, who sees only their own trial.
    client.post("/s/", data={"code": ids["b1"]["code"]})
    assert client.get("/s/api/current", headers=JSON).get_json()["trial"]["id"] == ids["b1"]["trial"]


def test_a_declined_consent_ends_the_session(app, client, tmp_path):
    with app.app_context():
        ids = build_study(tmp_path, participants=1)
        code = db.session.get(Participant, ids["participants"][0]).code
    client.post("/s/", data={"code": code})
    consent = client.get("/s/consent")
    assert consent.status_code == 200 and b"I agree" in consent.data
    assert client.post("/s/consent", data={"decision": "decline"}).headers["Location"].endswith("/s/done")
    done = client.get("/s/done")
    assert b"chose not to take part" in done.data
    assert client.post("/s/start").headers["Location"].endswith("/s/done")
    assert client.get("/s/api/current", headers=JSON).get_json()["end_reason"] == "declined"


def test_the_page_gets_only_the_frame_on_screen_and_the_next(app, client, tmp_path):
    with app.app_context():
        ids = build_study(tmp_path, frames=2, per_activity=2, participants=1)
        participant = db.session.get(Participant, ids["participants"][0])
        code, trials = participant.code, [t.id for t in participant.trials]  # in trial order

    def fetchable():
        statuses = []
        for trial in trials:
            with client.get(f"/s/trials/{trial}/image") as response:
                statuses.append(response.status_code)
        return statuses

    client.post("/s/", data={"code": code})
    assert fetchable() == [404, 404, 404, 404]  # before consent
    client.post("/s/consent", data={"decision": "agree"})
    assert fetchable() == [404, 404, 404, 404]  # before start
    client.post("/s/start")
    assert fetchable() == [200, 200, 404, 404]  # the first on screen, the second to preload
    state = client.get("/s/api/current", headers=JSON).get_json()
    assert (state["trial"]["id"], state["next"]["id"]) == (trials[0], trials[1])
    refused = client.get(f"/s/trials/{trials[2]}/image", headers=JSON)
    assert refused.status_code == 404 and refused.get_json()["error"] == "not_found"
    client.post(state["trial"]["submit_url"], json={"clicks": [], "none": True}, headers=JSON)
    assert fetchable() == [404, 200, 200, 404]  # the answered one is gone, the third comes
    for _ in range(3):
        state = client.get("/s/api/current", headers=JSON).get_json()
        client.post(state["trial"]["submit_url"], json={"clicks": [], "none": True}, headers=JSON)
    assert client.get("/s/api/current", headers=JSON).get_json()["step"] == "done"
    assert fetchable() == [404, 404, 404, 404]  # after the end


def test_participant_pages_are_never_stored(app, client, tmp_path):
    with app.app_context():
        ids = build_study(tmp_path, participants=1)
        code = db.session.get(Participant, ids["participants"][0]).code
    answers = [client.get("/s/"), client.post("/s/", data={"code": code}), client.get("/s/consent")]
    answers += [client.post("/s/consent", data={"decision": "agree"}), client.get("/s/instructions"), client.post("/s/start")]
    answers += [client.get("/s/trials"), state := client.get("/s/api/current", headers=JSON)]
    with client.get(state.get_json()["trial"]["image_url"]) as image:
        assert image.status_code == 200
        answers.append(image)
    answers.append(client.post(state.get_json()["trial"]["submit_url"], json={"clicks": [], "none": True}, headers=JSON))
    answers.append(client.get("/s/trials/999/image"))
    for response in answers:
        assert response.headers["Cache-Control"] == "no-store", (response.request.path, response.status_code)
        assert "Expires" not in response.headers
