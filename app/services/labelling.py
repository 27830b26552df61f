"""Labelling: a person's annotation of a frame, its review, the queue, and
the server-side GrabCut sessions that help draw it.

Saving. Each annotation (one per frame and author) carries a ``version``.
A save names the version it was made on; if the annotation has moved on
since (another tab, a reviewer's decision), the save is refused with 409 and
the current version, and nothing is written. A save replaces the instances
(each with its own binary mask, stored content-addressed) and the union mask
in one transaction, after the mask files are on disk, so an acknowledged save
is never lost.

Statuses. An annotation starts in progress; its author marks it done (at
least one drawn instance, or "no action-object"); a reviewer accepts a done
annotation (reviewed) or rejects it with a comment (rejected), which sends it
back to its author with the comment. Editing a rejected annotation puts it
back in progress; editing a done or reviewed one leaves it done, so a changed
annotation is reviewed again.

GrabCut. One ``egonet.grabcut.GrabCutSession`` per user, frame and instance
key. After every operation its state goes into the ``grabcut_state`` row, so
the session survives a restart and any worker process can continue it. Two
strokes never interleave: an operation holds a lock file for its session
(threads and processes of one machine wait for each other), on PostgreSQL
it also locks the row, and the row's revision token catches any writer the
locks cannot see (the operation is then redone on the winner's state). A
worker keeps recent sessions in memory under their revision, within a budget
of bytes, which spares decoding the frame and the state when the same worker
sees the next operation. What one operation may cost is bounded: frames up to
MAX_FRAME_SIDE pixels a side, strokes of up to GRABCUT_MAX_STROKE_POINTS
points and GRABCUT_MAX_RADIUS, and the pixels all of an object's strokes
sweep (a restored session paints them again) up to GRABCUT_MAX_STROKE_PIXELS.
"""

import contextlib
import fcntl
import io
import re
import threading
import warnings
import zlib
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pycocotools.mask as coco_mask
from flask import current_app
from sqlalchemy import and_, exists, func, or_, tuple_
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm.exc import StaleDataError

from app.errors import ApiError
from app.extensions import db
from app.models import FINISHED, Activity, Annotation, Frame, Instance, InstanceKind, Sequence, Status, User, utcnow
from app.models.annotations import GrabCutState
from app.services import media
from app.validation import Field, Invalid
from egonet import io as egonet_io
from egonet.grabcut import GrabCutSession

# The statuses an annotator may ask for; review decisions set the others.
AUTHOR_STATUSES = (Status.IN_PROGRESS, Status.DONE)
MAX_INSTANCES = 50
MAX_TIME_DELTA_S = 3600.0
KEY_PATTERN = re.compile(r"[A-Za-z0-9_-]{1,40}")


# --------------------------------------------------------------------------
# Masks as COCO run-length encodings (what the labelling page sends)


class Rle(Field):
    """A COCO run-length encoding: ``{"size": [h, w], "counts": ...}``.

    ``counts`` is COCO's compressed string or a list of run lengths; runs go
    down the columns (column-major), starting with background. The check
    only looks at the shape of the value: ``decode_rle`` checks the counts
    against the frame's size, before any of them is decoded.
    """

    def check(self, value):
        if not isinstance(value, dict) or set(value) != {"size", "counts"}:
            raise Invalid('must be {"size": [height, width], "counts": ...}')
        size = value["size"]
        if not (isinstance(size, list) and len(size) == 2 and all(type(v) is int and v > 0 for v in size)):
            raise Invalid("size must be [height, width] in pixels")
        if not isinstance(value["counts"], str | list):
            raise Invalid("counts must be a string (COCO compressed) or a list of run lengths")
        return value


def max_rle_chars(pixels: int) -> int:
    """The longest compressed counts string of a mask of ``pixels`` pixels.

    pycocotools and the page write each count in as few characters as it
    takes, and no empty run but the first, so a mask has at most pixels + 1
    counts of at least one character each. A count written as a difference
    ``d`` in k >= 2 characters has ``|d| >= 2**(5k - 6)``, and the
    differences add up to at most 2 * pixels (each is at most the sum of
    the two runs it compares), so at most 2 * pixels / 2**(5k - 6) counts
    take a k-th character: 2 * pixels * (1/16 + 1/512 + ...) = 4 * pixels / 31
    characters beyond one per count.
    """
    return pixels + 1 + 4 * pixels // 31


def _count_chars(pixels: int) -> int:
    """The most characters one count of such a mask takes (a difference in [-pixels, pixels])."""
    k = 1
    while 2 ** (5 * k - 1) <= pixels:
        k += 1
    return k


