"""Who proposes a frame's objects for Suggest: a trained run, or a source that needs none.

A ``Proposer`` is either a finished training run with the checkpoint chosen
for the frame (``source`` "model"), or one of ``egonet.proposals.SOURCES``:
"depth" (the nearest compact surfaces off the supporting planes, for frames
with depth), "handled" (the colour region nearest the centre) or
"saliency". Each gives a probability map of the frame and the threshold
that cuts it into regions (``regions``): a run's best-F threshold, or
``egonet.proposals.THRESHOLD``.

``choose`` picks one; "auto" chooses by evidence, not by order
(``auto_choice``):

1. a run for frames like this one: trained on the same kind of frames
   (the demo's rendered frames, or real ones: ``frame_kind``), or scoring
   at least ``MIN_MEASURED_F`` on held-out frames of that kind; the best
   measured on that kind first, then the latest;
2. else depth, when the frame has depth (measured by a sensor; depth
   predicted from the image, ``Frame.meta["depth_source"] == "predicted"``,
   is weaker evidence and the reason says so);
3. else handled, whose regions are object-sized (each under
   ``HandledViewedObject.max_area`` of the frame, kept apart).

So Suggest works on every frame from the first minute, and learned
proposals take over once a run trained on such frames exists.
``source_choices`` lists the sources for the labelling page before any
click: what Auto will use and why, and each choice that cannot work on the
frame disabled with the reason (a run that needs DHG on a frame without).

A run's checkpoint for a frame is one that never trained on it when there
is one (the fold that held the frame's activity, or the frame, out), so
its proposal is what the model does on data it never saw; its map is the
checkpoint's stored prediction of the frame, or one predicted now (and
stored) through ``training.predict``.
"""

import shlex
from dataclasses import dataclass

import numpy as np

from app.errors import Problem
from app.extensions import db
from sqlalchemy import func

from app.models import Activity, Frame, Sequence
from app.models.training import Checkpoint, FoldsMode, Prediction, RunStatus, TrainingRun
from app.services import frames as frames_service
from app.services import media, training
from app.services.demo import DEMO_SOURCE
from egonet import io as egonet_io
from egonet import proposals
from egonet.errors import EgonetError

SOURCES = ("auto", "model", *proposals.SOURCES)
"""What a suggestion may ask for: "auto" chooses (see ``choose``), "model" is a trained run."""
DESCRIPTIONS = {
    "depth": "the nearest compact surface",
    "handled": "the colour region nearest the centre",
    "saliency": "spectral residual saliency",
}
"""What each source looks for, as the page and the CLI say it."""
DEFAULT_THRESHOLD = 0.5
"""When a checkpoint stores no best-F threshold."""
FAST_MODELS = ("egonet-lite",)
"""Models that predict a frame fast enough on a CPU to answer the page inline."""
MIN_MEASURED_F = 0.3
"""A run scoring at least this mean F on held-out frames of a kind is for frames of that kind even
if it trained on others (the demo's quick-start run scores 0.36 on its held-out rendered frames,
where its proposals beat depth's: docs/labelling.md)."""
KIND_WORDS = {"rendered": "the demo's rendered frames", "real": "real frames"}
"""What ``frame_kind`` says, in the page's words."""


class SuggestProblem(Problem):
    """A suggestion that cannot be made; ``field`` names the bad input."""


