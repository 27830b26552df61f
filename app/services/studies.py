"""Human studies: building a study, running timed sessions, soft masks and exports.

Building: a study draws ``frames_per_activity`` frames at random from each
chosen activity's eligible frames (those with a finished ground truth, see
``app.services.ground_truth``), with ``random.Random(f"{seed}:{activity
name}")``, so the same seed over the same eligible frames draws the same
frames. Each participant gets every drawn frame once, shuffled with their own
``order_seed`` (derived from the study seed and their number).

Timing: the server is the authority. ``now()`` reads the app's
``STUDY_CLOCK`` (a callable returning an aware UTC datetime; tests freeze
it). The session deadline is stored when the participant starts. A trial is
stamped ``shown_at`` when it is first served; an answer is accepted until the
trial's deadline (the session deadline, or ``shown_at`` plus the per-trial
limit if sooner) plus ``LATE_GRACE_S``. The grace covers the request's
travel time: the page submits on its own when its countdown reaches zero, and
that request arrives a little after the deadline. A later answer is refused
with 409; past the session deadline the session ends (``time_up``), past a
per-trial limit only that trial is closed (``expired``) and the next follows.
While the session runs, the participant's page may fetch the frame on
screen and the next one (``trial_frame``), no other.

Soft masks: ``egonet.clicks.soft_mask`` on superpixels computed once per
frame and cached under ``CACHE_ROOT/superpixels/<settings key>/`` as a
compressed ``.npz`` named by the frame's content hash, written atomically.

For the scorer: ``study_participants(study_ids)`` and
``participant_soft_masks(participant)``.
"""

import csv
import hashlib
import io as _io
import json
import random
import secrets
import zipfile
from collections import defaultdict
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from datetime import datetime, timedelta
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from flask import current_app
from sqlalchemy import func, update
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import selectinload

from app.errors import ApiError, Problem
from app.extensions import db
from app.models import Activity, Frame, Role, Sequence, User, utcnow
from app.models.studies import (
    ANSWERED,
    Click,
    EndReason,
    EntryKind,
    EventKind,
    Outcome,
    Participant,
    Study,
    StudyFrame,
    Trial,
    TrialEvent,
)
from app.services import ground_truth, media
from egonet import clicks as egonet_clicks
from egonet import io
from egonet.clicks import SUPERPIXEL_DEFAULTS

LATE_GRACE_S = 2.0
"""Seconds after a deadline during which an answer is still accepted (network latency)."""

SUPERPIXEL_OPTIONS = {"slic": ("n_segments", "compactness"), "felzenszwalb": ("scale", "min_size")}
DEFAULT_SUPERPIXELS = {
    "method": SUPERPIXEL_DEFAULTS.method,
    **{name: getattr(SUPERPIXEL_DEFAULTS, name) for name in SUPERPIXEL_OPTIONS[SUPERPIXEL_DEFAULTS.method]},
    "max_side": SUPERPIXEL_DEFAULTS.max_side,
}
# Each option's default (egonet.clicks.SUPERPIXEL_DEFAULTS), type and accepted range.
OPTION_RULES = {
    "n_segments": (SUPERPIXEL_DEFAULTS.n_segments, int, 1, 10_000),
    "compactness": (SUPERPIXEL_DEFAULTS.compactness, float, 1e-3, 1e3),
    "scale": (SUPERPIXEL_DEFAULTS.scale, float, 1e-3, 1e5),
    "min_size": (SUPERPIXEL_DEFAULTS.min_size, int, 1, 100_000),
}

DEFAULT_INSTRUCTIONS = (
    "You will see photos taken by a camera worn on a person's head during an everyday activity.\n\n"
    "In each photo, click the centre of every object the person is acting on: touching it (taking a cup) "
    "or deliberately looking at it (watching a TV). If there is no such object, answer None.\n\n"
    "Work quickly but carefully: the session has a time limit, shown at the top of the page."
)
DEFAULT_CONSENT = (
    "This study records where you click on each photo, how long you take, and when the window loses focus "
    "or changes size. Your answers are stored under a participant number, not your name. Taking part is "
    "voluntary and you may stop at any time by closing the window."
)

# Access codes: 8 characters without look-alikes (no 0/O, 1/I/L): 31^8, about 10^12.
CODE_ALPHABET = "ABCDEFGHJKMNPQRSTUVWXYZ23456789"
CODE_LENGTH = 8

LINK_USED = "this study link has already been used; enter your access code instead"

MAX_CLICKS = 50
MAX_EVENTS = 2000


class StudyProblem(Problem):
    """A study or participant request that cannot go ahead; ``field`` names the bad input."""


def new_seed() -> int:
    """A random seed for a new study (recorded with it)."""
    return secrets.randbelow(2**31)


def now() -> datetime:
    """The server's time for study timing (the app's ``STUDY_CLOCK``, UTC)."""
    return current_app.config.get("STUDY_CLOCK", utcnow)()


