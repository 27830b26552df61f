"""Depth for RGB-only frames: train a monocular depth run, and predict depth and DHG for frames without depth.

A depth run is a ``TrainingRun`` whose model is ``egonet.depth.DEPTH_MODEL``
(``"depth-lite"``): created here (``create_depth_run``), trained by the same
job as every run (``app.services.training.job.execute_run``, in the worker or
``flask egonet train-depth``), with one ``Checkpoint`` (fold ``"depth"``) and
its epochs as ``TrainingEpoch`` rows. It trains on every frame with
*measured* depth and holds out the last 20 % of each activity's frames.

``predict_depth`` gives each frame of an activity that has no depth a
predicted depth map and its DHG, marked in ``Frame.meta``:
``depth_source = "predicted"``, ``depth_model`` (the checkpoint), and
``intrinsics_assumed`` with the camera matrix used when the frame has none
(:func:`egonet.depth.assumed_intrinsics`). Measured depth, and DHG imported
without depth, are never replaced.
"""

from dataclasses import dataclass

import numpy as np

from app.extensions import db
from app.models import Activity, Frame, Sequence, User, utcnow
from app.models.frames import DEPTH_PREDICTED
from app.models.training import Checkpoint, FoldsMode, RunStatus, TrainingRun
from app.queue import enqueue
from app.services import media
from app.services.training import files
from app.services.training.control import TrainingProblem, _activities, _check_epochs
from egonet import io
from egonet.depth import DEPTH_MODEL, DepthConfig
from egonet.errors import EgonetError

CHECKPOINT = "depth.pt"
"""A depth run's one checkpoint file, in the run's folder."""


@dataclass(frozen=True)
class DepthRequest:
    """What a person asks of a depth run; ``create_depth_run`` checks every field (defaults: ``DepthConfig``'s)."""

    epochs: int = DepthConfig.epochs
    width: int = DepthConfig.width
    height: int = DepthConfig.height
    lr: float = DepthConfig.lr
    batch_size: int = DepthConfig.batch_size
    seed: int = DepthConfig.seed
    device: str = DepthConfig.device
    activity_ids: tuple[int, ...] | None = None
    name: str | None = None


def measured_depth_frames(activity_ids: list[int] | None = None) -> list[Frame]:
    """Frames with measured depth (not predicted), in activity, sequence and frame order."""
    query = (
        db.select(Frame).join(Frame.sequence).join(Sequence.activity)
        .where(Frame.depth_path.is_not(None))
        .order_by(Activity.name, Sequence.name, Frame.index, Frame.id)
    )
    if activity_ids is not None:
        query = query.where(Sequence.activity_id.in_(activity_ids))
    return [f for f in db.session.execute(query).scalars() if not f.depth_predicted]


def create_depth_run(request: DepthRequest, *, created_by: User | None = None) -> TrainingRun:
    """Check a depth request and record its run, queued.

    Raises:
        TrainingProblem: A bad option, or fewer than two frames with measured depth, naming the field.
    """
    _check_epochs(request.epochs)
    try:
        config = DepthConfig(epochs=request.epochs, width=request.width, height=request.height, lr=request.lr,
                             batch_size=request.batch_size, seed=request.seed, device=request.device)
    except EgonetError as exc:
        field = "size" if exc.field in ("width", "height") else exc.field
        raise TrainingProblem(exc.message, field=field) from None
    activities = _activities(request.activity_ids)
    frames = measured_depth_frames([a.id for a in activities] if request.activity_ids is not None else None)
    if len(frames) < 2:
        raise TrainingProblem(
            f"depth training needs at least two frames with measured depth, found {len(frames)}: "
            "import RGB-D frames (--depth) or run `flask egonet demo`", field="activities")
    name = (request.name or "").strip() or f"{DEPTH_MODEL} {utcnow():%Y-%m-%d %H:%M}"
    if len(name) > 200:
        raise TrainingProblem("name must have at most 200 characters", field="name")
    run = TrainingRun(
        name=name, model_name=DEPTH_MODEL, model_options={"width": config.net_width}, folds=FoldsMode.SINGLE,
        epochs=config.epochs, device=config.device, seed=config.seed,
        config={
            "depth": config.to_dict(),
            "activity_ids": None if request.activity_ids is None else [a.id for a in activities],
            "activities": sorted({f.sequence.activity.name for f in frames}),
            "frames": len(frames),
        },
        created_by=created_by,
    )
    db.session.add(run)
    db.session.commit()
    return run


def start_depth_run(request: DepthRequest, *, created_by: User | None = None) -> TrainingRun:
    """Create a depth run and queue it for the worker."""
    run = create_depth_run(request, created_by=created_by)
    enqueue("train_run", run.id)
    return run


def depth_samples(run: TrainingRun) -> list:
    """The run's frames with measured depth as ``egonet.depth.DepthSample`` (keyed by frame id)."""
    from egonet.depth import DepthSample

    frames = measured_depth_frames(run.config.get("activity_ids"))
    if len(frames) < 2:
        raise TrainingProblem(f"depth training needs at least two frames with measured depth, found {len(frames)}")
    return [DepthSample(rgb=media.local_path(f.rgb_path), depth=media.local_path(f.depth_path), key=f.id,
                        group=f.sequence.activity.name) for f in frames]