@dataclass
class Proposer:
    """A trained run and its checkpoint for the frame (``source`` "model"), or a source that needs none."""

    source: str
    run: TrainingRun | None = None
    checkpoint: Checkpoint | None = None
    held_out: bool = False
    why: str = ""  # why this checkpoint, or what the source looks for
    reason: str = ""  # why Auto chose it, in the annotator's words ("" when the annotator chose)

    @property
    def label(self) -> str:
        """Who proposed, as the page's tag says it: "run 3", "depth"."""
        return f"run {self.run.id}" if self.run is not None else self.source

    def threshold(self) -> tuple[float, str]:
        """``(threshold, "checkpoint" | "default" | "source")``."""
        if self.checkpoint is None:
            return proposals.THRESHOLD, "source"
        return checkpoint_threshold(self.checkpoint)

    def fast(self, frame: Frame) -> bool:
        """Whether answering the frame inside a request is quick (see ``inline_is_fast``)."""
        return self.checkpoint is None or inline_is_fast(self.run, self.checkpoint, frame)

    def probability(self, frame: Frame, *, device: str = "auto") -> tuple[np.ndarray, str]:
        """The map of the frame, float32 ``(H, W)`` in [0, 1], and "stored" or "computed"."""
        if self.checkpoint is not None:
            return frame_probability(self.checkpoint, frame, device=device)
        rgb = egonet_io.read_image(media.local_path(frame.rgb_path))
        depth = frames_service.frame_depth(frame) if self.source == "depth" else None
        K = np.array(frame.intrinsics) if frame.intrinsics is not None else None
        try:
            return proposals.source_map(self.source, rgb, depth, K), "computed"
        except EgonetError as exc:  # depth without a single valid pixel, say
            raise SuggestProblem(f"source: {exc.message}", status=409, fields={"source": exc.message}) from None


def choose(frame: Frame, *, run_id: int | None = None, source: str = "auto") -> Proposer:
    """The proposer of the frame: ``run_id`` (a run asked for), else ``source``.

    "auto" chooses by evidence (``auto_choice``).

    Raises:
        SuggestProblem: 400 for an unknown source or a run with a source
            other than a model's; 404 / 409 for a bad run (``resolve_run``);
            409 for "depth" on a frame without depth, or "model" without a
            usable run.
    """
    if source not in SOURCES:
        raise SuggestProblem(f"source: unknown source {source!r}; choose one of {', '.join(SOURCES)}",
                             fields={"source": f"one of {', '.join(SOURCES)}"})
    if run_id is not None and source not in ("auto", "model"):
        raise SuggestProblem(f"run_id: only the model source takes a run, not {source!r}",
                             fields={"run_id": f"not with source {source!r}"})
    if source == "auto" and run_id is None:
        run, chosen, reason = auto_choice(frame)
        proposer = choose(frame, run_id=run.id if run is not None else None, source=chosen)
        proposer.reason = reason
        return proposer
    if source == "auto":
        source = "model"
    if source == "model":
        run = resolve_run(run_id, frame)
        checkpoint, held_out, why = choose_checkpoint(run, frame)
        return Proposer("model", run, checkpoint, held_out, why)
    if source == "depth" and frame.depth_path is None:
        raise SuggestProblem(f"source: frame {frame.id} has no depth; choose handled or saliency", status=409,
                             fields={"source": "this frame has no depth"})
    return Proposer(source, why=DESCRIPTIONS[source])


def frame_kind(frame: Frame) -> str:
    """"rendered" for the demo's frames (``flask egonet demo``), "real" for imported ones."""
    return "rendered" if frame.sequence.source == DEMO_SOURCE else "real"


@dataclass
class RunEvidence:
    """What speaks for a run on frames of one kind: trained on such frames, its held-out scores on them."""

    run: TrainingRun
    trained: bool  # trained on frames of the kind
    f_score: float | None  # mean F on held-out frames of the kind (None: none scored)
    scored: int  # how many

    @property
    def eligible(self) -> bool:
        return self.trained or (self.f_score is not None and self.f_score >= MIN_MEASURED_F)


def run_evidence(run: TrainingRun, kind: str) -> RunEvidence:
    """Whether ``run`` trained on frames of ``kind`` ("rendered" or "real"), and how it scored on held-out ones.

    The authors' released model trained on real frames; a run trained here
    on the kinds of the sequences of its activities that existed when it
    was created.
    """
    rendered = func.coalesce(Sequence.source, "") == DEMO_SOURCE
    of_kind = rendered if kind == "rendered" else ~rendered
    if run.folds is FoldsMode.RELEASED:
        trained = kind == "real"
    else:
        names = run.config.get("activities") or []
        trained = bool(names) and db.session.execute(
            db.select(Sequence.id).join(Activity)
            .where(Activity.name.in_(names), Sequence.created_at <= run.created_at, of_kind).limit(1)
        ).first() is not None
    f_score, scored = db.session.execute(
        db.select(func.avg(Prediction.f_score), func.count(Prediction.id))
        .join(Frame, Prediction.frame_id == Frame.id).join(Sequence, Frame.sequence_id == Sequence.id)
        .where(Prediction.run_id == run.id, Prediction.held_out.is_(True), Prediction.f_score.is_not(None), of_kind)
    ).one()
    return RunEvidence(run, trained, float(f_score) if f_score is not None else None, scored)


