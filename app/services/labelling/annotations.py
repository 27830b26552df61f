"""A person's annotation of a frame: loading it, saving it with a version
check, and its instances.

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
back to its author with the comment (see ``review``). Editing a rejected
annotation puts it back in progress. A done or reviewed annotation is
read-only: a save, a mask upload or a GrabCut step on it is refused (409,
``reason: "finished"``) until its author reopens it (``reopen_annotation``,
the page's "Edit"), which puts it back in progress, so it must be marked
done, and reviewed, again; reopening a reviewed one withdraws its
acceptance. Nothing demotes a finished annotation silently. (A reviewer may
fix a done annotation's masks before deciding: ``review.fix_annotation``.)
Marking it done lets go of the GrabCut sessions of instances it no longer has.

Proposals. An instance Suggest proposed (``suggest``) keeps its mark through
saves that bring its key with the same mask; a save that changes its mask
(paint, erase, a GrabCut step) clears the mark, as does accepting it. An
annotation with proposals still marked cannot be marked done: the annotator
accepts or rejects each first, so unreviewed model output never becomes
ground truth.
"""

import re
from dataclasses import dataclass

import numpy as np
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm.exc import StaleDataError

from app.errors import Problem
from app.extensions import db
from app.models import FINISHED, Annotation, Frame, Instance, InstanceKind, Status, User, is_hand, utcnow
from app.services import media
from app.services.labelling.classes import check_labels
from app.services.labelling.grabcut import forget_sessions
from app.services.labelling.masks import decode_mask_png, decode_rle
from egonet import io as egonet_io

# The statuses an annotator may ask for; review decisions set the others.
AUTHOR_STATUSES = (Status.IN_PROGRESS, Status.DONE)
MAX_INSTANCES = 50
MAX_TIME_DELTA_S = 3600.0
KEY_PATTERN = re.compile(r"[A-Za-z0-9_-]{1,40}")


# --------------------------------------------------------------------------
# Loading


def get_frame(frame_id: int, *, field: str | None = None) -> Frame:
    """The frame, or an error: 400 naming ``field`` when the id came in a
    request body, 404 when it was part of the URL."""
    frame = db.session.get(Frame, frame_id)
    if frame is None:
        if field is not None:
            raise Problem(f"{field}: there is no frame {frame_id}", fields={field: "no such frame"})
        raise Problem(f"there is no frame {frame_id}", status=404, fields={"frame_id": "no such frame"})
    return frame


def get_annotation(annotation_id: int) -> Annotation:
    annotation = db.session.get(Annotation, annotation_id)
    if annotation is None:
        raise Problem(f"there is no annotation {annotation_id}", status=404,
                      fields={"annotation_id": "no such annotation"})
    return annotation


def user_annotation(frame: Frame, user: User) -> Annotation | None:
    """The user's own annotation of the frame, if they started one."""
    return db.session.execute(db.select(Annotation).filter_by(frame_id=frame.id, author_id=user.id)).scalar_one_or_none()


def instance_of(annotation: Annotation, position: int) -> Instance:
    for instance in annotation.instances:
        if instance.position == position:
            return instance
    raise Problem(f"annotation {annotation.id} has no instance {position}", status=404,
                  fields={"position": "no such instance"})


def empty_mask(frame: Frame) -> np.ndarray:
    return np.zeros((frame.height, frame.width), bool)


def check_key(key: str, *, field: str = "instance") -> str:
    """An instance's key (which also names its GrabCut session): 1-40 letters, digits, - or _."""
    if not KEY_PATTERN.fullmatch(key):
        raise Problem(f"{field}: use 1-40 letters, digits, - or _", fields={field: "use 1-40 letters, digits, - or _"})
    return key


# --------------------------------------------------------------------------
# Saving


