"""Carrying a person's annotation to the adjacent frame of its sequence, and
the sequence's filmstrip.

"Propagate to next frame" takes every instance of the user's annotation of
a frame to the next frame of the same sequence (by ``Frame.index``), each
mask refined there by ``egonet.grabcut.propagate`` (with the frames' stored
depth when they have it), and saves them as the user's in-progress
annotation of that frame, each with a GrabCut session started from its
mask, so strokes correct it at once. "Copy from previous frame" is the same
move the other way round, into the frame the user is on.

Existing work is never overwritten silently: a target annotation of the
user's that has instances (or says "no action-object") is refused with 409
unless the request says ``replace`` and carries the target's version (the
normal version check); a finished one (done or reviewed) is refused with
409 even then: reopen it first.

The filmstrip is a window of the sequence's frames around one of them, so
a request costs the same for 30 frames or 10,000.
"""

from dataclasses import dataclass

import numpy as np
from flask import current_app

from app.errors import Problem
from app.extensions import db
from app.models import Annotation, Frame, Status, User
from app.services import frames as frames_service
from app.services import media
from app.services.labelling.annotations import InstanceSpec, _write, stale, user_annotation
from app.services.labelling.grabcut import forget_sessions, grabcut_seed
from egonet import io as egonet_io
from egonet.errors import EgonetError
from egonet.grabcut import propagate

FINISHED = (Status.DONE, Status.REVIEWED)
FILMSTRIP_MAX = 101  # frames one filmstrip request may return


# --------------------------------------------------------------------------
# Order within a sequence


def adjacent_frame(frame: Frame, *, step: int) -> Frame | None:
    """The next (``step=1``) or previous (``step=-1``) frame of the frame's
    sequence, by ``index`` (then id, for frames that share an index)."""
    same = db.select(Frame).where(Frame.sequence_id == frame.sequence_id)
    if step > 0:
        query = same.where(
            (Frame.index > frame.index) | ((Frame.index == frame.index) & (Frame.id > frame.id))
        ).order_by(Frame.index, Frame.id)
    else:
        query = same.where(
            (Frame.index < frame.index) | ((Frame.index == frame.index) & (Frame.id < frame.id))
        ).order_by(Frame.index.desc(), Frame.id.desc())
    return db.session.execute(query.limit(1)).scalar_one_or_none()


# --------------------------------------------------------------------------
# Propagation


def propagate_to_next(frame: Frame, user: User, *, replace: bool = False, version: int | None = None) -> Annotation:
    """Carry the user's annotation of ``frame`` to the next frame of its sequence.

    Args:
        frame: The frame the user is on (the source).
        user: The annotator; their own annotations only.
        replace: Replace the user's unfinished work on the next frame.
        version: The next frame's annotation version the page saw (required
            with ``replace`` when that annotation exists).

    Returns:
        The new in-progress annotation of the next frame (``.frame`` is it).

    Raises:
        Problem: 404 ``next`` without a next frame, 404 ``frame_id`` when the
            user has nothing drawn on ``frame``, 409 when the next frame
            already has the user's work (see the module's docstring).
    """
    target = adjacent_frame(frame, step=1)
    if target is None:
        raise Problem(f"frame #{frame.index} is the last of its sequence: there is no next frame", status=404,
                      fields={"next": "no next frame in this sequence"})
    return carry(frame, target, user, replace=replace, version=version, source_field="frame_id")


def copy_from_previous(frame: Frame, user: User, *, replace: bool = False, version: int | None = None) -> Annotation:
    """Carry the user's annotation of the previous frame of the sequence into ``frame``.

    Args and errors as ``propagate_to_next``, mirrored: 404 ``previous``
    without a previous frame or without the user's instances on it, 409 when
    ``frame`` already has the user's work.
    """
    source = adjacent_frame(frame, step=-1)
    if source is None:
        raise Problem(f"frame #{frame.index} is the first of its sequence: there is no previous frame", status=404,
                      fields={"previous": "no previous frame in this sequence"})
    return carry(source, frame, user, replace=replace, version=version, source_field="previous")


def carry(source: Frame, target: Frame, user: User, *, replace: bool, version: int | None,
          source_field: str) -> Annotation:
    """Save the user's instances of ``source``, each propagated, as their in-progress annotation of ``target``."""
    existing = user_annotation(source, user)
    if existing is None or not existing.instances:
        raise Problem(f"{source_field}: you have drawn no action-object on frame #{source.index} to carry over",
                      status=404, fields={source_field: "no action-object drawn on that frame"})
    current = _check_target(target, user, replace=replace, version=version)
    if (source.width, source.height) != (target.width, target.height):
        raise Problem(f"{source_field}: frames {source.id} and {target.id} differ in size "
                      f"({source.width}x{source.height} and {target.width}x{target.height})",
                      fields={source_field: "a frame of another size"})
    _check_size(target)

    prev_rgb = egonet_io.read_image(media.absolute_path(source.rgb_path))
    next_rgb = egonet_io.read_image(media.absolute_path(target.rgb_path))
    prev_depth, next_depth = _depth(source), _depth(target)
    specs = []
    for instance in existing.instances:
        prev_mask = egonet_io.read_mask(media.absolute_path(instance.mask_path))
        try:
            mask = propagate(prev_rgb, prev_mask, next_rgb, prev_depth=prev_depth, next_depth=next_depth)
        except EgonetError as exc:  # the stored media disagree with each other (sizes)
            raise Problem.from_egonet(exc) from None
        specs.append(InstanceSpec(key=instance.key, kind=instance.kind, label=instance.label,
                                  mask_path=media.store(egonet_io.encode_png(mask), ".png"), mask=mask))
    # The target's old GrabCut sessions belong to the work being replaced.
    forget_sessions(target, user, keep=set())
    annotation = _write(target, user, version=current, specs=specs, no_action_object=False,
                        status=Status.IN_PROGRESS, time_delta_s=0.0)
    _seed_sessions(target, user, specs)
    return annotation


