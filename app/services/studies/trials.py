"""The trials: serving them on time, recording answers, refusing late ones.

A trial is stamped ``shown_at`` when it is first served; an answer is
accepted until the trial's deadline (the session deadline, or ``shown_at``
plus the per-trial limit if sooner; practice trials have only the per-trial
limit) plus ``LATE_GRACE_S``. The grace covers the request's travel time:
the page submits on its own when its countdown reaches zero, and that
request arrives a little after the deadline. A later answer is refused with
409; past the session deadline the session ends (``time_up``), past a
per-trial limit only that trial is closed (``expired``) and the next
follows. While a phase runs (practice, then the timed part), the
participant's page may fetch the frame on screen and the next one
(``trial_frame``), no other. Events the page sends (focus, resize, ...) are
stored with the answer, stamped by the server. A catch trial's ``hit`` is
stored with its answer; a practice answer gets feedback from the ground
truth when the frame has one.
"""

from dataclasses import dataclass, field
from datetime import datetime, timedelta
from typing import Any

from sqlalchemy import func, update

from app.extensions import db
from app.models import Frame
from app.models.studies import Click, EndReason, EventKind, FrameKind, Outcome, Participant, Study, StudyFrame, Trial, TrialEvent
from app.services.studies import checks, protocol
from app.services.studies.common import LATE_GRACE_S, StudyProblem, now
from app.services.studies.session import finish, refresh, step

MAX_CLICKS = 50
MAX_EVENTS = 2000
PHASES = ("practice", "trials")


@dataclass
class SessionState:
    """What the trial page needs: the trial to show, the one to preload, the clocks, the phase's progress."""

    step: str
    end_reason: EndReason | None
    trial: Trial | None = None
    next_trial: Trial | None = None
    done: int = 0  # trials of this phase closed (answered, or closed by a time limit)
    total: int = 0
    time_left_s: float | None = None
    trial_time_left_s: float | None = None
    shown_ms: float = 0.0  # how long the trial had been on screen already (server clock): > 0 after a reload
    feedback: str | None = None  # on the practice answer just given


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


def _phase_query(participant: Participant, phase: str):
    query = db.select(Trial).join(StudyFrame, Trial.study_frame).where(Trial.participant_id == participant.id)
    practice = StudyFrame.kind == FrameKind.PRACTICE
    return query.where(practice if phase == "practice" else ~practice)


def _pending(participant: Participant, phase: str, limit: int = 2) -> list[Trial]:
    query = _phase_query(participant, phase).where(Trial.outcome.is_(None)).order_by(Trial.position).limit(limit)
    return list(db.session.execute(query).scalars())


def _progress(participant: Participant, phase: str) -> tuple[int, int]:
    """Trials of the phase closed (an outcome, whether answered or closed by a limit) and in all."""
    query = _phase_query(participant, phase).with_only_columns(func.count(), func.count(Trial.outcome))
    total, closed = db.session.execute(query).one()
    return closed, total


def trial_frame(participant: Participant, trial: Trial) -> Frame:
    """The frame of one of the participant's trials, if their page may fetch it now.

    While a phase runs, the page gets the frame on screen (the first trial
    without an outcome) and the next one, to preload; never an earlier
    frame, one further ahead, or any frame before the start or after the end.

    Raises:
        StudyProblem: 404 for any other frame.
    """
    phase = step(participant)
    if phase not in PHASES or (phase == "trials" and now() >= participant.deadline):
        raise StudyProblem("no photo is shown before the session starts or after it ends", status=404)
    if trial not in _pending(participant, phase):
        raise StudyProblem("only the photo on screen and the next one can be fetched", status=404)
    return trial.frame


def _trial_deadline(trial: Trial, participant: Participant) -> datetime | None:
    limit = protocol.settings_of(participant).trial_limit_s
    practice = trial.kind is FrameKind.PRACTICE
    session = None if practice else participant.deadline
    if limit is None or trial.shown_at is None:
        return session
    own = trial.shown_at + timedelta(seconds=limit)
    return own if session is None else min(session, own)


def _close(trial: Trial, **values: Any) -> bool:
    """Set a pending trial's outcome (once: a concurrent close makes this return False)."""
    result = db.session.execute(update(Trial).where(Trial.id == trial.id, Trial.outcome.is_(None)).values(**values))
    return result.rowcount == 1