# --------------------------------------------------------------------------
# Building a study


def eligible_counts() -> list[tuple[Activity, int]]:
    """Every activity with its number of frames eligible for a study (finished ground truth)."""
    counts: dict[int, int] = defaultdict(int)
    for frame in ground_truth.labelled_frames():
        counts[frame.sequence.activity_id] += 1
    activities = db.session.execute(db.select(Activity).order_by(Activity.name)).scalars()
    return [(activity, counts[activity.id]) for activity in activities]


def check_superpixels(settings: dict[str, Any]) -> dict[str, Any]:
    """Validate superpixel settings (``egonet.clicks.superpixels`` options); return them normalised.

    Raises:
        StudyProblem: naming the bad option.
    """
    method = settings.get("method")
    if method not in SUPERPIXEL_OPTIONS:
        raise StudyProblem(f"superpixel method must be one of {', '.join(SUPERPIXEL_OPTIONS)}", field="superpixel_method")
    allowed = {"method", "max_side", *SUPERPIXEL_OPTIONS[method]}
    unknown = sorted(k for k, v in settings.items() if k not in allowed and v is not None)
    if unknown:
        raise StudyProblem(f"{', '.join(unknown)} does not apply to the {method} method", field=unknown[0])
    out: dict[str, Any] = {"method": method}
    for name in SUPERPIXEL_OPTIONS[method]:
        default, kind, low, high = OPTION_RULES[name]
        value = settings.get(name)
        if value is None:
            value = default
        if isinstance(value, bool) or not isinstance(value, int | float) or not low <= value <= high:
            raise StudyProblem(f"{name} must be a number in [{low}, {high}]", field=name)
        if kind is int and value != int(value):
            raise StudyProblem(f"{name} must be a whole number", field=name)
        out[name] = kind(value)
    max_side = settings.get("max_side", DEFAULT_SUPERPIXELS["max_side"])
    if max_side is not None:
        if isinstance(max_side, bool) or not isinstance(max_side, int | float) or max_side != int(max_side) or not 8 <= max_side <= 8192:
            raise StudyProblem("max_side must be a whole number in [8, 8192] (or empty for full resolution)", field="max_side")
        max_side = int(max_side)
    out["max_side"] = max_side
    return out


def create_study(
    *,
    name: str,
    activity_ids: Iterable[int],
    frames_per_activity: int = 100,
    seed: int | None = None,
    time_limit_s: int = 3600,
    trial_limit_s: int | None = None,
    multiple_clicks: bool = True,
    sigma_px: float = egonet_clicks.DEFAULT_SIGMA,
    superpixels: dict[str, Any] | None = None,
    instructions: str = DEFAULT_INSTRUCTIONS,
    consent: str = DEFAULT_CONSENT,
    created_by: User | None = None,
) -> Study:
    """Create a study and draw its frames, in one transaction.

    Args:
        name: Shown to the admin only.
        activity_ids: Activities to draw from; each must have at least
            ``frames_per_activity`` eligible frames.
        frames_per_activity: Frames drawn from each activity (the paper: 100).
        seed: Seed of the draw and of the participants' orders; a random one
            is drawn and recorded when None.
        time_limit_s: Session time limit (the paper: about an hour).
        trial_limit_s: Optional limit per trial.
        multiple_clicks: Several clicks per frame (then Next), or one
            click that answers at once.
        sigma_px: Click Gaussian's standard deviation in native pixels.
        superpixels: Options of ``egonet.clicks.superpixels``.
        instructions, consent: Texts shown to participants (plain text).
        created_by: The admin creating it.

    Raises:
        StudyProblem: naming the bad field, e.g. an activity with too few
            eligible frames.
    """
    name = (name or "").strip()
    if not 1 <= len(name) <= 200:
        raise StudyProblem("the name must have 1-200 characters", field="name")
    activity_ids = sorted(set(activity_ids))
    if not activity_ids:
        raise StudyProblem("choose at least one activity", field="activities")
    _check_int(frames_per_activity, "frames_per_activity", 1, 100_000)
    if seed is None:
        seed = new_seed()
    _check_int(seed, "seed", 0, 2**31 - 1)
    _check_int(time_limit_s, "time_limit_s", 1, 7 * 24 * 3600)
    if trial_limit_s is not None:
        _check_int(trial_limit_s, "trial_limit_s", 1, 24 * 3600)
    if isinstance(sigma_px, bool) or not isinstance(sigma_px, int | float) or not 0.5 <= sigma_px <= 10_000:
        raise StudyProblem("sigma must be a number of pixels in [0.5, 10000]", field="sigma_px")
    settings = check_superpixels(dict(superpixels or DEFAULT_SUPERPIXELS))

    activities = db.session.execute(db.select(Activity).where(Activity.id.in_(activity_ids)).order_by(Activity.name)).scalars().all()
    if len(activities) != len(activity_ids):
        raise StudyProblem("unknown activity", field="activities")
    eligible: dict[int, list[Frame]] = defaultdict(list)
    for frame in ground_truth.labelled_frames(activity_ids):
        eligible[frame.sequence.activity_id].append(frame)
    short = [f"{a.name} has {len(eligible[a.id])}" for a in activities if len(eligible[a.id]) < frames_per_activity]
    if short:
        raise StudyProblem(
            f"not enough eligible frames (finished ground truth) for {frames_per_activity} per activity: {'; '.join(short)}",
            field="frames_per_activity",
        )

    study = Study(
        name=name,
        seed=seed,
        frames_per_activity=frames_per_activity,
        time_limit_s=time_limit_s,
        trial_limit_s=trial_limit_s,
        multiple_clicks=bool(multiple_clicks),
        sigma_px=float(sigma_px),
        superpixels=settings,
        # Browsers send CRLF from a textarea; blank lines separate paragraphs on the pages.
        instructions=instructions.replace("\r\n", "\n").strip(),
        consent=consent.replace("\r\n", "\n").strip(),
        created_by=created_by,
    )
    position = 0
    for activity in activities:
        drawn = random.Random(f"{seed}:{activity.name}").sample(eligible[activity.id], frames_per_activity)
        for frame in drawn:
            position += 1
            study.frames.append(StudyFrame(frame=frame, position=position))
    db.session.add(study)
    db.session.commit()
    return study


