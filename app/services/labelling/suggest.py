"""Proposals ("Suggest"): a trained run, depth, or a baseline proposes a frame's action-objects.

Who proposes is a ``proposers.Proposer``: by default ("auto") chosen by
evidence, a run trained on (or scoring well on) frames like this one, else
the frame's depth (the nearest compact surface off the supporting planes),
else the handled + viewed object's object-sized regions; or the source or
run the annotator chose (``proposers``).
The proposer's probability map of the frame is cut at its threshold (a
run's best-F threshold, one half for the other sources) into connected
regions (``regions``), each of which becomes an instance.
Each region is refined by GrabCut through the user's own GrabCut session
for the new instance, started from the region's mask
(``GrabCutSession.seed_mask``): its edge may move by ``regions.REFINE_BAND``
of the region's size, so it snaps to the object's edge without straying onto a
background of the object's colour, and the annotator can go on correcting
it with strokes; the session passes the frame's depth when the GrabCut
service does.

The proposals go into the user's annotation of the frame, each
instance marked with its source (and the run and checkpoint, from a run),
the annotation recording a run as well. The annotator's own work is never
overwritten: proposals go beside the instances already there (a region
GrabCut turns into much the same object as one of them is left out), and
only proposals still pending from an earlier suggestion are replaced. A
done or reviewed annotation, or one marked "no action-object", is refused
with 409: reopen it first. A proposal stays marked until the annotator
accepts it (``accept_proposal``) or edits its mask (see ``annotations``
and ``grabcut``); rejecting one is deleting it. Proposals alone do not claim the frame: an
annotation holding nothing of the annotator's own stays "todo"
(``annotations._next_status``), so trying Suggest leaves the frame to
label for everyone, until a proposal is accepted or edited.

One frame runs inline (the sources without a run take well under a second,
egonet-lite predicts a frame in about 0.3 s on a CPU); a model without a
stored prediction that would be slow here (the VGG models without a GPU)
is queued for the worker instead, as batches are (``suggest_frames``, the
``suggest_frames`` job, ``flask egonet suggest``).
"""

import secrets
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field

import numpy as np
from sqlalchemy.orm.exc import StaleDataError

from app.errors import Problem
from app.extensions import db
from app.models import Annotation, Frame, Instance, Role, Status, User, utcnow
from app.models.annotations import GrabCutState
from app.queue import enqueue
from app.services import media
from app.services.labelling.annotations import (
    InstanceSpec,
    _spec_of,
    _write,
    check_key,
    stale,
    user_annotation,
)
from app.services.labelling.grabcut import grabcut_seed
from app.services.labelling.proposers import DEFAULT_THRESHOLD, Proposer, SuggestProblem, choose
from app.services.labelling.regions import Region, iou, proposal_regions
from app.services.labelling.review import _unlabelled_for
from egonet import io as egonet_io

SAME_OBJECT_IOU = 0.5
"""A proposal overlapping an instance the annotator drew this much is that object again: left out."""


