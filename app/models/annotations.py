"""Action-object annotations: one per frame and author, with instances,
and the resumable GrabCut sessions that help draw them."""

import enum
import uuid
from datetime import datetime

from sqlalchemy import JSON, Float, ForeignKey, LargeBinary, String, Text, UniqueConstraint
from sqlalchemy.orm import Mapped, backref, mapped_column, relationship

from app.models.base import Base, UTCDateTime, enum_type, utcnow
from app.models.frames import Frame
from app.models.users import User
from egonet.hands import HAND_LABEL


class Status(enum.StrEnum):
    TODO = "todo"
    IN_PROGRESS = "in_progress"
    DONE = "done"
    REVIEWED = "reviewed"
    REJECTED = "rejected"


# Annotations with these statuses count as ground truth for training,
# studies and scoring.
FINISHED = (Status.DONE, Status.REVIEWED)


class InstanceKind(enum.StrEnum):
    TACTILE = "tactile"
    VISUAL = "visual"


def is_hand(label: str | None) -> bool:
    """Whether an instance with this label outlines the wearer's hands (``egonet.hands.HAND_LABEL``, any case, outer spaces ignored).

    Such instances train the hand detector of the Handled+Viewed-Obj baseline
    and are left out of the annotation's action-object mask; the demo ships
    them for every frame where hands show.
    """
    return label is not None and label.strip().lower() == HAND_LABEL


class ObjectClass(Base):
    """A name in the project-wide list of object classes the labelling page's label field completes from.

    Whether a label outside the list is refused is the ``LABEL_CLASSES_STRICT``
    setting (``app.services.labelling.classes``).
    """

    __tablename__ = "object_class"

    id: Mapped[int] = mapped_column(primary_key=True)
    name: Mapped[str] = mapped_column(String(120), unique=True)
    created_at: Mapped[datetime] = mapped_column(UTCDateTime(), default=utcnow)


class Annotation(Base):
    """A person's action-object labelling of one frame.

    ``mask_path`` points at the binary PNG of the union of the instances
    (None while nothing is drawn, or when the frame has no action-object).
    ``version`` is the optimistic-locking counter: SQLAlchemy adds it to
    every UPDATE, so a stale writer gets StaleDataError instead of silently
    overwriting someone else's work.

    ``proposed_by_run_id`` / ``proposed_by_checkpoint_id`` record the
    training run (and its fold's checkpoint) whose "Suggest" last added
    proposals to the annotation; they stay after the proposals are accepted,
    as the annotation's provenance (``app.services.labelling.suggest``).
    """

    __tablename__ = "annotation"
    __table_args__ = (UniqueConstraint("frame_id", "author_id"),)

    id: Mapped[int] = mapped_column(primary_key=True)
    frame_id: Mapped[int] = mapped_column(ForeignKey("frame.id", ondelete="CASCADE"), index=True)
    author_id: Mapped[int] = mapped_column(ForeignKey("user.id"), index=True)
    status: Mapped[Status] = mapped_column(enum_type(Status), default=Status.TODO, index=True)
    mask_path: Mapped[str | None] = mapped_column(String(200), info={"media": True})
    no_action_object: Mapped[bool] = mapped_column(default=False)
    version: Mapped[int] = mapped_column(default=1)
    time_spent_s: Mapped[float] = mapped_column(Float, default=0.0)
    review_comment: Mapped[str | None] = mapped_column(Text)
    # Who accepted or rejected the annotation last, and when.
    reviewer_id: Mapped[int | None] = mapped_column(ForeignKey("user.id"))
    reviewed_at: Mapped[datetime | None] = mapped_column(UTCDateTime())
    # A reviewer who fixed the masks before deciding, and when (the annotation stays its author's).
    fixed_by_id: Mapped[int | None] = mapped_column(ForeignKey("user.id"))
    fixed_at: Mapped[datetime | None] = mapped_column(UTCDateTime())
    created_at: Mapped[datetime] = mapped_column(UTCDateTime(), default=utcnow)
    updated_at: Mapped[datetime] = mapped_column(UTCDateTime(), default=utcnow, onupdate=utcnow)
    # Ids, not relationships: a deleted run or checkpoint leaves the annotation as it is.
    proposed_by_run_id: Mapped[int | None] = mapped_column(ForeignKey("training_run.id", ondelete="SET NULL"))
    proposed_by_checkpoint_id: Mapped[int | None] = mapped_column(
        ForeignKey("training_checkpoint.id", ondelete="SET NULL")
    )

    frame: Mapped[Frame] = relationship(back_populates="annotations")
    author: Mapped[User] = relationship(foreign_keys=[author_id])
    reviewer: Mapped[User | None] = relationship(foreign_keys=[reviewer_id])
    fixed_by: Mapped[User | None] = relationship(foreign_keys=[fixed_by_id])
    instances: Mapped[list["Instance"]] = relationship(
        back_populates="annotation", order_by="Instance.position", cascade="all, delete-orphan", passive_deletes=True
    )

    __mapper_args__ = {"version_id_col": version}