def _string_runs(text: str, pixels: int) -> np.ndarray:
    """Run lengths from COCO's compressed string, checked: pycocotools leaves
    the rest of the mask uninitialised when the runs fall short, and older
    versions read past a string that ends inside a number.

    Each count is written in 5-bit groups, least significant first (6 bits
    per character offset by 48: 0x20 says another group follows, 0x10 of the
    last group is the sign), from the fourth count on as the difference to
    the count two places before.

    Raises:
        ValueError: the reason, for ``counts``.
    """
    if len(text) > max_rle_chars(pixels):
        raise ValueError(f"{len(text)} characters, more than a mask of {pixels} pixels takes "
                         f"({max_rle_chars(pixels)} at most)")
    codes = np.frombuffer(text.encode("ascii", "replace"), np.uint8) - np.uint8(48)  # the alphabet is 0..63
    if not text.isascii() or (codes >= 64).any():
        wide = np.frombuffer(text.encode("utf-32-le", "surrogatepass"), np.uint32)
        first = text[np.argmax((wide < 48) | (wide >= 112))]
        raise ValueError(f"character {first!r} is not part of COCO's RLE alphabet")
    if not codes.size:
        return codes.astype(np.int64)
    last = (codes & 0x20) == 0  # the last character of a number
    if not last[-1]:
        raise ValueError("the string ends inside a number")
    ends = np.flatnonzero(last)
    widths = np.empty_like(ends)
    widths[0] = ends[0] + 1
    np.subtract(ends[1:], ends[:-1], out=widths[1:])
    if widths.max() > _count_chars(pixels):
        raise ValueError(f"a number of {widths.max()} characters; no count of this mask takes more than "
                         f"{_count_chars(pixels)}")
    if len(ends) > pixels + 1:
        raise ValueError(f"{len(ends)} runs, more than a mask of {pixels} pixels has ({pixels + 1} at most)")
    # Horner's rule from each number's last (most significant) group back, on
    # the numbers that still have groups left.
    values = (codes[ends] & 0x1F).astype(np.int64)
    longer = np.flatnonzero(widths > 1)
    for j in range(1, int(widths.max())):
        longer = longer[widths[longer] > j]
        values[longer] = (values[longer] << 5) | (codes[ends[longer] - j] & 0x1F)
    negative = np.flatnonzero(codes[ends] & 0x10)
    values[negative] -= np.left_shift(1, 5 * widths[negative])
    runs = values.copy()
    runs[1::2] = np.cumsum(values[1::2])  # counts[i] = values[i] + counts[i - 2] from i = 3 on
    runs[2::2] = np.cumsum(values[2::2])
    return runs


def _list_runs(counts: list, pixels: int) -> np.ndarray:
    if len(counts) > pixels + 1:  # before looking at each
        raise ValueError(f"{len(counts)} runs, more than a mask of {pixels} pixels has ({pixels + 1} at most)")
    if not set(map(type, counts)) <= {int}:
        raise ValueError("must be non-negative integers")
    try:
        return np.array(counts, np.int64)
    except OverflowError:
        raise ValueError(f"a run is longer than the mask's {pixels} pixels") from None


def coco_decode(rle: dict) -> np.ndarray:
    """A bool ``(H, W)`` mask from a compressed COCO RLE, with pycocotools."""
    with warnings.catch_warnings():
        # pycocotools' decoder predates numpy 2's __array__(copy=...) and says so.
        warnings.simplefilter("ignore", DeprecationWarning)
        return np.ascontiguousarray(coco_mask.decode(rle), dtype=bool)


def decode_rle(rle: dict, shape: tuple[int, int], *, field: str) -> np.ndarray:
    """A bool ``(H, W)`` mask from a checked ``Rle`` value.

    The counts are checked (length, alphabet, signs, total) before
    pycocotools decodes them, so a hostile string costs no more than a
    frame's worth of work.

    Raises:
        ApiError: 400 naming ``field`` when the size is not the frame's or
            the runs do not cover the mask exactly.
    """
    h, w = shape
    if list(rle["size"]) != [h, w]:
        raise ApiError(
            400,
            f"{field}: the mask is {rle['size'][1]}x{rle['size'][0]}, the frame {w}x{h}",
            fields={f"{field}.size": f"must be [{h}, {w}] (the frame's height and width)"},
        )
    counts, where = rle["counts"], f"{field}.counts"
    try:
        runs = _string_runs(counts, h * w) if isinstance(counts, str) else _list_runs(counts, h * w)
        if (runs < 0).any():
            raise ValueError("a run length is negative")
    except ValueError as exc:
        raise ApiError(400, f"{where}: {exc}", fields={where: str(exc)}) from None
    total = int(runs.sum())
    if total != h * w:
        raise ApiError(400, f"{where}: the runs cover {total} pixels, the mask has {h * w}",
                       fields={where: f"must add up to {h * w} pixels"})
    if isinstance(counts, str):
        return coco_decode({"size": [h, w], "counts": counts.encode()})
    return coco_decode(coco_mask.frPyObjects({"size": [h, w], "counts": counts}, h, w))


