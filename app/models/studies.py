"""Human studies: studies, their frames and conditions, participants, trials, clicks, events and entry counts.

A study draws frames (``StudyFrame``) once, when it is created (or edited
before anyone entered): the timed part's frames (``kind`` main), practice
frames and attention-check (catch) frames. Each participant is a ``User``
with the participant role plus a ``Participant`` row holding the access
code, the optional single-use link or the recruiting platform's id, the
condition they were assigned to and the session clock (``started_at``,
``deadline``, ``finished_at``, all stamped by the server). A participant's
trials are created with the participant, in their own seeded order; a trial
is pending until it has an ``outcome``.
"""

import enum
from datetime import datetime
from typing import Any

from sqlalchemy import JSON, BigInteger, Float, ForeignKey, String, Text, UniqueConstraint, false
from sqlalchemy.orm import Mapped, mapped_column, relationship

from app.models.base import Base, UTCDateTime, enum_type, utcnow
from app.models.frames import Frame
from app.models.users import User


class EntryKind(enum.StrEnum):
    """How a participant enters: a code, a single-use link, or the study's open link (the code always works)."""

    CODE = "code"
    LINK = "link"
    OPEN = "open"


class EndReason(enum.StrEnum):
    COMPLETED = "completed"  # every trial answered
    TIME_UP = "time_up"  # the session deadline passed
    DECLINED = "declined"  # consent refused
    SCREENED_OUT = "screened_out"  # the comprehension questions were failed too often


class StudyStatus(enum.StrEnum):
    """Whether new participants may enter (those already in always finish)."""

    OPEN = "open"
    PAUSED = "paused"
    CLOSED = "closed"


class FrameKind(enum.StrEnum):
    MAIN = "main"  # the timed part: scored
    PRACTICE = "practice"  # before the timed part, never scored
    CATCH = "catch"  # attention check with a known answer region, never scored as data


class ActivityOrder(enum.StrEnum):
    SHUFFLED = "shuffled"  # every participant's own random order
    COUNTERBALANCED = "counterbalanced"  # blocks of one activity, block order rotated over participants


class Outcome(enum.StrEnum):
    CLICKED = "clicked"  # one or more clicks, submitted in time
    NONE = "none"  # "no action-object", submitted in time
    TIMED_OUT = "timed_out"  # sent by the page when a limit ran out, with the clicks made until then
    EXPIRED = "expired"  # no answer: nothing arrived in time, or time ran out before any click


# Outcomes that carry an answer (clicks, possibly none): these give soft masks.
ANSWERED = (Outcome.CLICKED, Outcome.NONE, Outcome.TIMED_OUT)


class EventKind(enum.StrEnum):
    BLUR = "blur"
    FOCUS = "focus"
    VISIBILITY = "visibility"  # detail: {"state": "hidden" | "visible"}
    RESIZE = "resize"  # detail: {"width", "height"} of the window
    UNDO = "undo"  # detail: {"x", "y"} of the removed click
    RELOAD = "reload"  # server-side: the trial was served again (page reloaded)
    FULLSCREEN = "fullscreen"  # detail: {"state": "entered" | "exited"}


