"""The per-frame browser's pages of a run's held-out predictions, worst F first.

Every held-out prediction keeps its frame's precision, recall and F at its
fold's best threshold (``predictions.scores_at``), so the frames that pull a
fold's score down can be listed worst first. The job scores maps as a fold
ends (``predictions.FoldScorer``); runs recorded before per-frame scores
existed are scored by ``score_run_frames`` (the worker's
``score_run_frames`` job, queued from the run's frames page).
"""

from dataclasses import dataclass

from sqlalchemy import func

from app.extensions import db
from app.models import Frame
from app.models.training import Prediction, TrainingRun
from app.services import ground_truth, media
from app.services.training.predictions import frame_counts, read_probability, scores_at, threshold_of

PAGE_SIZE = 24


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
            mask = media.local_path(annotation.mask_path) if annotation is not None and annotation.mask_path else None
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
