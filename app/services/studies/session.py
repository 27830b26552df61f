"""The participant's side of a study: entering, consent, the timed session, trials and answers.

A participant enters with an access code or a single-use link. The session
deadline is stored when the participant starts. A trial is stamped
``shown_at`` when it is first served; an answer is accepted until the
trial's deadline (the session deadline, or ``shown_at`` plus the per-trial
limit if sooner) plus ``LATE_GRACE_S``. The grace covers the request's
travel time: the page submits on its own when its countdown reaches zero, and
that request arrives a little after the deadline. A later answer is refused
with 409; past the session deadline the session ends (``time_up``), past a
per-trial limit only that trial is closed (``expired``) and the next follows.
While the session runs, the participant's page may fetch the frame on
screen and the next one (``trial_frame``), no other. Events the page sends
(focus, resize, ...) are stored with the answer, stamped by the server.
"""

from dataclasses import dataclass, field
from datetime import datetime, timedelta
from typing import Any

from sqlalchemy import func, update

from app.extensions import db
from app.models import Frame, User
from app.models.studies import Click, EndReason, EventKind, Outcome, Participant, Study, Trial, TrialEvent
from app.services.studies.building import CODE_LENGTH
from app.services.studies.common import LATE_GRACE_S, StudyProblem, now

LINK_USED = "this study link has already been used; enter your access code instead"

MAX_CLICKS = 50
MAX_EVENTS = 2000



def participant_by_code(code: str) -> Participant | None:
    """The participant with this access code (case, spaces and dashes ignored)."""
    cleaned = "".join(c for c in (code or "").upper() if c.isalnum())
    if len(cleaned) != CODE_LENGTH:
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


def participant_of(user: User) -> Participant | None:
    return db.session.execute(db.select(Participant).filter_by(user_id=user.id)).scalar_one_or_none()


def refresh(participant: Participant) -> Participant:
    """End the session once its deadline and the grace have passed.

    The server notices time-up on the participant's next request. Within
    the grace the session stays open for an answer already on its way;
    ``session_state`` serves nothing new after the deadline itself.
    """
    if (
        participant.finished_at is None
        and participant.deadline is not None
        and now() > participant.deadline + timedelta(seconds=LATE_GRACE_S)
    ):
        _finish(participant, EndReason.TIME_UP, at=participant.deadline)
        db.session.commit()
    return participant


def step(participant: Participant) -> str:
    """Where the participant is: ``consent``, ``instructions``, ``trials`` or ``done``."""
    if participant.finished_at is not None:
        return "done"
    if participant.consented_at is None:
        return "consent"
    if participant.started_at is None:
        return "instructions"
    return "trials"


def answer_consent(participant: Participant, *, agree: bool) -> None:
    """Record consent, or end the session when it is declined."""
    if step(participant) != "consent":
        return
    if agree:
        db.session.execute(
            update(Participant).where(Participant.id == participant.id, Participant.consented_at.is_(None)).values(consented_at=now())
        )
    else:
        _finish(participant, EndReason.DECLINED, at=now())
    db.session.commit()


def start_session(participant: Participant) -> None:
    """Start the clock: store ``started_at`` and ``deadline`` (once)."""
    if step(participant) != "instructions":
        return
    t = now()
    db.session.execute(
        update(Participant)
        .where(Participant.id == participant.id, Participant.started_at.is_(None))
        .values(started_at=t, deadline=t + timedelta(seconds=participant.study.time_limit_s))
    )
    db.session.commit()


def _finish(participant: Participant, reason: EndReason, *, at: datetime) -> None:
    """Close the session (once) and expire the trial on screen; the caller commits."""
    done = db.session.execute(
        update(Participant)
        .where(Participant.id == participant.id, Participant.finished_at.is_(None))
        .values(finished_at=at, end_reason=reason)
    )
    if done.rowcount and reason is EndReason.TIME_UP:
        db.session.execute(
            update(Trial)
            .where(Trial.participant_id == participant.id, Trial.outcome.is_(None), Trial.shown_at.is_not(None))
            .values(outcome=Outcome.EXPIRED)
        )



@dataclass
class SessionState:
    """What the trial page needs: the trial to show, the one to preload, the clocks."""

    step: str
    end_reason: EndReason | None
    trial: Trial | None = None
    next_trial: Trial | None = None
    done: int = 0
    total: int = 0
    time_left_s: float | None = None
    trial_time_left_s: float | None = None


