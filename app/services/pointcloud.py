"""A frame in 3-D: its depth back-projected, with the labelled and predicted action-object marked.

``frame_cloud`` gathers what ``egonet.pointcloud`` needs from the database
(depth, intrinsics, the ground truth, a prediction and its fold's best-F
threshold); ``export_ply`` writes the PLY file of ``flask egonet
export-3d``; ``browser_points`` encodes a bounded cloud for the frame
viewer's 3-D view.
"""

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from app.errors import Problem
from app.extensions import db
from app.models import Frame
from app.models.training import Prediction
from app.services import ground_truth, media
from app.services import frames as frames_service
from app.services.training import latest_prediction, read_probability
from egonet import io
from egonet.pointcloud import PointCloud, encode_points, write_ply
from egonet.pointcloud import frame_cloud as egonet_frame_cloud

#: Points the browser gets by default, and at most (the request's ``max``).
BROWSER_POINTS, MAX_BROWSER_POINTS = 40_000, 100_000
DEFAULT_THRESHOLD = 0.5


class PointCloudProblem(Problem):
    """A frame that cannot be shown in 3-D (no depth, no intrinsics, an unknown prediction)."""


@dataclass(frozen=True)
class FrameCloud:
    """A frame's cloud and where its marks come from."""

    cloud: PointCloud
    frame: Frame
    prediction: Prediction | None
    threshold: float | None
    has_truth: bool

    def comments(self) -> tuple[str, ...]:
        made = [f"egonet-studio frame {self.frame.id} ({self.frame.source_name}), camera coordinates in metres"]
        made.append("truth: the frame's ground truth" if self.has_truth else "truth: none (no finished annotation)")
        if self.prediction is not None:
            made.append(f"predicted: prediction {self.prediction.id} of run {self.prediction.run_id}, p >= {self.threshold:.3f}")
        return tuple(made)


def frame_cloud(frame: Frame, *, prediction_id: int | None = None, max_points: int = BROWSER_POINTS) -> FrameCloud:
    """The frame's point cloud with its marks.

    Args:
        frame: A frame with depth and intrinsics.
        prediction_id: The prediction to mark (one of this frame's); None: its latest, if any.
        max_points: Most points.

    Raises:
        PointCloudProblem: No depth (404), no intrinsics (409), or a prediction of another frame (404).
    """
    if frame.depth_path is None:
        raise PointCloudProblem(f"frame {frame.id} has no depth map: import depth to see it in 3-D", field="frame", status=404)
    if not frame.fx or not frame.fy:
        raise PointCloudProblem(f"frame {frame.id} has no camera intrinsics: import them (camera.json)", field="frame", status=409)
    prediction = latest_prediction(frame.id) if prediction_id is None else db.session.get(Prediction, prediction_id)
    if prediction is not None and prediction.frame_id != frame.id:
        prediction = None
    if prediction_id is not None and prediction is None:
        raise PointCloudProblem(f"frame {frame.id} has no prediction {prediction_id}", field="prediction", status=404)
    threshold = None
    probability = None
    if prediction is not None:
        probability = read_probability(prediction.path, shape=(frame.height, frame.width))
        threshold = float((prediction.checkpoint.metrics or {}).get("threshold") or DEFAULT_THRESHOLD)
    annotation = ground_truth.ground_truths([frame.id]).get(frame.id)
    K = np.array([[frame.fx, 0.0, frame.cx], [0.0, frame.fy, frame.cy], [0.0, 0.0, 1.0]])
    cloud = egonet_frame_cloud(
        frames_service.frame_depth(frame), K, io.read_image(media.local_path(frame.rgb_path)),
        truth=ground_truth.mask_of(annotation) if annotation is not None else None,
        probability=probability, threshold=threshold or DEFAULT_THRESHOLD, max_points=max_points,
    )
    return FrameCloud(cloud, frame, prediction, threshold, annotation is not None)


def export_ply(frame: Frame, out: Path, *, prediction_id: int | None = None, max_points: int = 1_000_000) -> FrameCloud:
    """Write the frame's cloud to ``out`` (binary PLY, marked colours, ``truth``/``predicted`` properties)."""
    made = frame_cloud(frame, prediction_id=prediction_id, max_points=max_points)
    write_ply(out, made.cloud, comments=made.comments())
    return made


def browser_points(frame: Frame, *, max_points: int = BROWSER_POINTS, prediction_id: int | None = None) -> bytes:
    """The encoded cloud for the frame viewer (``egonet.pointcloud.encode_points``), at most ``max_points``."""
    if not 1 <= max_points <= MAX_BROWSER_POINTS:
        raise PointCloudProblem(f"max must be between 1 and {MAX_BROWSER_POINTS}, got {max_points}", field="max")
    return encode_points(frame_cloud(frame, prediction_id=prediction_id, max_points=max_points).cloud)