@dataclass
class InstanceSpec:
    """One instance of a save, with its mask already stored (and, for a
    proposal, its source and the run and checkpoint that proposed it)."""

    key: str | None
    kind: InstanceKind | None
    label: str | None
    mask_path: str
    mask: np.ndarray
    proposal_source: str | None = None
    proposed_by_run_id: int | None = None
    proposed_by_checkpoint_id: int | None = None

    @property
    def proposed(self) -> bool:
        return self.proposal_source is not None


def save_annotation(frame: Frame, user: User, data: dict) -> Annotation:
    """Save the user's annotation of the frame from a checked request body.

    ``data`` holds ``version`` (the version the page has; 0 when it has
    none yet), ``instances`` (``key``, ``kind``, ``label``, ``mask`` as RLE),
    ``no_action_object``, optionally ``status`` ("in_progress" or "done")
    and ``time_spent_delta_s`` (seconds spent since the last save).

    Raises:
        Problem: 400 naming a bad field, 409 with ``current_version`` when
            ``version`` is stale.
    """
    existing = user_annotation(frame, user)
    status = Status(data["status"]) if data["status"] else None
    if _marks_done_again(existing, data, status):
        specs = instance_specs(frame, data["instances"])
        if _same_content(existing, specs, data["no_action_object"]):
            return existing  # "Mark done" twice (a double click): already done, as asked
    if data["version"] != (existing.version if existing is not None else 0):
        raise stale(existing.version if existing is not None else 0)  # before any mask is decoded or stored
    if existing is not None:
        check_open(existing)
    return _write(
        frame,
        user,
        version=data["version"],
        specs=instance_specs(frame, data["instances"]),
        no_action_object=data["no_action_object"],
        status=status,
        time_delta_s=data["time_spent_delta_s"],
    )


def _marks_done_again(existing: Annotation | None, data: dict, status: Status | None) -> bool:
    """A request to mark done an annotation that its last save marked done,
    sent on that save's version or the one before it (the same click sent twice)."""
    return (existing is not None and status is Status.DONE and existing.status is Status.DONE
            and data["version"] in (existing.version, existing.version - 1))


def _same_content(annotation: Annotation, specs: list["InstanceSpec"], no_action_object: bool) -> bool:
    """Whether a save brings exactly the annotation's objects (masks compared by their content-addressed files)."""
    stored = [(i.key, i.kind, i.label, i.mask_path) for i in annotation.instances]
    return annotation.no_action_object == no_action_object and stored == [
        (s.key, s.kind, s.label, s.mask_path) for s in specs
    ]


def instance_specs(frame: Frame, instances: list[dict]) -> list["InstanceSpec"]:
    """A save's instances (``key``, ``kind``, ``label``, ``mask`` as RLE), checked, with their masks stored.

    Mask files go first: if the commit then fails, only unreferenced
    content-addressed files remain.
    """
    shape = (frame.height, frame.width)
    _check_keys([item["key"] for item in instances])
    check_labels([(item["label"] or "").strip() or None for item in instances])
    masks = [decode_rle(item["mask"], shape, field=f"instances[{i}].mask") for i, item in enumerate(instances)]
    return [
        InstanceSpec(
            key=item["key"],
            kind=InstanceKind(item["kind"]) if item["kind"] else None,
            label=(item["label"] or "").strip() or None,
            mask_path=media.store(egonet_io.encode_png(mask), ".png"),
            mask=mask,
        )
        for item, mask in zip(instances, masks)
    ]


def check_open(annotation: Annotation) -> None:
    """Refuse to change a done or reviewed annotation that was not reopened.

    Raises:
        Problem: 409 with ``reason: "finished"`` and ``current_version``.
    """
    if annotation.status not in FINISHED:
        return
    what = "done" if annotation.status is Status.DONE else "reviewed (accepted)"
    raise Problem(
        f"this annotation is {what} and read-only: reopen it (Edit) to change it, which puts it back in progress",
        status=409,
        fields={"status": f"is {annotation.status.value}: reopen it first"},
        reason="finished",
        current_version=annotation.version,
    )


def check_open_frame(frame: Frame, user: User) -> None:
    """Refuse a change of the user's annotation of the frame while it is done or reviewed (see ``check_open``)."""
    annotation = user_annotation(frame, user)
    if annotation is not None:
        check_open(annotation)


