"""Browsing the dataset: activities, frame grids, a frame and its media views."""

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from sqlalchemy import func

from app.extensions import db
from app.models import Activity, Annotation, Frame, Sequence, Status
from app.models.training import Prediction
from app.services import media
from app.services.demo import DEMO_SOURCE
from app.services.training import read_probability
from egonet import io
from egonet.overlay import heatmap

# What a demo frame's metadata says about its answer (egonet.synth's truth: the
# action-object, its kind, where it is, the hands on it, its mask's size).
# The viewer never shows these: on an unlabelled frame they give the
# labeller the answer, on a labelled one they prime the reviewer.
RENDERER_TRUTH_KEYS = frozenset(
    {"kind", "object", "object_distance_m", "object_height_m", "object_rgb", "hands_touching", "mask_fraction"}
)
# Maps whose range is narrower than this are shown on the probability scale only.
MIN_NORMALISE_RANGE = 1e-3
THUMB_WIDTH = 240
THUMB_MAX_HEIGHT = 480
# The status a frame shows is the most advanced of its annotations.
STATUS_ORDER = [Status.TODO, Status.REJECTED, Status.IN_PROGRESS, Status.DONE, Status.REVIEWED]


@dataclass
class ActivitySummary:
    activity: Activity
    frames: int
    by_status: dict[str, int]
    cover: Frame | None

    @property
    def labelled(self) -> int:
        """Frames with a finished (done or reviewed) annotation: the ones with ground truth."""
        return self.by_status[Status.DONE.value] + self.by_status[Status.REVIEWED.value]

    @property
    def left(self) -> int:
        """Frames left to label: no finished annotation yet (in progress and rejected included)."""
        return self.frames - self.labelled


def frame_statuses(frame_ids: list[int]) -> dict[int, Status]:
    """The labelling status of each frame (TODO when it has no annotation)."""
    rows = db.session.execute(
        db.select(Annotation.frame_id, Annotation.status).where(Annotation.frame_id.in_(frame_ids))
    ).all()
    statuses = {fid: Status.TODO for fid in frame_ids}
    for fid, status in rows:
        if STATUS_ORDER.index(status) > STATUS_ORDER.index(statuses[fid]):
            statuses[fid] = status
    return statuses


def activity_summary(activity: Activity) -> ActivitySummary:
    """How many frames the activity has, by status, and its first frame as a cover."""
    ids = list(
        db.session.execute(
            db.select(Frame.id).join(Sequence).where(Sequence.activity_id == activity.id).order_by(Frame.id)
        ).scalars()
    )
    counts = {s.value: 0 for s in STATUS_ORDER}
    for status in frame_statuses(ids).values():
        counts[status.value] += 1
    cover = db.session.get(Frame, ids[0]) if ids else None
    return ActivitySummary(activity, len(ids), counts, cover)


def activity_summaries() -> list[ActivitySummary]:
    activities = db.session.execute(db.select(Activity).order_by(Activity.name)).scalars().all()
    return [activity_summary(act) for act in activities]