def session_state(participant: Participant, *, reload: bool = False, feedback: str | None = None) -> SessionState:
    """The current trial of the phase, served: stamped ``shown_at`` on first serve.

    The current trial is the first without an outcome, so a reload resumes
    there. A trial whose per-trial limit has passed is closed as expired
    and the next one is served. With ``reload``, serving a trial that was
    already shown records a ``reload`` event.
    """
    t = now()
    if step(refresh(participant)) == "trials" and t >= participant.deadline:
        finish(participant, EndReason.TIME_UP, at=participant.deadline)
        db.session.commit()
    phase = step(participant)
    if phase not in PHASES:
        done, total = _progress(participant, "trials")
        return SessionState(phase, participant.end_reason, done=done, total=total, feedback=feedback)
    while True:
        pending = _pending(participant, phase)
        if not pending:
            if phase == "trials":
                finish(participant, EndReason.COMPLETED, at=t)
                db.session.commit()
            return session_state(participant, feedback=feedback)
        trial = pending[0]
        deadline = _trial_deadline(trial, participant)
        if trial.shown_at is None:
            trial.shown_at = t
            deadline = _trial_deadline(trial, participant)
        elif deadline is not None and t > deadline + timedelta(seconds=LATE_GRACE_S):
            _close(trial, outcome=Outcome.EXPIRED)
            db.session.commit()
            continue
        elif reload:
            db.session.add(TrialEvent(trial=trial, position=len(trial.events) + 1, kind=EventKind.RELOAD, client_ms=None, server_at=t))
        db.session.commit()
        done, total = _progress(participant, phase)
        return SessionState(
            phase,
            None,
            trial=trial,
            next_trial=pending[1] if len(pending) > 1 else None,
            done=done,
            total=total,
            time_left_s=max(0.0, (participant.deadline - t).total_seconds()) if phase == "trials" else None,
            trial_time_left_s=None if deadline is None or protocol.settings_of(participant).trial_limit_s is None
            else max(0.0, (deadline - t).total_seconds()),
            shown_ms=round((t - trial.shown_at).total_seconds() * 1000, 1),
            feedback=feedback,
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
    feedback = _record(trial, answer, at=t)
    return session_state(participant, feedback=feedback)


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
    phase = step(participant)
    practice = trial.kind is FrameKind.PRACTICE
    if phase not in PHASES or (phase == "practice") != practice:
        raise StudyProblem("the session has not started", status=409, reason="not_started")
    grace = timedelta(seconds=LATE_GRACE_S)
    if not practice and at > participant.deadline + grace:
        finish(participant, EndReason.TIME_UP, at=participant.deadline)
        db.session.commit()
        raise StudyProblem("time is up: the session has ended", status=409, reason="time_up")
    pending = _pending(participant, phase, limit=1)
    if not pending or pending[0].id != trial.id or trial.shown_at is None:
        raise StudyProblem("this is not the trial on screen; reload the page", status=409, reason="not_current")
    deadline = _trial_deadline(trial, participant)
    if deadline is not None and at > deadline + grace:
        _close(trial, outcome=Outcome.EXPIRED)
        db.session.commit()
        raise StudyProblem("the time for this photo is up; the next one follows", status=409, reason="trial_time_up")


def _record(trial: Trial, answer: Answer, *, at: datetime) -> str | None:
    """Close the trial with the answer, its clicks and events (once: a concurrent answer gets 409); return practice feedback."""
    if answer.none:
        outcome = Outcome.NONE
    elif not answer.timed_out:
        outcome = Outcome.CLICKED
    else:  # sent by the page when time ran out: the clicks made until then are the answer, if any
        outcome = Outcome.TIMED_OUT if answer.clicks else Outcome.EXPIRED
    points = [(x, y) for x, y, _ in answer.clicks]
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
        hit=checks.catch_hit(trial.study_frame, points) if trial.kind is FrameKind.CATCH else None,
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
    return _practice_feedback(trial, points, none=answer.none) if trial.kind is FrameKind.PRACTICE else None


def _practice_feedback(trial: Trial, points: list[tuple[float, float]], *, none: bool) -> str | None:
    """A sentence on a practice answer, from the frame's ground truth (None without one)."""
    mask = checks.truth_mask(trial.frame)
    if mask is None:
        return None
    if not mask.any():
        return "Right: this photo has no action-object." if none else "This photo has no action-object: None was the answer."
    if none or not points:
        return "This photo has an action-object: click its centre."
    if all(checks.inside_mask(mask, points)):
        return "Well done: your click is on the action-object."
    return "Not quite: click the centre of the object the person is acting on."


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
