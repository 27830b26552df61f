"""The job that trains a run: in the worker, or in the foreground (``flask egonet train``).

``execute_run`` collects the frames with ground truth
(``app.services.ground_truth``), trains with ``egonet.train.cross_validate``
and, after each fold, records in one transaction the fold's ``Checkpoint``
and a ``Prediction`` for every held-out frame (16-bit PNGs in the media
store, probability x 65535), with each held-out frame's precision,
recall and F at the fold's best threshold. Each epoch's record is written
as the epoch ends (``app.services.training.history``). Progress, loss and
ETA go to the row at most once a second; the web page polls them. A
resumed run keeps its finished folds, and the fold that was under way
continues from its last epoch's checkpoint file.

Training writes into this host's scratch folder (``files.scratch``) and each
checkpoint and ``config.json`` goes to storage as soon as it is written; a
run that goes on, here or on another host, starts from the files storage
has (``app.services.training.files``). Under ``torchrun`` only rank 0 writes.

While it trains, the run holds a lease (``control.holding_lease``): a worker
killed mid-run leaves it running only until the lease expires, then another
worker queues it again and it goes on from storage's files. An attempt
whose run was taken over meanwhile stops at its next report.
"""

import logging
import shutil
import time
from collections.abc import Callable, Iterable
from pathlib import Path

import numpy as np
from sqlalchemy import update

from app.extensions import db
from app.models import User, is_hand, utcnow
from app.models.training import FINAL_STATUSES, Checkpoint, Prediction, RunStatus, TrainingRun
from app.services import ground_truth, media
from app.services.training.control import RunRequest, TrainingProblem, cancel_run, claim_run, create_run, holding_lease
from app.services.training import depth, files
from app.services.training.predictions import FoldScorer
from app.services.training.history import record_epochs
from egonet import io
from egonet.errors import Cancelled

log = logging.getLogger(__name__)

PROGRESS_INTERVAL_S = 1.0
"""Least time between two progress writes to the run's row (the callback runs every step)."""


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


class _Recorder:
    """The engine's callbacks: progress to the row, each file to storage, and each fold's results in one transaction."""

    def __init__(self, run: TrainingRun, upload: Callable[[], None], on_progress: Callable | None):
        self.run_id, self.attempt, self.upload, self.on_progress = run.id, run.started_at, upload, on_progress
        self.last_write = 0.0
        self.last_phase = None
        self.maps: list[tuple[int, str]] = []  # (frame id, media path) of the fold under way
        self.scorer = FoldScorer()

    def progress(self, progress) -> None:
        if self.on_progress is not None:
            self.on_progress(progress)
        now = time.monotonic()
        phase = (progress.fold, progress.epoch, progress.phase)
        if now - self.last_write < PROGRESS_INTERVAL_S and phase == self.last_phase:
            return
        self.last_write, self.last_phase = now, phase
        where = f"fold {progress.fold_index + 1}/{progress.folds} ({progress.fold})"
        doing = {"train": f"epoch {progress.epoch}/{progress.epochs}", "evaluate": "scoring held-out frames", "done": "done"}
        ours = db.session.execute(
            update(TrainingRun)  # renews the lease of this attempt, while the run is still its own
            .where(TrainingRun.id == self.run_id, TrainingRun.status == RunStatus.RUNNING,
                   TrainingRun.started_at == self.attempt)
            .values(
                progress=progress.fraction,
                loss=progress.loss,
                eta_s=progress.eta_s,
                message=f"{where}: {doing[progress.phase]}",
                updated_at=utcnow(),
            )
        ).rowcount
        db.session.commit()
        if not ours:  # cancelled, or taken over by another worker after this one's lease expired
            raise Cancelled

    def map(self, fold: str, sample, probability: np.ndarray) -> None:
        png = io.encode_probability_png(probability)
        self.maps.append((int(sample.key), media.store(png, ".png")))
        self.scorer.add(int(sample.key), probability, sample.mask)

    def epoch(self, fold: str, record: dict) -> None:
        self.upload()  # the epoch's checkpoint (and config.json) is written: storage gets it now
        record_epochs(self.run_id, fold, [_plain(record)])
        db.session.commit()

    def fold_end(self, result) -> None:
        self.upload()
        checkpoint = Checkpoint(
            run_id=self.run_id,
            fold=result.name,
            path=f"{files.run_folder(self.run_id)}/{result.checkpoint.name}",
            epochs=int(result.metrics["epochs"]),
            metrics=_plain(result.metrics | {"history": result.history}),
            test_frame_ids=[int(k) for k in result.test_keys],
        )
        db.session.add(checkpoint)
        db.session.flush()
        predictions = [
            Prediction(run_id=self.run_id, checkpoint_id=checkpoint.id, frame_id=frame_id, path=path, held_out=True)
            for frame_id, path in self.maps
        ]
        self.scorer.apply(predictions, float(result.metrics.get("threshold", 0.5)))
        db.session.add_all(predictions)
        self.maps = []
        # The whole history again: a run that continues a checkpoint inherits its earlier epochs.
        record_epochs(self.run_id, result.name, _plain(result.history))
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
    from egonet.checkpoint import TrainConfig
    from egonet.train import cross_validate, resolve_device, setup_distributed

    run = db.session.get(TrainingRun, run_id)
    if run is None:
        raise TrainingProblem(f"no training run with id {run_id}")
    if depth.is_depth_run(run):
        return _execute_depth_run(run, on_progress=on_progress)
    config = TrainConfig.from_dict(run.config["train"])
    try:
        rank, _ = setup_distributed(resolve_device(config.device))
    except ValueError as exc:
        return _fail(run, exc)
    if rank != 0:
        return _train_as_follower(run, config, rank)

    def train(out_dir: Path, recorder: _Recorder) -> None:
        samples, folds, start = _plan(run, config, out_dir)
        cross_validate(
            samples, config, out_dir=out_dir, folds=folds, start=start,
            on_progress=recorder.progress, on_fold_end=recorder.fold_end, on_map=recorder.map, on_epoch=recorder.epoch,
        )

    return _claimed_and_run(run, train, on_progress=on_progress)