class Study(Base):
    """A click study: its settings and, through ``frames``, the frames it drew.

    ``superpixels`` holds the keyword options of ``egonet.clicks.superpixels``
    (``method`` plus that method's options); ``sigma_px`` is the click
    Gaussian's standard deviation at the frame's native resolution. With
    ``sigma_scaled`` it was the paper's 60 px at 1280 px wide scaled to the
    frames (``60 * width / 1280``, per frame; ``sigma_px`` records the value
    for the study's widest frames).

    The open link (``open_link_token``; None when off) admits anyone while
    the study is open, up to ``cap`` participants; ``arrivals`` counts the
    admissions and is the row every admission updates first (its lock).
    ``comprehension``, ``display`` and the conditions are the protocol
    settings of ``app.services.studies.protocol``; ``version`` grows with
    every edit.
    """

    __tablename__ = "study"

    id: Mapped[int] = mapped_column(primary_key=True)
    name: Mapped[str] = mapped_column(String(200))
    seed: Mapped[int]
    frames_per_activity: Mapped[int]
    time_limit_s: Mapped[int]
    trial_limit_s: Mapped[int | None]
    multiple_clicks: Mapped[bool] = mapped_column(default=True)
    sigma_px: Mapped[float] = mapped_column(Float, default=60.0)
    superpixels: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    instructions: Mapped[str] = mapped_column(Text, default="")
    consent: Mapped[str] = mapped_column(Text, default="")
    status: Mapped[StudyStatus] = mapped_column(enum_type(StudyStatus), default=StudyStatus.OPEN)
    version: Mapped[int] = mapped_column(default=1)
    sigma_scaled: Mapped[bool] = mapped_column(default=False)
    activity_order: Mapped[ActivityOrder] = mapped_column(enum_type(ActivityOrder), default=ActivityOrder.SHUFFLED)
    open_link_token: Mapped[str | None] = mapped_column(String(64), unique=True)
    cap: Mapped[int | None]
    arrivals: Mapped[int] = mapped_column(default=0)
    completion_code: Mapped[str | None] = mapped_column(String(64))
    failed_code: Mapped[str | None] = mapped_column(String(64))
    redirect_url: Mapped[str | None] = mapped_column(String(2000))
    comprehension: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    display: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    created_by_id: Mapped[int | None] = mapped_column(ForeignKey("user.id"))
    created_at: Mapped[datetime] = mapped_column(UTCDateTime(), default=utcnow)

    created_by: Mapped[User | None] = relationship()
    frames: Mapped[list["StudyFrame"]] = relationship(
        back_populates="study", order_by="StudyFrame.position", cascade="all, delete-orphan", passive_deletes=True
    )
    participants: Mapped[list["Participant"]] = relationship(
        back_populates="study", order_by="Participant.number", cascade="all, delete-orphan", passive_deletes=True
    )
    conditions: Mapped[list["StudyCondition"]] = relationship(
        back_populates="study", order_by="StudyCondition.position", cascade="all, delete-orphan", passive_deletes=True
    )

    def frames_of(self, kind: FrameKind) -> list["StudyFrame"]:
        return [sf for sf in self.frames if sf.kind is kind]


class StudyCondition(Base):
    """A between-subject condition: its name, what it overrides and its optional quota.

    ``overrides`` uses the definition file's keys (``time_limit_minutes``,
    ``trial_limit_seconds``, ``instructions``, ``activities``,
    ``frames_per_activity``); ``quota`` caps the participants the open link
    admits into it.
    """

    __tablename__ = "study_condition"
    __table_args__ = (UniqueConstraint("study_id", "name"), UniqueConstraint("study_id", "position"))

    id: Mapped[int] = mapped_column(primary_key=True)
    study_id: Mapped[int] = mapped_column(ForeignKey("study.id", ondelete="CASCADE"), index=True)
    position: Mapped[int]
    name: Mapped[str] = mapped_column(String(64))
    overrides: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    quota: Mapped[int | None]

    study: Mapped[Study] = relationship(back_populates="conditions")


class StudyFrame(Base):
    """A frame drawn for a study; ``position`` is the draw order (activity by activity, then practice and catch frames).

    A catch frame has ``catch_position``, its place in the timed part
    (1-based), and ``region``: ``{"box": [x0, y0, x1, y1]}`` in native
    pixels, or None for the frame's ground-truth mask.
    """

    __tablename__ = "study_frame"
    __table_args__ = (UniqueConstraint("study_id", "frame_id"), UniqueConstraint("study_id", "position"))

    id: Mapped[int] = mapped_column(primary_key=True)
    study_id: Mapped[int] = mapped_column(ForeignKey("study.id", ondelete="CASCADE"), index=True)
    # No cascade: a frame that a study used cannot disappear under its results.
    frame_id: Mapped[int] = mapped_column(ForeignKey("frame.id"), index=True)
    position: Mapped[int]
    kind: Mapped[FrameKind] = mapped_column(enum_type(FrameKind), default=FrameKind.MAIN)
    catch_position: Mapped[int | None]
    region: Mapped[dict[str, Any] | None] = mapped_column(JSON)

    study: Mapped[Study] = relationship(back_populates="frames")
    frame: Mapped[Frame] = relationship()