def _check_int(value: Any, name: str, low: int, high: int) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
        raise StudyProblem(f"{name} must be a whole number in [{low}, {high}]", field=name)


def order_seed(study_seed: int, number: int) -> int:
    """The seed of participant ``number``'s trial order (31 bits, stable across platforms)."""
    digest = hashlib.sha256(f"{study_seed}:participant:{number}".encode()).digest()
    return int.from_bytes(digest[:4], "big") >> 1


def add_participants(study: Study, *, count: int, entry: EntryKind | str = EntryKind.CODE) -> list[Participant]:
    """Create ``count`` participants, each a user with the participant role and their trials.

    Every participant gets an access code; with ``entry="link"`` also a
    single-use sign-in link. Their trials cover every study frame in an
    order shuffled with their own ``order_seed``. One transaction.

    Raises:
        StudyProblem: for a bad count or entry kind, or when someone else
            added participants at the same moment (try again).
    """
    _check_int(count, "count", 1, 500)
    try:
        entry = EntryKind(entry)
    except ValueError:
        raise StudyProblem(f"entry must be one of {', '.join(e.value for e in EntryKind)}", field="entry") from None
    last = db.session.execute(db.select(func.max(Participant.number)).where(Participant.study_id == study.id)).scalar()
    frames = list(study.frames)
    created = []
    for number in range((last or 0) + 1, (last or 0) + 1 + count):
        seed = order_seed(study.seed, number)
        user = User(username=f"p-{study.id}-{number:03d}", role=Role.PARTICIPANT, password_hash=None)
        participant = Participant(
            study=study,
            user=user,
            number=number,
            entry=entry,
            code=_new_code(),
            link_token=secrets.token_urlsafe(32) if entry is EntryKind.LINK else None,
            order_seed=seed,
        )
        order = frames[:]
        random.Random(seed).shuffle(order)
        participant.trials = [Trial(study_frame=sf, position=i) for i, sf in enumerate(order, start=1)]
        db.session.add(participant)
        created.append(participant)
    try:
        db.session.commit()
    except IntegrityError:
        db.session.rollback()
        raise StudyProblem("participants were added at the same moment by someone else; try again", field="count") from None
    return created


def _new_code() -> str:
    return "".join(secrets.choice(CODE_ALPHABET) for _ in range(CODE_LENGTH))


def format_code(code: str) -> str:
    """``ABCD2345`` -> ``ABCD-2345`` (easier to read out and type)."""
    return f"{code[:4]}-{code[4:]}"


# --------------------------------------------------------------------------
# Entering, consent, start


def participant_by_code(code: str) -> Participant | None:
    """The participant with this access code (case, spaces and dashes ignored)."""
    cleaned = "".join(c for c in (code or "").upper() if c.isalnum())
    if len(cleaned) != CODE_LENGTH:
        return None
    return db.session.execute(db.select(Participant).filter_by(code=cleaned)).scalar_one_or_none()


def link_participant(token: str) -> Participant:
    """The participant whose single-use link this is, leaving the link unused.

    Raises:
        ApiError: 404 for an unknown link, 410 for one already used.
    """
    participant = db.session.execute(db.select(Participant).filter_by(link_token=token)).scalar_one_or_none()
    if participant is None:
        raise ApiError(404, "this study link does not exist")
    if participant.link_used_at is not None:
        raise ApiError(410, LINK_USED)
    return participant


