"""Studies made before revision 0009 keep working after it (their rows go down to 0006 and up again)."""

from flask_migrate import downgrade, upgrade

from app.extensions import db
from app.models.studies import EntryKind, FrameKind, Participant, Study, StudyStatus
from app.services import studies
from tests.app.access.studies import build_study


def test_a_study_from_before_the_upgrade_runs_as_it_did(ctx, tmp_path):
    ids = build_study(tmp_path, participants=2, sigma_px=5.0)
    first = db.session.get(Participant, ids["participants"][0])
    studies.answer_consent(first, agree=True)
    studies.start_session(first)
    trial = studies.session_state(first).trial
    studies.submit(first, trial, studies.Answer(clicks=[(3.0, 4.0, 120.0)]))
    db.session.remove()

    downgrade(revision="0006")  # the new columns and table go, the rows stay
    upgrade()
    db.session.remove()

    study = db.session.get(Study, ids["study"])
    assert (study.status, study.open_link_token, study.sigma_scaled, study.sigma_px, study.version) == (StudyStatus.OPEN, None, False, 5.0, 1)
    assert study.display == {} and study.comprehension == {} and study.conditions == []
    assert {sf.kind for sf in study.frames} == {FrameKind.MAIN}
    first, second = study.participants
    assert first.entry is EntryKind.CODE and first.external == {} and first.condition is None
    # The one who had started goes on where they were; the other enters as before.
    state = studies.session_state(first)
    assert state.step == "trials" and state.trial.position == 2 and state.done == 1
    assert studies.step(second) == "consent"
    studies.answer_consent(second, agree=True)
    studies.start_session(second)
    assert studies.step(second) == "trials"
    assert len(list(studies.participant_soft_masks(first))) == 1