@dataclass
class Suggestion:
    """What one suggestion did (the page shows it, the CLI prints it)."""

    frame_id: int
    proposer: Proposer
    threshold: float
    threshold_source: str  # "checkpoint", "default" (a checkpoint without one) or "source"
    prediction: str  # "stored" or "computed"
    annotation: Annotation | None = None
    proposals: list[str] = field(default_factory=list)  # keys of the new instances
    replaced: int = 0  # earlier proposals, still pending, that these replace
    repeated: int = 0  # regions left out: objects the annotator drew already
    notes: list[str] = field(default_factory=list)
    seconds: float = 0.0

    def to_dict(self) -> dict:
        p = self.proposer
        return {
            "frame_id": self.frame_id,
            "source": p.source,
            "proposed_by": p.label,
            "run_id": p.run.id if p.run else None,
            "run_name": p.run.name if p.run else None,
            "checkpoint_id": p.checkpoint.id if p.checkpoint else None,
            "fold": p.checkpoint.fold if p.checkpoint else None,
            "checkpoint_choice": p.why if p.checkpoint else None,
            "held_out": p.held_out,
            "reason": p.reason or None,
            "threshold": round(self.threshold, 4),
            "threshold_source": self.threshold_source,
            "prediction": self.prediction,
            "proposals": list(self.proposals),
            "replaced": self.replaced,
            "notes": list(self.notes),
            "seconds": round(self.seconds, 3),
        }

    def summary(self) -> str:
        """What happened, in the annotator's words (the page's message; the CLI adds the frame): who
        proposed and, when Auto chose, why; how many objects; what to do when there are none."""
        p, n = self.proposer, len(self.proposals)
        who = p.label[0].upper() + p.label[1:]
        line = f"{who}: {p.reason}. " if p.reason else ""
        if n:
            line += (f"{who if not p.reason else 'It'} proposed {n} object{'' if n == 1 else 's'}: "
                     f"accept or reject {'it' if n == 1 else 'each'}.")
        else:
            line += (f"{who if not p.reason else 'It'} found no object to propose here; "
                     "choose another source, or draw a box (B).")
        if self.replaced:
            line += f" It replaced {self.replaced} earlier proposal{'' if self.replaced == 1 else 's'}."
        if self.repeated:
            line += f" {self.repeated} {'was' if self.repeated == 1 else 'were'} drawn already, left out."
        return line


def suggest_frame(
    frame: Frame,
    user: User,
    *,
    run_id: int | None = None,
    source: str = "auto",
    version: int | None = None,
    device: str = "auto",
) -> Suggestion:
    """Propose the frame's action-objects into the user's annotation of it.

    Args:
        frame: The frame.
        user: Whose in-progress annotation the proposals join.
        run_id: The run to ask (source "auto" or "model").
        source: Who proposes: "auto", "model" or one of
            ``egonet.proposals.SOURCES`` (see ``proposers.choose``).
        version: The annotation's version the caller has (0: none yet), as
            a save; ``None`` (batches) takes the current one.
        device: Where a model runs when no stored map is there.

    Returns:
        The suggestion, with the saved annotation.

    Raises:
        SuggestProblem: 409 for a stale ``version``, a done, reviewed or
            "no action-object" annotation; 400 / 404 / 409 for a bad
            ``source`` or ``run_id`` (see ``proposers.choose``).
    """
    started = time.perf_counter()
    existing = user_annotation(frame, user)
    _check_open(existing, version)
    proposer = choose(frame, run_id=run_id, source=source)
    threshold, threshold_source = proposer.threshold()
    probability, how = proposer.probability(frame, device=device)
    result = Suggestion(frame.id, proposer, threshold, threshold_source, how)
    if threshold_source == "default":
        result.notes.append(f"checkpoint {proposer.checkpoint.id} stores no best-F threshold: used {DEFAULT_THRESHOLD}")
    regions, dropped = proposal_regions(probability, threshold)
    result.notes += dropped
    if not regions:
        result.notes.append(f"no region of the map reaches {threshold:.2f}")
    _propose(frame, user, existing, regions, result)
    result.seconds = time.perf_counter() - started
    return result


def _propose(frame: Frame, user: User, existing: Annotation | None, regions: list[Region], result: Suggestion) -> None:
    """Refine the regions into instances beside the user's own, replacing pending proposals, and save."""
    p = result.proposer
    kept = [_spec_of(i) for i in existing.instances if not i.proposed] if existing else []
    replaced = [i.key for i in existing.instances if i.proposed] if existing else []
    specs, repeated = [], 0
    for region in regions:
        key = f"s{secrets.token_hex(6)}"
        mask = _refine(frame, user, key, region, result.notes)
        if any(iou(mask, s.mask) >= SAME_OBJECT_IOU for s in kept):
            repeated += 1
            _forget(frame, user, [key])
            continue
        specs.append(InstanceSpec(
            key=key, kind=None, label=None, mask_path=media.store(egonet_io.encode_png(mask), ".png"), mask=mask,
            proposal_source=p.source, proposed_by_run_id=p.run.id if p.run else None,
            proposed_by_checkpoint_id=p.checkpoint.id if p.checkpoint else None,
        ))
    result.repeated = repeated
    if repeated:
        result.notes.append(f"{repeated} region{'' if repeated == 1 else 's'} left out: already drawn")
    result.annotation = existing  # nothing to write: no new version, no empty annotation
    if specs or replaced:
        try:
            result.annotation = _write(
                frame, user, version=existing.version if existing is not None else 0, specs=kept + specs,
                no_action_object=False, status=None, time_delta_s=0.0,
                proposed_by=(p.run.id, p.checkpoint.id) if specs and p.run else None,
            )
        except Problem:  # a save won the race meanwhile: its version stands, these sessions are no one's
            _forget(frame, user, [s.key for s in specs])
            raise
        _forget(frame, user, replaced)
    result.proposals = [s.key for s in specs]
    result.replaced = len(replaced)