def use_link(token: str) -> Participant:
    """The participant whose single-use link this is, marking the link used.

    Raises:
        ApiError: 404 for an unknown link, 410 for one already used.
    """
    participant = link_participant(token)
    claimed = db.session.execute(
        update(Participant)
        .where(Participant.id == participant.id, Participant.link_used_at.is_(None))
        .values(link_used_at=now())
    )
    db.session.commit()
    if claimed.rowcount != 1:
        raise ApiError(410, LINK_USED)
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


# --------------------------------------------------------------------------
# Trials


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
        ApiError: 404 for any other frame.
    """
    if step(participant) != "trials" or now() >= participant.deadline:
        raise ApiError(404, "no photo is shown before the session starts or after it ends")
    if trial not in _pending(participant):
        raise ApiError(404, "only the photo on screen and the next one can be fetched")
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
        ApiError: 409 (with ``reason``) when the trial was already answered
            (``submitted``), is not the one on screen (``not_current``), the
            session is not running (``not_started``, ``finished``), or the
            answer came too late (``time_up``: the session ends;
            ``trial_time_up``: this trial is closed and the session goes
            on); 400 naming the field for an answer that does not fit the
            frame or the study's click rules.
    """
    t = now()
    if trial.outcome is Outcome.EXPIRED:
        if participant.end_reason is EndReason.TIME_UP:
            raise ApiError(409, "time is up: the session has ended", reason="time_up")
        raise ApiError(409, "the time for this photo ran out", reason="trial_time_up")
    if trial.outcome is not None:
        raise ApiError(409, "this trial was already answered and cannot be changed", reason="submitted")
    if participant.finished_at is not None:
        raise ApiError(409, "the session is over", reason="finished")
    if participant.started_at is None:
        raise ApiError(409, "the session has not started", reason="not_started")
    grace = timedelta(seconds=LATE_GRACE_S)
    if t > participant.deadline + grace:
        _finish(participant, EndReason.TIME_UP, at=participant.deadline)
        db.session.commit()
        raise ApiError(409, "time is up: the session has ended", reason="time_up")
    pending = _pending(participant, limit=1)
    if not pending or pending[0].id != trial.id or trial.shown_at is None:
        raise ApiError(409, "this is not the trial on screen; reload the page", reason="not_current")
    if t > _trial_deadline(trial, participant) + grace:
        _close(trial, outcome=Outcome.EXPIRED)
        db.session.commit()
        raise ApiError(409, "the time for this photo is up; the next one follows", reason="trial_time_up")
    _check_answer(participant.study, trial.frame, answer)

    if answer.none:
        outcome = Outcome.NONE
    elif not answer.timed_out:
        outcome = Outcome.CLICKED
    else:  # sent by the page when time ran out: the clicks made until then are the answer, if any
        outcome = Outcome.TIMED_OUT if answer.clicks else Outcome.EXPIRED
    closed = _close(
        trial,
        outcome=outcome,
        submitted_at=t,
        rt_ms=answer.rt_ms,
        window_width=answer.window_width,
        window_height=answer.window_height,
        display_width=answer.display_width,
        display_height=answer.display_height,
        pixel_ratio=answer.pixel_ratio,
    )
    if not closed:
        db.session.rollback()
        raise ApiError(409, "this trial was already answered and cannot be changed", reason="submitted")
    for i, (x, y, rt) in enumerate(answer.clicks, start=1):
        db.session.add(Click(trial_id=trial.id, position=i, x=x, y=y, rt_ms=rt, received_at=t))
    first = db.session.execute(db.select(func.count()).where(TrialEvent.trial_id == trial.id)).scalar_one() + 1
    for i, event in enumerate(answer.events, start=first):
        db.session.add(
            TrialEvent(trial_id=trial.id, position=i, kind=event.kind, client_ms=event.client_ms, server_at=t, detail=event.detail)
        )
    db.session.commit()
    return session_state(participant)


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
        raise ApiError(400, f"invalid field {first}: {fields[first]}", fields=fields)


# --------------------------------------------------------------------------
# Progress (admin)


@dataclass
class Progress:
    participant: Participant
    status: str
    answered: int
    closed: int
    total: int
    time_used_s: float | None


def progress(participant: Participant) -> Progress:
    """Trials answered and closed, and time used, for the admin's table."""
    counts: dict[Outcome | None, int] = defaultdict(int)
    for outcome, n in db.session.execute(
        db.select(Trial.outcome, func.count()).where(Trial.participant_id == participant.id).group_by(Trial.outcome)
    ):
        counts[outcome] += n
    total = sum(counts.values())
    answered = sum(counts[o] for o in ANSWERED)
    used = None
    if participant.started_at is not None:
        end = participant.finished_at or min(now(), participant.deadline)
        used = max(0.0, (end - participant.started_at).total_seconds())
    if participant.finished_at is not None:
        status = participant.end_reason.value.replace("_", " ")
    elif participant.started_at is not None:
        status = "time up" if now() >= participant.deadline else "running"
    elif participant.consented_at is not None:
        status = "consented"
    else:
        status = "not started"
    return Progress(participant, status, answered, total - counts[None], total, used)