def auto_runs(frame: Frame) -> tuple[list[RunEvidence], list[RunEvidence]]:
    """The runs usable for the frame, as ``(for Auto, the others)``: those for frames like it, the best
    measured on its kind first (then the latest), and those trained on other frames only."""
    kind = frame_kind(frame)
    evidence = [run_evidence(run, kind) for run in suggestion_runs() if _usable_checkpoints(run, frame)]
    eligible = sorted((e for e in evidence if e.eligible), key=lambda e: -(e.f_score if e.f_score is not None else -1))
    return eligible, [e for e in evidence if not e.eligible]


def auto_choice(frame: Frame, eligible: list[RunEvidence] | None = None) -> tuple[TrainingRun | None, str, str]:
    """What "auto" uses on the frame and why: ``(run or None, source, reason)``, the reason in the
    annotator's words ("this frame has depth"); ``eligible`` as ``auto_runs`` gives it, when known."""
    if eligible is None:
        eligible, _ = auto_runs(frame)
    if eligible:
        best = eligible[0]
        why = f"trained on {KIND_WORDS[frame_kind(frame)]} like this one" if best.trained else \
            f"scores F {best.f_score:.2f} on {best.scored} held-out {KIND_WORDS[frame_kind(frame)]}"
        return best.run, "model", why
    if frame.depth_path is not None:
        if (frame.meta or {}).get("depth_source") == "predicted":
            return None, "depth", "this frame has depth, predicted from its image (less sure than measured depth)"
        return None, "depth", "this frame has depth"
    return None, "handled", "no depth here; it proposes object-sized colour regions near the centre"


def source_choices(frame: Frame) -> dict:
    """The labelling page's choice of proposer for the frame, and the hint beside it, before any click.

    Returns:
        ``{"choices": [{"source", "run_id", "label", "disabled"}, ...], "hint": str}``: the
        first choice is Auto, labelled with what it will use; a choice that
        cannot work on the frame is disabled and says why.
    """
    eligible, others = auto_runs(frame)
    run, chosen, reason = auto_choice(frame, eligible)
    auto = f"run {run.id}" if run is not None else chosen
    choices = [{"source": "auto", "run_id": None, "label": f"Auto ({auto})", "disabled": False}]
    for source in proposals.SOURCES:
        missing = source == "depth" and frame.depth_path is None
        label = f"{source.capitalize()}: {'this frame has none' if missing else DESCRIPTIONS[source]}"
        choices.append({"source": source, "run_id": None, "label": label, "disabled": missing})
    usable = {e.run.id for e in eligible + others}
    other_ids = {e.run.id for e in others}
    for r in suggestion_runs():
        note = ""
        if r.id not in usable:
            note = " — needs depth (DHG): this frame has none" if frame.dhg_path is None else " — cannot read this frame"
        elif r.id in other_ids:
            note = f" — {_trained_words(r)}"
        choices.append({"source": "model", "run_id": r.id, "label": f"Run {r.id}: {r.name}{note}",
                        "disabled": r.id not in usable})
    return {"choices": choices, "hint": _hint(frame, run, reason, auto, others)}


def _trained_words(run: TrainingRun) -> str:
    """"trained on the demo's rendered frames", as the page says what a run learnt from."""
    kinds = [KIND_WORDS[kind] for kind in KIND_WORDS if run_evidence(run, kind).trained]
    return f"trained on {' and '.join(kinds)}" if kinds else "trained on frames no longer here"