@dataclass
class ClientEvent:
    kind: EventKind
    client_ms: float
    detail: dict[str, Any] = field(default_factory=dict)


@dataclass
class Answer:
    """A trial's answer as the page sends it. Coordinates in native frame pixels, times in ms since paint."""

    clicks: list[tuple[float, float, float]]  # (x, y, rt_ms)
    none: bool = False
    timed_out: bool = False
    rt_ms: float | None = None
    events: list[ClientEvent] = field(default_factory=list)
    window_width: int | None = None
    window_height: int | None = None
    display_width: float | None = None
    display_height: float | None = None
    pixel_ratio: float | None = None


def _pending(participant: Participant, limit: int = 2) -> list[Trial]:
    return list(
        db.session.execute(
            db.select(Trial)
            .where(Trial.participant_id == participant.id, Trial.outcome.is_(None))
            .order_by(Trial.position)
            .limit(limit)
        ).scalars()
    )


def trial_frame(participant: Participant, trial: Trial) -> Frame:
    """The frame of one of the participant's trials, if their page may fetch it now.

    While the session runs, the page gets the frame on screen (the first
    trial without an outcome) and the next one, to preload; never an earlier
    frame, one further ahead, or any frame before the start or after the end.

    Raises:
        StudyProblem: 404 for any other frame.
    """
    if step(participant) != "trials" or now() >= participant.deadline:
        raise StudyProblem("no photo is shown before the session starts or after it ends", status=404)
    if trial not in _pending(participant):
        raise StudyProblem("only the photo on screen and the next one can be fetched", status=404)
    return trial.frame


def _trial_deadline(trial: Trial, participant: Participant) -> datetime:
    limit = participant.study.trial_limit_s
    if limit is None or trial.shown_at is None:
        return participant.deadline
    return min(participant.deadline, trial.shown_at + timedelta(seconds=limit))


def _close(trial: Trial, **values: Any) -> bool:
    """Set a pending trial's outcome (once: a concurrent close makes this return False)."""
    result = db.session.execute(update(Trial).where(Trial.id == trial.id, Trial.outcome.is_(None)).values(**values))
    return result.rowcount == 1


def session_state(participant: Participant, *, reload: bool = False) -> SessionState:
    """The current trial, served: stamped ``shown_at`` on first serve.

    The current trial is the first without an outcome, so a reload resumes
    there. A trial whose per-trial limit has passed is closed as expired
    and the next one is served. With ``reload``, serving a trial that was
    already shown records a ``reload`` event.
    """
    t = now()
    if step(refresh(participant)) == "trials" and t >= participant.deadline:
        _finish(participant, EndReason.TIME_UP, at=participant.deadline)
        db.session.commit()
    counts = dict(
        db.session.execute(
            db.select(Trial.outcome.is_not(None), func.count())
            .where(Trial.participant_id == participant.id)
            .group_by(Trial.outcome.is_not(None))
        ).all()
    )
    total = sum(counts.values())
    where = step(participant)
    if where != "trials":
        return SessionState(where, participant.end_reason, done=counts.get(True, 0), total=total)
    while True:
        pending = _pending(participant)
        if not pending:
            _finish(participant, EndReason.COMPLETED, at=t)
            db.session.commit()
            return SessionState("done", participant.end_reason, done=total, total=total)
        trial = pending[0]
        if trial.shown_at is None:
            trial.shown_at = t
        elif t > _trial_deadline(trial, participant) + timedelta(seconds=LATE_GRACE_S):
            _close(trial, outcome=Outcome.EXPIRED)
            db.session.commit()
            continue
        elif reload:
            db.session.add(TrialEvent(trial=trial, position=len(trial.events) + 1, kind=EventKind.RELOAD, client_ms=None, server_at=t))
        db.session.commit()
        trial_left = None
        if participant.study.trial_limit_s is not None:
            trial_left = max(0.0, (_trial_deadline(trial, participant) - t).total_seconds())
        return SessionState(
            "trials",
            None,
            trial=trial,
            next_trial=pending[1] if len(pending) > 1 else None,
            done=trial.position - 1,
            total=total,
            time_left_s=max(0.0, (participant.deadline - t).total_seconds()),
            trial_time_left_s=trial_left,
        )


