"""Who else is on a frame: people who have it open on the labelling page,
and others' annotations of it.

The page says it has a frame open when it opens it and then every
HEARTBEAT_S seconds while it is shown (``mark_present``), and that it left
when it closes (``leave``). Presence older than PRESENCE_TTL_S no longer
counts (a closed laptop, a crashed tab). "Next unlabelled" skips frames that
someone else has open, as it skips those with someone else's annotation in
progress (``review._unlabelled_for``), so two people are not sent to the
same frame; the page warns whoever opens such a frame anyway.
"""

from dataclasses import dataclass
from datetime import datetime, timedelta

from sqlalchemy.exc import IntegrityError

from app.extensions import db
from app.models import Annotation, Frame, Status, User, utcnow
from app.models.annotations import FramePresence

HEARTBEAT_S = 30
PRESENCE_TTL_S = 90


@dataclass
class Holder:
    """Another person on the frame: ``status`` is their annotation's
    (``in_progress``, ``done``...), or ``open`` when they have the frame open
    with nothing saved yet; ``since`` is when they started, ``last_seen``
    their last save or heartbeat, ``here`` whether they have it open now."""

    username: str
    status: str
    since: datetime
    last_seen: datetime
    here: bool

    def to_dict(self) -> dict:
        return {"username": self.username, "status": self.status, "since": self.since.isoformat(),
                "last_seen": self.last_seen.isoformat(), "here": self.here}


def live_since():
    """The oldest heartbeat that still counts."""
    return utcnow() - timedelta(seconds=PRESENCE_TTL_S)


def mark_present(frame: Frame, user: User) -> None:
    """Record that the user has the frame open now."""
    now = utcnow()
    for _ in range(2):  # two tabs of the same person may insert at once: the loser updates
        row = db.session.execute(db.select(FramePresence).filter_by(frame_id=frame.id, user_id=user.id)).scalar_one_or_none()
        if row is None:
            db.session.add(FramePresence(frame_id=frame.id, user_id=user.id, opened_at=now, seen_at=now))
        else:
            if row.seen_at < live_since():
                row.opened_at = now  # back after a gap: a new visit
            row.seen_at = now
        try:
            db.session.commit()
            return
        except IntegrityError:
            db.session.rollback()


def leave(frame: Frame, user: User) -> None:
    """The user closed the frame."""
    db.session.execute(db.delete(FramePresence).where(FramePresence.frame_id == frame.id,
                                                      FramePresence.user_id == user.id))
    db.session.commit()


def others_on(frame: Frame, user: User) -> list[Holder]:
    """Everyone but ``user`` who has the frame open or an annotation of it, earliest first."""
    present = {
        row.user_id: row
        for row in db.session.execute(
            db.select(FramePresence).where(FramePresence.frame_id == frame.id, FramePresence.user_id != user.id,
                                           FramePresence.seen_at >= live_since())
        ).scalars()
    }
    holders = []
    annotations = db.session.execute(
        db.select(Annotation).where(Annotation.frame_id == frame.id, Annotation.author_id != user.id,
                                    Annotation.status != Status.TODO)  # proposals nobody took up claim nothing
    ).scalars()
    for annotation in annotations:
        row = present.pop(annotation.author_id, None)
        since = min(annotation.created_at, row.opened_at) if row else annotation.created_at
        last = max(annotation.updated_at, row.seen_at) if row else annotation.updated_at
        holders.append(Holder(annotation.author.username, annotation.status.value, since, last, row is not None))
    for row in present.values():
        holders.append(Holder(row.user.username, "open", row.opened_at, row.seen_at, True))
    return sorted(holders, key=lambda h: h.since)


def held_by_others(user: User):
    """SQL condition on ``Frame``: someone other than ``user`` has the frame open now."""
    return (
        db.select(FramePresence.id)
        .where(FramePresence.frame_id == Frame.id, FramePresence.user_id != user.id,
               FramePresence.seen_at >= live_since())
        .exists()
    )
