"""Predictions: run a checkpoint on frames, score and read stored maps (the scorer, the viewer).

Every model run outside training goes through ``egonet.predictor.NetworkPredictor``
(the frame at the checkpoint's training size, probabilities back at the
frame's own), so ``predict`` stores what the training job stored for the
same frame. Maps are 16-bit PNGs in the media store (probability x 65535).

A held-out map is scored on its frame at its fold's best threshold
(``Checkpoint.metrics["threshold"]``, the threshold of the fold's pooled
MF; ``scores_at``). Counts come from ``egonet.metrics.count_stats`` (the
same thresholds and comparisons as the pooled score). A frame without an
action-object scores F = 1 when nothing reaches the threshold and 0
otherwise (the pooled metric's convention, recall 0 without positives,
would call a perfect empty map the worst).

For the scorer: ``held_out_predictions(run)``.
"""

from collections.abc import Callable, Iterable, Iterator
from pathlib import Path

import numpy as np

from app.extensions import db
from app.models import Activity, Frame, Sequence, utcnow
from app.models.training import Checkpoint, FoldsMode, Prediction, TrainingRun
from app.services import media
from app.services.training import files
from app.services.training.control import TrainingProblem
from egonet import io
from egonet.metrics import Counts, count_stats, curve_from_counts, threshold_values
from egonet.overlay import heatmap
from egonet.overlay import overlay as egonet_overlay

PICTURE_WIDTH = 320
"""Width of the per-frame browser's pictures."""
DEFAULT_THRESHOLD = 0.5
"""A fold whose metrics hold no threshold (recorded before thresholds were kept)."""


def held_out_predictions(run: TrainingRun) -> Iterator[tuple[Frame, np.ndarray]]:
    """Every held-out frame of a run with its probability map.

    Yields:
        ``(frame, float32 (H, W) probabilities in [0, 1] at the frame's full
        size)``, read from the stored 16-bit PNG (value / 65535), one per
        frame, in frame-id order. Maps are read one at a time.
    """
    rows = db.session.execute(
        db.select(Prediction.frame_id, Prediction.path)
        .where(Prediction.run_id == run.id, Prediction.held_out.is_(True))
        .order_by(Prediction.frame_id, Prediction.id.desc())
    ).all()
    latest: dict[int, str] = {}
    for frame_id, path in rows:
        latest.setdefault(frame_id, path)
    for frame_id, path in latest.items():
        frame = db.session.get(Frame, frame_id)
        yield frame, read_probability(path, shape=(frame.height, frame.width))


def read_probability(path: str, *, shape: tuple[int, int] | None = None) -> np.ndarray:
    """A stored prediction as float32 (H, W) in [0, 1]."""
    probability = io.decode_probability_png(media.read(path), path=path)
    if shape is not None and probability.shape != tuple(shape):
        raise io.MediaError(path, f"prediction is {probability.shape[1]}x{probability.shape[0]}, "
                                  f"the frame {shape[1]}x{shape[0]}")
    return probability


def threshold_of(checkpoint: Checkpoint) -> float:
    value = checkpoint.metrics.get("threshold")
    return float(value) if isinstance(value, int | float) else DEFAULT_THRESHOLD


def scores_at(counts: Counts, threshold: float) -> tuple[float, float, float | None]:
    """``(f, precision, recall)`` of one map's counts at the threshold nearest ``threshold``.

    Recall is ``None`` for a frame without an action-object.
    """
    k = int(np.argmin(np.abs(threshold_values(len(counts.tp)) - threshold)))
    tp, fp, fn = (int(c[k]) for c in counts)
    if tp + fn == 0:  # no action-object: right only when nothing is predicted
        return (1.0, 1.0, None) if fp == 0 else (0.0, 0.0, None)
    precision, recall = curve_from_counts(Counts(*(np.array([c]) for c in (tp, fp, fn))))
    p, r = float(precision[0]), float(recall[0])
    return (2 * p * r / (p + r) if p + r > 0 else 0.0), p, r


def frame_counts(probability: np.ndarray, mask_path) -> Counts:
    """A map's counts against a truth mask file (``None``: no action-object)."""
    mask = io.read_mask(mask_path) if mask_path is not None else np.zeros(probability.shape, bool)
    return count_stats(probability, mask)


