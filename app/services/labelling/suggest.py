"""Model proposals ("Suggest"): a trained run proposes a frame's action-objects.

A suggestion takes a finished training run (the latest one with a usable
checkpoint by default) and one of its folds' checkpoints, preferring the
fold that held the frame's activity out (or the frame itself), so the
proposal is what the model does on data it never saw. It reuses the
checkpoint's stored prediction of the frame, or predicts it with
``egonet.predictor.NetworkPredictor`` (through ``training.predict``, which
stores it for the viewer too), thresholds the map at the fold's best-F
threshold (``Checkpoint.metrics["threshold"]``, 0.5 when none is stored),
and turns each connected region above it into an instance (``regions``).
Each region is refined by GrabCut through the user's own GrabCut session
for the new instance, started from the region's mask
(``GrabCutSession.seed_mask``): its edge may move by ``regions.REFINE_BAND``
of the region's size, so it snaps to the object's edge without straying onto a
background of the object's colour, and the annotator can go on correcting
it with strokes; the session passes the frame's depth when the GrabCut
service does.

The proposals become the user's in-progress annotation of the frame, each
instance marked with the run and checkpoint that proposed it, the
annotation recording the run as well. The annotator's own work is never
overwritten: proposals go beside the instances already there (a region
GrabCut turns into much the same object as one of them is left out), and
only proposals still pending from an earlier suggestion are replaced. A
done or reviewed annotation, or one marked "no action-object", is refused
with 409: reopen it first. A proposal stays marked until the annotator
accepts it (``accept_proposal``) or edits its mask (see ``annotations``
and ``grabcut``); rejecting one is deleting it.

One frame runs inline (egonet-lite predicts a frame in about 0.3 s on a CPU);
a model without a stored prediction that would be slow here (the VGG
models without a GPU) is queued for the worker instead, as batches are
(``suggest_frames``, the ``suggest_frames`` job, ``flask egonet suggest``).
"""

import secrets
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field

import numpy as np
from sqlalchemy.orm.exc import StaleDataError

from app.errors import Problem
from app.extensions import db
from app.models import Annotation, Frame, Role, Status, User, utcnow
from app.models.annotations import GrabCutState
from app.models.training import Checkpoint, FoldsMode, Prediction, RunStatus, TrainingRun
from app.queue import enqueue
from app.services import media, training
from app.services.labelling.annotations import (
    InstanceSpec,
    _spec_of,
    _write,
    check_key,
    stale,
    user_annotation,
)
from app.services.labelling.grabcut import grabcut_seed
from app.services.labelling.regions import Region, iou, proposal_regions
from app.services.labelling.review import _unlabelled_for
from egonet import io as egonet_io

DEFAULT_THRESHOLD = 0.5
"""When a checkpoint stores no best-F threshold."""
SAME_OBJECT_IOU = 0.5
"""A proposal overlapping an instance the annotator drew this much is that object again: left out."""
FAST_MODELS = ("egonet-lite",)
"""Models that predict a frame fast enough on a CPU to answer the page inline."""


class SuggestProblem(Problem):
    """A suggestion that cannot be made; ``field`` names the bad input."""


