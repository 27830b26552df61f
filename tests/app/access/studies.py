"""Access rules of the studies area (see __init__), and a study maker its tests share.

Participant routes admit the participant role, then ``_participant`` /
``_owned_trial`` refuse anyone who is not enrolled (the matrix's participant
user is not): 403. The link in ``url_values`` is already used: 410 for all,
for the page (GET) and for its Start button (POST); the open link is a
closed study's: 410 too. The admin's study has a participant who entered:
it can be neither edited (a redirect to the study) nor deleted (409). No
entry lock has ``lock_id`` (404), and a withdrawal lacks its confirmation (400).
"""

from app.extensions import db
from app.models import Activity, Role, Status
from app.models.studies import EntryKind, Participant
from app.services import studies
from app.services.importing import import_path
from tests.app.access import ADMIN
from tests.app.factories import image_folder

PARTICIPANT = frozenset({Role.PARTICIPANT})

RULES = {
    "studies.index": (ADMIN, 200),
    "studies.create": (ADMIN, {"GET": 200, "POST": 400}),
    "studies.detail": (ADMIN, 200),
    "studies.add_participants": (ADMIN, 400),
    "studies.participant": (ADMIN, 200),
    "studies.frames": (ADMIN, 200),
    "studies.frame": (ADMIN, 200),
    "studies.mean_overlay": (ADMIN, 200),
    "studies.trial_overlay": (ADMIN, 200),
    "studies.trial_mask": (ADMIN, 200),
    "studies.export": (ADMIN, 200),
    "studies.create_from_file": (ADMIN, 400),
    "studies.edit": (ADMIN, 302),
    "studies.duplicate": (ADMIN, 302),
    "studies.delete": (ADMIN, 409),
    "studies.set_status": (ADMIN, 400),
    "studies.set_active": (ADMIN, 400),
    "studies.release": (ADMIN, 302),
    "studies.clear_lock": (ADMIN, 404),
    "studies.withdraw": (ADMIN, 400),
    "study.entry": (None, {"GET": 200, "POST": 400}),
    "study.link": (None, 410),
    "study.open_link": (None, 410),
    "study.open_example": (None, 200),
    "study.comprehension": (PARTICIPANT, 403),
    "study.practice": (PARTICIPANT, 403),
    "study.ready": (PARTICIPANT, 403),
    "study.environment": (PARTICIPANT, 403),
    "study.consent": (PARTICIPANT, 403),
    "study.instructions": (PARTICIPANT, 403),
    "study.start": (PARTICIPANT, 403),
    "study.trials": (PARTICIPANT, 403),
    "study.done": (PARTICIPANT, 403),
    "study.current": (PARTICIPANT, 403),
    "study.submit": (PARTICIPANT, 403),
    "study.image": (PARTICIPANT, 403),
}


def build_study(
    tmp_path,
    *,
    activities=("cooking", "hotel"),
    frames=3,
    per_activity=2,
    participants=2,
    entry=EntryKind.CODE,
    **options,
) -> dict:
    """Import ``frames`` labelled frames per activity, create a study and participants (call in an app context).

    Returns ids: ``study``, ``participants`` (in number order), ``activities``.
    """
    for name in activities:
        import_path(image_folder(tmp_path / f"rec-{name}", n=frames, masks=True), activity=name, mask_status=Status.DONE)
    activity_ids = list(db.session.execute(db.select(Activity.id).where(Activity.name.in_(activities))).scalars())
    options.setdefault("seed", 7)
    study = studies.create_study(name="test study", activity_ids=activity_ids, frames_per_activity=per_activity, **options)
    people = studies.add_participants(study, count=participants, entry=entry) if participants else []
    return {"study": study.id, "participants": [p.id for p in people], "activities": activity_ids}


def url_values(app, tmp_path) -> dict:
    with app.app_context():
        ids = build_study(tmp_path / "studies", activities=("desk work",), participants=2, entry=EntryKind.LINK)
        first, second = (db.session.get(Participant, pid) for pid in ids["participants"])
        studies.use_link(second.link_token)
        closed = studies.create_study(
            name="closed", activity_ids=ids["activities"], frames_per_activity=1, seed=1, open_link={"cap": 5}
        )
        studies.set_status(closed, "closed")
        # The first participant answers a trial, so masks and overlays exist.
        studies.answer_consent(first, agree=True)
        studies.start_session(first)
        state = studies.session_state(first)
        trial = state.trial
        studies.submit(first, trial, studies.Answer(clicks=[(10.0, 20.0, 500.0)]))
        return {
            "study_id": ids["study"],
            "participant_id": first.id,
            "trial_id": trial.id,
            "study_frame_id": trial.study_frame_id,
            "export_name": "trials.csv",
            "token": second.link_token,
            "open_token": closed.open_link_token,
            "lock_id": 999_999,
        }