def _seed_sessions(target: Frame, user: User, specs: list[InstanceSpec]) -> None:
    """A GrabCut session for each carried object, started from its mask as it
    was saved (``grabcut_seed``), so strokes correct it at once, no box needed.
    An object GrabCut cannot start from (empty, or covering the frame) keeps
    no session: a stroke on it asks for a box (GrabCut cannot start from such a mask)."""
    for spec in specs:
        if not spec.mask.any():
            continue
        try:
            grabcut_seed(target, user, spec.key, spec.mask)
        except Problem:
            continue


def _check_target(target: Frame, user: User, *, replace: bool, version: int | None) -> int:
    """The version to write the target at, or the 409 that protects the work already there."""
    annotation = user_annotation(target, user)
    if annotation is None:
        return 0
    if annotation.status in FINISHED:
        raise Problem(f"your annotation of frame #{target.index} is {annotation.status.value.replace('_', ' ')}; "
                      "reopen it before carrying another one over it", status=409,
                      fields={"status": f"is {annotation.status.value}"}, frame_id=target.id,
                      current_version=annotation.version)
    has_work = bool(annotation.instances) or annotation.no_action_object
    if has_work and not replace:
        n = len(annotation.instances)
        what = f"{n} action-object{'s' if n != 1 else ''}" if n else '"no action-object"'
        raise Problem(f"frame #{target.index} already has your annotation ({what})",
                      status=409, fields={"replace": "the frame has your work: send replace=true with its version"},
                      frame_id=target.id, current_version=annotation.version)
    if has_work and version != annotation.version:
        raise stale(annotation.version)
    return annotation.version


def _check_size(frame: Frame) -> None:
    # Propagation costs about what a GrabCut box does: the same frame-size limit.
    side = current_app.config["MAX_FRAME_SIDE"]
    if max(frame.width, frame.height) > side:
        raise Problem(f"frame_id: frame {frame.id} is {frame.width}x{frame.height}, larger than GrabCut's "
                      f"limit of {side} pixels a side", fields={"frame_id": f"larger than {side} pixels a side"})


def _depth(frame: Frame) -> np.ndarray | None:
    """The frame's stored depth in metres (H, W), None when it has none."""
    if not frame.depth_path:
        return None
    return egonet_io.read_depth(media.absolute_path(frame.depth_path))


# --------------------------------------------------------------------------
# Filmstrip


@dataclass
class Filmstrip:
    """A window of a sequence's frames: ``frames[k]`` is at ``start + k`` in the sequence's order."""

    total: int
    start: int
    focus: Frame
    focus_position: int
    frames: list[Frame]
    statuses: dict[int, Status]


def filmstrip(frame: Frame, *, at_index: int | None = None, start: int | None = None, count: int = 41) -> Filmstrip:
    """Up to ``count`` frames of ``frame``'s sequence: from position ``start``
    when given, else centred on the frame whose ``index`` is ``at_index``
    (``frame`` itself by default).

    Raises:
        Problem: 400 naming ``count``; 404 naming ``at`` when the sequence
            has no frame with that index.
    """
    if not 1 <= count <= FILMSTRIP_MAX:
        raise Problem(f"count: must be 1-{FILMSTRIP_MAX}", fields={"count": f"must be 1-{FILMSTRIP_MAX}"})
    focus = frame
    if at_index is not None:
        focus = db.session.execute(
            db.select(Frame).filter_by(sequence_id=frame.sequence_id, index=at_index).order_by(Frame.id).limit(1)
        ).scalar_one_or_none()
        if focus is None:
            raise Problem(f"at: the sequence has no frame {at_index}", status=404,
                          fields={"at": f"no frame {at_index} in this sequence"})
    same = db.select(db.func.count()).select_from(Frame).where(Frame.sequence_id == frame.sequence_id)
    total = db.session.execute(same).scalar_one()
    position = db.session.execute(
        same.where((Frame.index < focus.index) | ((Frame.index == focus.index) & (Frame.id < focus.id)))
    ).scalar_one()
    if start is None:
        start = position - count // 2
    start = max(0, min(start, total - count))
    frames = list(
        db.session.execute(
            db.select(Frame).where(Frame.sequence_id == frame.sequence_id)
            .order_by(Frame.index, Frame.id).offset(start).limit(count)
        ).scalars()
    )
    statuses = frames_service.frame_statuses([f.id for f in frames])
    return Filmstrip(total=total, start=start, focus=focus, focus_position=position, frames=frames, statuses=statuses)