def _hint(frame: Frame, run: TrainingRun | None, reason: str, auto: str, others: list[RunEvidence]) -> str:
    """What Auto uses and why; the runs it passes over and why; how to train one for the frame's activity."""
    activity = frame.sequence.activity.name
    train = f"Train one for {activity}: the Training page, or flask egonet train --activities {shlex.quote(activity)}"
    hint = f"Auto uses {auto}: {reason}."
    if run is not None:
        activities = run.config.get("activities") or []
        if run.folds is not FoldsMode.RELEASED and activity not in activities:
            hint += f" It never saw {activity}. {train}"
        return hint
    for e in others[:2]:
        hint += (f" Run {e.run.id} was {_trained_words(e.run)}, not on {KIND_WORDS[frame_kind(frame)]} like this one:"
                 " choose it above to try it anyway.")
    return f"{hint} {train}"


# --------------------------------------------------------------------------
# Which run, which checkpoint, which threshold


def suggestion_runs(*, limit: int = 20) -> list[TrainingRun]:
    """Finished action-object runs (not depth runs) with at least one checkpoint file, newest first (the page's choice of run)."""
    from egonet.depth import DEPTH_MODEL

    query = (
        db.select(TrainingRun)
        .where(TrainingRun.status == RunStatus.DONE, TrainingRun.model_name != DEPTH_MODEL)
        .order_by(TrainingRun.finished_at.desc(), TrainingRun.id.desc())
    )
    out = []
    for run in db.session.execute(query).scalars():
        if any(training.files.exists(c.path) for c in run.checkpoints):
            out.append(run)
            if len(out) == limit:
                break
    return out


def latest_run(frame: Frame | None) -> TrainingRun | None:
    """The latest finished run with a checkpoint usable for the frame (any frame when None), or None."""
    return next((run for run in suggestion_runs(limit=1000) if _usable_checkpoints(run, frame)), None)


def resolve_run(run_id: int | None, frame: Frame | None = None) -> TrainingRun:
    """The run asked for, checked; or the latest finished run with a checkpoint usable for the
    frame (any frame when ``frame`` is None: a batch checks each frame as it goes).

    Raises:
        SuggestProblem: ``run_id``: no such run (404), a run not finished or
            without checkpoints (409), or no usable run at all (409, "Train a
            model first"); a depth run (409).
    """
    from egonet.depth import DEPTH_MODEL

    if run_id is None:
        run = latest_run(frame)
        if run is None:
            raise SuggestProblem(
                f"Train a model first: no finished training run has a checkpoint that can predict "
                f"{'these frames' if frame is None else 'this frame'} (Training page, or `flask egonet train`); "
                "or choose the depth, handled or saliency source, which need none",
                status=409, fields={"run_id": "no finished training run"},
            )
        return run
    run = db.session.get(TrainingRun, run_id)
    if run is None:
        raise SuggestProblem(f"run_id: there is no training run {run_id}", status=404,
                             fields={"run_id": "no such run"})
    if run.model_name == DEPTH_MODEL:
        raise SuggestProblem(f"run_id: run {run.id} predicts depth, not action-objects", status=409,
                             fields={"run_id": "a depth run"})
    if run.status is not RunStatus.DONE:
        raise SuggestProblem(
            f"run_id: run {run.id} is {run.status.value}; only a finished (done) run can suggest",
            status=409, fields={"run_id": f"is {run.status.value}"},
        )
    if not _usable_checkpoints(run, frame):
        what = "any frame" if frame is None else f"frame {frame.id}"
        if frame is not None and frame.dhg_path is None:
            raise SuggestProblem(f"run_id: run {run.id} needs depth (DHG) and frame {frame.id} has none; "
                                 "choose depth, handled or saliency", status=409,
                                 fields={"run_id": "needs depth (DHG)"})
        raise SuggestProblem(f"run_id: run {run.id} has no checkpoint that can predict {what}",
                             status=409, fields={"run_id": "no usable checkpoint"})
    return run


def _usable_checkpoints(run: TrainingRun, frame: Frame | None) -> list[Checkpoint]:
    """The run's checkpoints with a stored map of the frame, or whose file is there and whose
    model can read the frame (any frame when ``frame`` is None)."""
    readable = frame is None or frame.dhg_path is not None or not _uses_dhg(run)
    return [
        c for c in run.checkpoints
        if (frame is not None and _stored_prediction(c, frame) is not None) or (readable and training.files.exists(c.path))
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
