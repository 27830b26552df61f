"""The participant's way through a study: entering, consent, instructions and questions, practice, start, end.

Steps (``step``): ``consent``, ``instructions`` (with the comprehension
questions, when the study has them: all must be answered right to go on,
within ``max_attempts`` tries, else the participant is screened out),
``practice`` (the practice trials, untimed but for the per-trial limit),
``ready`` (the Start button of the timed part), ``trials`` and ``done``.
Without questions or practice, the instructions' Start starts the clock at
once. The session deadline is stored when the timed part starts (the
condition's time limit, or the study's). The trials themselves are
``app.services.studies.trials``.
"""

from datetime import datetime, timedelta
from typing import Any

from sqlalchemy import update

from app.extensions import db
from app.models import User
from app.models.studies import EndReason, EntryKind, FrameKind, Outcome, Participant, StudyFrame, StudyStatus, Trial
from app.services.studies import checks, protocol
from app.services.studies.common import LATE_GRACE_S, StudyProblem, now
from app.services.studies.recruiting import CLOSED, CODE_ALPHABET, CODE_LENGTH, PAUSED

LINK_USED = "this study link has already been used; enter your access code instead"
ENVIRONMENT_KEYS = ("screen", "window", "pixel_ratio", "time_zone", "touch")


def participant_by_code(code: str) -> Participant | None:
    """The participant with this access code (case, spaces and dashes ignored)."""
    cleaned = "".join(c for c in (code or "").upper() if c.isalnum())
    if len(cleaned) != CODE_LENGTH or not set(cleaned) <= set(CODE_ALPHABET):  # checked before any query
        return None
    return db.session.execute(db.select(Participant).filter_by(code=cleaned)).scalar_one_or_none()


def link_participant(token: str) -> Participant:
    """The participant whose single-use link this is, leaving the link unused.

    Raises:
        StudyProblem: 404 for an unknown link, 410 for one already used.
    """
    participant = db.session.execute(db.select(Participant).filter_by(link_token=token)).scalar_one_or_none()
    if participant is None:
        raise StudyProblem("this study link does not exist", status=404)
    if participant.link_used_at is not None:
        raise StudyProblem(LINK_USED, status=410)
    return participant


def use_link(token: str) -> Participant:
    """The participant whose single-use link this is, marking the link used.

    Raises:
        StudyProblem: 404 for an unknown link, 410 for one already used.
    """
    participant = link_participant(token)
    claimed = db.session.execute(
        update(Participant)
        .where(Participant.id == participant.id, Participant.link_used_at.is_(None))
        .values(link_used_at=now())
    )
    db.session.commit()
    if claimed.rowcount != 1:
        raise StudyProblem(LINK_USED, status=410)
    return participant


def check_may_enter(participant: Participant) -> None:
    """Refuse a participant who has not entered yet while the study is paused (409) or closed (410).

    Those who consented go on: a paused or closed study lets them finish.
    """
    if participant.consented_at is not None or participant.finished_at is not None:
        return
    status = participant.study.status
    if status is StudyStatus.PAUSED:
        raise StudyProblem(PAUSED, status=409, reason="paused")
    if status is StudyStatus.CLOSED:
        raise StudyProblem(CLOSED, status=410, reason="closed")


def participant_of(user: User) -> Participant | None:
    return db.session.execute(db.select(Participant).filter_by(user_id=user.id)).scalar_one_or_none()


def refresh(participant: Participant) -> Participant:
    """End the session once its deadline and the grace have passed.

    The server notices time-up on the participant's next request (or when
    staff look: ``close_overdue``). Within the grace the session stays open
    for an answer already on its way; ``session_state`` serves nothing new
    after the deadline itself.
    """
    if (
        participant.finished_at is None
        and participant.deadline is not None
        and now() > participant.deadline + timedelta(seconds=LATE_GRACE_S)
    ):
        finish(participant, EndReason.TIME_UP, at=participant.deadline)
        db.session.commit()
    return participant


def close_overdue(participant_ids: list[int]) -> int:
    """End the sessions among these whose deadline passed with nobody there to notice; return how many."""
    late = db.session.execute(
        db.select(Participant).where(
            Participant.id.in_(participant_ids),
            Participant.finished_at.is_(None),
            Participant.deadline < now() - timedelta(seconds=LATE_GRACE_S),
        )
    ).scalars().all()
    for participant in late:
        refresh(participant)
    return len(late)