@dataclass
class Suggestion:
    """What one suggestion did (the page shows it, the CLI prints it)."""

    frame_id: int
    run: TrainingRun
    checkpoint: Checkpoint
    checkpoint_choice: str
    held_out: bool
    threshold: float
    threshold_source: str  # "checkpoint" or "default"
    prediction: str  # "stored" or "computed"
    annotation: Annotation | None = None
    proposals: list[str] = field(default_factory=list)  # keys of the new instances
    replaced: int = 0  # earlier proposals, still pending, that these replace
    notes: list[str] = field(default_factory=list)
    seconds: float = 0.0

    def to_dict(self) -> dict:
        return {
            "frame_id": self.frame_id,
            "run_id": self.run.id,
            "run_name": self.run.name,
            "checkpoint_id": self.checkpoint.id,
            "fold": self.checkpoint.fold,
            "checkpoint_choice": self.checkpoint_choice,
            "held_out": self.held_out,
            "threshold": round(self.threshold, 4),
            "threshold_source": self.threshold_source,
            "prediction": self.prediction,
            "proposals": list(self.proposals),
            "replaced": self.replaced,
            "notes": list(self.notes),
            "seconds": round(self.seconds, 3),
        }

    def summary(self) -> str:
        """One line, for the CLI and the page's message."""
        n = len(self.proposals)
        line = (f"frame {self.frame_id}: run {self.run.id} proposed {n} object{'' if n == 1 else 's'} "
                f"(fold {self.checkpoint.fold!r}, {self.checkpoint_choice}; threshold {self.threshold:.2f}"
                f"{'' if self.threshold_source == 'checkpoint' else ', the default'})")
        if self.replaced:
            line += f", replacing {self.replaced} earlier proposal{'' if self.replaced == 1 else 's'}"
        return line + "".join(f"; {note}" for note in self.notes)


# --------------------------------------------------------------------------
# Which run, which checkpoint, which threshold


def suggestion_runs(*, limit: int = 20) -> list[TrainingRun]:
    """Finished runs with at least one checkpoint file, newest first (the page's choice of run)."""
    root = training.checkpoint_root()
    query = (
        db.select(TrainingRun)
        .where(TrainingRun.status == RunStatus.DONE)
        .order_by(TrainingRun.finished_at.desc(), TrainingRun.id.desc())
    )
    out = []
    for run in db.session.execute(query).scalars():
        if any((root / c.path).is_file() for c in run.checkpoints):
            out.append(run)
            if len(out) == limit:
                break
    return out


def resolve_run(run_id: int | None, frame: Frame | None = None) -> TrainingRun:
    """The run asked for, checked; or the latest finished run with a checkpoint usable for the
    frame (any frame when ``frame`` is None: a batch checks each frame as it goes).

    Raises:
        SuggestProblem: ``run_id``: no such run (404), a run not finished or
            without checkpoints (409), or no usable run at all (409, "Train a
            model first").
    """
    if run_id is not None:
        run = db.session.get(TrainingRun, run_id)
        if run is None:
            raise SuggestProblem(f"run_id: there is no training run {run_id}", status=404,
                                 fields={"run_id": "no such run"})
        if run.status is not RunStatus.DONE:
            raise SuggestProblem(
                f"run_id: run {run.id} is {run.status.value}; only a finished (done) run can suggest",
                status=409, fields={"run_id": f"is {run.status.value}"},
            )
        if not _usable_checkpoints(run, frame):
            what = "any frame" if frame is None else f"frame {frame.id}"
            why = " (it has no DHG image)" if frame is not None and frame.dhg_path is None else ""
            raise SuggestProblem(f"run_id: run {run.id} has no checkpoint that can predict {what}{why}",
                                 status=409, fields={"run_id": "no usable checkpoint"})
        return run
    for run in suggestion_runs(limit=1000):
        if _usable_checkpoints(run, frame):
            return run
    raise SuggestProblem(
        f"Train a model first: no finished training run has a checkpoint that can predict "
        f"{'these frames' if frame is None else 'this frame'} (Training page, or `flask egonet train`)",
        status=409, fields={"run_id": "no finished training run"},
    )


def _usable_checkpoints(run: TrainingRun, frame: Frame | None) -> list[Checkpoint]:
    """The run's checkpoints with a stored map of the frame, or whose file is there and whose
    model can read the frame (any frame when ``frame`` is None)."""
    root = training.checkpoint_root()
    readable = frame is None or frame.dhg_path is not None or not _uses_dhg(run)
    return [
        c for c in run.checkpoints
        if (frame is not None and _stored_prediction(c, frame) is not None) or (readable and (root / c.path).is_file())
    ]


def _uses_dhg(run: TrainingRun) -> bool:
    import torch

    from egonet.network.builders import build_model

    with torch.device("meta"):  # shapes only: instant
        return build_model(run.model_name, **run.model_options).uses_dhg