def record_depth_result(run: TrainingRun, result) -> None:
    """The finished run's checkpoint and summary (the caller commits); NaN (no valid pixel) is stored as null."""
    metrics = _json_numbers(result.metrics)
    db.session.add(Checkpoint(
        run_id=run.id, fold="depth", path=f"{files.run_folder(run.id)}/{CHECKPOINT}",
        epochs=int(result.metrics["epochs"]), metrics=metrics | {"history": _json_numbers(result.history)},
        test_frame_ids=[int(k) for k in result.test_keys],
    ))
    run.metrics = {"depth": metrics}


def _json_numbers(value):
    if isinstance(value, dict):
        return {k: _json_numbers(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_json_numbers(v) for v in value]
    if isinstance(value, float) and not np.isfinite(value):
        return None
    return value


def is_depth_run(run: TrainingRun) -> bool:
    """Whether a run predicts depth, not action-objects (scoring and predictions leave it out)."""
    return run.model_name == DEPTH_MODEL


# --------------------------------------------------------------------------- predicting


@dataclass
class DepthReport:
    """What ``predict_depth`` did to an activity's frames."""

    checkpoint_id: int
    predicted: int = 0
    assumed_intrinsics: int = 0
    kept_measured: int = 0
    kept_dhg: int = 0


def depth_checkpoint(checkpoint_id: int | None) -> Checkpoint:
    """A depth run's checkpoint: the one asked for, else the newest of a finished depth run.

    Raises:
        TrainingProblem: 404 if there is none, 400 if the checkpoint is not a depth model's.
    """
    if checkpoint_id is not None:
        checkpoint = db.session.get(Checkpoint, checkpoint_id)
        if checkpoint is None:
            raise TrainingProblem(f"no checkpoint with id {checkpoint_id}", status=404, field="checkpoint")
        if not is_depth_run(checkpoint.run):
            raise TrainingProblem(
                f"checkpoint {checkpoint_id} is a {checkpoint.run.model_name} model, not {DEPTH_MODEL}: "
                "train one with `flask egonet train-depth`", field="checkpoint")
        return checkpoint
    checkpoint = db.session.execute(
        db.select(Checkpoint).join(Checkpoint.run)
        .where(TrainingRun.model_name == DEPTH_MODEL, TrainingRun.status == RunStatus.DONE)
        .order_by(Checkpoint.id.desc()).limit(1)
    ).scalar_one_or_none()
    if checkpoint is None:
        raise TrainingProblem(f"no finished {DEPTH_MODEL} run: train one with `flask egonet train-depth`",
                              status=404, field="checkpoint")
    return checkpoint


def predict_depth(activity: str, *, checkpoint_id: int | None = None, device: str = "cpu") -> DepthReport:
    """Give every frame of ``activity`` without depth a predicted depth map and its DHG, in one transaction.

    A frame without intrinsics gets :func:`egonet.depth.assumed_intrinsics`
    for its DHG (recorded in its ``meta``, its own intrinsics stay unknown).
    A frame predicted before is predicted again; measured depth and imported
    DHG are left as they are.

    Raises:
        TrainingProblem: No such activity, or no usable depth checkpoint.
    """
    from egonet.depth import DepthPredictor, assumed_intrinsics, intrinsics_record
    from egonet.dhg import dhg_from_depth

    found = db.session.execute(db.select(Activity).filter_by(name=activity)).scalar_one_or_none()
    if found is None:
        raise TrainingProblem(f"no activity named {activity!r}", status=404, field="activity")
    checkpoint = depth_checkpoint(checkpoint_id)
    try:
        predictor = DepthPredictor(files.load(checkpoint.path), device=device)
    except EgonetError as exc:
        raise TrainingProblem(exc.message, field="checkpoint") from None
    report = DepthReport(checkpoint_id=checkpoint.id)
    frames = db.session.execute(
        db.select(Frame).join(Frame.sequence).where(Sequence.activity_id == found.id).order_by(Sequence.name, Frame.index)
    ).scalars()
    with media.transaction() as written:
        for frame in frames:
            if frame.depth_path is not None and not frame.depth_predicted:
                report.kept_measured += 1
                continue
            if frame.dhg_path is not None and not frame.depth_predicted:
                report.kept_dhg += 1
                continue
            rgb = io.decode_image(media.read(frame.rgb_path), path=frame.rgb_path)
            depth = predictor.predict(rgb)
            meta = {k: v for k, v in (frame.meta or {}).items() if k not in ("intrinsics_assumed", "assumed_intrinsics")}
            if frame.intrinsics is not None:
                K = np.asarray(frame.intrinsics)
            else:
                K = assumed_intrinsics(frame.width, frame.height)
                meta |= {"intrinsics_assumed": True, "assumed_intrinsics": intrinsics_record(K)}
                report.assumed_intrinsics += 1
            frame.depth_path = media.store(io.encode_depth_png(depth), ".png", written=written)
            frame.dhg_path = media.store(io.encode_png(dhg_from_depth(depth, K, rgb)), ".png", written=written)
            frame.meta = meta | {"depth_source": DEPTH_PREDICTED,
                                 "depth_model": f"{DEPTH_MODEL} run {checkpoint.run_id} checkpoint {checkpoint.id}"}
            report.predicted += 1
    return report


def depth_config(run: TrainingRun) -> DepthConfig:
    return DepthConfig.from_dict(run.config["depth"])


__all__ = [
    "DepthReport", "DepthRequest", "create_depth_run", "depth_checkpoint", "depth_config", "depth_samples",
    "is_depth_run", "measured_depth_frames", "predict_depth", "record_depth_result", "start_depth_run",
]
