"""Carrying a person's annotation through its sequence, and the sequence's
filmstrip.

"Propagate" takes every instance of the user's annotation of a frame to the
next (or the previous) frame of the same sequence (by ``Frame.index``), each
mask refined there by ``egonet.grabcut.carry`` (with the frames' stored
depth when they have it), and saves them as the user's in-progress
annotation of that frame, each with a GrabCut session started from its
mask, so strokes correct it at once. Asked for ``count`` frames, it goes on
from each carried frame to the one after, and stops early at the first
frame whose result looks unsure (that frame is saved, so the annotator
lands on it to fix it), at a frame that already has the user's work (left
as it is), or at the sequence's end; the answer says which. "Copy from
previous frame" is the one-frame move into the frame the user is on.

Existing work is never overwritten silently: a first target annotation of
the user's that has instances (or says "no action-object") is refused with
409 unless the request says ``replace`` and carries the target's version
(the normal version check); a finished one (done or reviewed) is refused
with 409 even then: reopen it first. Further frames of a range are never
replaced: the range stops before them.

A range is bounded so one request stays short: at most ``RANGE_MAX``
frames and ``RANGE_OBJECT_FRAMES`` objects times frames (about 0.2 s CPU
each, carrying and seeding its GrabCut session: 50 make about 10 s, the
bound one frame of 50 objects already had). The page carries longer ranges
as a chain of such requests, showing its progress and stopping where one
stops; each carried frame is committed on its own, so nothing carried is
lost when a later frame fails.

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
from egonet.grabcut import carry as carry_mask

FINISHED = (Status.DONE, Status.REVIEWED)
FILMSTRIP_MAX = 101  # frames one filmstrip request may return
RANGE_MAX = 10  # frames one propagate request may carry to
RANGE_OBJECT_FRAMES = 50  # ... and objects times frames


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


@dataclass
class Stop:
    """Why a range ended before its count: ``kind`` is ``unsure`` (``frame`` was
    carried and saved, but a person should look at it), ``work`` (``frame``
    has the user's work and was left alone) or ``end`` (no frame after ``frame``)."""

    kind: str
    frame: Frame
    reason: str


@dataclass
class CarryRun:
    """What a propagate request did: ``annotations`` of the carried frames, in order."""

    annotations: list[Annotation]
    stop: Stop | None


def propagate(frame: Frame, user: User, *, step: int = 1, count: int = 1, replace: bool = False,
              version: int | None = None) -> CarryRun:
    """Carry the user's annotation of ``frame`` to the next ``count`` frames
    (``step=1``) or the previous ones (``step=-1``) of its sequence.

    Args:
        frame: The frame the user is on (the source).
        user: The annotator; their own annotations only.
        step: 1 towards the end of the sequence, -1 towards its start.
        count: How many frames to carry to, 1 to ``RANGE_MAX`` (and at most
            ``RANGE_OBJECT_FRAMES`` objects times frames).
        replace: Replace the user's unfinished work on the first target.
        version: The first target's annotation version the page saw
            (required with ``replace`` when that annotation exists).

    Returns:
        The carried annotations and why the range stopped early, if it did.

    Raises:
        Problem: 400 naming ``count`` over the bounds; 404 ``next`` /
            ``previous`` without such a frame, 404 ``frame_id`` when the user
            has nothing drawn on ``frame``, 409 when the first target
            already has the user's work (see the module's docstring).
    """
    way = "next" if step > 0 else "previous"
    first = adjacent_frame(frame, step=step)
    if first is None:
        end = "last" if step > 0 else "first"
        raise Problem(f"frame #{frame.index} is the {end} of its sequence: there is no {way} frame", status=404,
                      fields={way: f"no {way} frame in this sequence"})
    existing = _source(frame, user, "frame_id")
    if not 1 <= count <= RANGE_MAX:
        raise Problem(f"count: carry to 1-{RANGE_MAX} frames a request", fields={"count": f"must be 1-{RANGE_MAX}"})
    objects = len(existing.instances)
    if objects * count > RANGE_OBJECT_FRAMES:
        most = max(1, RANGE_OBJECT_FRAMES // objects)
        raise Problem(f"count: {objects} objects can be carried to at most {most} frames a request "
                      f"({RANGE_OBJECT_FRAMES} objects times frames)", fields={"count": f"at most {most} with {objects} objects"})
    annotations: list[Annotation] = []
    source, target = frame, first
    while True:
        if annotations:
            current = user_annotation(target, user)
            if current is not None and (current.status in FINISHED or current.instances or current.no_action_object):
                return CarryRun(annotations, Stop("work", target, f"stopped before frame #{target.index}: "
                                                  f"it already has your annotation ({_what(current)})"))
        annotation, unsure = carry(source, target, user, replace=replace, version=version, source_field="frame_id")
        annotations.append(annotation)
        if unsure:
            return CarryRun(annotations, Stop("unsure", target, f"stopped at frame #{target.index}: the result looks "
                                              f"unsure ({unsure}); check it there"))
        if len(annotations) == count:
            return CarryRun(annotations, None)
        source, target = target, adjacent_frame(target, step=step)
        if target is None:
            end = "last" if step > 0 else "first"
            return CarryRun(annotations, Stop("end", source, f"frame #{source.index} is the {end} of its sequence"))


def copy_from_previous(frame: Frame, user: User, *, replace: bool = False, version: int | None = None) -> Annotation:
    """Carry the user's annotation of the previous frame of the sequence into ``frame``.

    Args and errors as ``propagate`` for one frame, mirrored: 404 ``previous``
    without a previous frame or without the user's instances on it, 409 when
    ``frame`` already has the user's work.
    """
    source = adjacent_frame(frame, step=-1)
    if source is None:
        raise Problem(f"frame #{frame.index} is the first of its sequence: there is no previous frame", status=404,
                      fields={"previous": "no previous frame in this sequence"})
    return carry(source, frame, user, replace=replace, version=version, source_field="previous")[0]


def _source(source: Frame, user: User, source_field: str) -> Annotation:
    existing = user_annotation(source, user)
    if existing is None or not existing.instances:
        raise Problem(f"{source_field}: you have drawn no action-object on frame #{source.index} to carry over",
                      status=404, fields={source_field: "no action-object drawn on that frame"})
    return existing


def _what(annotation: Annotation) -> str:
    n = len(annotation.instances)
    if annotation.status in FINISHED:
        return annotation.status.value.replace("_", " ")
    return f"{n} action-object{'s' if n != 1 else ''}" if n else '"no action-object"'


def carry(source: Frame, target: Frame, user: User, *, replace: bool, version: int | None,
          source_field: str) -> tuple[Annotation, str]:
    """Save the user's instances of ``source``, each propagated, as their in-progress annotation of ``target``.

    Returns:
        The annotation, and why the carried objects look unsure ("" when none
        does): the first unsure object's label (or number) and the engine's reason.
    """
    existing = _source(source, user, source_field)
    current = _check_target(target, user, replace=replace, version=version)
    if (source.width, source.height) != (target.width, target.height):
        raise Problem(f"{source_field}: frames {source.id} and {target.id} differ in size "
                      f"({source.width}x{source.height} and {target.width}x{target.height})",
                      fields={source_field: "a frame of another size"})
    _check_size(target)

    prev_rgb = egonet_io.read_image(media.local_path(source.rgb_path))
    next_rgb = egonet_io.read_image(media.local_path(target.rgb_path))
    prev_depth, next_depth = _depth(source), _depth(target)
    specs, unsure = [], ""
    for n, instance in enumerate(existing.instances, start=1):
        prev_mask = egonet_io.read_mask(media.local_path(instance.mask_path))
        try:
            carried = carry_mask(prev_rgb, prev_mask, next_rgb, prev_depth=prev_depth, next_depth=next_depth)
        except EgonetError as exc:  # the stored media disagree with each other (sizes)
            raise Problem.from_egonet(exc) from None
        if carried.unsure and not unsure:
            unsure = f'object {n}{f" ({instance.label})" if instance.label else ""} {carried.reason}'
        specs.append(InstanceSpec(key=instance.key, kind=instance.kind, label=instance.label,
                                  mask_path=media.store(egonet_io.encode_png(carried.mask), ".png"), mask=carried.mask))
    # The target's old GrabCut sessions belong to the work being replaced.
    forget_sessions(target, user, keep=set())
    annotation = _write(target, user, version=current, specs=specs, no_action_object=False,
                        status=Status.IN_PROGRESS, time_delta_s=0.0)
    _seed_sessions(target, user, specs)
    return annotation, unsure


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
        raise Problem(f"frame #{target.index} already has your annotation ({_what(annotation)})",
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
    return egonet_io.read_depth(media.local_path(frame.depth_path))


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