def decode_mask_png(data: bytes, shape: tuple[int, int], *, field: str = "mask") -> np.ndarray:
    """A bool mask from PNG bytes that must be binary and of the frame's size.

    The size is read from the PNG's header first, so a PNG of another size
    (or a decompression bomb) is refused without being decoded.

    Raises:
        ApiError: 400 naming ``field``.
    """
    try:
        width, height = egonet_io.image_size(data, path=field)
        if (height, width) != shape:
            got = f"{width}x{height}"
            raise ApiError(
                400,
                f"{field}: the PNG is {got}, the frame {shape[1]}x{shape[0]}",
                fields={field: f"must be {shape[1]}x{shape[0]} like the frame, got {got}"},
            )
        return egonet_io.decode_mask(data, path=field)
    except egonet_io.MediaError as exc:
        raise ApiError(400, str(exc), fields={field: exc.reason}) from None


# --------------------------------------------------------------------------
# Loading


def get_frame(frame_id: int, *, field: str | None = None) -> Frame:
    """The frame, or an error: 400 naming ``field`` when the id came in a
    request body, 404 when it was part of the URL."""
    frame = db.session.get(Frame, frame_id)
    if frame is None:
        if field is not None:
            raise ApiError(400, f"{field}: there is no frame {frame_id}", fields={field: "no such frame"})
        raise ApiError(404, f"there is no frame {frame_id}", fields={"frame_id": "no such frame"})
    return frame


def get_annotation(annotation_id: int) -> Annotation:
    annotation = db.session.get(Annotation, annotation_id)
    if annotation is None:
        raise ApiError(404, f"there is no annotation {annotation_id}", fields={"annotation_id": "no such annotation"})
    return annotation


def user_annotation(frame: Frame, user: User) -> Annotation | None:
    """The user's own annotation of the frame, if they started one."""
    return db.session.execute(db.select(Annotation).filter_by(frame_id=frame.id, author_id=user.id)).scalar_one_or_none()


def instance_of(annotation: Annotation, position: int) -> Instance:
    for instance in annotation.instances:
        if instance.position == position:
            return instance
    raise ApiError(404, f"annotation {annotation.id} has no instance {position}", fields={"position": "no such instance"})


def empty_mask(frame: Frame) -> np.ndarray:
    return np.zeros((frame.height, frame.width), bool)


def grabcut_keys(frame: Frame, user: User) -> list[str]:
    """The instance keys for which the user has a saved GrabCut session on the frame."""
    return list(
        db.session.execute(
            db.select(GrabCutState.instance_key)
            .filter_by(frame_id=frame.id, user_id=user.id)
            .order_by(GrabCutState.instance_key)
        ).scalars()
    )


# --------------------------------------------------------------------------
# Saving


@dataclass
class InstanceSpec:
    """One instance of a save, with its mask already stored."""

    key: str | None
    kind: InstanceKind | None
    label: str | None
    mask_path: str
    mask: np.ndarray


