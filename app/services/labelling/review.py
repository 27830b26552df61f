"""Review and the queues: a reviewer's decision on a done annotation, a
reviewer's fix of its masks, which frames and annotations wait for whom, and
the masks' thumbnails they show.

A reviewer accepts a done annotation (reviewed; its GrabCut sessions go, its
author's undo history stays) or
rejects it with a comment (rejected, back to its author). Before deciding, a
reviewer may fix its masks on the review page (``fix_annotation``): the fix
is saved into the author's annotation (it stays theirs, one per frame and
author, with the author's time), with the usual version check, and records
the reviewer as ``fixed_by`` with ``fixed_at``; it stays done, waiting for
the decision, which the reviewer then makes on the fixed version. An
annotator's queue runs in dataset order (activity, sequence, index) over the
frames nobody else has taken or has open; a reviewer's runs oldest first.
"""

import hashlib
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from sqlalchemy import and_, exists, func, or_, tuple_
from sqlalchemy.orm import joinedload, selectinload
from sqlalchemy.orm.exc import StaleDataError

from app.errors import Problem
from app.extensions import db
from app.models import FINISHED, Activity, Annotation, Frame, Sequence, Status, User, utcnow
from app.services import frames as frames_service
from app.services import media
from app.services.labelling.annotations import _write, get_annotation, instance_specs, stale, user_annotation
from app.services.labelling.grabcut import forget_sessions
from app.services.labelling.history import forget_histories
from app.services.labelling.presence import held_by_others
from egonet import io

# The instances' colours, in order (the labelling page's, the frame viewer's and the thumbnails').
INSTANCE_COLOURS = (
    (0, 180, 255),
    (255, 60, 170),
    (255, 140, 0),
    (255, 214, 0),
    (110, 220, 60),
    (150, 95, 255),
    (0, 205, 170),
    (255, 110, 110),
)
# Opacity (0-255) of a thumbnail's filled object and of its outline.
THUMB_FILL_ALPHA = 90
THUMB_LINE_ALPHA = 255


def instance_colour(i: int) -> tuple[int, int, int]:
    """The colour of the ``i``-th instance (0-based), as (R, G, B)."""
    return INSTANCE_COLOURS[i % len(INSTANCE_COLOURS)]

# --------------------------------------------------------------------------
# Review


def review_annotation(annotation: Annotation, reviewer: User, *, version: int, decision: str, comment: str | None) -> Annotation:
    """Accept (reviewed) or reject (rejected, back to its author) a done annotation.

    Raises:
        Problem: 403 for the reviewer's own annotation, 400 for a rejection
            without a comment, 409 when the annotation is not done or
            ``version`` is stale.
    """
    if annotation.author_id == reviewer.id:
        raise Problem("you cannot review your own annotation", status=403, fields={"annotation_id": "is your own"})
    comment = (comment or "").strip() or None
    if decision == "reject" and comment is None:
        raise Problem("comment: say what to fix when rejecting", fields={"comment": "required when rejecting"})
    if annotation.version != version:
        raise stale(annotation.version)
    _check_done(annotation)
    annotation.status = Status.REVIEWED if decision == "accept" else Status.REJECTED
    annotation.review_comment = comment
    annotation.reviewer = reviewer
    annotation.reviewed_at = utcnow()
    forget_histories(annotation, user=reviewer)
    if user_annotation(annotation.frame, reviewer) is None:
        forget_sessions(annotation.frame, reviewer, keep=set())  # those of a fix
    if annotation.status is Status.REVIEWED:
        # The author's undo history stays: reopened, the frame undoes as before.
        forget_sessions(annotation.frame, annotation.author, keep=set())
    try:
        db.session.commit()
    except StaleDataError:
        db.session.rollback()
        raise stale(get_annotation(annotation.id).version) from None
    return annotation


def fix_annotation(annotation: Annotation, reviewer: User, data: dict) -> Annotation:
    """Save a reviewer's fix of a done annotation's masks, before the decision.

    ``data`` holds ``version``, ``instances`` and ``no_action_object`` as a
    save does (``annotations.save_annotation``). The annotation stays its
    author's and stays done; ``fixed_by`` / ``fixed_at`` record the fix.

    Raises:
        Problem: 403 for the reviewer's own annotation (fix it on the
            labelling page), 409 for a stale ``version`` or an annotation
            that is not done, 400 naming a bad field.
    """
    if annotation.author_id == reviewer.id:
        raise Problem("this is your own annotation: change it on the labelling page", status=403,
                      fields={"annotation_id": "is your own"})
    if data["version"] != annotation.version:
        raise stale(annotation.version)
    _check_done(annotation)
    frame, author = annotation.frame, annotation.author
    return _write(frame, author, version=data["version"], specs=instance_specs(frame, data["instances"]),
                  no_action_object=data["no_action_object"], status=None, time_delta_s=0.0, fixed_by=reviewer)


NOT_DONE = {
    Status.TODO: "is not started",
    Status.IN_PROGRESS: "is still in progress with its author",
    Status.REVIEWED: "was accepted already",
    Status.REJECTED: "was rejected already and is back with its author",
}
"""Why an annotation waits for no decision, in words."""


def _check_done(annotation: Annotation) -> None:
    if annotation.status is not Status.DONE:
        raise Problem(
            f"only done annotations can be reviewed; this one {NOT_DONE[annotation.status]}",
            status=409,
            fields={"status": f"is {annotation.status.value}"},
        )


# --------------------------------------------------------------------------
# Queues


def _frame_order():
    return (Activity.name, Sequence.name, Frame.index, Frame.id)