class FoldScorer:
    """Collects the counts of a fold's held-out maps as they come; scores them once the threshold is known."""

    def __init__(self) -> None:
        self.counts: dict[int, Counts] = {}

    def add(self, frame_id: int, probability: np.ndarray, mask_path) -> None:
        self.counts[frame_id] = frame_counts(probability, mask_path)

    def apply(self, predictions: list[Prediction], threshold: float) -> None:
        for prediction in predictions:
            counts = self.counts.get(prediction.frame_id)
            if counts is not None:
                prediction.f_score, prediction.precision, prediction.recall = scores_at(counts, threshold)
        self.counts = {}


def latest_prediction(frame_id: int) -> Prediction | None:
    """The frame's newest prediction, if any (the frame viewer's overlay)."""
    return db.session.execute(
        db.select(Prediction).where(Prediction.frame_id == frame_id).order_by(Prediction.id.desc()).limit(1)
    ).scalar_one_or_none()


def frame_predictions(run: TrainingRun, *, limit: int = 24) -> list[Prediction]:
    """Some held-out predictions of a run, for its page."""
    return list(
        db.session.execute(
            db.select(Prediction)
            .where(Prediction.run_id == run.id, Prediction.held_out.is_(True))
            .order_by(Prediction.frame_id)
            .limit(limit)
        ).scalars()
    )


def prediction_overlay(prediction: Prediction) -> Path:
    """A colour PNG of the prediction (``egonet.overlay.heatmap``: turbo colours, faint where unlikely), cached.

    Prediction files are content-addressed, so the overlay is cached under
    the file's name and never goes stale.
    """
    return media.derived(f"predictions/overlay-{Path(prediction.path).stem}.png",
                         lambda: io.encode_png(heatmap(read_probability(prediction.path))))


def prediction_picture(prediction: Prediction, kind: str) -> Path:
    """A small PNG for the per-frame browser, cached (its name holds every input's content hash).

    ``kind`` ``"prediction"``: the frame with the map's heat map and the
    ground truth's outline in green; ``"truth"``: the frame with the ground
    truth's mask (red) and outline.

    Raises:
        TrainingProblem: 404 for another ``kind``.
    """
    from app.services import ground_truth

    if kind not in ("prediction", "truth"):
        raise TrainingProblem(f"no picture {kind!r}: prediction or truth", status=404)
    frame = prediction.frame
    annotation = ground_truth.ground_truths([frame.id]).get(frame.id)
    truth_name = Path(annotation.mask_path).stem if annotation is not None and annotation.mask_path else "none"
    source = Path(prediction.path).stem if kind == "prediction" else Path(frame.rgb_path).stem

    def make() -> bytes:
        rgb = io.read_image(media.local_path(frame.rgb_path))
        truth = ground_truth.mask_of(annotation) if annotation is not None else np.zeros(rgb.shape[:2], bool)
        layer = read_probability(prediction.path, shape=rgb.shape[:2]) if kind == "prediction" else truth.astype(np.float32)
        return io.encode_png(egonet_overlay(rgb, layer, outline=truth, max_width=PICTURE_WIDTH))

    return media.derived(f"predictions/{kind}-{source}-{truth_name}-{Path(frame.rgb_path).stem}.png", make)


# --------------------------------------------------------------------------- predicting


def frames_for_prediction(*, activity_names: Iterable[str] = (), frame_ids: Iterable[int] = ()) -> list[Frame]:
    """Frames chosen by activity name and/or id (every frame when neither is given).

    Raises:
        TrainingProblem: An unknown activity or frame id.
    """
    names, ids = list(activity_names), list(frame_ids)
    query = db.select(Frame).join(Sequence).join(Activity).order_by(Activity.name, Sequence.name, Frame.index, Frame.id)
    if names:
        known = set(db.session.execute(db.select(Activity.name).where(Activity.name.in_(names))).scalars())
        if missing := [n for n in names if n not in known]:
            raise TrainingProblem(f"no activity named {', '.join(map(repr, missing))}", field="activity")
    if ids:
        known_ids = set(db.session.execute(db.select(Frame.id).where(Frame.id.in_(ids))).scalars())
        if missing := [i for i in ids if i not in known_ids]:
            raise TrainingProblem(f"no frame with id {', '.join(map(str, missing))}", field="frames")
    if names and ids:
        query = query.where((Activity.name.in_(names)) | (Frame.id.in_(ids)))
    elif names:
        query = query.where(Activity.name.in_(names))
    elif ids:
        query = query.where(Frame.id.in_(ids))
    return list(db.session.execute(query).scalars())