def save_annotation(frame: Frame, user: User, data: dict) -> Annotation:
    """Save the user's annotation of the frame from a checked request body.

    ``data`` holds ``version`` (the version the page has; 0 when it has
    none yet), ``instances`` (``key``, ``kind``, ``label``, ``mask`` as RLE),
    ``no_action_object``, optionally ``status`` ("in_progress" or "done")
    and ``time_spent_delta_s`` (seconds spent since the last save).

    Raises:
        ApiError: 400 naming a bad field, 409 with ``current_version`` when
            ``version`` is stale.
    """
    existing = user_annotation(frame, user)
    if data["version"] != (existing.version if existing is not None else 0):
        raise _stale(existing.version if existing is not None else 0)  # before any mask is decoded or stored
    shape = (frame.height, frame.width)
    keys: set[str] = set()
    for i, item in enumerate(data["instances"]):
        key = item["key"]
        if not KEY_PATTERN.fullmatch(key):
            raise ApiError(400, f"instances[{i}].key: use 1-40 letters, digits, - or _",
                           fields={f"instances[{i}].key": "use 1-40 letters, digits, - or _"})
        if key in keys:
            raise ApiError(400, f"instances[{i}].key: {key!r} is used twice", fields={f"instances[{i}].key": "duplicate key"})
        keys.add(key)
    masks = [decode_rle(item["mask"], shape, field=f"instances[{i}].mask") for i, item in enumerate(data["instances"])]
    # Mask files first: if the commit then fails, only unreferenced
    # content-addressed files remain.
    specs = [
        InstanceSpec(
            key=item["key"],
            kind=InstanceKind(item["kind"]) if item["kind"] else None,
            label=(item["label"] or "").strip() or None,
            mask_path=media.store(egonet_io.encode_png(mask), ".png"),
            mask=mask,
        )
        for item, mask in zip(data["instances"], masks)
    ]
    status = Status(data["status"]) if data["status"] else None
    return _write(
        frame,
        user,
        version=data["version"],
        specs=specs,
        no_action_object=data["no_action_object"],
        status=status,
        time_delta_s=data["time_spent_delta_s"],
    )


def upload_instance_mask(annotation: Annotation, user: User, *, position: int, version: int, png: bytes) -> Annotation:
    """Replace one instance's mask with a PNG (``position`` = the number of
    instances adds one); only the annotation's author may.

    Raises:
        ApiError: 403 for someone else's annotation, 409 for a stale
            ``version``, 404 for an unknown position, 400 for a PNG that is
            not binary or not the frame's size (in that order: the PNG is
            decoded last).
    """
    frame = annotation.frame
    if annotation.author_id != user.id:
        raise ApiError(403, "only its author can change an annotation")
    if version != annotation.version:
        raise _stale(annotation.version)
    current = annotation.instances
    if not 0 <= position <= len(current):
        raise ApiError(404, f"there is no instance {position} (the annotation has {len(current)})",
                       fields={"position": f"must be 0-{len(current)}"})
    mask = decode_mask_png(png, (frame.height, frame.width))
    specs = [_spec_of(instance) for instance in current]
    path = media.store(egonet_io.encode_png(mask), ".png")
    if position == len(specs):
        specs.append(InstanceSpec(key=None, kind=None, label=None, mask_path=path, mask=mask))
    else:
        specs[position].mask_path, specs[position].mask = path, mask
    return _write(frame, user, version=version, specs=specs, no_action_object=annotation.no_action_object,
                  status=None, time_delta_s=0.0)


def _spec_of(instance: Instance) -> InstanceSpec:
    return InstanceSpec(
        key=instance.key,
        kind=instance.kind,
        label=instance.label,
        mask_path=instance.mask_path,
        mask=egonet_io.read_mask(media.absolute_path(instance.mask_path)),
    )


def _write(
    frame: Frame,
    user: User,
    *,
    version: int,
    specs: list[InstanceSpec],
    no_action_object: bool,
    status: Status | None,
    time_delta_s: float,
) -> Annotation:
    annotation = user_annotation(frame, user)
    current = annotation.version if annotation is not None else 0
    if version != current:
        raise _stale(current)
    drawn = [s for s in specs if s.mask.any()]
    if no_action_object and drawn:
        raise ApiError(
            400,
            "no_action_object: the frame has drawn action-objects; delete them first",
            fields={"no_action_object": "delete the drawn instances first"},
        )
    if status is Status.DONE:
        _check_complete(specs, no_action_object)
    union = np.zeros((frame.height, frame.width), bool)
    for spec in specs:
        union |= spec.mask
    union_path = media.store(egonet_io.encode_png(union), ".png") if union.any() else None

    if annotation is None:
        annotation = Annotation(frame=frame, author=user, status=Status.IN_PROGRESS)
        db.session.add(annotation)
        changed = True
    else:
        old = [(i.key, i.kind, i.label, i.mask_path) for i in annotation.instances]
        new = [(s.key, s.kind, s.label, s.mask_path) for s in specs]
        changed = old != new or annotation.no_action_object != no_action_object
    annotation.no_action_object = no_action_object
    annotation.mask_path = union_path
    annotation.status = _next_status(annotation.status, requested=status, changed=changed)
    annotation.time_spent_s = (annotation.time_spent_s or 0.0) + time_delta_s
    annotation.updated_at = utcnow()  # always an UPDATE, so the version moves on
    try:
        # The annotation's row goes first: its UPDATE carries the version
        # check (and locks the row), so a concurrent save fails here, before
        # any instance row is touched.
        db.session.flush()
        if changed:
            annotation.instances.clear()
            db.session.flush()  # free the positions before the new rows take them
            for position, spec in enumerate(specs):
                annotation.instances.append(
                    Instance(position=position, key=spec.key, kind=spec.kind, label=spec.label, mask_path=spec.mask_path)
                )
        if annotation.status is Status.DONE:
            _forget_sessions(frame, user, keep={s.key for s in specs})
        db.session.commit()
    except (StaleDataError, IntegrityError):
        # Another save of the same annotation won the race.
        db.session.rollback()
        latest = user_annotation(frame, user)
        raise _stale(latest.version if latest is not None else 0) from None
    return annotation