def reopen_annotation(frame: Frame, user: User, *, version: int) -> Annotation:
    """Put the user's done or reviewed annotation back in progress ("Edit"), with a version check.

    A reviewed annotation loses its acceptance: it must be marked done and
    reviewed again. The last decision's reviewer and comment stay on it.
    An annotation already open is returned as it is.

    Raises:
        Problem: 404 when the user has no annotation of the frame, 409 for a stale ``version``.
    """
    annotation = user_annotation(frame, user)
    if annotation is None:
        raise Problem("you have no annotation of this frame to reopen", status=404, fields={"frame_id": "no annotation"})
    if version != annotation.version:
        raise stale(annotation.version)
    if annotation.status not in FINISHED:
        return annotation
    annotation.status = Status.IN_PROGRESS
    annotation.updated_at = utcnow()
    try:
        db.session.commit()
    except StaleDataError:
        db.session.rollback()
        raise stale(user_annotation(frame, user).version) from None
    return annotation


def _check_keys(keys: list[str]) -> None:
    """Each instance's key well-formed and used once."""
    seen: set[str] = set()
    for i, key in enumerate(keys):
        check_key(key, field=f"instances[{i}].key")
        if key in seen:
            raise Problem(f"instances[{i}].key: {key!r} is used twice", fields={f"instances[{i}].key": "duplicate key"})
        seen.add(key)


def upload_instance_mask(annotation: Annotation, user: User, *, position: int, version: int, png: bytes) -> Annotation:
    """Replace one instance's mask with a PNG (``position`` = the number of
    instances adds one); only the annotation's author may.

    Raises:
        Problem: 403 for someone else's annotation, 409 for a stale
            ``version``, 404 for an unknown position, 400 for a PNG that is
            not binary or not the frame's size (in that order: the PNG is
            decoded last).
    """
    frame = annotation.frame
    if annotation.author_id != user.id:
        raise Problem("only its author can change an annotation", status=403)
    if version != annotation.version:
        raise stale(annotation.version)
    check_open(annotation)
    current = annotation.instances
    if not 0 <= position <= len(current):
        raise Problem(f"there is no instance {position} (the annotation has {len(current)})", status=404,
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
        mask=egonet_io.read_mask(media.local_path(instance.mask_path)),
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
    proposed_by: tuple[int, int] | None = None,
    fixed_by: User | None = None,
) -> Annotation:
    """Write the user's annotation of the frame (see ``save_annotation``);
    ``proposed_by`` ``(run id, checkpoint id)`` records a suggestion's source,
    ``fixed_by`` the reviewer whose fix this is (``review.fix_annotation``)."""
    annotation = user_annotation(frame, user)
    current = annotation.version if annotation is not None else 0
    if version != current:
        raise stale(current)
    if annotation is not None:
        _carry_marks(annotation, specs)
    drawn = [s for s in specs if s.mask.any() and not is_hand(s.label)]
    if no_action_object and drawn:
        raise Problem(
            "no_action_object: the frame has drawn action-objects; delete them first",
            fields={"no_action_object": "delete the drawn instances first"},
        )
    if status is Status.DONE:
        _check_complete(specs, no_action_object)
    union = np.zeros((frame.height, frame.width), bool)
    for spec in specs:
        if not is_hand(spec.label):  # hands are drawn to train the hand detector, they are no action-object
            union |= spec.mask
    union_path = media.store(egonet_io.encode_png(union), ".png") if union.any() else None

    if annotation is None:
        annotation = Annotation(frame=frame, author=user, status=Status.IN_PROGRESS)
        db.session.add(annotation)
        changed = True
    else:
        old = [(i.key, i.kind, i.label, i.mask_path, i.proposal_source) for i in annotation.instances]
        new = [(s.key, s.kind, s.label, s.mask_path, s.proposal_source) for s in specs]
        changed = old != new or annotation.no_action_object != no_action_object
    if proposed_by is not None:
        annotation.proposed_by_run_id, annotation.proposed_by_checkpoint_id = proposed_by
    annotation.no_action_object = no_action_object
    annotation.mask_path = union_path
    own = no_action_object or any(not s.proposed for s in specs)
    annotation.status = _next_status(annotation.status, requested=status, changed=changed, own=own)
    if fixed_by is not None and changed:
        annotation.fixed_by, annotation.fixed_at = fixed_by, utcnow()
    annotation.time_spent_s = (annotation.time_spent_s or 0.0) + time_delta_s
    annotation.updated_at = utcnow()  # always an UPDATE, so the version moves on
    _commit(annotation, frame, user, specs, changed=changed)
    return annotation