@dataclass
class StudySummary:
    study: Study
    frames: int
    participants: int
    finished: int


def study_summaries() -> list[StudySummary]:
    """Every study, newest first, with its participant counts (the admin's list)."""
    finished = dict(
        db.session.execute(
            db.select(Participant.study_id, func.count()).where(Participant.finished_at.is_not(None)).group_by(Participant.study_id)
        ).all()
    )
    rows = []
    for study in db.session.execute(db.select(Study).order_by(Study.created_at.desc(), Study.id.desc())).scalars():
        rows.append(StudySummary(study, len(study.frames), len(study.participants), finished.get(study.id, 0)))
    return rows


def activity_table(study: Study) -> tuple[list[dict[str, Any]], int]:
    """Per activity of a study: frames drawn and eligible now; and how many frames have cached superpixels."""
    eligible = {activity.id: n for activity, n in eligible_counts()}
    rows: dict[int, dict[str, Any]] = {}
    cached = 0
    for sf in study.frames:
        activity = sf.frame.sequence.activity
        row = rows.setdefault(activity.id, {"activity": activity, "drawn": 0, "eligible": eligible.get(activity.id, 0)})
        row["drawn"] += 1
        cached += cached_superpixels(sf.frame, study.superpixels)
    return sorted(rows.values(), key=lambda r: r["activity"].name), cached


def answered_counts(study_frames: Iterable[StudyFrame]) -> dict[int, int]:
    """How many participants answered each of these study frames (by study frame id)."""
    ids = [sf.id for sf in study_frames]
    return dict(
        db.session.execute(
            db.select(Trial.study_frame_id, func.count())
            .where(Trial.study_frame_id.in_(ids), Trial.outcome.in_(ANSWERED))
            .group_by(Trial.study_frame_id)
        ).all()
    )


# --------------------------------------------------------------------------
# Superpixels (cached) and soft masks


def settings_key(settings: dict[str, Any]) -> str:
    """A short stable name for a set of superpixel options."""
    return hashlib.sha256(json.dumps(settings, sort_keys=True).encode()).hexdigest()[:16]


def _labels_path(frame: Frame, settings: dict[str, Any]) -> Path:
    root = Path(current_app.config["CACHE_ROOT"]) / "superpixels" / settings_key(settings)
    return root / frame.content_hash[:2] / f"{frame.content_hash}.npz"


def cached_superpixels(frame: Frame, settings: dict[str, Any]) -> bool:
    return _labels_path(frame, settings).exists()


def superpixel_labels(frame: Frame, settings: dict[str, Any]) -> np.ndarray:
    """The frame's superpixel labels, int (H, W): from the cache, or computed once and cached."""
    path = _labels_path(frame, settings)
    try:
        with np.load(path, allow_pickle=False) as data:
            labels = data["labels"]
        if labels.shape == (frame.height, frame.width):
            return labels
    except (OSError, ValueError, KeyError, zipfile.BadZipFile):
        pass  # missing or unreadable: compute it again
    rgb = io.read_image(media.absolute_path(frame.rgb_path))
    labels = egonet_clicks.superpixels(rgb, **settings)
    # uint16 holds any realistic region count and halves the file.
    stored = labels.astype(np.uint16) if labels.max() < 2**16 else labels
    buffer = _io.BytesIO()
    np.savez_compressed(buffer, labels=stored)
    media.write_atomic(path, buffer.getvalue())
    return stored


def precompute_superpixels(study: Study, *, on_progress=None) -> int:
    """Compute and cache the superpixels of every study frame; return how many were computed."""
    computed = 0
    for sf in study.frames:
        if not cached_superpixels(sf.frame, study.superpixels):
            superpixel_labels(sf.frame, study.superpixels)
            computed += 1
        if on_progress is not None:
            on_progress(1)
    return computed


def trial_soft_mask(trial: Trial) -> np.ndarray:
    """The trial's soft mask, float32 (H, W) in [0, 1] at the frame's native size.

    Raises:
        ValueError: if the trial has no answer (pending or expired).
    """
    if trial.outcome not in ANSWERED:
        raise ValueError(f"trial {trial.id} has no answer ({trial.outcome or 'pending'})")
    frame, study = trial.frame, trial.participant.study
    points = [(c.x, c.y) for c in trial.clicks]
    if not points:  # an answer of none: no need for superpixels
        return np.zeros((frame.height, frame.width), np.float32)
    labels = superpixel_labels(frame, study.superpixels)
    return egonet_clicks.soft_mask((frame.height, frame.width), points, sigma=study.sigma_px, labels=labels)


