"""The demo dataset: synthetic first-person RGB-D frames with ground truth."""

import math
from collections.abc import Callable, Iterator

import cv2
import numpy as np

from app.errors import Problem
from app.models import Frame, Status
from app.services import media
from app.services.importing import FrameItem, ImportReport, add_frames
from egonet import io, synth
from egonet.dhg import encode_dhg

DEMO_AUTHOR = "demo"
DEMO_SOURCE = "flask egonet demo"


def unlabelled_count(frames: int, fraction: float) -> int:
    """How many of an activity's ``frames`` the demo leaves without an annotation.

    ``frames * fraction`` rounded half up, and at least one when the fraction
    is above 0 and the activity has two frames or more (so a small demo
    still leaves something to label, and keeps something labelled).

    Example:
        >>> unlabelled_count(40, 0.25), unlabelled_count(5, 0.25), unlabelled_count(2, 0.25), unlabelled_count(1, 0.25)
        (10, 1, 1, 0)
    """
    count = math.floor(frames * fraction + 0.5)
    if fraction > 0 and frames >= 2:
        count = max(1, count)
    return min(count, frames)


def create_demo(
    *,
    frames_per_activity: int = 40,
    unlabelled_fraction: float = 0.25,
    seed: int = 0,
    width: int = 320,
    height: int = 240,
    on_start: Callable[[int], None] | None = None,
    on_progress: Callable[[int], None] | None = None,
) -> list[ImportReport]:
    """Render and import the demo frames of every activity.

    Each frame's ground-truth mask becomes a reviewed annotation by the
    "demo" author (its action-object, labelled with the object's class, and
    the renderer's hands and arms as an instance labelled ``hand``, which is
    no part of the action-object mask but trains the hand detector of
    Handled+Viewed-Obj), except for the last ``unlabelled_count(frames_per_activity,
    unlabelled_fraction)`` frames of each activity, which get none: a new
    user finds them as one block at the end of each activity's grid (and the
    first of them right after the labelled ones in "next unlabelled"), as in a
    video labelled up to some point. Their truth is not stored (an
    annotation of any status would show on the frame, in its status and in
    exports as somebody's work): ``renderer_truth`` renders it again,
    exactly, when a test or a score of a labeller's work needs it. Training,
    studies and scoring use the labelled frames only.

    The DHG image (gray, height, depth, the authors' channel order) uses the
    renderer's true height above the floor, as a rig with an IMU would know it; imported frames without DHG get the height
    estimated from depth (egonet.dhg.height_map), which needs the floor in
    view. Frames are rendered deterministically from ``seed``, so running
    this twice with the same arguments adds nothing (and frames already
    present keep their annotations, whatever the fraction).

    ``on_start`` is called with the number of frames to render once the
    options are checked, ``on_progress`` with 1 after each frame.

    Raises:
        Problem: ``frames_per_activity`` below 1 or ``unlabelled_fraction``
            outside [0, 1], naming the option.
    """
    if frames_per_activity < 1:
        raise Problem(f"--frames-per-activity must be >= 1, got {frames_per_activity}", field="frames_per_activity")
    if not (0.0 <= unlabelled_fraction <= 1.0):  # also refuses NaN
        raise Problem(
            f"--unlabelled-fraction must be between 0 and 1 (0 labels every frame), got {unlabelled_fraction}",
            field="unlabelled_fraction",
        )
    first_unlabelled = frames_per_activity - unlabelled_count(frames_per_activity, unlabelled_fraction)
    if on_start:
        on_start(frames_per_activity * len(synth.ACTIVITIES))

    def items(activity: str) -> Iterator[FrameItem]:
        for f in synth.render_activity(activity, frames_per_activity, seed=seed, width=width, height=height):
            name = f"{activity.replace(' ', '-')}-{seed}-{f.index:04d}"
            dhg = encode_dhg(f.depth_m, f.height_m, cv2.cvtColor(f.rgb, cv2.COLOR_RGB2GRAY))
            labelled = f.index < first_unlabelled
            yield FrameItem(
                name, f.index, f"demo {name}", rgb=f.rgb, depth_m=f.depth_m, dhg=dhg, K=f.K, mask=f.mask if labelled else None,
                meta=dict(f.meta), hands=f.hands if labelled else None,
            )

    return [
        add_frames(
            activity=activity,
            sequence=f"demo-seed{seed}",
            items=items(activity),
            source=DEMO_SOURCE,
            mask_author=DEMO_AUTHOR,
            mask_status=Status.REVIEWED,
            on_progress=on_progress,
        )
        for activity in synth.ACTIVITIES
    ]


def renderer_truth(frame: Frame) -> np.ndarray:
    """The renderer's action-object mask of a demo frame, labelled or not.

    Renders the frame again from what it stores (activity, index and seed in
    its metadata, its size), about 0.1 s at 320x240 on 2 CPU cores, and checks that the
    RGB comes out identical to the stored image, so a renderer changed since
    the demo was made cannot hand back the truth of a different scene.

    Returns:
        bool (H, W) at the frame's size.

    Raises:
        Problem: the frame is not a demo frame, or the renderer no longer
            makes it (field ``frame``).
    """
    meta = frame.meta or {}
    if frame.sequence.source != DEMO_SOURCE or not {"activity", "index", "seed"} <= meta.keys():
        raise Problem(f"frame {frame.id} is not a demo frame: only those have a renderer's truth", field="frame")
    rendered = synth.render_frame(meta["activity"], meta["index"], seed=meta["seed"], width=frame.width, height=frame.height)
    if not np.array_equal(rendered.rgb, io.read_image(media.local_path(frame.rgb_path))):
        raise Problem(
            f"frame {frame.id}: the renderer no longer makes this image (egonet.synth changed since the demo was created)",
            field="frame",
        )
    return rendered.mask
