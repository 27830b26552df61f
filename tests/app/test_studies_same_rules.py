"""The same rules everywhere: pilots in no mean map, the open link's places, a withdrawn participant's row, the
per-frame CSV's pixel count, what the pages and docs say of time."""

import csv
import io
import re
from pathlib import Path

import cv2
import numpy as np

from app.extensions import db
from app.models import Frame
from app.models.studies import Participant, Study
from app.services import studies
from app.services.scoring.perframe import frame_table
from app.services.users import create_user
from tests.app.access.studies import build_study
from tests.app.test_studies_pilots import answer_all, table

DOCS = Path(__file__).resolve().parents[2] / "docs" / "studies.md"


def test_the_results_pages_mean_maps_leave_pilots_out_and_badge_them(app, admin_client, tmp_path):
    with app.app_context():
        ids = build_study(tmp_path, frames=2, per_activity=1, participants=2)
        study = db.session.get(Study, ids["study"])
        pilot = studies.add_participants(study, count=1, pilot=True)[0]
        people = [*ids["participants"], pilot.id]
        for pid in people:
            answer_all(pid)
        # The pilot clicks elsewhere than the others: their mask must not move the mean.
        for trial in db.session.get(Participant, pilot.id).trials:
            trial.clicks[0].x, trial.clicks[0].y = 40.0, 40.0
        db.session.commit()
        study_frame = study.frames[0]
        masks = [studies.trial_soft_mask(t) for t in studies.answered_trials(study_frame)]
        pilots = [t.participant.pilot for t in studies.answered_trials(study_frame)]
        mean, count = studies.mean_soft_mask(study_frame)
        expected = np.mean([m.astype(np.float64) for m, p in zip(masks, pilots, strict=True) if not p], axis=0)
        assert count == 2 and np.abs(mean - expected).max() < 1e-6
        assert np.abs(np.mean(masks, axis=0) - mean).max() > 1e-3  # the pilot would have changed it
        frame_page = f"/studies/{study.id}/frames/{study_frame.id}"
    page = admin_client.get(frame_page).get_data(as_text=True)
    assert "Mean soft mask of 2 participants (pilots left out)" in page
    assert page.count('<span class="kind">pilot</span>') == 1
    results = admin_client.get(f"/studies/{ids['study']}/frames").get_data(as_text=True)
    assert "pilots left out" in results and "2 in the mean" in results


def test_the_open_links_places_are_its_own_arrivals(app, admin_client, tmp_path):
    with app.app_context():
        ids = build_study(tmp_path, participants=2, open_link={"cap": 3})  # two lab codes
        study = db.session.get(Study, ids["study"])
        studies.add_participants(study, count=1, entry="link")  # a single-use link, never used
        token = study.open_link_token
    newcomer = app.test_client()
    assert newcomer.post(f"/s/o/{token}", data={"PROLIFIC_PID": "5f1e2d3c4b5a69788796a5b1", "STUDY_ID": "s", "SESSION_ID": "v1"}).status_code == 302
    page = admin_client.get(f"/studies/{ids['study']}").get_data(as_text=True)
    assert "Open link (1 place taken of 3)" in page
    with app.app_context():
        study = db.session.get(Study, ids["study"])
        assert studies.places_taken(study) == 1
        studies.set_active(study.participants[-1], False)  # deactivating the newcomer frees their place
        assert studies.places_taken(study) == 0


def test_a_withdrawn_participants_row_says_who_and_when_and_no_checks(app, tmp_path):
    with app.app_context():
        ids = build_study(tmp_path, frames=2, per_activity=1, participants=2)
        for pid in ids["participants"]:
            answer_all(pid)
        staff, _ = create_user("ethics", "admin")
        gone = db.session.get(Participant, ids["participants"][0])
        studies.withdraw(gone, by=staff)
        rows = list(csv.DictReader(io.StringIO(studies.export_csv(db.session.get(Study, ids["study"]), "participants"))))
        when = gone.withdrawn_at.isoformat()
    withdrawn, kept = rows
    assert (withdrawn["status"], withdrawn["withdrawn_by"], withdrawn["withdrawn_at"]) == ("withdrawn", "ethics", when)
    assert [withdrawn[k] for k in ("checks_passed", "comprehension", "catch_passed", "catch_total")] == ["", "", "", ""]
    assert (kept["checks_passed"], kept["comprehension"], kept["withdrawn_at"], kept["withdrawn_by"]) == ("True", "none", "", "")


def test_the_per_frame_csv_counts_action_object_pixels(app, tmp_path):
    with app.app_context():
        ids = build_study(tmp_path, frames=3, per_activity=3, participants=1)
        answer_all(ids["participants"][0])
        csv_text = frame_table(study_ids=[ids["study"]], activity="cooking").to_csv()
        sources = {f.id: f.source_name for f in db.session.execute(db.select(Frame)).scalars()}
    rows = list(csv.DictReader(io.StringIO(csv_text)))
    assert len(rows) == 3
    for row in rows:
        # the mask files the frames were imported with, counted here
        stem = sources[int(row["frame_id"])]
        mask = cv2.imread(str(tmp_path / "rec-cooking" / "masks" / f"{Path(stem).stem}.png"), cv2.IMREAD_GRAYSCALE)
        assert int(row["action-object pixels"]) == int(np.count_nonzero(mask)) > 1


def test_pages_and_docs_say_what_the_time_limit_and_the_grace_are(app, client, tmp_path):
    with app.app_context():
        ids = build_study(tmp_path, participants=0, open_link={"cap": 5}, time_limit_s=30 * 60)
        token = db.session.get(Study, ids["study"]).open_link_token
    page = client.get(f"/s/o/{token}").get_data(as_text=True)
    assert "with at most 30 min to do them (the time limit)" in page and "in about" not in page
    docs = DOCS.read_text()
    assert re.search(rf"late grace\*\*: an answer arriving up to {studies.LATE_GRACE_S:g} s after a deadline", docs)