def answered_trials(study_frame: StudyFrame) -> list[Trial]:
    """The answered trials of one study frame, by participant number."""
    return list(
        db.session.execute(
            db.select(Trial)
            .join(Participant)
            .where(Trial.study_frame_id == study_frame.id, Trial.outcome.in_(ANSWERED))
            .order_by(Participant.number)
            .options(selectinload(Trial.clicks))
        ).scalars()
    )


def mean_soft_mask(study_frame: StudyFrame) -> tuple[np.ndarray | None, int]:
    """The mean of the participants' soft masks of a frame (the paper's Fig. 5), and how many answered."""
    trials = answered_trials(study_frame)
    if not trials:
        return None, 0
    total = np.zeros((study_frame.frame.height, study_frame.frame.width), np.float64)
    for trial in trials:
        total += trial_soft_mask(trial)
    return (total / len(trials)).astype(np.float32), len(trials)


def study_participants(study_ids: Iterable[int]) -> list[Participant]:
    """The participants of these studies, by study and number (for the scorer)."""
    return list(
        db.session.execute(
            db.select(Participant)
            .where(Participant.study_id.in_(list(study_ids)))
            .order_by(Participant.study_id, Participant.number)
        ).scalars()
    )


def participant_soft_masks(participant: Participant) -> Iterator[tuple[Frame, np.ndarray]]:
    """Each answered trial's frame and soft mask, float32 (H, W) in [0, 1], in trial order.

    Answers of "none" give zeros; a time-out keeps the clicks made before it.
    Expired and unanswered trials are left out (the participant gave no
    answer).
    """
    trials = db.session.execute(
        db.select(Trial)
        .where(Trial.participant_id == participant.id, Trial.outcome.in_(ANSWERED))
        .order_by(Trial.position)
        .options(selectinload(Trial.clicks), selectinload(Trial.study_frame).selectinload(StudyFrame.frame))
    ).scalars()
    for trial in trials:
        yield trial.frame, trial_soft_mask(trial)


def mask_png(mask: np.ndarray) -> bytes:
    """A soft mask as a 16-bit grayscale PNG (value * 65535), precise enough for 1/100 thresholds."""
    return io.encode_probability_png(mask)