def _execute_depth_run(run: TrainingRun, *, on_progress: Callable | None) -> TrainingRun:
    """A depth run (``app.services.training.depth``): one network, the last 20 % of each activity held out.

    Trained again from the start when resumed (it keeps no partial checkpoint).
    """
    from egonet.depth import fit_depth

    def train(out_dir: Path, recorder: _Recorder) -> None:
        result = fit_depth(
            depth.depth_samples(run), depth.depth_config(run), out_path=out_dir / depth.CHECKPOINT,
            on_progress=recorder.progress, on_epoch=lambda record: recorder.epoch("depth", record),
        )
        recorder.upload()
        depth.record_depth_result(run, result)
        db.session.commit()

    return _claimed_and_run(run, train, on_progress=on_progress)


def _claimed_and_run(run: TrainingRun, train: Callable[[Path, "_Recorder"], None], *,
                     on_progress: Callable | None) -> TrainingRun:
    """Claim the run, then ``train(out_dir, recorder)`` in this host's scratch folder (the run's files in
    storage fetched into it) while holding its lease; running -> done, failed, or left cancelled."""
    if not claim_run(run, "loading frames"):
        return run
    out_dir = files.scratch(run.id)
    try:
        with holding_lease(run):
            train(out_dir, _Recorder(run, files.fetch_run(run.id, out_dir), on_progress))
    except Cancelled:
        db.session.rollback()
        db.session.refresh(run)
        return run
    except KeyboardInterrupt:  # Ctrl-C in `flask egonet train`: resumable like a cancelled run
        db.session.rollback()
        cancel_run(run)
        raise
    except Exception as exc:
        log.exception("training run %s failed", run.id)
        _fail(run, exc)
        raise
    finally:
        shutil.rmtree(out_dir, ignore_errors=True)
    _finish(run)
    return run


def _finish(run: TrainingRun) -> None:
    """Running -> done (a run cancelled in its last moments stays cancelled)."""
    db.session.execute(
        update(TrainingRun)
        .where(TrainingRun.id == run.id, TrainingRun.status == RunStatus.RUNNING)
        .values(status=RunStatus.DONE, progress=1.0, eta_s=None, finished_at=utcnow(), message="done")
    )
    db.session.commit()
    db.session.refresh(run)


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