def predict(
    checkpoint: Checkpoint,
    frames: list[Frame],
    *,
    device: str = "auto",
    on_progress: Callable[[int], None] | None = None,
) -> list[Prediction]:
    """Run a checkpoint on frames and store a prediction for each (one transaction).

    A frame in the checkpoint's test set gets ``held_out=True`` (every frame,
    for the authors' released model: it was not trained on ours; every frame
    of an activity it was not trained on, for a run on all frames) and its
    per-frame scores at the fold's threshold (``scores_at``);
    predicting a frame again replaces that checkpoint's earlier prediction of it.

    Args:
        checkpoint: The trained fold.
        frames: Any frames (with DHG when the model reads it).
        device: ``"auto"``, ``"cpu"`` or ``"cuda"``.
        on_progress: Called with 1 after each frame.

    Raises:
        TrainingProblem: No frames, frames without DHG, or an unreadable checkpoint.
    """
    from app.services import ground_truth
    from egonet.predictor import NetworkPredictor
    from egonet.depth import DEPTH_MODEL
    from egonet.train import resolve_device

    if not frames:
        raise TrainingProblem("no frames to predict", field="frames")
    if checkpoint.run.model_name == DEPTH_MODEL:
        raise TrainingProblem(f"checkpoint {checkpoint.id} predicts depth: use `flask egonet predict-depth`", field="checkpoint")
    try:
        state = files.load(checkpoint.path)
        predictor = NetworkPredictor.from_checkpoint(state, device=resolve_device(device))
    except ValueError as exc:  # an unreadable checkpoint, or no GPU: the run's problem, not a field's
        raise TrainingProblem(str(exc)) from None
    uses_dhg = predictor.model.uses_dhg
    if uses_dhg and (without := [f.id for f in frames if f.dhg_path is None]):
        raise TrainingProblem(
            f"{checkpoint.run.model_name} needs DHG images; frames without one: {', '.join(map(str, without[:10]))}",
            field="frames",
        )
    held_out = set(checkpoint.test_frame_ids)
    if checkpoint.run.folds is FoldsMode.RELEASED:
        held_out = {frame.id for frame in frames}
    elif checkpoint.run.folds is FoldsMode.ALL:  # trained on every frame of its activities: the others are held out
        seen = set(checkpoint.run.config.get("activity_ids") or [])
        held_out = {frame.id for frame in frames if frame.sequence.activity_id not in seen}
    truths = ground_truth.ground_truths([f.id for f in frames if f.id in held_out])
    existing = _existing_predictions(checkpoint, frames)
    out = []
    for frame in frames:
        rgb = io.read_image(media.local_path(frame.rgb_path))
        dhg = io.read_dhg(media.local_path(frame.dhg_path)) if frame.dhg_path and uses_dhg else None
        probability = predictor.predict(rgb, dhg)
        path = media.store(io.encode_probability_png(probability), ".png")
        prediction = existing.get(frame.id) or Prediction(run_id=checkpoint.run_id, checkpoint_id=checkpoint.id, frame_id=frame.id)
        prediction.path, prediction.held_out, prediction.created_at = path, frame.id in held_out, utcnow()
        prediction.f_score = prediction.precision = prediction.recall = None
        if frame.id in truths:
            mask = truths[frame.id].mask_path
            counts = frame_counts(probability, media.local_path(mask) if mask else None)
            prediction.f_score, prediction.precision, prediction.recall = scores_at(counts, threshold_of(checkpoint))
        db.session.add(prediction)
        out.append(prediction)
        if on_progress is not None:
            on_progress(1)
    db.session.commit()
    return out


def _existing_predictions(checkpoint: Checkpoint, frames: list[Frame]) -> dict[int, Prediction]:
    """The checkpoint's earlier predictions of these frames, by frame id (predicting again replaces them)."""
    query = db.select(Prediction).where(
        Prediction.checkpoint_id == checkpoint.id, Prediction.frame_id.in_([f.id for f in frames])
    )
    return {p.frame_id: p for p in db.session.execute(query).scalars()}