def add_time(frame: Frame, user: User, seconds: float) -> bool:
    """Add time spent on the user's annotation of the frame, without a new version.

    Time alone is no edit: it must not make other pages' versions stale
    (the page sends it when it is hidden or closed). Returns False when the
    user has no annotation of the frame.
    """
    result = db.session.execute(
        db.update(Annotation)
        .where(Annotation.frame_id == frame.id, Annotation.author_id == user.id)
        .values(time_spent_s=Annotation.time_spent_s + seconds, updated_at=Annotation.updated_at)
        .execution_options(synchronize_session=False)
    )
    db.session.commit()
    return result.rowcount > 0


def _check_complete(specs: list[InstanceSpec], no_action_object: bool) -> None:
    for i, spec in enumerate(specs):
        if not spec.mask.any():
            raise ApiError(400, f"instances[{i}].mask: empty; draw the object or delete the instance",
                           fields={f"instances[{i}].mask": "empty"})
    if not specs and not no_action_object:
        raise ApiError(
            400,
            'status: draw at least one action-object or mark the frame "no action-object" before marking it done',
            fields={"status": "nothing drawn and not marked no action-object"},
        )


def _next_status(current: Status, *, requested: Status | None, changed: bool) -> Status:
    if requested is Status.DONE:
        # Confirming "done" on an accepted annotation that did not change keeps the acceptance.
        return Status.REVIEWED if current is Status.REVIEWED and not changed else Status.DONE
    if requested is Status.IN_PROGRESS:
        return Status.IN_PROGRESS
    if not changed:
        return current
    if current in (Status.DONE, Status.REVIEWED):
        return Status.DONE  # an edited finished annotation goes back to review
    return Status.IN_PROGRESS


def _stale(current: int) -> ApiError:
    return ApiError(
        409,
        f"this annotation was changed elsewhere: it is at version {current}",
        fields={"version": f"is {current} now"},
        current_version=current,
    )


# --------------------------------------------------------------------------
# Review


def review_annotation(annotation: Annotation, reviewer: User, *, version: int, decision: str, comment: str | None) -> Annotation:
    """Accept (reviewed) or reject (rejected, back to its author) a done annotation.

    Raises:
        ApiError: 403 for the reviewer's own annotation, 400 for a rejection
            without a comment, 409 when the annotation is not done or
            ``version`` is stale.
    """
    if annotation.author_id == reviewer.id:
        raise ApiError(403, "you cannot review your own annotation", fields={"annotation_id": "is your own"})
    comment = (comment or "").strip() or None
    if decision == "reject" and comment is None:
        raise ApiError(400, "comment: say what to fix when rejecting", fields={"comment": "required when rejecting"})
    if annotation.version != version:
        raise _stale(annotation.version)
    if annotation.status is not Status.DONE:
        raise ApiError(
            409,
            f"only done annotations can be reviewed; this one is {annotation.status.value.replace('_', ' ')}",
            fields={"status": f"is {annotation.status.value}"},
        )
    annotation.status = Status.REVIEWED if decision == "accept" else Status.REJECTED
    annotation.review_comment = comment
    annotation.reviewer = reviewer
    annotation.reviewed_at = utcnow()
    if annotation.status is Status.REVIEWED:
        _forget_sessions(annotation.frame, annotation.author, keep=set())
    try:
        db.session.commit()
    except StaleDataError:
        db.session.rollback()
        raise _stale(get_annotation(annotation.id).version) from None
    return annotation


# --------------------------------------------------------------------------
# Queues


def _frame_order():
    return (Activity.name, Sequence.name, Frame.index, Frame.id)