def _check_open(existing: Annotation | None, version: int | None) -> None:
    current = existing.version if existing is not None else 0
    if version is not None and version != current:
        raise stale(current)
    if existing is None:
        return
    if existing.status in (Status.DONE, Status.REVIEWED):
        raise SuggestProblem(
            f"status: your annotation of this frame is {existing.status.value}; reopen it to add a model's proposals",
            status=409, fields={"status": f"is {existing.status.value}"},
        )
    if existing.no_action_object:
        raise SuggestProblem(
            'no_action_object: the frame is marked "no action-object"; untick it to add a model\'s proposals',
            status=409, fields={"no_action_object": "is set"},
        )


def _refine(frame: Frame, user: User, key: str, region: Region, notes: list[str]) -> np.ndarray:
    """GrabCut from the region, in the user's session for ``key``; the region itself when GrabCut cannot run.

    The session starts from the region's mask (``grabcut_seed``): GrabCut
    snaps its edge to the image's within ``region.band`` pixels (with the
    frame's depth when the GrabCut service uses it), and strokes correct it
    at once.
    """
    if region.mask.all():
        notes.append("a region spanning the frame kept as the map drew it (no room for GrabCut's background)")
        return region.mask
    try:
        return grabcut_seed(frame, user, key, region.mask, band=region.band).mask
    except Problem as exc:  # a frame over GrabCut's size limit
        _forget(frame, user, [key])
        notes.append(f"a region kept as the map drew it (GrabCut: {exc.message})")
        return region.mask


def _forget(frame: Frame, user: User, keys: list[str]) -> None:
    """Delete the user's GrabCut sessions of these instance keys on the frame."""
    if not keys:
        return
    db.session.execute(
        db.delete(GrabCutState).where(
            GrabCutState.frame_id == frame.id, GrabCutState.user_id == user.id, GrabCutState.instance_key.in_(keys)
        )
    )
    db.session.commit()


@dataclass
class Queued:
    """A suggestion handed to the worker: the model would be slow in the request."""

    frame_id: int
    proposer: Proposer

    def summary(self) -> str:
        return (f"run {self.proposer.run.id}'s {self.proposer.run.model_name} is slow without a GPU: frame "
                f"{self.frame_id} is queued for the worker; its proposals appear when you reload the frame")


def suggest_from_page(frame: Frame, user: User, *, run_id: int | None, source: str, version: int) -> Suggestion | Queued:
    """One frame from the labelling page: inline when that is quick (``Proposer.fast``), else queued.

    Raises:
        SuggestProblem: as ``suggest_frame``, checked before anything is queued.
    """
    _check_open(user_annotation(frame, user), version)
    proposer = choose(frame, run_id=run_id, source=source)
    if proposer.fast(frame):
        return suggest_frame(frame, user, run_id=run_id, source=source, version=version)
    enqueue("suggest_frames", proposer.run.id, [frame.id], user.id, "auto", "model")
    return Queued(frame.id, proposer)


# --------------------------------------------------------------------------
# Accepting


