"""Activities, sequences (recordings) and frames."""

from datetime import datetime
from typing import Any

from sqlalchemy import JSON, Float, ForeignKey, String, UniqueConstraint
from sqlalchemy.orm import Mapped, WriteOnlyMapped, mapped_column, relationship

from app.models.base import Base, UTCDateTime, utcnow

DEPTH_PREDICTED = "predicted"
"""``Frame.meta["depth_source"]`` of a frame whose depth (and DHG) a network predicted, not a sensor."""


class Activity(Base):
    """One of the recorded activities ("scenes" in the paper): cooking, hotel..."""

    __tablename__ = "activity"

    id: Mapped[int] = mapped_column(primary_key=True)
    name: Mapped[str] = mapped_column(String(120), unique=True)
    created_at: Mapped[datetime] = mapped_column(UTCDateTime(), default=utcnow)

    sequences: Mapped[list["Sequence"]] = relationship(
        back_populates="activity", order_by="Sequence.name", cascade="all, delete-orphan"
    )

    def __repr__(self) -> str:
        return f"<Activity {self.name}>"


class Sequence(Base):
    """A recording within an activity: a video or a folder of frames."""

    __tablename__ = "sequence"
    __table_args__ = (UniqueConstraint("activity_id", "name"),)

    id: Mapped[int] = mapped_column(primary_key=True)
    activity_id: Mapped[int] = mapped_column(ForeignKey("activity.id", ondelete="CASCADE"), index=True)
    name: Mapped[str] = mapped_column(String(200))
    source: Mapped[str | None] = mapped_column(String(1000))
    created_at: Mapped[datetime] = mapped_column(UTCDateTime(), default=utcnow)

    activity: Mapped[Activity] = relationship(back_populates="sequences")
    frames: WriteOnlyMapped["Frame"] = relationship(
        back_populates="sequence", order_by="Frame.index", cascade="all, delete-orphan", passive_deletes=True
    )


class Frame(Base):
    """One first-person frame: RGB, and optionally depth, DHG and intrinsics.

    Media paths are relative to the media root and named by the SHA-256 of
    their bytes; ``content_hash`` is the RGB file's hash, which makes
    re-importing the same file a no-op.
    """

    __tablename__ = "frame"
    __table_args__ = (UniqueConstraint("sequence_id", "content_hash"),)

    id: Mapped[int] = mapped_column(primary_key=True)
    sequence_id: Mapped[int] = mapped_column(ForeignKey("sequence.id", ondelete="CASCADE"), index=True)
    index: Mapped[int]
    timestamp_s: Mapped[float | None] = mapped_column(Float)
    source_name: Mapped[str] = mapped_column(String(500))
    width: Mapped[int]
    height: Mapped[int]
    content_hash: Mapped[str] = mapped_column(String(64), index=True)
    rgb_path: Mapped[str] = mapped_column(String(200), info={"media": True})
    depth_path: Mapped[str | None] = mapped_column(String(200), info={"media": True})
    dhg_path: Mapped[str | None] = mapped_column(String(200), info={"media": True})
    fx: Mapped[float | None] = mapped_column(Float)
    fy: Mapped[float | None] = mapped_column(Float)
    cx: Mapped[float | None] = mapped_column(Float)
    cy: Mapped[float | None] = mapped_column(Float)
    meta: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    created_at: Mapped[datetime] = mapped_column(UTCDateTime(), default=utcnow)

    sequence: Mapped[Sequence] = relationship(back_populates="frames")
    annotations: Mapped[list["Annotation"]] = relationship(  # noqa: F821
        back_populates="frame", cascade="all, delete-orphan", passive_deletes=True
    )

    @property
    def depth_predicted(self) -> bool:
        """Whether the frame's depth and DHG are predicted from its RGB (``meta["depth_source"]``), not measured."""
        return (self.meta or {}).get("depth_source") == DEPTH_PREDICTED

    @property
    def intrinsics(self) -> list[list[float]] | None:
        """The 3x3 camera matrix as nested lists, or None when unknown."""
        if self.fx is None:
            return None
        return [[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]]