class Instance(Base):
    """One action-object within an annotation; the frame's mask is their union.

    A proposal (``app.services.labelling.suggest``) carries its source
    (``"model"``, ``"depth"``, ``"handled"``, ``"saliency"``) and, from a
    trained run, the run and checkpoint, until the annotator accepts it or
    edits its mask (``UNMARKED`` clears all three); ``proposed`` says whether
    it is still one.
    """

    __tablename__ = "instance"
    __table_args__ = (UniqueConstraint("annotation_id", "position"),)

    id: Mapped[int] = mapped_column(primary_key=True)
    annotation_id: Mapped[int] = mapped_column(ForeignKey("annotation.id", ondelete="CASCADE"), index=True)
    position: Mapped[int]
    kind: Mapped[InstanceKind | None] = mapped_column(enum_type(InstanceKind))
    label: Mapped[str | None] = mapped_column(String(120))
    mask_path: Mapped[str] = mapped_column(String(200), info={"media": True})
    # A stable name the labelling page gives the instance: positions shift
    # when an instance is deleted, keys do not (GrabCut sessions use them).
    key: Mapped[str | None] = mapped_column(String(40))
    proposed_by_run_id: Mapped[int | None] = mapped_column(ForeignKey("training_run.id", ondelete="SET NULL"))
    proposed_by_checkpoint_id: Mapped[int | None] = mapped_column(
        ForeignKey("training_checkpoint.id", ondelete="SET NULL")
    )

    proposal_source: Mapped[str | None] = mapped_column(String(20))

    annotation: Mapped[Annotation] = relationship(back_populates="instances")

    UNMARKED = {"proposal_source": None, "proposed_by_run_id": None, "proposed_by_checkpoint_id": None}
    """The values that make a proposal an ordinary instance (accepted, or its mask edited)."""

    @property
    def proposed(self) -> bool:
        """Whether this is a proposal the annotator has not accepted or edited yet."""
        return self.proposal_source is not None

    @property
    def is_hand(self) -> bool:
        """Whether it outlines the wearer's hand rather than an action-object (``is_hand``)."""
        return is_hand(self.label)


class AttentionPoints(Base):
    """Where an annotation's mask came from when it was made from attention points (``flask egonet import-points``).

    The paper's Table 4 takes as ground truth "a fixed size Gaussian around
    the ground truth attention location"; the annotation's mask is that
    Gaussian binarised (``egonet.clicks.points_mask``), and this row keeps the
    points ((x, y) in the frame's pixels; empty: a "no action-object" frame),
    the Gaussian's standard deviation in the frame's pixels, whether it was
    the paper's click width scaled to the frame (``sigma_scaled``) or given,
    and the file they came from. The frame page and every score report say
    so (``app.services.attention_points``).
    """

    __tablename__ = "attention_points"

    id: Mapped[int] = mapped_column(primary_key=True)
    annotation_id: Mapped[int] = mapped_column(ForeignKey("annotation.id", ondelete="CASCADE"), unique=True)
    points: Mapped[list[list[float]]] = mapped_column(JSON, default=list)
    sigma_px: Mapped[float] = mapped_column(Float)
    sigma_scaled: Mapped[bool] = mapped_column(default=False)
    source: Mapped[str] = mapped_column(String(200))
    created_at: Mapped[datetime] = mapped_column(UTCDateTime(), default=utcnow)

    annotation: Mapped[Annotation] = relationship(
        backref=backref("attention_points", uselist=False, cascade="all, delete-orphan", passive_deletes=True)
    )