class Participant(Base):
    """One person taking a study, signed in as ``user``.

    ``deadline`` is ``started_at`` plus the time limit (the condition's or
    the study's), stored when the session starts so the limit in force
    cannot change under it. ``order_seed`` is the seed the trial order was
    shuffled with. ``external_id`` is the recruiting platform's id
    (Prolific's ``PROLIFIC_PID``, MTurk's ``workerId``, or ``external_id``;
    ``platform`` says which) and ``external`` its other parameters; the same
    id twice is the same participant. ``environment`` is what the page
    reported of the screen, window, pixel ratio and time zone.
    ``completion_code`` is the code given at the end. A ``pilot`` is staff
    trying the study: marked in every export, left out of scores by default,
    taking no place under the cap. A withdrawn participant's answers were
    deleted on request (``withdrawn_at`` by ``withdrawn_by``); the row stays
    so that counts stay honest.
    """

    __tablename__ = "study_participant"
    __table_args__ = (UniqueConstraint("study_id", "number"), UniqueConstraint("study_id", "external_id"))

    id: Mapped[int] = mapped_column(primary_key=True)
    study_id: Mapped[int] = mapped_column(ForeignKey("study.id", ondelete="CASCADE"), index=True)
    user_id: Mapped[int] = mapped_column(ForeignKey("user.id"), unique=True)
    number: Mapped[int]
    entry: Mapped[EntryKind] = mapped_column(enum_type(EntryKind))
    code: Mapped[str] = mapped_column(String(16), unique=True)
    link_token: Mapped[str | None] = mapped_column(String(64), unique=True)
    link_used_at: Mapped[datetime | None] = mapped_column(UTCDateTime())
    order_seed: Mapped[int]
    consented_at: Mapped[datetime | None] = mapped_column(UTCDateTime())
    started_at: Mapped[datetime | None] = mapped_column(UTCDateTime())
    deadline: Mapped[datetime | None] = mapped_column(UTCDateTime())
    finished_at: Mapped[datetime | None] = mapped_column(UTCDateTime())
    end_reason: Mapped[EndReason | None] = mapped_column(enum_type(EndReason))
    created_at: Mapped[datetime] = mapped_column(UTCDateTime(), default=utcnow)
    condition_id: Mapped[int | None] = mapped_column(ForeignKey("study_condition.id", ondelete="SET NULL"), index=True)
    external_id: Mapped[str | None] = mapped_column(String(64))
    platform: Mapped[str | None] = mapped_column(String(20))
    external: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    user_agent: Mapped[str | None] = mapped_column(String(512))
    environment: Mapped[dict[str, Any] | None] = mapped_column(JSON)
    instructions_done_at: Mapped[datetime | None] = mapped_column(UTCDateTime())
    comprehension_attempts: Mapped[int] = mapped_column(default=0)
    comprehension_passed_at: Mapped[datetime | None] = mapped_column(UTCDateTime())
    completion_code: Mapped[str | None] = mapped_column(String(64))
    pilot: Mapped[bool] = mapped_column(default=False, server_default=false())
    withdrawn_at: Mapped[datetime | None] = mapped_column(UTCDateTime())
    withdrawn_by_id: Mapped[int | None] = mapped_column(ForeignKey("user.id"))

    study: Mapped[Study] = relationship(back_populates="participants")
    condition: Mapped[StudyCondition | None] = relationship()
    user: Mapped[User] = relationship(foreign_keys=[user_id])
    withdrawn_by: Mapped[User | None] = relationship(foreign_keys=[withdrawn_by_id])
    trials: Mapped[list["Trial"]] = relationship(
        back_populates="participant", order_by="Trial.position", cascade="all, delete-orphan", passive_deletes=True
    )

    @property
    def label(self) -> str:
        return f"P{self.number:02d}"