def choose_checkpoint(run: TrainingRun, frame: Frame) -> tuple[Checkpoint, bool, str]:
    """The run's checkpoint for the frame: one that never trained on it if there is one.

    Returns:
        ``(checkpoint, held_out, why)``: ``held_out`` is true when the
        checkpoint's fold held the frame's activity (leave-one-activity-out)
        or the frame itself (single split) out of training; ``why`` says so
        in words.
    """
    usable = _usable_checkpoints(run, frame)
    activity = frame.sequence.activity.name
    if run.folds is FoldsMode.RELEASED:
        return usable[-1], True, "the authors' released model was not trained on this project's frames"
    for checkpoint in usable:
        if run.folds is FoldsMode.LOAO and checkpoint.fold == activity:
            return checkpoint, True, f"its fold held the activity {activity!r} out"
    for checkpoint in usable:
        if frame.id in checkpoint.test_frame_ids:
            return checkpoint, True, "its fold held this frame out"
    checkpoint = usable[-1]
    return checkpoint, False, "no fold held this frame's activity out; the newest fold's"


def checkpoint_threshold(checkpoint: Checkpoint) -> tuple[float, str]:
    """The fold's best-F threshold on its held-out frames, or ``DEFAULT_THRESHOLD``.

    Returns:
        ``(threshold, "checkpoint" | "default")``.
    """
    value = (checkpoint.metrics or {}).get("threshold")
    if isinstance(value, int | float) and not isinstance(value, bool) and 0.0 < value < 1.0:
        return float(value), "checkpoint"
    return DEFAULT_THRESHOLD, "default"


def inline_is_fast(run: TrainingRun, checkpoint: Checkpoint, frame: Frame) -> bool:
    """Whether answering one frame in the request is quick: a stored map, a fast model or a GPU."""
    import torch

    return _stored_prediction(checkpoint, frame) is not None or run.model_name in FAST_MODELS or torch.cuda.is_available()


def _stored_prediction(checkpoint: Checkpoint, frame: Frame) -> Prediction | None:
    return db.session.execute(
        db.select(Prediction).filter_by(checkpoint_id=checkpoint.id, frame_id=frame.id).order_by(Prediction.id.desc()).limit(1)
    ).scalar_one_or_none()


def frame_probability(checkpoint: Checkpoint, frame: Frame, *, device: str = "auto") -> tuple[np.ndarray, str]:
    """The checkpoint's probability map of the frame: stored, or predicted now (and stored).

    Returns:
        ``(float32 (H, W) in [0, 1] at the frame's size, "stored" | "computed")``.
    """
    stored = _stored_prediction(checkpoint, frame)
    if stored is not None:
        return training.read_probability(stored.path, shape=(frame.height, frame.width)), "stored"
    try:
        (prediction,) = training.predict(checkpoint, [frame], device=device)
    except training.TrainingProblem as exc:
        raise SuggestProblem(exc.message, status=exc.status, fields={"frame_id": exc.message}) from None
    return training.read_probability(prediction.path, shape=(frame.height, frame.width)), "computed"


# --------------------------------------------------------------------------
# Suggesting


