"""The demo dataset: synthetic first-person RGB-D frames with ground truth."""

from collections.abc import Callable, Iterator

import cv2

from app.errors import Problem
from app.models import Status
from app.services.importing import FrameItem, ImportReport, add_frames
from egonet import synth
from egonet.dhg import encode_dhg

DEMO_AUTHOR = "demo"


def create_demo(
    *,
    frames_per_activity: int = 40,
    seed: int = 0,
    width: int = 320,
    height: int = 240,
    on_progress: Callable[[int], None] | None = None,
) -> list[ImportReport]:
    """Render and import the demo frames of every activity.

    Each frame's ground-truth mask becomes a reviewed annotation by the
    "demo" author. The DHG image uses the renderer's true height above the
    floor, as a rig with an IMU would know it; imported frames without DHG
    get the height estimated from depth (egonet.dhg.height_map), which needs
    the floor in view. Frames are rendered deterministically from ``seed``, so
    running this twice with the same arguments adds nothing.
    """
    if frames_per_activity < 1:
        raise Problem(f"--frames-per-activity must be >= 1, got {frames_per_activity}", field="frames_per_activity")

    def items(activity: str) -> Iterator[FrameItem]:
        for f in synth.render_activity(activity, frames_per_activity, seed=seed, width=width, height=height):
            name = f"{activity.replace(' ', '-')}-{seed}-{f.index:04d}"
            dhg = encode_dhg(f.depth_m, f.height_m, cv2.cvtColor(f.rgb, cv2.COLOR_RGB2GRAY))
            yield FrameItem(
                name, f.index, f"demo {name}", rgb=f.rgb, depth_m=f.depth_m, dhg=dhg, K=f.K, mask=f.mask, meta=dict(f.meta)
            )

    return [
        add_frames(
            activity=activity,
            sequence=f"demo-seed{seed}",
            items=items(activity),
            source="flask egonet demo",
            mask_author=DEMO_AUTHOR,
            mask_status=Status.REVIEWED,
            on_progress=on_progress,
        )
        for activity in synth.ACTIVITIES
    ]