class Trial(Base):
    """One frame shown to one participant.

    ``shown_at`` and ``submitted_at`` are the server's clock; ``rt_ms`` and
    the click times are the page's ``performance.now()`` since the frame was
    painted. ``window_*`` and ``display_*`` are the window and the drawn
    frame in CSS pixels when the answer was given. ``hit`` is set for catch
    trials when they close: whether a click fell in the answer region.
    """

    __tablename__ = "study_trial"
    __table_args__ = (UniqueConstraint("participant_id", "position"), UniqueConstraint("participant_id", "study_frame_id"))

    id: Mapped[int] = mapped_column(primary_key=True)
    participant_id: Mapped[int] = mapped_column(ForeignKey("study_participant.id", ondelete="CASCADE"), index=True)
    study_frame_id: Mapped[int] = mapped_column(ForeignKey("study_frame.id", ondelete="CASCADE"), index=True)
    position: Mapped[int]
    shown_at: Mapped[datetime | None] = mapped_column(UTCDateTime())
    submitted_at: Mapped[datetime | None] = mapped_column(UTCDateTime())
    outcome: Mapped[Outcome | None] = mapped_column(enum_type(Outcome))
    rt_ms: Mapped[float | None] = mapped_column(Float)
    window_width: Mapped[int | None]
    window_height: Mapped[int | None]
    display_width: Mapped[float | None] = mapped_column(Float)
    display_height: Mapped[float | None] = mapped_column(Float)
    pixel_ratio: Mapped[float | None] = mapped_column(Float)
    hit: Mapped[bool | None]

    participant: Mapped[Participant] = relationship(back_populates="trials")
    study_frame: Mapped[StudyFrame] = relationship()
    clicks: Mapped[list["Click"]] = relationship(
        back_populates="trial", order_by="Click.position", cascade="all, delete-orphan", passive_deletes=True
    )
    events: Mapped[list["TrialEvent"]] = relationship(
        back_populates="trial", order_by="[TrialEvent.position, TrialEvent.id]", cascade="all, delete-orphan", passive_deletes=True
    )

    @property
    def frame(self) -> Frame:
        return self.study_frame.frame

    @property
    def kind(self) -> FrameKind:
        return self.study_frame.kind


class Click(Base):
    """A click in the frame's native pixels (x = column, y = row, pixel centres at integers)."""

    __tablename__ = "study_click"
    __table_args__ = (UniqueConstraint("trial_id", "position"),)

    id: Mapped[int] = mapped_column(primary_key=True)
    trial_id: Mapped[int] = mapped_column(ForeignKey("study_trial.id", ondelete="CASCADE"), index=True)
    position: Mapped[int]
    x: Mapped[float] = mapped_column(Float)
    y: Mapped[float] = mapped_column(Float)
    rt_ms: Mapped[float] = mapped_column(Float)
    received_at: Mapped[datetime] = mapped_column(UTCDateTime())

    trial: Mapped[Trial] = relationship(back_populates="clicks")


class TrialEvent(Base):
    """Something that happened during a trial: focus, visibility, resize, undo, reload.

    ``client_ms`` is the page's time since the frame was painted (None for
    events the server records itself); ``server_at`` is when the server
    received or recorded it. ``position`` orders a trial's events; it is not
    unique, because a reload can be logged while the answer is being saved.
    """

    __tablename__ = "study_event"

    id: Mapped[int] = mapped_column(primary_key=True)
    trial_id: Mapped[int] = mapped_column(ForeignKey("study_trial.id", ondelete="CASCADE"), index=True)
    position: Mapped[int]
    kind: Mapped[EventKind] = mapped_column(enum_type(EventKind))
    client_ms: Mapped[float | None] = mapped_column(Float)
    server_at: Mapped[datetime] = mapped_column(UTCDateTime())
    detail: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)

    trial: Mapped[Trial] = relationship(back_populates="events")


class EntryCount(Base):
    """Study entries from one address in one fixed window of ``RATELIMIT_WINDOW`` (``window``: its number since the epoch).

    ``scope`` is ``codes`` (wrong codes and unknown links, whatever study the
    URL names) or ``open-<study id>`` (admissions through that study's open
    link, ``study_id`` set). ``count`` attempts are counted before they are
    checked; past the scope's free budget each one makes the address wait
    until ``wait_until``. One row per (scope, address, window): concurrent
    requests update the same row. ``app.throttle`` counts and checks these;
    staff see and clear them on the study's page.
    """

    __tablename__ = "study_entry_counts"
    __table_args__ = (UniqueConstraint("scope", "address", "window"),)

    id: Mapped[int] = mapped_column(primary_key=True)
    scope: Mapped[str] = mapped_column(String(32))
    study_id: Mapped[int | None] = mapped_column(ForeignKey("study.id", ondelete="CASCADE"), index=True)
    address: Mapped[str] = mapped_column(String(64))
    window: Mapped[int] = mapped_column(BigInteger)
    count: Mapped[int] = mapped_column(default=0)
    since: Mapped[datetime] = mapped_column(UTCDateTime(), default=utcnow)
    wait_until: Mapped[datetime | None] = mapped_column(UTCDateTime())