def suggest_frame(
    frame: Frame,
    user: User,
    *,
    run_id: int | None = None,
    version: int | None = None,
    device: str = "auto",
) -> Suggestion:
    """Propose the frame's action-objects into the user's annotation of it.

    Args:
        frame: The frame.
        user: Whose in-progress annotation the proposals join.
        run_id: The run to ask; ``None``: the latest finished run with a
            checkpoint usable for the frame.
        version: The annotation's version the caller has (0: none yet), as
            a save; ``None`` (batches) takes the current one.
        device: Where the model runs when no stored map is there.

    Returns:
        The suggestion, with the saved annotation.

    Raises:
        SuggestProblem: 409 for a stale ``version``, a done, reviewed or
            "no action-object" annotation, or no usable run; 404 / 409 for
            a bad ``run_id`` (see ``resolve_run``).
    """
    started = time.perf_counter()
    existing = user_annotation(frame, user)
    _check_open(existing, version)
    run = resolve_run(run_id, frame)
    checkpoint, held_out, why = choose_checkpoint(run, frame)
    threshold, source = checkpoint_threshold(checkpoint)
    probability, how = frame_probability(checkpoint, frame, device=device)
    result = Suggestion(frame.id, run, checkpoint, why, held_out, threshold, source, how)
    if source == "default":
        result.notes.append(f"checkpoint {checkpoint.id} stores no best-F threshold: used {DEFAULT_THRESHOLD}")
    regions, dropped = proposal_regions(probability, threshold)
    result.notes += dropped

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
            proposed_by_run_id=run.id, proposed_by_checkpoint_id=checkpoint.id,
        ))
    if repeated:
        result.notes.append(f"{repeated} region{'' if repeated == 1 else 's'} left out: already drawn")
    if not regions:
        result.notes.append(f"no region of the map reaches {threshold:.2f}")

    current = existing.version if existing is not None else 0
    if not specs and not replaced:
        result.annotation = existing  # nothing to write: no new version, no empty annotation
    else:
        try:
            result.annotation = _write(
                frame, user, version=current, specs=kept + specs, no_action_object=False, status=None,
                time_delta_s=0.0, proposed_by=(run.id, checkpoint.id) if specs else None,
            )
        except Problem:  # a save won the race meanwhile: its version stands, these sessions are no one's
            _forget(frame, user, [s.key for s in specs])
            raise
        _forget(frame, user, replaced)
    result.proposals = [s.key for s in specs]
    result.replaced = len(replaced)
    result.seconds = time.perf_counter() - started
    return result


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
    run: TrainingRun
    checkpoint: Checkpoint

    def summary(self) -> str:
        return (f"run {self.run.id}'s {self.run.model_name} is slow without a GPU: frame {self.frame_id} is queued "
                "for the worker; its proposals appear when you reload the frame")


def suggest_from_page(frame: Frame, user: User, *, run_id: int | None, version: int) -> Suggestion | Queued:
    """One frame from the labelling page: inline when that is quick (``inline_is_fast``), else queued.

    Raises:
        SuggestProblem: as ``suggest_frame``, checked before anything is queued.
    """
    existing = user_annotation(frame, user)
    _check_open(existing, version)
    run = resolve_run(run_id, frame)
    checkpoint, _, _ = choose_checkpoint(run, frame)
    if inline_is_fast(run, checkpoint, frame):
        return suggest_frame(frame, user, run_id=run.id, version=version)
    enqueue("suggest_frames", run.id, [frame.id], user.id, "auto")
    return Queued(frame.id, run, checkpoint)


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
    instance.proposed_by_run_id = instance.proposed_by_checkpoint_id = None
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
    run: TrainingRun,
    frames: list[Frame],
    user: User,
    *,
    device: str = "auto",
    on_progress: Callable[[int], None] | None = None,
) -> BatchReport:
    """Suggest on several frames (the worker's job, ``flask egonet suggest``).

    Frames that are labelled already or taken by someone else are skipped,
    as are those ``suggest_frame`` refuses (the user's annotation done, say); the
    report says why.
    """
    report = BatchReport()
    todo, report.skipped = batch_frames(frames, user)
    if on_progress is not None and report.skipped:
        on_progress(len(report.skipped))
    for frame in todo:
        try:
            report.suggestions.append(suggest_frame(frame, user, run_id=run.id, device=device))
        except Problem as exc:
            db.session.rollback()
            report.skipped.append((frame.id, exc.message))
        if on_progress is not None:
            on_progress(1)
    return report


def queue_suggestions(run: TrainingRun, frames: list[Frame], user: User, *, device: str = "auto") -> None:
    """Queue a batch for the worker (job ``suggest_frames`` of ``app.tasks``); returns at once."""
    if not frames:
        raise SuggestProblem("frames: no frames to suggest on", fields={"frames": "none chosen"})
    enqueue("suggest_frames", run.id, [f.id for f in frames], user.id, device)