def frame_page(activity: Activity, page: int, per_page: int) -> tuple[list[Frame], int]:
    """One page of an activity's frames in sequence order, and the number of pages."""
    query = db.select(Frame).join(Sequence).where(Sequence.activity_id == activity.id)
    total = db.session.execute(db.select(func.count()).select_from(query.subquery())).scalar_one()
    frames = (
        db.session.execute(
            query.order_by(Sequence.name, Frame.index, Frame.id).limit(per_page).offset((page - 1) * per_page)
        )
        .scalars()
        .all()
    )
    return frames, max(1, -(-total // per_page))


def neighbours(frame: Frame) -> tuple[int | None, int | None]:
    """The previous and next frame ids within the frame's activity."""
    order = db.select(Frame.id).join(Sequence).where(Sequence.activity_id == frame.sequence.activity_id)
    ids = list(db.session.execute(order.order_by(Sequence.name, Frame.index, Frame.id)).scalars())
    i = ids.index(frame.id)
    return (ids[i - 1] if i > 0 else None), (ids[i + 1] if i + 1 < len(ids) else None)


def frame_depth(frame: Frame) -> np.ndarray | None:
    """The frame's depth as float32 metres ``(H, W)``, 0 where missing, or None when it has none.

    Imported and demo depth alike are stored as 16-bit PNGs in millimetres.
    """
    if frame.depth_path is None:
        return None
    return io.read_depth(media.local_path(frame.depth_path))


def depth_preview(frame: Frame) -> Path:
    """A colour-mapped PNG of the frame's depth (near = warm), cached on disk."""
    return media.derived(f"depth-{Path(frame.depth_path).stem}.png", lambda: _colour_depth(io.read_depth(media.local_path(frame.depth_path))))


def thumbnail_size(frame: Frame) -> tuple[int, int]:
    """(width, height) of the frame's thumbnail (and of its masks' thumbnails, which lie over it).

    ``THUMB_WIDTH`` wide, the frame's aspect, at most ``THUMB_MAX_HEIGHT`` tall.
    """
    return THUMB_WIDTH, max(1, min(THUMB_MAX_HEIGHT, round(frame.height * THUMB_WIDTH / frame.width)))


def thumbnail(frame: Frame) -> Path:
    """A small JPEG of the frame for grids, cached on disk."""
    size = thumbnail_size(frame)

    def make() -> bytes:
        rgb = io.read_image(media.local_path(frame.rgb_path))
        small = cv2.resize(rgb, size, interpolation=cv2.INTER_AREA)
        ok, buf = cv2.imencode(".jpg", cv2.cvtColor(small, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, 85])
        return buf.tobytes()

    return media.derived(f"thumb{size[0]}x{size[1]}-{frame.content_hash}.jpg", make)


def _colour_depth(depth: np.ndarray) -> bytes:
    valid = depth > 0
    far = float(np.percentile(depth[valid], 99)) if valid.any() else 1.0
    scaled = np.clip(depth / max(far, 1e-3), 0, 1)
    gray = (255 * (1 - scaled)).astype(np.uint8)
    bgr = cv2.applyColorMap(gray, cv2.COLORMAP_TURBO)
    bgr[~valid] = 0
    ok, buf = cv2.imencode(".png", bgr)
    return buf.tobytes()


# --------------------------------------------------------------------------
# The frame viewer


# Where the depth came from: the page's Depth and Intrinsics rows say it in words.
DEPTH_KEYS = ("depth_source", "depth_model", "intrinsics_assumed", "assumed_intrinsics")


def shown_meta(frame: Frame) -> dict:
    """The frame's metadata as staff see it: without the demo renderer's truth (``RENDERER_TRUTH_KEYS``)
    and the depth's origin (``DEPTH_KEYS``, shown in words)."""
    hidden = set(DEPTH_KEYS) | (RENDERER_TRUTH_KEYS if frame.sequence.source == DEMO_SOURCE else set())
    return {k: v for k, v in (frame.meta or {}).items() if k not in hidden}


def viewer_annotations(frame: Frame) -> list[tuple[Annotation, bool]]:
    """The frame's annotations, its ground truth first (then by status and latest update), each with
    whether the viewer shows it at first: the finished ones (done, reviewed)."""
    rank = {s: i for i, s in enumerate(reversed(STATUS_ORDER))}
    ordered = sorted(frame.annotations, key=lambda a: (rank[a.status], -a.updated_at.timestamp(), -a.id))
    return [(a, a.status in (Status.DONE, Status.REVIEWED)) for a in ordered]


@dataclass
class PredictionRange:
    """A prediction map's lowest and highest probability, and whether stretching it can show more."""

    low: float
    high: float

    @property
    def can_normalise(self) -> bool:
        return self.high - self.low >= MIN_NORMALISE_RANGE


def prediction_range(prediction: Prediction) -> PredictionRange:
    """The map's range (read from its 16-bit PNG)."""
    probability = read_probability(prediction.path)
    return PredictionRange(float(probability.min()), float(probability.max()))


def normalised_overlay(prediction: Prediction) -> Path:
    """The prediction's heat map stretched to its own range (low -> 0, high -> 1), cached.

    For display only: the viewer's "normalise" switch. Scores, thresholds and
    stored predictions always use the probabilities themselves.
    """

    def make() -> bytes:
        probability = read_probability(prediction.path)
        low, high = float(probability.min()), float(probability.max())
        stretched = (probability - low) / max(high - low, MIN_NORMALISE_RANGE)
        return io.encode_png(heatmap(stretched))

    return media.derived(f"predictions/overlay-range-{Path(prediction.path).stem}.png", make)


def colour_bar() -> Path:
    """The heat map's colours and opacity from probability 0 (left) to 1 (right), 256 x 12 RGBA, cached."""
    ramp = np.repeat(np.linspace(0.0, 1.0, 256, dtype=np.float32)[None, :], 12, axis=0)
    return media.derived("colour-bar-v1.png", lambda: io.encode_png(heatmap(ramp)))