def has_pending(participant: Participant, kind: FrameKind) -> bool:
    query = (
        db.select(Trial.id)
        .join(StudyFrame, Trial.study_frame)
        .where(Trial.participant_id == participant.id, Trial.outcome.is_(None), StudyFrame.kind == kind)
        .limit(1)
    )
    return db.session.execute(query).first() is not None


def step(participant: Participant) -> str:
    """Where the participant is: ``consent``, ``instructions``, ``practice``, ``ready``, ``trials`` or ``done``."""
    if participant.finished_at is not None:
        return "done"
    if participant.consented_at is None:
        return "consent"
    if participant.started_at is not None:
        return "trials"
    if participant.instructions_done_at is None:
        return "instructions"
    return "practice" if has_pending(participant, FrameKind.PRACTICE) else "ready"


def answer_consent(participant: Participant, *, agree: bool) -> None:
    """Record consent, or end the session when it is declined."""
    if step(participant) != "consent":
        return
    if agree:
        db.session.execute(
            update(Participant).where(Participant.id == participant.id, Participant.consented_at.is_(None)).values(consented_at=now())
        )
    else:
        finish(participant, EndReason.DECLINED, at=now())
    db.session.commit()


def answer_comprehension(participant: Participant, answers: dict[int, int]) -> int | None:
    """Grade one try at the comprehension questions; return the tries left (None: unlimited).

    Right answers to all questions end the instructions step; a wrong try
    beyond the last allowed screens the participant out.
    """
    questions = participant.study.comprehension.get("questions") or []
    if step(participant) != "instructions" or not questions:
        return None
    limit = participant.study.comprehension.get("max_attempts")
    query = update(Participant).where(Participant.id == participant.id)
    if limit is not None:  # a try counts only while tries are left
        query = query.where(Participant.comprehension_attempts < limit)
    counted = db.session.execute(query.values(comprehension_attempts=Participant.comprehension_attempts + 1))
    db.session.refresh(participant)
    left = None if limit is None else max(0, limit - participant.comprehension_attempts)
    if counted.rowcount and checks.grade(questions, answers):
        t = now()
        participant.comprehension_passed_at = t
        participant.instructions_done_at = t
    elif left == 0:
        finish(participant, EndReason.SCREENED_OUT, at=now())
    db.session.commit()
    return left


def start_session(participant: Participant) -> None:
    """The instructions' and the ready page's Start: end the instructions, and start the clock when nothing
    (questions, practice) comes first: store ``started_at`` and ``deadline`` (once)."""
    where = step(participant)
    if where == "instructions" and not participant.study.comprehension:
        participant.instructions_done_at = now()
        db.session.commit()
        where = step(participant)
    if where != "ready":
        return
    t = now()
    limit = protocol.settings_of(participant).time_limit_s
    db.session.execute(
        update(Participant)
        .where(Participant.id == participant.id, Participant.started_at.is_(None))
        .values(started_at=t, deadline=t + timedelta(seconds=limit))
    )
    db.session.commit()


def finish(participant: Participant, reason: EndReason, *, at: datetime) -> None:
    """Close the session (once), expire the trial on screen at time-up and record the code given; the caller commits."""
    done = db.session.execute(
        update(Participant)
        .where(Participant.id == participant.id, Participant.finished_at.is_(None))
        .values(finished_at=at, end_reason=reason)
    )
    if not done.rowcount:
        return
    if reason is EndReason.TIME_UP:
        db.session.execute(
            update(Trial)
            .where(Trial.participant_id == participant.id, Trial.outcome.is_(None), Trial.shown_at.is_not(None))
            .values(outcome=Outcome.EXPIRED)
        )
    db.session.refresh(participant)
    participant.completion_code = checks.completion_code(participant, reason)


def completion(participant: Participant) -> tuple[str | None, str | None]:
    """The code given at the end and where to send the participant with it, if anywhere: the study's redirect URL
    (a platform's completion page) is for those who came from a platform through the open link; lab codes and
    single-use links stay on the page (MTurk's own form is ``recruiting.mturk_submit_url``)."""
    code = participant.completion_code
    if code is None:
        return None, None
    if participant.entry is not EntryKind.OPEN:
        return code, None
    return code, protocol.redirect_to(participant.study.redirect_url, code)


def record_environment(participant: Participant, environment: dict[str, Any], *, user_agent: str | None) -> None:
    """Store what the page reports of its screen, window, pixel ratio and time zone (the latest report wins)."""
    participant.environment = {key: environment.get(key) for key in ENVIRONMENT_KEYS} | {"reported_at": now().isoformat()}
    if user_agent:
        participant.user_agent = user_agent[:512]
    db.session.commit()
