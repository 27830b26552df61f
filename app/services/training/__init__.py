"""Training runs: start, run (in the worker or the CLI), cancel, resume, predict.

A run is a ``TrainingRun`` row first, then a job that trains it with
``egonet.train.cross_validate`` and records a ``Checkpoint`` per fold and a
``Prediction`` for every held-out frame. The package follows those seams:

* ``control``: start, check, cancel, resume and list runs (every request is
  checked before anything is queued); ``TrainingProblem``.
* ``files``: checkpoints in storage (``checkpoints/run-<id>/…``): load and
  save one by its path, the scratch folder a run trains in.
* ``job``: ``execute_run``, the job the worker (``train_run`` of
  ``app.tasks``) or ``flask egonet train`` runs, and its bookkeeping.
* ``predictions``: run a checkpoint on frames (``predict``), score each map on
  its frame (``scores_at``) and read stored maps; for the scorer,
  ``completed_runs()`` and ``held_out_predictions(run)``.
* ``released``: the authors' released ``.caffemodel`` as a run with one
  checkpoint (``register_release``, ``convert_release``, the page's chunked upload).
* ``history``: the per-epoch rows the job writes and the charts poll.
* ``frames``: the per-frame browser of held-out predictions; scoring old runs' maps.
* ``manage``: rename and tag runs, their downloads, deleting a run and all it made.
* ``depth``: depth runs (``depth-lite``, trained by the same job) and
  ``predict_depth``, predicted depth and DHG for frames without depth.

Callers import from here: ``from app.services import training``.
"""

from app.services.training.control import (
    MAX_EPOCHS,
    RunRequest,
    TrainingProblem,
    cancel_run,
    checkpoints,
    completed_runs,
    create_run,
    resume_run,
    runs,
    start_run,
    take_over_stopped_runs,
    trained_on,
)
from app.services.training.frames import FramePage, frame_page, score_run_frames, unscored_count
from app.services.training.history import MAX_COMPARED_RUNS, chart_data, parse_run_ids, runs_with_history
from app.services.training.job import execute_run, summarise, train_in_foreground
from app.services.training.released import (
    cancel_upload,
    convert_release,
    convert_upload,
    finish_upload,
    import_in_foreground,
    register_release,
    start_upload,
    write_chunk,
)
from app.services.training.manage import (
    DeletionPlan,
    all_tags,
    checkpoint_file,
    delete_run,
    deletion_plan,
    edit_run,
    parse_tags,
    run_config,
    runs_tagged,
)
from app.services.training.predictions import (
    frame_predictions,
    frames_for_prediction,
    held_out_predictions,
    latest_prediction,
    predict,
    prediction_overlay,
    prediction_picture,
    read_probability,
)

__all__ = [
    "MAX_COMPARED_RUNS",
    "MAX_EPOCHS",
    "DeletionPlan",
    "FramePage",
    "RunRequest",
    "TrainingProblem",
    "all_tags",
    "cancel_run",
    "cancel_upload",
    "convert_release",
    "convert_upload",
    "finish_upload",
    "import_in_foreground",
    "register_release",
    "start_upload",
    "write_chunk",
    "chart_data",
    "checkpoint_file",
    "checkpoints",
    "completed_runs",
    "create_run",
    "delete_run",
    "deletion_plan",
    "edit_run",
    "execute_run",
    "frame_page",
    "frame_predictions",
    "frames_for_prediction",
    "held_out_predictions",
    "latest_prediction",
    "parse_run_ids",
    "parse_tags",
    "predict",
    "prediction_overlay",
    "prediction_picture",
    "read_probability",
    "resume_run",
    "run_config",
    "runs",
    "runs_tagged",
    "runs_with_history",
    "score_run_frames",
    "start_run",
    "summarise",
    "take_over_stopped_runs",
    "train_in_foreground",
    "trained_on",
    "unscored_count",
]