def _carry_marks(annotation: Annotation, specs: list[InstanceSpec]) -> None:
    """A proposal stays marked while a save brings it back unchanged: same key, same mask file
    (masks are stored by content, so any change of a pixel is a new file)."""
    marked = {i.key: i for i in annotation.instances if i.proposed and i.key is not None}
    for spec in specs:
        old = marked.get(spec.key)
        if spec.proposed or old is None or old.mask_path != spec.mask_path:
            continue
        for name in Instance.UNMARKED:
            setattr(spec, name, getattr(old, name))


def _commit(annotation: Annotation, frame: Frame, user: User, specs: list[InstanceSpec], *, changed: bool) -> None:
    """Write the annotation's row, then its instances when they changed, in one transaction.

    Raises:
        Problem: 409 with ``current_version`` when another save won the race.
    """
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
                    Instance(
                        position=position,
                        key=spec.key,
                        kind=spec.kind,
                        label=spec.label,
                        mask_path=spec.mask_path,
                        proposal_source=spec.proposal_source,
                        proposed_by_run_id=spec.proposed_by_run_id,
                        proposed_by_checkpoint_id=spec.proposed_by_checkpoint_id,
                    )
                )
        if annotation.status is Status.DONE:
            forget_sessions(frame, user, keep={s.key for s in specs})
        db.session.commit()
    except (StaleDataError, IntegrityError):
        # Another save of the same annotation won the race.
        db.session.rollback()
        latest = user_annotation(frame, user)
        raise stale(latest.version if latest is not None else 0) from None


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
    if pending := [i for i, spec in enumerate(specs) if spec.proposed]:
        raise Problem(
            f"status: {len(pending)} of the model's proposals are not accepted yet; accept or reject each "
            "before marking the frame done",
            fields={"status": f"proposals pending: instances {', '.join(map(str, pending))}"},
        )
    for i, spec in enumerate(specs):
        if not spec.mask.any():
            raise Problem(f"instances[{i}].mask: empty; draw the object or delete the instance",
                          fields={f"instances[{i}].mask": "empty"})
    if not any(not is_hand(s.label) for s in specs) and not no_action_object:
        raise Problem(
            'status: draw at least one action-object or mark the frame "no action-object" before marking it done',
            fields={"status": "nothing drawn and not marked no action-object"},
        )


def _next_status(current: Status, *, requested: Status | None, changed: bool, own: bool) -> Status:
    """The status after a write. An open annotation is in progress while it holds something of the
    annotator's own (an object not merely proposed, or "no action-object"), else "todo": proposals
    nobody accepted yet (Suggest) do not claim the frame."""
    if requested is not None:
        return requested
    if current in (Status.TODO, Status.IN_PROGRESS):
        return Status.IN_PROGRESS if own else Status.TODO
    if not changed:
        return current
    if current is Status.DONE:
        return Status.DONE  # a reviewer's fix (review.fix_annotation): still waiting for the decision
    return Status.IN_PROGRESS


def stale(current: int) -> Problem:
    """The 409 of a save or review made on an older version than ``current``."""
    return Problem(
        f"this annotation was changed elsewhere: it is at version {current}",
        status=409,
        fields={"version": f"is {current} now"},
        current_version=current,
    )
