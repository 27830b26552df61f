"""Pilots (marked in every export, left out of scores and the cap) and withdrawal (one participant's data deleted on request)."""

import csv
import io
import logging
import zipfile

from app.extensions import db
from app.models.studies import Click, EntryKind, Participant, Study, Trial, TrialEvent
from app.services import studies
from app.services.scoring import cache, sources
from tests.app.access.studies import build_study
from tests.app.conftest import PASSWORD


def answer_all(participant_id: int) -> None:
    """The participant consents and answers every trial with one click and a blur event (call in an app context)."""
    participant = db.session.get(Participant, participant_id)
    studies.answer_consent(participant, agree=True)
    studies.start_session(participant)
    while (trial := studies.session_state(participant).trial) is not None:
        blur = studies.ClientEvent(kind="blur", client_ms=10.0, detail={})
        studies.submit(participant, trial, studies.Answer(clicks=[(5.0, 5.0, 300.0)], rt_ms=320.0, events=[blur]))


def table(client, study_id: int, name: str) -> list[dict]:
    return list(csv.DictReader(io.StringIO(client.get(f"/studies/{study_id}/export/{name}.csv").get_data(as_text=True))))


def test_pilots_are_marked_in_exports_and_left_out_of_scores_and_the_cap(app, admin_client, tmp_path):
    with app.app_context():
        ids = build_study(tmp_path, frames=2, per_activity=1, participants=1, open_link={"cap": 2})
        study = db.session.get(Study, ids["study"])
        study_id, token = study.id, study.open_link_token
    added = admin_client.post(f"/studies/{study_id}/participants", data={"count": "2", "entry": "link", "pilot": "y"})
    assert added.status_code == 302
    assert "pilot" in admin_client.get(f"/studies/{study_id}").get_data(as_text=True)
    with app.app_context():
        people = db.session.get(Study, study_id).participants
        assert [p.pilot for p in people] == [False, True, True]
        for person in people:
            answer_all(person.id)
        assert studies.places_taken(db.session.get(Study, study_id)) == 0  # neither the pilots nor a lab code hold a place
        real = people[0].id
    # Two arrivals fit under the open link's cap of 2, whatever the pilots and the lab code.
    assert app.test_client().post(f"/s/o/{token}").status_code == 302
    assert app.test_client().post(f"/s/o/{token}").status_code == 302
    assert app.test_client().get(f"/s/o/{token}").status_code == 409

    for name in ("trials", "clicks", "events", "participants"):
        rows = table(admin_client, study_id, name)
        pilots = {r["participant"] for r in rows if r["pilot"] == "True"}
        assert pilots == {"P02", "P03"} and {r["pilot"] for r in rows if r["participant"] == "P01"} == {"False"}, name
    archive = zipfile.ZipFile(io.BytesIO(admin_client.get(f"/studies/{study_id}/export/masks.zip").data))
    manifest = list(csv.DictReader(io.StringIO(archive.read("manifest.csv").decode())))
    assert {r["participant"] for r in manifest if r["pilot"] == "True"} == {"P02", "P03"}
    assert {r["participants"] for r in manifest if r["participant"] == "mean"} == {"1"}  # the means leave pilots out
    document = admin_client.get(f"/studies/{study_id}/export/study.json").get_json()
    assert [p["pilot"] for p in document["participants"]] == [False, True, True, False, False]

    with app.app_context():
        scored = [p.id for p, _ in sources.human_participants([study_id])]
        assert real in scored and len(scored) == 3  # P01 and the open link's two newcomers
        assert len(studies.study_participants([study_id], include_pilots=True)) == 5


def test_withdrawal_deletes_one_participants_data_and_keeps_their_row(app, admin_client, make_user, tmp_path, caplog):
    with app.app_context():
        ids = build_study(tmp_path, frames=2, per_activity=1, participants=2, entry=EntryKind.LINK)
        gone, kept = ids["participants"]
        for pid in (gone, kept):
            answer_all(pid)
        trials = db.session.execute(db.select(Trial.id).where(Trial.participant_id == gone)).scalars().all()
        files = [cache.cache_path({"participant": pid, "trials": [1]}) for pid in (gone, kept)]
        for path in files:
            cache.write_cached(path, {}, [])
        participant_user = db.session.get(Participant, gone).user
    page = f"/studies/{ids['study']}/participants/{gone}"
    assert 'id="withdraw"' in admin_client.get(page).get_data(as_text=True)

    # Staff only, CSRF-protected, and confirmed by typing the participant's label.
    make_user("annotator", "ann")
    annotator = app.test_client()
    assert annotator.login("ann", PASSWORD).status_code == 302
    assert annotator.post(f"{page}/withdraw", data={"confirm": "P01"}).status_code == 403
    assert admin_client.post(f"{page}/withdraw", data={"confirm": "P01"}, csrf=False).status_code == 400
    refused = admin_client.post(f"{page}/withdraw", data={"confirm": "P02"}, headers={"Accept": "application/json"})
    assert refused.status_code == 400 and refused.get_json()["fields"] == {"confirm": "must be P01"}

    taking_part = app.test_client()
    taking_part.login_as(participant_user)
    assert taking_part.get("/s/api/current").status_code == 200
    with caplog.at_level(logging.WARNING):
        done = admin_client.post(f"{page}/withdraw", data={"confirm": "p01"})
    assert done.status_code == 302 and done.headers["Location"].endswith(page)
    assert any("P01 withdrawn by admin" in r.getMessage() for r in caplog.records)

    with app.app_context():
        person = db.session.get(Participant, gone)
        assert person.withdrawn_at is not None and person.withdrawn_by.username == "admin" and not person.user.active
        assert person.user_agent is None and person.code and not person.trials
        for model in (Trial, Click, TrialEvent):
            column = model.participant_id if model is Trial else model.trial_id
            owned = db.select(model).where(column.in_(trials) if model is not Trial else column == gone)
            assert db.session.execute(owned).first() is None, model
        assert len(db.session.get(Participant, kept).trials) == len(trials) == 2
        assert [p.id for p in studies.study_participants([ids["study"]])] == [kept]
    assert not files[0].exists() and files[1].exists()
    ended = taking_part.get("/s/api/current")  # their session ended with their data
    assert ended.status_code == 302 and ended.headers["Location"].endswith("/s/")  # back to the entry form
    assert admin_client.get(f"/studies/{ids['study']}/trials/{trials[0]}/overlay.png").status_code == 404

    rows = table(admin_client, ids["study"], "participants")
    assert [(r["participant"], r["status"]) for r in rows] == [("P01", "withdrawn"), ("P02", "completed")]
    assert {r["participant"] for r in table(admin_client, ids["study"], "trials")} == {"P02"}
    shown = admin_client.get(page).get_data(as_text=True)
    assert 'id="withdrawn"' in shown and "by admin" in shown and 'id="withdraw"' not in shown
    assert admin_client.post(f"{page}/withdraw", data={"confirm": "P01"}).status_code == 409
    assert admin_client.post(f"{page}/active", data={"active": "1"}).status_code == 409
