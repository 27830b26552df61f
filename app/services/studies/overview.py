"""The admin's overview of studies: participant progress, summaries, conditions, frames per activity, answers per frame."""

from collections import defaultdict
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

from sqlalchemy import func

from app.extensions import db
from app.models.studies import ANSWERED, FrameKind, Outcome, Participant, Study, StudyFrame, Trial
from app.services.studies.building import eligible_counts
from app.services.studies.common import now
from app.services.studies.masks import cached_superpixels
from app.services.studies.recruiting import condition_places, places_taken
from app.services.studies.session import has_pending


@dataclass
class Progress:
    participant: Participant
    status: str
    answered: int
    closed: int
    total: int
    time_used_s: float | None


def progress(participant: Participant) -> Progress:
    """Trials of the timed part answered and closed, and time used, for the admin's table."""
    counts: dict[Outcome | None, int] = defaultdict(int)
    for outcome, n in db.session.execute(
        db.select(Trial.outcome, func.count())
        .join(StudyFrame, Trial.study_frame)
        .where(Trial.participant_id == participant.id, StudyFrame.kind != FrameKind.PRACTICE)
        .group_by(Trial.outcome)
    ):
        counts[outcome] += n
    total = sum(counts.values())
    answered = sum(counts[o] for o in ANSWERED)
    used = None
    if participant.started_at is not None:
        end = participant.finished_at or min(now(), participant.deadline)
        used = max(0.0, (end - participant.started_at).total_seconds())
    if participant.withdrawn_at is not None:
        status = "withdrawn"
    elif not participant.user.active:
        status = "deactivated"
    elif participant.finished_at is not None:
        status = participant.end_reason.value.replace("_", " ")
    elif participant.started_at is not None:
        status = "time up" if now() >= participant.deadline else "running"
    elif participant.instructions_done_at is not None:
        status = "practice" if has_pending(participant, FrameKind.PRACTICE) else "ready"
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
    places: int


def study_summaries() -> list[StudySummary]:
    """Every study, newest first, with its participant counts (the admin's list)."""
    finished = dict(
        db.session.execute(
            db.select(Participant.study_id, func.count()).where(Participant.finished_at.is_not(None)).group_by(Participant.study_id)
        ).all()
    )
    rows = []
    for study in db.session.execute(db.select(Study).order_by(Study.created_at.desc(), Study.id.desc())).scalars():
        main = len(study.frames_of(FrameKind.MAIN))
        rows.append(StudySummary(study, main, len(study.participants), finished.get(study.id, 0), places_taken(study)))
    return rows


def condition_table(study: Study) -> list[dict[str, Any]]:
    """Per condition: what it changes, its quota, the open link's places taken and everyone in it (balanced
    assignment keeps these even)."""
    places, everyone = condition_places(study), condition_places(study, open_link=False)
    return [{"condition": c, "places": places.get(c.id, 0), "everyone": everyone.get(c.id, 0)} for c in study.conditions]


def activity_table(study: Study) -> tuple[list[dict[str, Any]], int]:
    """Per activity of a study: frames drawn and eligible now; and how many frames have cached superpixels."""
    eligible = {activity.id: n for activity, n in eligible_counts()}
    rows: dict[int, dict[str, Any]] = {}
    for sf in study.frames_of(FrameKind.MAIN):
        activity = sf.frame.sequence.activity
        row = rows.setdefault(activity.id, {"activity": activity, "drawn": 0, "eligible": eligible.get(activity.id, 0)})
        row["drawn"] += 1
    cached = sum(cached_superpixels(sf.frame, study.superpixels) for sf in study.frames)
    return sorted(rows.values(), key=lambda r: r["activity"].name), cached


def answered_counts(study_frames: Iterable[StudyFrame]) -> dict[int, int]:
    """How many participants answered each of these study frames (by study frame id), pilots left out (as from the means)."""
    ids = [sf.id for sf in study_frames]
    return dict(
        db.session.execute(
            db.select(Trial.study_frame_id, func.count())
            .join(Participant)
            .where(Trial.study_frame_id.in_(ids), Trial.outcome.in_(ANSWERED), Participant.pilot.is_(False))
            .group_by(Trial.study_frame_id)
        ).all()
    )

