"""Training runs, checkpoints and predictions.

A ``TrainingRun`` is one request to train: a model, its options, the folds
mode and the resolved training configuration (``config``, the dict of
``egonet.checkpoint.TrainConfig.to_dict()`` plus the activities used). The worker
(or ``flask egonet train``) moves it from queued to running to done, failed
or cancelled, and reports ``progress``, ``loss`` and ``eta_s`` as it goes;
``updated_at`` is the time of the last report or lease renewal: while running,
the run's lease, and ``started_at`` names the attempt holding it
(``app.services.training.control``).

Each finished fold leaves a ``Checkpoint`` (the file in storage, its key
after ``checkpoints/`` in ``path``) and one ``Prediction`` per
frame it held out. A prediction is a 16-bit PNG in the media store
(probability x 65535). ``held_out`` is true when the frame was in the
checkpoint's test set, which is what scoring reads; predictions made later
on other frames (``flask egonet predict``) have it false, except for a run
that never saw them: the authors' released model (every frame), and a run
trained on all frames of its activities (``FoldsMode.ALL``: every frame of
another activity). A held-out
prediction also keeps its frame's precision, recall and F at the fold's
best threshold (the per-frame browser sorts by it).

``TrainingEpoch`` rows are the per-epoch history of every fold, written as
each epoch ends (the Training page's charts poll them). ``name`` and
``tags`` are edited by admins; ``version`` counts those edits (the worker's
progress reports leave it alone), so two admins editing at once cannot
overwrite each other.
"""

import enum
from datetime import datetime
from typing import Any

from sqlalchemy import JSON, Float, ForeignKey, String, Text, UniqueConstraint
from sqlalchemy.orm import Mapped, mapped_column, relationship

from app.models.base import Base, UTCDateTime, enum_type, utcnow
from app.models.frames import Frame
from app.models.users import User


class RunStatus(enum.StrEnum):
    QUEUED = "queued"
    RUNNING = "running"
    DONE = "done"
    FAILED = "failed"
    CANCELLED = "cancelled"


# Statuses a run does not leave by itself.
FINAL_STATUSES = (RunStatus.DONE, RunStatus.FAILED, RunStatus.CANCELLED)


class FoldsMode(enum.StrEnum):
    LOAO = "loao"  # leave one activity out: one model per held-out activity
    SINGLE = "single"  # one model, tested on the last part of every activity
    RELEASED = "released"  # the authors' released model, imported: not trained here, every frame held out
    ALL = "all"  # one model on every labelled frame of its activities: held out are the frames of *other* activities


class TrainingRun(Base):
    __tablename__ = "training_run"

    id: Mapped[int] = mapped_column(primary_key=True)
    name: Mapped[str] = mapped_column(String(200))
    model_name: Mapped[str] = mapped_column(String(40))
    model_options: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    folds: Mapped[FoldsMode] = mapped_column(enum_type(FoldsMode))
    epochs: Mapped[int]
    device: Mapped[str] = mapped_column(String(10))
    seed: Mapped[int]
    config: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    status: Mapped[RunStatus] = mapped_column(enum_type(RunStatus), default=RunStatus.QUEUED, index=True)
    progress: Mapped[float] = mapped_column(Float, default=0.0)
    loss: Mapped[float | None] = mapped_column(Float)
    eta_s: Mapped[float | None] = mapped_column(Float)
    message: Mapped[str | None] = mapped_column(Text)
    metrics: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    tags: Mapped[list[str]] = mapped_column(JSON, default=list)
    version: Mapped[int] = mapped_column(default=1)
    created_by_id: Mapped[int | None] = mapped_column(ForeignKey("user.id"))
    created_at: Mapped[datetime] = mapped_column(UTCDateTime(), default=utcnow)
    started_at: Mapped[datetime | None] = mapped_column(UTCDateTime())
    finished_at: Mapped[datetime | None] = mapped_column(UTCDateTime())
    updated_at: Mapped[datetime] = mapped_column(UTCDateTime(), default=utcnow, onupdate=utcnow)

    created_by: Mapped[User | None] = relationship()
    checkpoints: Mapped[list["Checkpoint"]] = relationship(
        back_populates="run", order_by="Checkpoint.id", cascade="all, delete-orphan", passive_deletes=True
    )

    @property
    def finished(self) -> bool:
        return self.status in FINAL_STATUSES


class Checkpoint(Base):
    """A fold's trained model: the file, and what it scored on its held-out frames.

    ``test_frame_ids`` are the frames the fold held out (its test set);
    ``metrics`` are ``egonet.train.FoldResult.metrics`` plus ``history``.
    """

    __tablename__ = "training_checkpoint"
    __table_args__ = (UniqueConstraint("run_id", "fold"),)

    id: Mapped[int] = mapped_column(primary_key=True)
    run_id: Mapped[int] = mapped_column(ForeignKey("training_run.id", ondelete="CASCADE"), index=True)
    fold: Mapped[str] = mapped_column(String(120))
    path: Mapped[str] = mapped_column(String(500))
    epochs: Mapped[int]
    metrics: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    test_frame_ids: Mapped[list[int]] = mapped_column(JSON, default=list)
    created_at: Mapped[datetime] = mapped_column(UTCDateTime(), default=utcnow)

    run: Mapped[TrainingRun] = relationship(back_populates="checkpoints")


class Prediction(Base):
    """A checkpoint's action-object probability map of one frame (16-bit PNG, value / 65535)."""

    __tablename__ = "training_prediction"
    __table_args__ = (UniqueConstraint("checkpoint_id", "frame_id"),)

    id: Mapped[int] = mapped_column(primary_key=True)
    run_id: Mapped[int] = mapped_column(ForeignKey("training_run.id", ondelete="CASCADE"), index=True)
    checkpoint_id: Mapped[int] = mapped_column(ForeignKey("training_checkpoint.id", ondelete="CASCADE"), index=True)
    frame_id: Mapped[int] = mapped_column(ForeignKey("frame.id", ondelete="CASCADE"), index=True)
    path: Mapped[str] = mapped_column(String(200), info={"media": True})
    held_out: Mapped[bool] = mapped_column(default=False)
    # Held-out frames: scores of this map against the frame's ground truth at the fold's best threshold.
    f_score: Mapped[float | None] = mapped_column(Float)
    precision: Mapped[float | None] = mapped_column(Float)
    recall: Mapped[float | None] = mapped_column(Float)
    created_at: Mapped[datetime] = mapped_column(UTCDateTime(), default=utcnow)

    run: Mapped[TrainingRun] = relationship()
    checkpoint: Mapped[Checkpoint] = relationship()
    frame: Mapped[Frame] = relationship()


class TrainingEpoch(Base):
    """One epoch of one fold: its training loss and learning rate, and its held-out scores when evaluated."""

    __tablename__ = "training_epoch"
    __table_args__ = (UniqueConstraint("run_id", "fold", "epoch"),)

    id: Mapped[int] = mapped_column(primary_key=True)
    run_id: Mapped[int] = mapped_column(ForeignKey("training_run.id", ondelete="CASCADE"), index=True)
    fold: Mapped[str] = mapped_column(String(120))
    epoch: Mapped[int]
    lr: Mapped[float | None] = mapped_column(Float)
    train_loss: Mapped[float | None] = mapped_column(Float)
    loss: Mapped[float | None] = mapped_column(Float)
    max_f: Mapped[float | None] = mapped_column(Float)
    ap: Mapped[float | None] = mapped_column(Float)
    created_at: Mapped[datetime] = mapped_column(UTCDateTime(), default=utcnow)
