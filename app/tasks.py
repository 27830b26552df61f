"""The jobs ``flask egonet worker`` runs: each calls one service, inside an
application context the queue (``app.queue``) provides.

Services queue a job by name (``app.queue.enqueue("train_run", run_id)``);
calling a job here queues it too. Importing this module creates no queue.
"""

from app.extensions import db
from app.models import User
from app.models.training import Checkpoint, TrainingRun
from app.queue import job
from app.services import exchange, labelling
from app.services.scoring import fitting, load_sources, sources
from app.services.training import (
    TrainingProblem,
    convert_upload,
    execute_run,
    frames_for_prediction,
    predict,
    score_run_frames,
    take_over_stopped_runs,
)


def on_heartbeat() -> None:
    """What a worker does with each heartbeat (``app.queue``): runs whose worker died are queued again."""
    take_over_stopped_runs()


@job
def ping(value: int) -> int:
    """A job that only proves the queue round trip (used by tests)."""
    return value + 1


@job
def train_run(run_id: int) -> None:
    """Train a queued run (see app.services.training.execute_run)."""
    execute_run(run_id)


@job
def import_weights(run_id: int, upload: str) -> None:
    """Convert an uploaded release (its chunks in storage) into its run's checkpoint; the upload is removed afterwards."""
    convert_upload(run_id, upload)


@job
def predict_frames(checkpoint_id: int, frame_ids: list[int], device: str = "auto") -> int:
    """Run a checkpoint on frames and store the predictions; returns how many."""
    checkpoint = db.session.get(Checkpoint, checkpoint_id)
    if checkpoint is None:
        raise TrainingProblem(f"no checkpoint with id {checkpoint_id}")
    return len(predict(checkpoint, frames_for_prediction(frame_ids=frame_ids), device=device))


@job
def score_frames(run_id: int) -> int:
    """Score a run's held-out frames that have no per-frame score (runs recorded before they were kept)."""
    run = db.session.get(TrainingRun, run_id)
    if run is None:
        raise TrainingProblem(f"no training run with id {run_id}")
    return score_run_frames(run)


@job
def suggest_frames(run_id: int | None, frame_ids: list[int], user_id: int, device: str = "auto",
                   source: str = "auto") -> int:
    """A run (or another source) proposes action-objects on frames, into the user's annotations;
    returns how many proposals."""
    user = db.session.get(User, user_id)
    if user is None:
        raise labelling.SuggestProblem(f"no user {user_id}")
    frames = frames_for_prediction(frame_ids=frame_ids)
    return labelling.suggest_frames(frames, user, run_id=run_id, source=source, device=device).proposals


@job
def build_export(export_id: int) -> int:
    """Write a queued export's zip (see app.services.exchange.jobs); returns its frames."""
    return exchange.build_export(export_id).done


@job
def score_baselines(thresholds: int, trained_on: list[str] | None = None, columns: str = "activities") -> int:
    """Fit the learned baselines per fold and score every baseline into the score cache (a request queued it); returns rows.

    ``trained_on``: for a table of models trained on those activities, the
    baselines fitted once on them and scored on the others; ``columns``: the
    table's columns (activities, or each activity's recordings).
    A baseline that could not be scored is kept as the error the page shows,
    so that the page does not queue the same failing work again.
    """
    truth = sources.load_truth(trained_on or (), columns)
    try:
        found, notes = load_sources(run_ids=[], study_ids=[], baselines=True, thresholds=thresholds,
                                    trained_on=trained_on or None, columns=columns)
    except Exception as exc:
        fitting.worker_done(truth, thresholds, f"{type(exc).__name__}: {exc}")
        raise
    failed = [note for note in notes if " could not be scored: " in note]
    fitting.worker_done(truth, thresholds, "; ".join(failed) or None)
    return len(found)