def _unlabelled_for(user: User):
    """SQL condition: the frame still needs labelling, as far as ``user`` goes.

    A frame is taken when any annotation of it is finished, or another
    person's is in progress or rejected (it is theirs to finish).
    """
    taken = exists().where(
        Annotation.frame_id == Frame.id,
        or_(
            Annotation.status.in_(FINISHED),
            and_(Annotation.author_id != user.id, Annotation.status.in_((Status.IN_PROGRESS, Status.REJECTED))),
        ),
    )
    return ~taken


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
    rows = db.session.execute(waiting.order_by(Annotation.updated_at, Annotation.id).limit(limit)).scalars().all()
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
# GrabCut sessions


@dataclass
class GrabCutResult:
    mask: np.ndarray
    can_undo: bool


class _Recent:
    """Recently used objects of this worker, by key, within a budget of bytes:
    the least recently used go first, and one larger than the budget is not kept."""

    def __init__(self):
        self._items: OrderedDict = OrderedDict()  # key -> (value, bytes), least recent first
        self._lock = threading.Lock()
        self.nbytes = 0

    def keys(self) -> list:
        with self._lock:
            return list(self._items)

    def get(self, key):
        with self._lock:
            if key not in self._items:
                return None
            self._items.move_to_end(key)
            return self._items[key][0]

    def take(self, key):
        with self._lock:
            value, size = self._items.pop(key, (None, 0))
            self.nbytes -= size
            return value

    def put(self, key, value, *, nbytes: int, budget: int) -> None:
        with self._lock:
            self.nbytes -= self._items.pop(key, (None, 0))[1]
            if nbytes > budget:
                return
            self._items[key] = (value, nbytes)
            self.nbytes += nbytes
            while self.nbytes > budget:
                _, (_, size) = self._items.popitem(last=False)
                self.nbytes -= size


# Sessions under their row's revision. A session is taken out while an
# operation runs on it (so two threads never share one) and put back under
# the new revision afterwards; since a revision is random and changes with
# every write, a cached session is used only while the database still holds
# exactly its state. A client's keep-alive connection stays with one worker,
# so an annotator's strokes usually find their session here. They are kept
# within GRABCUT_CACHE_BYTES, counted by their arrays (8-10 MB each at
# 1280x960: the frame's copy, the mask, the ROI's guide, the footprints).
_sessions = _Recent()
# Decoded frames by their (content-addressed, so never stale) media path,
# within GRABCUT_IMAGE_CACHE_BYTES: a session restored in another worker then
# only needs its state decoded.
_images = _Recent()


def _dump_state(session: GrabCutSession) -> bytes:
    buffer = io.BytesIO()
    np.savez(buffer, **session.state())
    # np.savez_compressed is several times slower than zlib's fastest level
    # for about the same size on these mostly-bit-packed arrays.
    return zlib.compress(buffer.getvalue(), 1)


def _frame_image(frame: Frame) -> np.ndarray:
    image = _images.get(frame.rgb_path)
    if image is None:
        image = egonet_io.read_image(media.absolute_path(frame.rgb_path))
        _images.put(frame.rgb_path, image, nbytes=image.nbytes, budget=current_app.config["GRABCUT_IMAGE_CACHE_BYTES"])
    return image


def _keep(revision: str, session: GrabCutSession) -> None:
    _sessions.put(revision, session, nbytes=session.nbytes, budget=current_app.config["GRABCUT_CACHE_BYTES"])


def _load_session(frame: Frame, blob: bytes) -> GrabCutSession:
    with np.load(io.BytesIO(zlib.decompress(blob)), allow_pickle=False) as arrays:
        return GrabCutSession.from_state(_frame_image(frame), dict(arrays))


def _new_session(frame: Frame) -> GrabCutSession:
    return GrabCutSession(_frame_image(frame))


def check_key(key: str, *, field: str = "instance") -> str:
    if not KEY_PATTERN.fullmatch(key):
        raise ApiError(400, f"{field}: use 1-40 letters, digits, - or _", fields={field: "use 1-40 letters, digits, - or _"})
    return key


def check_box(frame: Frame, box: list[float]) -> tuple[int, int, int, int]:
    """A box ``[x0, y0, x1, y1]`` (pixels, x1 and y1 exclusive) inside the frame, not empty."""
    x0, y0, x1, y1 = (int(round(v)) for v in box)
    w, h = frame.width, frame.height
    if not (0 <= x0 < x1 <= w and 0 <= y0 < y1 <= h):
        raise ApiError(
            400,
            f"box: [{x0}, {y0}, {x1}, {y1}] is empty or outside the {w}x{h} frame",
            fields={"box": f"must satisfy 0 <= x0 < x1 <= {w} and 0 <= y0 < y1 <= {h}"},
        )
    if (x0, y0, x1, y1) == (0, 0, w, h):
        raise ApiError(400, "box: covers the whole frame; leave some background around the object",
                       fields={"box": "covers the whole frame"})
    return x0, y0, x1, y1


