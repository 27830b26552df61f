"""Which annotation of a frame is its ground truth, and its mask.

A frame's ground truth is its finished annotation (status done or
reviewed), a reviewed one preferred, the most recently updated first. A
finished annotation marked "no action-object" gives an all-false mask.
Training, studies and scoring all read ground truth through here.
"""

from collections.abc import Iterable

import numpy as np
from sqlalchemy import case

from app.extensions import db
from app.models import FINISHED, Annotation, Frame, Sequence, Status
from app.services import media
from egonet import io


def ground_truths(frame_ids: Iterable[int]) -> dict[int, Annotation]:
    """The ground-truth annotation of each frame that has one."""
    frame_ids = list(frame_ids)
    if not frame_ids:
        return {}
    rank = case((Annotation.status == Status.REVIEWED, 0), else_=1)
    rows = db.session.execute(
        db.select(Annotation)
        .where(Annotation.frame_id.in_(frame_ids), Annotation.status.in_(FINISHED))
        .order_by(Annotation.frame_id, rank, Annotation.updated_at.desc(), Annotation.id.desc())
    ).scalars()
    chosen: dict[int, Annotation] = {}
    for annotation in rows:
        chosen.setdefault(annotation.frame_id, annotation)
    return chosen


def labelled_frames(activity_ids: Iterable[int] | None = None) -> list[Frame]:
    """Frames with a ground truth, optionally limited to some activities, in a stable order."""
    query = (
        db.select(Frame)
        .join(Sequence)
        .where(Frame.id.in_(db.select(Annotation.frame_id).where(Annotation.status.in_(FINISHED))))
        .order_by(Sequence.activity_id, Sequence.name, Frame.index, Frame.id)
    )
    if activity_ids is not None:
        query = query.where(Sequence.activity_id.in_(list(activity_ids)))
    return list(db.session.execute(query).scalars())


def mask_of(annotation: Annotation) -> np.ndarray:
    """The annotation's action-object mask, bool (H, W) at the frame's size."""
    frame = annotation.frame
    if annotation.mask_path is None:
        return np.zeros((frame.height, frame.width), bool)
    return io.read_mask(media.local_path(annotation.mask_path))