def _unlabelled_for(user: User):
    """SQL condition: the frame still needs labelling, as far as ``user`` goes.

    A frame is taken when any annotation of it is finished, or another
    person's is in progress or rejected (it is theirs to finish), or another
    person has it open (``presence``).
    """
    taken = exists().where(
        Annotation.frame_id == Frame.id,
        or_(
            Annotation.status.in_(FINISHED),
            and_(Annotation.author_id != user.id, Annotation.status.in_((Status.IN_PROGRESS, Status.REJECTED))),
        ),
    )
    return ~taken & ~held_by_others(user)


def next_unlabelled(user: User, *, after: Frame | None = None, activity_id: int | None = None) -> int | None:
    """The id of the next frame the user should label, in dataset order
    (activity, sequence, index), after ``after`` and wrapping around (so
    the last one left is ``after`` itself)."""
    query = (
        db.select(Frame.id)
        .join(Sequence, Frame.sequence_id == Sequence.id)
        .join(Activity, Sequence.activity_id == Activity.id)
        .where(_unlabelled_for(user))
        .order_by(*_frame_order())
        .limit(1)
    )
    if activity_id is not None:
        query = query.where(Activity.id == activity_id)
    if after is not None:
        key = (after.sequence.activity.name, after.sequence.name, after.index, after.id)
        later = db.session.execute(query.where(tuple_(*_frame_order()) > tuple_(*key))).scalar_one_or_none()
        if later is not None:
            return later
    return db.session.execute(query).scalar_one_or_none()


@dataclass
class ActivityProgress:
    activity: Activity
    frames: int
    unlabelled: int


def annotator_queue(user: User) -> dict:
    """What the labelling overview shows an annotator: per-activity progress,
    frames returned with a comment, frames in progress, recent work."""
    counts = dict(
        db.session.execute(
            db.select(Sequence.activity_id, func.count(Frame.id)).join(Frame).group_by(Sequence.activity_id)
        ).all()
    )
    open_counts = dict(
        db.session.execute(
            db.select(Sequence.activity_id, func.count(Frame.id))
            .join(Frame)
            .where(_unlabelled_for(user))
            .group_by(Sequence.activity_id)
        ).all()
    )
    activities = db.session.execute(db.select(Activity).order_by(Activity.name)).scalars().all()
    mine = db.select(Annotation).filter_by(author_id=user.id)
    return {
        "progress": [ActivityProgress(a, counts.get(a.id, 0), open_counts.get(a.id, 0)) for a in activities],
        "rejected": db.session.execute(
            mine.filter_by(status=Status.REJECTED).order_by(Annotation.reviewed_at.desc())
        ).scalars().all(),
        "in_progress": db.session.execute(
            mine.filter_by(status=Status.IN_PROGRESS).order_by(Annotation.updated_at.desc()).limit(50)
        ).scalars().all(),
        "recent": db.session.execute(
            mine.where(Annotation.status.in_(FINISHED)).order_by(Annotation.updated_at.desc()).limit(12)
        ).scalars().all(),
    }


def review_queue(*, limit: int = 200) -> tuple[list[Annotation], int]:
    """Done annotations waiting for a decision, oldest first, and how many there are."""
    waiting = db.select(Annotation).filter_by(status=Status.DONE)
    total = db.session.execute(db.select(func.count()).select_from(waiting.subquery())).scalar_one()
    rows = db.session.execute(
        waiting.options(selectinload(Annotation.instances), joinedload(Annotation.author),
                        joinedload(Annotation.frame).joinedload(Frame.sequence).joinedload(Sequence.activity))
        .order_by(Annotation.updated_at, Annotation.id).limit(limit)
    ).unique().scalars().all()
    return rows, total


def next_to_review(reviewer: User, *, after: Annotation | None = None) -> int | None:
    """The id of the oldest done annotation other than ``after`` and the reviewer's own."""
    query = (
        db.select(Annotation.id)
        .filter_by(status=Status.DONE)
        .where(Annotation.author_id != reviewer.id)
        .order_by(Annotation.updated_at, Annotation.id)
    )
    if after is not None:
        query = query.where(Annotation.id != after.id)
    return db.session.execute(query.limit(1)).scalar_one_or_none()


# --------------------------------------------------------------------------
# Thumbnails


def mask_thumbnail(annotation: Annotation) -> Path:
    """The annotation's instances as an RGBA PNG the size of the frame's thumbnail, cached on disk.

    Each instance is filled faintly and outlined in its colour
    (``instance_colour``) on a transparent background, so the picture lies
    over the frame's thumbnail (``frames.thumbnail_size``: 240 px wide, so
    its cost is bounded whatever the frame's size). Masks are stored by
    content, so the cache is named after the instances' mask files and never
    goes stale.
    """
    frame = annotation.frame
    width, height = frames_service.thumbnail_size(frame)
    paths = [i.mask_path for i in annotation.instances]
    digest = hashlib.sha256("|".join([f"{width}x{height}", *paths]).encode()).hexdigest()[:32]

    def make() -> bytes:
        picture = np.zeros((height, width, 4), np.uint8)
        for i, path in enumerate(paths):
            small = _shrunk(io.read_mask(media.local_path(path)), (width, height))
            colour = instance_colour(i)
            picture[small] = (*colour, THUMB_FILL_ALPHA)
            contours, _ = cv2.findContours(small.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
            cv2.drawContours(picture, contours, -1, (*colour, THUMB_LINE_ALPHA), 1)
        ok, buf = cv2.imencode(".png", cv2.cvtColor(picture, cv2.COLOR_RGBA2BGRA))
        return buf.tobytes()

    return media.derived(f"review/mask-{digest}.png", make)


def _shrunk(mask: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """A bool mask at ``size`` (width, height): a pixel is set when a quarter of what it covers is,
    so thin and small objects still show."""
    return cv2.resize(mask.astype(np.float32), size, interpolation=cv2.INTER_AREA) >= 0.25