def check_stroke(frame: Frame, points: list[list[float]], radius: float) -> None:
    """A stroke with at least one point, a radius in (0, GRABCUT_MAX_RADIUS],
    points no further than a frame's size outside it, touching the frame.
    (The request's schema holds the number of points to
    GRABCUT_MAX_STROKE_POINTS; ``grabcut_stroke`` checks what the object's
    strokes cost in all.)"""
    w, h = frame.width, frame.height
    if not points:
        raise ApiError(400, "points: a stroke needs at least one point", fields={"points": "must not be empty"})
    limit = current_app.config["GRABCUT_MAX_RADIUS"]
    if not 0 < radius <= limit:
        raise ApiError(400, f"radius: must be a positive number of pixels up to {limit:g}",
                       fields={"radius": f"must be > 0 and <= {limit:g}"})
    for i, (x, y) in enumerate(points):
        if not (-w <= x <= 2 * w and -h <= y <= 2 * h):
            raise ApiError(400, f"points[{i}]: ({x}, {y}) is far outside the {w}x{h} frame",
                           fields={f"points[{i}]": "far outside the frame"})
    xs = [p[0] for p in points]
    ys = [p[1] for p in points]
    if max(xs) < -radius or min(xs) > w - 1 + radius or max(ys) < -radius or min(ys) > h - 1 + radius:
        raise ApiError(400, "points: the stroke lies outside the frame", fields={"points": "outside the frame"})


def stroke_pixels(shape: tuple[int, int], points: list | np.ndarray, radius: float) -> int:
    """The pixels that painting a stroke visits: ``egonet.grabcut`` measures
    the distance to each segment over the segment's box widened by the
    radius, into a crop of the whole stroke's box (all clipped to the frame).
    Its time and memory, and those of replaying the stroke when a worker
    restores the session, follow this number."""
    h, w = shape
    p = np.asarray(points, np.float64).reshape(-1, 2)
    starts, ends = (p, p) if len(p) == 1 else (p[:-1], p[1:])
    lows = np.vstack([np.minimum(starts, ends), p.min(axis=0)])
    highs = np.vstack([np.maximum(starts, ends), p.max(axis=0)])
    x0 = np.clip(np.floor(lows[:, 0] - radius), 0, w)
    y0 = np.clip(np.floor(lows[:, 1] - radius), 0, h)
    x1 = np.clip(np.ceil(highs[:, 0] + radius) + 1, 0, w)
    y1 = np.clip(np.ceil(highs[:, 1] + radius) + 1, 0, h)
    return int((np.maximum(x1 - x0, 0) * np.maximum(y1 - y0, 0)).sum())


def _check_frame_size(frame: Frame) -> None:
    side = current_app.config["MAX_FRAME_SIDE"]
    if max(frame.width, frame.height) > side:
        raise ApiError(400, f"frame_id: frame {frame.id} is {frame.width}x{frame.height}, larger than GrabCut's "
                            f"limit of {side} pixels a side; label it by hand or import it smaller",
                       fields={"frame_id": f"larger than {side} pixels a side"})


def _check_sweep(session: GrabCutSession, points: list, radius: float) -> None:
    """Refuse a stroke that would take the object's strokes past GRABCUT_MAX_STROKE_PIXELS (see ``stroke_pixels``)."""
    limit = current_app.config["GRABCUT_MAX_STROKE_PIXELS"]
    new = stroke_pixels(session.shape, points, radius)
    earlier = sum(stroke_pixels(session.shape, p, r) for p, _, r in session.strokes)
    if new > limit:
        raise ValueError(f"points: the stroke sweeps {new / 1e6:.1f} Mpx (its segments' boxes widened by the radius), "
                         f"more than the limit of {limit / 1e6:.1f} Mpx; draw shorter strokes or use a smaller brush")
    if earlier + new > limit:
        raise ValueError(f"points: the object's strokes would sweep {(earlier + new) / 1e6:.1f} Mpx, more than the "
                         f"limit of {limit / 1e6:.1f} Mpx; undo some of them or start the object again with a box")


def grabcut_box(frame: Frame, user: User, key: str, box: tuple[int, int, int, int]) -> GrabCutResult:
    """Start (or restart) the object ``key`` from a box; see ``check_box``."""
    return _operate(frame, user, key, lambda s: s.box(*box), create=True)