def overlay_png(
    frame: Frame,
    mask: np.ndarray | None,
    *,
    points: Iterable[tuple[float, float]] = (),
    outline: np.ndarray | None = None,
    max_width: int = 640,
) -> bytes:
    """The frame with a soft mask as a heat map, clicks as rings and an optional outline (e.g. ground truth).

    The heat map's opacity follows the mask, so the frame shows through where
    the mask is low.
    """
    rgb = io.read_image(media.absolute_path(frame.rgb_path)).astype(np.float32)
    h, w = rgb.shape[:2]
    scale = min(1.0, max_width / w)
    size = (max(1, round(w * scale)), max(1, round(h * scale)))
    if scale < 1.0:
        rgb = cv2.resize(rgb, size, interpolation=cv2.INTER_AREA)
    out = rgb
    if mask is not None:
        m = cv2.resize(mask.astype(np.float32), size, interpolation=cv2.INTER_LINEAR) if scale < 1.0 else mask
        heat = cv2.cvtColor(cv2.applyColorMap(np.round(m * 255).astype(np.uint8), cv2.COLORMAP_TURBO), cv2.COLOR_BGR2RGB)
        alpha = (0.75 * np.clip(m, 0, 1))[..., None]
        out = rgb * (1 - alpha) + heat.astype(np.float32) * alpha
    out = np.clip(out, 0, 255).astype(np.uint8)
    if outline is not None:
        edge = cv2.resize(outline.astype(np.uint8), size, interpolation=cv2.INTER_NEAREST)
        contours, _ = cv2.findContours(edge, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
        cv2.drawContours(out, contours, -1, (60, 255, 60), 2, lineType=cv2.LINE_AA)
    for x, y in points:
        centre = (round((x + 0.5) * scale - 0.5), round((y + 0.5) * scale - 0.5))
        cv2.circle(out, centre, 7, (0, 0, 0), 3, lineType=cv2.LINE_AA)
        cv2.circle(out, centre, 7, (255, 255, 255), 2, lineType=cv2.LINE_AA)
    return io.encode_png(out)


# --------------------------------------------------------------------------
# Exports

TRIAL_COLUMNS = [
    "study_id", "participant", "participant_id", "trial_id", "position", "activity", "frame_id", "frame_source",
    "frame_width", "frame_height", "outcome", "clicks", "rt_ms", "shown_at", "submitted_at", "server_ms",
    "window_width", "window_height", "display_width", "display_height", "pixel_ratio", "events",
]  # fmt: skip
CLICK_COLUMNS = ["study_id", "participant", "trial_id", "position", "frame_id", "click", "x", "y", "rt_ms", "received_at"]
EVENT_COLUMNS = ["study_id", "participant", "trial_id", "position", "frame_id", "event", "kind", "client_ms", "server_at", "detail"]
EXPORTS = ("trials.csv", "clicks.csv", "events.csv", "study.json", "masks.zip")


def _iso(value: datetime | None) -> str | None:
    return value.isoformat() if value is not None else None


def _study_trials(study: Study) -> list[Trial]:
    return list(
        db.session.execute(
            db.select(Trial)
            .join(Participant)
            .where(Participant.study_id == study.id)
            .order_by(Participant.number, Trial.position)
            .options(
                selectinload(Trial.clicks),
                selectinload(Trial.events),
                selectinload(Trial.participant),
                selectinload(Trial.study_frame).selectinload(StudyFrame.frame).selectinload(Frame.sequence).selectinload(Sequence.activity),
            )
        ).scalars()
    )


def _trial_row(study: Study, trial: Trial) -> dict[str, Any]:
    frame = trial.frame
    server_ms = None
    if trial.shown_at is not None and trial.submitted_at is not None:
        server_ms = round((trial.submitted_at - trial.shown_at).total_seconds() * 1000, 1)
    return {
        "study_id": study.id,
        "participant": trial.participant.label,
        "participant_id": trial.participant_id,
        "trial_id": trial.id,
        "position": trial.position,
        "activity": frame.sequence.activity.name,
        "frame_id": frame.id,
        "frame_source": frame.source_name,
        "frame_width": frame.width,
        "frame_height": frame.height,
        "outcome": trial.outcome.value if trial.outcome else "pending",
        "clicks": len(trial.clicks),
        "rt_ms": trial.rt_ms,
        "shown_at": _iso(trial.shown_at),
        "submitted_at": _iso(trial.submitted_at),
        "server_ms": server_ms,
        "window_width": trial.window_width,
        "window_height": trial.window_height,
        "display_width": trial.display_width,
        "display_height": trial.display_height,
        "pixel_ratio": trial.pixel_ratio,
        "events": len(trial.events),
    }


def _click_rows(study: Study, trial: Trial) -> list[dict[str, Any]]:
    base = {"study_id": study.id, "participant": trial.participant.label, "trial_id": trial.id, "position": trial.position, "frame_id": trial.frame.id}
    return [
        {**base, "click": c.position, "x": c.x, "y": c.y, "rt_ms": c.rt_ms, "received_at": _iso(c.received_at)} for c in trial.clicks
    ]


def _event_rows(study: Study, trial: Trial) -> list[dict[str, Any]]:
    base = {"study_id": study.id, "participant": trial.participant.label, "trial_id": trial.id, "position": trial.position, "frame_id": trial.frame.id}
    return [
        {**base, "event": e.position, "kind": e.kind.value, "client_ms": e.client_ms, "server_at": _iso(e.server_at), "detail": e.detail}
        for e in trial.events
    ]


def export_csv(study: Study, table: str) -> str:
    """One table of the study's results as CSV: ``trials``, ``clicks`` or ``events``."""
    columns, rows_of = {
        "trials": (TRIAL_COLUMNS, lambda t: [_trial_row(study, t)]),
        "clicks": (CLICK_COLUMNS, lambda t: _click_rows(study, t)),
        "events": (EVENT_COLUMNS, lambda t: _event_rows(study, t)),
    }[table]
    out = _io.StringIO()
    writer = csv.DictWriter(out, fieldnames=columns, lineterminator="\n")
    writer.writeheader()
    for trial in _study_trials(study):
        for row in rows_of(trial):
            if "detail" in row:
                row["detail"] = json.dumps(row["detail"], sort_keys=True)
            writer.writerow(row)
    return out.getvalue()


def export_json(study: Study) -> dict[str, Any]:
    """The whole study as one JSON document: settings, frames, participants with trials, clicks and events."""
    trials = _study_trials(study)
    by_participant: dict[int, list[Trial]] = defaultdict(list)
    for trial in trials:
        by_participant[trial.participant_id].append(trial)
    participants = []
    for p in study.participants:
        participants.append(
            {
                "id": p.id,
                "label": p.label,
                "number": p.number,
                "entry": p.entry.value,
                "order_seed": p.order_seed,
                "consented_at": _iso(p.consented_at),
                "started_at": _iso(p.started_at),
                "deadline": _iso(p.deadline),
                "finished_at": _iso(p.finished_at),
                "end_reason": p.end_reason.value if p.end_reason else None,
                "trials": [
                    {
                        **{k: v for k, v in _trial_row(study, t).items() if k not in ("study_id", "participant", "participant_id", "clicks", "events")},
                        "clicks": [{"x": c.x, "y": c.y, "rt_ms": c.rt_ms, "received_at": _iso(c.received_at)} for c in t.clicks],
                        "events": [
                            {"kind": e.kind.value, "client_ms": e.client_ms, "server_at": _iso(e.server_at), "detail": e.detail}
                            for e in t.events
                        ],
                    }
                    for t in by_participant[p.id]
                ],
            }
        )
    return {
        "study": {
            "id": study.id,
            "name": study.name,
            "seed": study.seed,
            "frames_per_activity": study.frames_per_activity,
            "time_limit_s": study.time_limit_s,
            "trial_limit_s": study.trial_limit_s,
            "late_grace_s": LATE_GRACE_S,
            "multiple_clicks": study.multiple_clicks,
            "sigma_px": study.sigma_px,
            "superpixels": study.superpixels,
            "instructions": study.instructions,
            "consent": study.consent,
            "created_at": _iso(study.created_at),
        },
        "frames": [
            {
                "position": sf.position,
                "frame_id": sf.frame_id,
                "activity": sf.frame.sequence.activity.name,
                "sequence": sf.frame.sequence.name,
                "source_name": sf.frame.source_name,
                "content_hash": sf.frame.content_hash,
                "width": sf.frame.width,
                "height": sf.frame.height,
            }
            for sf in study.frames
        ],
        "participants": participants,
    }


def mask_files(study: Study) -> Iterator[tuple[str, bytes]]:
    """The soft masks as 16-bit PNGs: one per answered trial and the mean per frame, plus a manifest.

    Names: ``P01/0001-frame12.png`` (participant, trial position, frame id)
    and ``mean/frame12.png``; ``manifest.csv`` lists them.
    """
    manifest = _io.StringIO()
    writer = csv.writer(manifest, lineterminator="\n")
    writer.writerow(["file", "participant", "position", "frame_id", "activity", "frame_source", "outcome", "participants"])
    sums: dict[int, np.ndarray] = {}
    counts: dict[int, int] = defaultdict(int)
    for trial in _study_trials(study):
        if trial.outcome not in ANSWERED:
            continue
        frame = trial.frame
        mask = trial_soft_mask(trial)
        name = f"{trial.participant.label}/{trial.position:04d}-frame{frame.id}.png"
        writer.writerow([name, trial.participant.label, trial.position, frame.id, frame.sequence.activity.name, frame.source_name, trial.outcome.value, ""])
        yield name, mask_png(mask)
        sums[frame.id] = sums.get(frame.id, 0) + mask.astype(np.float64)
        counts[frame.id] += 1
    for sf in study.frames:
        frame = sf.frame
        if counts[frame.id]:
            name = f"mean/frame{frame.id}.png"
            writer.writerow([name, "mean", "", frame.id, frame.sequence.activity.name, frame.source_name, "", counts[frame.id]])
            yield name, mask_png((sums[frame.id] / counts[frame.id]).astype(np.float32))
    yield "manifest.csv", manifest.getvalue().encode()


class _Chunks(_io.RawIOBase):
    """A write-only stream whose bytes are taken out as they come (for a streamed zip)."""

    def __init__(self):
        self.parts: list[bytes] = []

    def writable(self) -> bool:
        return True

    def write(self, data) -> int:
        self.parts.append(bytes(data))
        return len(data)

    def take(self) -> bytes:
        out = b"".join(self.parts)
        self.parts.clear()
        return out


def masks_zip(study: Study) -> Iterator[bytes]:
    """``mask_files`` as a zip archive, produced piece by piece (PNGs are stored, not recompressed)."""
    stream = _Chunks()
    with zipfile.ZipFile(stream, "w", compression=zipfile.ZIP_STORED) as archive:
        for name, data in mask_files(study):
            archive.writestr(name, data)
            yield stream.take()
    yield stream.take()


def export_to_folder(study: Study, out: Path, *, on_start=None, on_progress=None) -> list[Path]:
    """Write every export (CSV, JSON, mask PNGs under ``masks/``) into ``out``; return the files.

    ``on_start(total)`` and ``on_progress(n)`` report the files written.
    """
    out = Path(out)
    answered = db.session.execute(
        db.select(func.count(), func.count(func.distinct(Trial.study_frame_id)))
        .select_from(Trial)
        .join(Participant)
        .where(Participant.study_id == study.id, Trial.outcome.in_(ANSWERED))
    ).one()
    if on_start is not None:
        on_start(4 + answered[0] + answered[1] + 1)  # tables, JSON, masks, means, manifest
    written = []

    def write(path: Path, data: bytes) -> None:
        media.write_atomic(path, data)
        written.append(path)
        if on_progress is not None:
            on_progress(1)

    for table in ("trials", "clicks", "events"):
        write(out / f"{table}.csv", export_csv(study, table).encode())
    write(out / "study.json", json.dumps(export_json(study), indent=1).encode())
    for name, data in mask_files(study):
        write(out / "masks" / name, data)
    return written