def accept_proposal(frame: Frame, user: User, *, key: str, version: int) -> Annotation:
    """The annotator accepts a proposal: its mark goes, the annotation moves to a new version.

    Raises:
        Problem: 404 when the user has no annotation or no such instance,
            409 for a stale ``version`` or an instance that is no proposal.
    """
    check_key(key, field="key")
    annotation = user_annotation(frame, user)
    if annotation is None:
        raise Problem("you have no annotation of this frame yet", status=404, fields={"frame_id": "no annotation"})
    if version != annotation.version:
        raise stale(annotation.version)
    instance = next((i for i in annotation.instances if i.key == key), None)
    if instance is None:
        raise Problem(f"key: the annotation has no instance {key!r}", status=404, fields={"key": "no such instance"})
    if not instance.proposed:
        raise Problem(f"key: instance {key!r} is no proposal (accepted or edited already)", status=409,
                      fields={"key": "not a proposal"})
    for name, value in Instance.UNMARKED.items():
        setattr(instance, name, value)
    if annotation.status is Status.TODO:  # the first object of the annotator's own: now it is being labelled
        annotation.status = Status.IN_PROGRESS
    annotation.updated_at = utcnow()  # always an UPDATE, so the version moves on
    try:
        db.session.commit()
    except StaleDataError:  # another save won the race
        db.session.rollback()
        latest = user_annotation(frame, user)
        raise stale(latest.version if latest is not None else 0) from None
    return annotation


# --------------------------------------------------------------------------
# Batches


@dataclass
class BatchReport:
    suggestions: list[Suggestion] = field(default_factory=list)
    skipped: list[tuple[int, str]] = field(default_factory=list)  # (frame id, why)

    @property
    def proposals(self) -> int:
        return sum(len(s.proposals) for s in self.suggestions)


def labelling_user(username: str) -> User:
    """The annotator (or admin) a batch works for.

    Raises:
        SuggestProblem: ``user``: no such user, or one who does not label.
    """
    user = db.session.execute(db.select(User).filter_by(username=username)).scalar_one_or_none()
    if user is None:
        raise SuggestProblem(f"user: there is no user {username!r}", fields={"user": "no such user"})
    if user.role not in (Role.ANNOTATOR, Role.ADMIN):
        raise SuggestProblem(f"user: {username} is a {user.role.value}; proposals go to an annotator or admin",
                             fields={"user": "does not label"})
    return user


def batch_frames(frames: Iterable[Frame], user: User) -> tuple[list[Frame], list[tuple[int, str]]]:
    """The frames a batch works on: those still to label as far as ``user`` goes
    (no finished ground truth, nobody else's work in progress); the others with why."""
    frames = list(frames)
    open_ids = set(
        db.session.execute(
            db.select(Frame.id).where(Frame.id.in_([f.id for f in frames]), _unlabelled_for(user))
        ).scalars()
    )
    return [f for f in frames if f.id in open_ids], [
        (f.id, "labelled already, or someone else is labelling it") for f in frames if f.id not in open_ids
    ]


def suggest_frames(
    frames: list[Frame],
    user: User,
    *,
    run_id: int | None = None,
    source: str = "auto",
    device: str = "auto",
    on_progress: Callable[[int], None] | None = None,
) -> BatchReport:
    """Suggest on several frames (the worker's job, ``flask egonet suggest``), each as ``suggest_frame``.

    Frames that are labelled already or taken by someone else are skipped,
    as are those ``suggest_frame`` refuses (the user's annotation done, a
    frame without depth for the depth source, say); the report says why.
    """
    report = BatchReport()
    todo, report.skipped = batch_frames(frames, user)
    if on_progress is not None and report.skipped:
        on_progress(len(report.skipped))
    for frame in todo:
        try:
            report.suggestions.append(suggest_frame(frame, user, run_id=run_id, source=source, device=device))
        except Problem as exc:
            db.session.rollback()
            report.skipped.append((frame.id, exc.message))
        if on_progress is not None:
            on_progress(1)
    return report


def queue_suggestions(frames: list[Frame], user: User, *, run_id: int | None = None, source: str = "auto",
                      device: str = "auto") -> None:
    """Queue a batch for the worker (job ``suggest_frames`` of ``app.tasks``); returns at once."""
    if not frames:
        raise SuggestProblem("frames: no frames to suggest on", fields={"frames": "none chosen"})
    enqueue("suggest_frames", run_id, [f.id for f in frames], user.id, device, source)