class GrabCutState(Base):
    """A GrabCut session (one per user, frame and instance key), saved after
    every operation so it survives restarts and works across worker processes.

    ``state`` is ``egonet.grabcut.GrabCutSession.state()`` written with
    ``np.savez`` and zlib-compressed. ``revision`` serialises operations: each
    one loads the row, works, and writes back only if no other operation has
    written in between (SQLAlchemy adds the revision to the UPDATE). It is a
    random token rather than a counter so that a worker may keep a session in
    memory under its revision and know it is still the current one.
    """

    __tablename__ = "grabcut_state"
    __table_args__ = (UniqueConstraint("user_id", "frame_id", "instance_key"),)

    id: Mapped[int] = mapped_column(primary_key=True)
    user_id: Mapped[int] = mapped_column(ForeignKey("user.id", ondelete="CASCADE"))
    frame_id: Mapped[int] = mapped_column(ForeignKey("frame.id", ondelete="CASCADE"), index=True)
    instance_key: Mapped[str] = mapped_column(String(40))
    state: Mapped[bytes] = mapped_column(LargeBinary)
    revision: Mapped[str] = mapped_column(String(32))
    updated_at: Mapped[datetime] = mapped_column(UTCDateTime(), default=utcnow, onupdate=utcnow)

    __mapper_args__ = {"version_id_col": revision, "version_id_generator": lambda _: uuid.uuid4().hex}


class EditHistory(Base):
    """A person's undo / redo history of an annotation on the labelling page,
    so it survives reloads, restarts and another browser.

    ``data`` is what the page sent (gzip-compressed JSON: the history's
    snapshots as row runs); the server never decodes it, it only bounds its
    size (LABEL_HISTORY_MAX_BYTES). ``version`` is the annotation's version
    the history ends at: the page restores it as it is when that is still
    the annotation's version, and otherwise bridges the gap with one undoable
    step (``app.services.labelling.history``).
    """

    __tablename__ = "edit_history"
    __table_args__ = (UniqueConstraint("user_id", "annotation_id"),)

    id: Mapped[int] = mapped_column(primary_key=True)
    user_id: Mapped[int] = mapped_column(ForeignKey("user.id", ondelete="CASCADE"))
    annotation_id: Mapped[int] = mapped_column(ForeignKey("annotation.id", ondelete="CASCADE"), index=True)
    version: Mapped[int]
    data: Mapped[bytes] = mapped_column(LargeBinary)
    updated_at: Mapped[datetime] = mapped_column(UTCDateTime(), default=utcnow, onupdate=utcnow)


class FramePresence(Base):
    """Who has a frame open on the labelling page: the page says so when it
    opens the frame and then every half minute; a row not seen for
    ``presence.PRESENCE_TTL_S`` no longer counts (the tab was closed or the
    machine slept)."""

    __tablename__ = "frame_presence"
    __table_args__ = (UniqueConstraint("frame_id", "user_id"),)

    id: Mapped[int] = mapped_column(primary_key=True)
    frame_id: Mapped[int] = mapped_column(ForeignKey("frame.id", ondelete="CASCADE"), index=True)
    user_id: Mapped[int] = mapped_column(ForeignKey("user.id", ondelete="CASCADE"))
    opened_at: Mapped[datetime] = mapped_column(UTCDateTime(), default=utcnow)
    seen_at: Mapped[datetime] = mapped_column(UTCDateTime(), default=utcnow, index=True)

    user: Mapped[User] = relationship()
