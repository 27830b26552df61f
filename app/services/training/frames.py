"""Per-frame scores of a run's held-out predictions, and the per-frame browser's pages.

Every held-out prediction keeps its frame's precision, recall and F at its
fold's best threshold (``Checkpoint.metrics["threshold"]``, the threshold
of the fold's pooled MF), so the frames that pull a fold's score down can
be listed worst first. Counts come from ``egonet.metrics.count_stats`` (the
same thresholds and comparisons as the pooled score). A frame without an
action-object scores F = 1 when nothing reaches the threshold and 0
otherwise (the pooled metric's convention, recall 0 without positives,
would call a perfect empty map the worst).

The job scores maps as a fold ends (``FoldScorer``); runs recorded before
per-frame scores existed are scored by ``score_run_frames`` (the worker's
``score_run_frames`` job, queued from the run's frames page).
"""

from dataclasses import dataclass

import numpy as np
from sqlalchemy import func

from app.extensions import db
from app.models import Frame
from app.models.training import Checkpoint, Prediction, TrainingRun
from app.services import ground_truth, media
from app.services.training.predictions import read_probability
from egonet import io
from egonet.metrics import Counts, count_stats, curve_from_counts, threshold_values

DEFAULT_THRESHOLD = 0.5
"""A fold whose metrics hold no threshold (recorded before thresholds were kept)."""
PAGE_SIZE = 24


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


def unscored_count(run: TrainingRun) -> int:
    return db.session.execute(
        db.select(func.count(Prediction.id)).where(
            Prediction.run_id == run.id, Prediction.held_out.is_(True), Prediction.f_score.is_(None)
        )
    ).scalar_one()


def score_run_frames(run: TrainingRun) -> int:
    """Score every held-out prediction of a run that has no per-frame score yet; returns how many.

    Reads each stored map and the frame's current ground truth; one commit per fold.
    """
    done = 0
    for checkpoint in run.checkpoints:
        predictions = db.session.execute(
            db.select(Prediction).where(
                Prediction.checkpoint_id == checkpoint.id, Prediction.held_out.is_(True), Prediction.f_score.is_(None)
            )
        ).scalars().all()
        if not predictions:
            continue
        truths = ground_truth.ground_truths([p.frame_id for p in predictions])
        threshold = threshold_of(checkpoint)
        for prediction in predictions:
            frame = db.session.get(Frame, prediction.frame_id)
            annotation = truths.get(frame.id)
            mask = media.absolute_path(annotation.mask_path) if annotation is not None and annotation.mask_path else None
            probability = read_probability(prediction.path, shape=(frame.height, frame.width))
            prediction.f_score, prediction.precision, prediction.recall = scores_at(frame_counts(probability, mask), threshold)
            done += 1
        db.session.commit()
    return done


@dataclass(frozen=True)
class FramePage:
    """One page of a run's held-out frames, worst F first."""

    predictions: list[Prediction]
    page: int
    pages: int
    total: int
    unscored: int
    folds: list[str]
    fold: str | None
    per_page: int = PAGE_SIZE


def frame_page(run: TrainingRun, *, page: int = 1, fold: str | None = None, per_page: int = PAGE_SIZE) -> FramePage:
    """Held-out predictions of a run (one fold's, or all), worst F first, unscored last; ties by frame id.

    ``page`` beyond the last gives the last page.
    """
    folds = [c.fold for c in run.checkpoints]
    where = [Prediction.run_id == run.id, Prediction.held_out.is_(True)]
    if fold is not None:
        where.append(Prediction.checkpoint_id.in_([c.id for c in run.checkpoints if c.fold == fold]))
    total = db.session.execute(db.select(func.count(Prediction.id)).where(*where)).scalar_one()
    pages = max(1, -(-total // per_page))
    page = min(max(1, page), pages)
    unscored_last = Prediction.f_score.is_(None)  # False sorts before True on both backends
    predictions = db.session.execute(
        db.select(Prediction)
        .where(*where)
        .order_by(unscored_last, Prediction.f_score, Prediction.frame_id, Prediction.id)
        .offset((page - 1) * per_page)
        .limit(per_page)
    ).scalars().all()
    return FramePage(list(predictions), page, pages, total, unscored_count(run), folds, fold, per_page)