def _train_as_follower(run: TrainingRun, config, rank: int) -> TrainingRun:
    """Ranks > 0 under torchrun: the same frames, folds and starting files, no database or storage writes."""
    from egonet.train import cross_validate

    out_dir = files.scratch(run.id, rank)
    try:
        files.fetch_run(run.id, out_dir)
        samples, folds, start = _plan(run, config, out_dir)
        cross_validate(samples, config, out_dir=out_dir, folds=folds, start=start)
    finally:
        shutil.rmtree(out_dir, ignore_errors=True)
    return run


def _plan(run: TrainingRun, config, out_dir: Path):
    """The run's samples, the folds still to train, and the checkpoint to continue (if any)."""
    from egonet.train import make_folds

    from egonet.network.builders import learns_classes

    samples = _samples(run.config.get("activity_ids"), classes=learns_classes(config.model))
    resume_id = run.config.get("resume_checkpoint")
    if resume_id is not None:
        return _resumed_plan(run, samples, resume_id, out_dir)
    folds = make_folds([s.group for s in samples], mode=config.folds, test_fraction=config.test_fraction)
    finished = {c.fold for c in run.checkpoints}
    return samples, [f for f in folds if f.name not in finished], None


def _class_of(label: str | None) -> str:
    """An instance's object class for DeepLab-Obj: its label in lower case, "object" when it has none."""
    return " ".join((label or "").split()).lower() or "object"


def _samples(activity_ids: list[int] | None, *, classes: bool = False) -> list:
    """The frames with ground truth as ``egonet.data.Sample`` (keyed by frame id, grouped by activity).

    With ``classes``, each sample carries its action-objects' instances as
    ``(class, mask path)`` (:func:`_class_of`; hands are no object class).
    """
    from egonet.data import Sample

    frames = ground_truth.labelled_frames(activity_ids)
    truths = ground_truth.ground_truths([f.id for f in frames])
    samples = []
    for frame in frames:
        annotation = truths[frame.id]
        samples.append(
            Sample(
                rgb=media.local_path(frame.rgb_path),
                dhg=media.local_path(frame.dhg_path) if frame.dhg_path else None,
                # As ground_truth.mask_of: no mask file means no action-object. Paths, not
                # arrays, so a large dataset is read as training goes, not held in memory.
                mask=media.local_path(annotation.mask_path) if annotation.mask_path else None,
                group=frame.sequence.activity.name,
                key=frame.id,
                instances=tuple((_class_of(i.label), media.local_path(i.mask_path))
                                for i in annotation.instances if not is_hand(i.label)) if classes else (),
            )
        )
    if not samples:
        raise TrainingProblem("no frames with ground truth left to train on")
    return samples


def _resumed_plan(run: TrainingRun, samples: list, resume_id: int, out_dir: Path):
    """A run that continues a checkpoint: that checkpoint's fold, on the same frames."""
    from egonet.train import Fold, fold_slug

    checkpoint = db.session.get(Checkpoint, resume_id)
    if checkpoint is None:
        raise TrainingProblem(f"checkpoint {resume_id} no longer exists")
    start = files.load(checkpoint.path)
    own = out_dir / f"{fold_slug(start['fold'])}.pt"
    position = {s.key: i for i, s in enumerate(samples)}
    lost = [k for k in start["train_keys"] + start["test_keys"] if k not in position]
    if lost:
        raise TrainingProblem(f"{len(lost)} frames of checkpoint {resume_id}'s fold have no ground truth any more")
    fold = Fold(start["fold"], [position[k] for k in start["train_keys"]], [position[k] for k in start["test_keys"]])
    # Once this run has a file of its own (it was interrupted), that file is further along.
    return samples, [] if run.checkpoints else [fold], None if own.exists() else start


def summarise(checkpoints: Iterable[Checkpoint]) -> dict:
    """A run's metrics: per fold, and the mean over folds (the paper reports each activity and the mean)."""
    keys = ("max_f", "ap", "aop_max_f", "aop_ap")
    folds = {c.fold: {k: c.metrics.get(k) for k in (*keys, "loss", "train_loss", "epochs", "test_frames")} for c in checkpoints}
    # A run on every frame holds none out: it has no held-out scores to average.
    mean = {k: float(np.mean(values)) for k in keys if (values := [f[k] for f in folds.values() if f[k] is not None])}
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