def submit(participant: Participant, trial: Trial, answer: Answer) -> SessionState:
    """Record a trial's answer and serve the next trial.

    Raises:
        StudyProblem: 409 (with ``reason``) when the trial was already answered
            (``submitted``), is not the one on screen (``not_current``), the
            session is not running (``not_started``, ``finished``), or the
            answer came too late (``time_up``: the session ends;
            ``trial_time_up``: this trial is closed and the session goes
            on); 400 naming the field for an answer that does not fit the
            frame or the study's click rules.
    """
    t = now()
    _check_on_time(participant, trial, at=t)
    _check_answer(participant.study, trial.frame, answer)
    _record(trial, answer, at=t)
    return session_state(participant)


def _check_on_time(participant: Participant, trial: Trial, *, at: datetime) -> None:
    """Refuse (409 with ``reason``) an answer to a trial that is not open now; close what ran out."""
    if trial.outcome is Outcome.EXPIRED:
        if participant.end_reason is EndReason.TIME_UP:
            raise StudyProblem("time is up: the session has ended", status=409, reason="time_up")
        raise StudyProblem("the time for this photo ran out", status=409, reason="trial_time_up")
    if trial.outcome is not None:
        raise StudyProblem("this trial was already answered and cannot be changed", status=409, reason="submitted")
    if participant.finished_at is not None:
        raise StudyProblem("the session is over", status=409, reason="finished")
    if participant.started_at is None:
        raise StudyProblem("the session has not started", status=409, reason="not_started")
    grace = timedelta(seconds=LATE_GRACE_S)
    if at > participant.deadline + grace:
        _finish(participant, EndReason.TIME_UP, at=participant.deadline)
        db.session.commit()
        raise StudyProblem("time is up: the session has ended", status=409, reason="time_up")
    pending = _pending(participant, limit=1)
    if not pending or pending[0].id != trial.id or trial.shown_at is None:
        raise StudyProblem("this is not the trial on screen; reload the page", status=409, reason="not_current")
    if at > _trial_deadline(trial, participant) + grace:
        _close(trial, outcome=Outcome.EXPIRED)
        db.session.commit()
        raise StudyProblem("the time for this photo is up; the next one follows", status=409, reason="trial_time_up")


def _record(trial: Trial, answer: Answer, *, at: datetime) -> None:
    """Close the trial with the answer, its clicks and events (once: a concurrent answer gets 409)."""
    if answer.none:
        outcome = Outcome.NONE
    elif not answer.timed_out:
        outcome = Outcome.CLICKED
    else:  # sent by the page when time ran out: the clicks made until then are the answer, if any
        outcome = Outcome.TIMED_OUT if answer.clicks else Outcome.EXPIRED
    closed = _close(
        trial,
        outcome=outcome,
        submitted_at=at,
        rt_ms=answer.rt_ms,
        window_width=answer.window_width,
        window_height=answer.window_height,
        display_width=answer.display_width,
        display_height=answer.display_height,
        pixel_ratio=answer.pixel_ratio,
    )
    if not closed:
        db.session.rollback()
        raise StudyProblem("this trial was already answered and cannot be changed", status=409, reason="submitted")
    for i, (x, y, rt) in enumerate(answer.clicks, start=1):
        db.session.add(Click(trial_id=trial.id, position=i, x=x, y=y, rt_ms=rt, received_at=at))
    first = db.session.execute(db.select(func.count()).where(TrialEvent.trial_id == trial.id)).scalar_one() + 1
    for i, event in enumerate(answer.events, start=first):
        db.session.add(
            TrialEvent(trial_id=trial.id, position=i, kind=event.kind, client_ms=event.client_ms, server_at=at, detail=event.detail)
        )
    db.session.commit()


def _check_answer(study: Study, frame: Frame, answer: Answer) -> None:
    w, h = frame.width, frame.height
    fields = {}
    for i, (x, y, _) in enumerate(answer.clicks):
        if not (-0.5 <= x <= w - 0.5 and -0.5 <= y <= h - 0.5):
            fields[f"clicks[{i}]"] = f"({x:.1f}, {y:.1f}) lies outside the {w}x{h} frame"
    if answer.none and answer.clicks:
        fields["none"] = "an answer of none has no clicks"
    if answer.none and answer.timed_out:
        fields["timed_out"] = "an answer of none is not a time-out"
    if not study.multiple_clicks and len(answer.clicks) > 1:
        fields["clicks"] = "this study takes one click per photo"
    if not answer.clicks and not answer.none and not answer.timed_out:
        fields["clicks"] = "click the action-object, or answer none"
    if fields:
        first = sorted(fields)[0]
        raise StudyProblem(f"invalid field {first}: {fields[first]}", field=first, fields=fields)