def grabcut_stroke(frame: Frame, user: User, key: str, *, points: list, label: str, radius: float) -> GrabCutResult:
    """Add a corrective fg/bg stroke to the object ``key``; see ``check_stroke``.
    The object's strokes in all may sweep at most GRABCUT_MAX_STROKE_PIXELS."""

    def apply(session: GrabCutSession) -> np.ndarray:
        _check_sweep(session, points, radius)
        return session.stroke(points, label, radius)

    return _operate(frame, user, key, apply, create=False)


def grabcut_undo(frame: Frame, user: User, key: str) -> GrabCutResult:
    """Step the object's GrabCut session back by one operation."""
    return _operate(frame, user, key, lambda s: s.undo(), create=False)


def grabcut_mask(frame: Frame, user: User, key: str) -> GrabCutResult:
    """The session's current mask, without changing it."""
    _check_frame_size(frame)
    row = _state_row(frame, user, key, lock=False)
    if row is None:
        raise ApiError(404, f"no GrabCut session for object {key!r} on this frame", fields={"instance": "no session"})
    session = _sessions.take(row.revision) or _load_session(frame, row.state)
    _keep(row.revision, session)
    return GrabCutResult(session.mask, session.can_undo)


def _state_row(frame: Frame, user: User, key: str, *, lock: bool) -> GrabCutState | None:
    query = db.select(GrabCutState).filter_by(user_id=user.id, frame_id=frame.id, instance_key=key)
    if lock:
        query = query.with_for_update()
    return db.session.execute(query).scalar_one_or_none()


@contextlib.contextmanager
def _session_lock(frame: Frame, user: User, key: str):
    """Hold an exclusive lock for one GrabCut session, across threads and
    processes on this machine (one of 64 lock files under CACHE_ROOT)."""
    folder = Path(current_app.config["CACHE_ROOT"]) / "grabcut-locks"
    folder.mkdir(parents=True, exist_ok=True)
    stripe = zlib.crc32(f"{user.id}/{frame.id}/{key}".encode()) % 64
    with open(folder / f"{stripe:02d}.lock", "a+b") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


def _operate(frame: Frame, user: User, key: str, apply: Callable[[GrabCutSession], np.ndarray], *, create: bool) -> GrabCutResult:
    _check_frame_size(frame)
    # The lock file serialises the workers of one machine; the revision check
    # below still catches a writer that it cannot see (another machine).
    with _session_lock(frame, user, key):
        return _operate_locked(frame, user, key, apply, create=create)


def _operate_locked(frame: Frame, user: User, key: str, apply: Callable[[GrabCutSession], np.ndarray], *, create: bool) -> GrabCutResult:
    for _ in range(3):
        row = _state_row(frame, user, key, lock=True)
        if row is None:
            if not create:
                db.session.rollback()
                raise ApiError(400, "box: draw a box around the object first", fields={"box": "no box yet for this object"})
            session = _new_session(frame)
        else:
            session = _sessions.take(row.revision) or _load_session(frame, row.state)
        try:
            mask = apply(session)
        except ValueError as exc:
            db.session.rollback()
            field, _, reason = str(exc).partition(": ")
            raise ApiError(400, str(exc), fields={field: reason or str(exc)}) from None
        except RuntimeError as exc:  # undo with nothing to undo
            db.session.rollback()
            raise ApiError(409, str(exc), fields={"undo": "nothing to undo"}) from None
        if row is None:
            row = GrabCutState(user_id=user.id, frame_id=frame.id, instance_key=key, state=_dump_state(session))
            db.session.add(row)
        else:
            row.state = _dump_state(session)
        try:
            db.session.commit()
        except (StaleDataError, IntegrityError):
            # Another operation on this session committed first: redo ours on its state.
            db.session.rollback()
            continue
        _keep(row.revision, session)
        return GrabCutResult(mask, session.can_undo)
    raise ApiError(409, "another GrabCut operation on this object is still running; try again",
                   fields={"instance": "busy"})


def _forget_sessions(frame: Frame, user: User, *, keep: set[str | None]) -> None:
    """Delete the user's GrabCut sessions on the frame except those of ``keep``."""
    query = db.delete(GrabCutState).where(GrabCutState.frame_id == frame.id, GrabCutState.user_id == user.id)
    kept = [k for k in keep if k]
    if kept:
        query = query.where(GrabCutState.instance_key.not_in(kept))
    db.session.execute(query)
