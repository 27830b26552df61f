"""A frame as a coloured 3-D point cloud, with its action-object marked (the paper's Fig. 8).

:func:`frame_cloud` back-projects a depth map through the camera
intrinsics (pinhole: ``X = (u - cx) Z / fx``, ``Y = (v - cy) Z / fy``, camera
coordinates, metres, x right, y down, z forward), keeps at most
``max_points`` valid pixels on a regular grid, and flags the ones in the
labelled action-object and in the predicted one (probability >= a
threshold). :func:`write_ply` writes it with ``plyfile`` (marked colours
plus ``truth`` and ``predicted`` vertex properties); :func:`encode_points`
packs it for the browser's 3-D view::

    >>> import numpy as np
    >>> K = np.array([[100.0, 0, 31.5], [0, 100.0, 23.5], [0, 0, 1]])
    >>> cloud = frame_cloud(np.ones((48, 64), np.float32), K, np.zeros((48, 64, 3), np.uint8), max_points=500)
    >>> len(cloud), cloud.xyz.dtype.name
    (384, 'float32')
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from egonet.errors import EgonetError
from egonet.io import check_rgb, write_atomic

__all__ = ["MARK_COLORS", "PointCloud", "encode_points", "frame_cloud", "marked_colors", "write_ply"]

#: Colours blended into marked points: labelled only, predicted only, both.
MARK_COLORS = {"truth": (40, 220, 60), "predicted": (230, 40, 40), "both": (250, 220, 30)}
MARK_ALPHA = 0.65
#: Format tag of :func:`encode_points` (the browser checks it).
POINTS_MAGIC = b"EGP1"


@dataclass(frozen=True)
class PointCloud:
    """Points of one frame.

    Attributes:
        xyz: float32 ``(N, 3)`` camera coordinates in metres.
        rgb: uint8 ``(N, 3)`` the frame's colour at each point.
        pixels: int32 ``(N, 2)`` the ``(row, col)`` each point comes from.
        truth: bool ``(N,)`` in the labelled action-object.
        predicted: bool ``(N,)`` in the predicted action-object.
        stride: The sampling step on the pixel grid.
    """

    xyz: np.ndarray
    rgb: np.ndarray
    pixels: np.ndarray
    truth: np.ndarray
    predicted: np.ndarray
    stride: int

    def __len__(self) -> int:
        return len(self.xyz)


def _check_map(value: np.ndarray | None, name: str, shape: tuple[int, int], dtype_kind: str) -> None:
    if value is None:
        return
    if not isinstance(value, np.ndarray) or value.shape != shape or value.dtype.kind != dtype_kind:
        got = f"{value.dtype} {value.shape}" if isinstance(value, np.ndarray) else type(value).__name__
        kinds = {"b": "bool", "f": "float"}
        raise EgonetError(f"{name} must be a {kinds[dtype_kind]} array of shape {shape}, got {got}", field=name)


def frame_cloud(
    depth_m: np.ndarray,
    K: np.ndarray,
    rgb: np.ndarray,
    *,
    truth: np.ndarray | None = None,
    probability: np.ndarray | None = None,
    threshold: float = 0.5,
    max_points: int = 50_000,
) -> PointCloud:
    """Back-project a frame's valid depth into points, at most ``max_points`` of them.

    Args:
        depth_m: float ``(H, W)`` depth in metres, 0 (or not finite) where missing.
        K: ``(3, 3)`` intrinsics (fx, fy, cx, cy in pixels of this frame).
        rgb: uint8 ``(H, W, 3)``.
        truth: bool ``(H, W)`` labelled action-object, or None.
        probability: float ``(H, W)`` predicted action-object probability, or None.
        threshold: A pixel is predicted when ``probability >= threshold``.
        max_points: Most points kept: every ``stride``-th pixel in both
            directions, the smallest stride that keeps the valid pixels
            under the bound (so the cloud stays evenly spread).

    Returns:
        The :class:`PointCloud` (empty when no pixel has depth).

    Raises:
        EgonetError: A shape, dtype, matrix or bound that does not fit (named).
    """
    h, w = check_rgb(rgb, "rgb")
    _check_map(np.asarray(depth_m) if isinstance(depth_m, np.ndarray) else depth_m, "depth_m", (h, w), "f")
    _check_map(truth, "truth", (h, w), "b")
    _check_map(probability, "probability", (h, w), "f")
    K = np.asarray(K, dtype=np.float64)
    if K.shape != (3, 3) or not np.all(np.isfinite(K)) or K[0, 0] <= 0 or K[1, 1] <= 0:
        raise EgonetError(f"K must be a finite (3, 3) intrinsics matrix with fx, fy > 0, got {K.tolist()}", field="K")
    if isinstance(max_points, bool) or not isinstance(max_points, int) or max_points < 1:
        raise EgonetError(f"max_points must be a positive int, got {max_points!r}", field="max_points")
    valid = np.isfinite(depth_m) & (depth_m > 0)
    stride = _stride(valid, max_points)
    rows, cols = np.nonzero(valid[::stride, ::stride])
    rows, cols = rows * stride, cols * stride
    z = depth_m[rows, cols].astype(np.float64)
    xyz = np.stack([(cols - K[0, 2]) * z / K[0, 0], (rows - K[1, 2]) * z / K[1, 1], z], axis=1).astype(np.float32)
    none = np.zeros(len(rows), bool)
    return PointCloud(
        xyz=xyz,
        rgb=rgb[rows, cols].copy(),
        pixels=np.stack([rows, cols], axis=1).astype(np.int32),
        truth=truth[rows, cols] if truth is not None else none,
        predicted=(probability[rows, cols] >= threshold) if probability is not None else none.copy(),
        stride=stride,
    )


def _stride(valid: np.ndarray, max_points: int) -> int:
    """The smallest grid step keeping at most ``max_points`` valid pixels."""
    stride = max(1, math.floor(math.sqrt(valid.sum() / max_points)))
    while valid[::stride, ::stride].sum() > max_points:
        stride += 1
    return stride


def marked_colors(cloud: PointCloud) -> np.ndarray:
    """The points' colours with the labelled (green), predicted (red) and both (yellow) blended in, uint8 ``(N, 3)``."""
    out = cloud.rgb.astype(np.float32)
    for mask, key in ((cloud.truth & ~cloud.predicted, "truth"), (cloud.predicted & ~cloud.truth, "predicted"),
                      (cloud.truth & cloud.predicted, "both")):
        out[mask] = (1 - MARK_ALPHA) * out[mask] + MARK_ALPHA * np.array(MARK_COLORS[key], np.float32)
    return np.clip(np.round(out), 0, 255).astype(np.uint8)


def write_ply(path: str | Path, cloud: PointCloud, *, comments: tuple[str, ...] = ()) -> None:
    """Write the cloud as a binary PLY (atomically): x, y, z, red, green, blue (marked), truth, predicted.

    Args:
        path: The ``.ply`` file.
        cloud: The points.
        comments: Header comments (the frame, the prediction, the threshold).
    """
    from plyfile import PlyData, PlyElement

    colors = marked_colors(cloud)
    vertex = np.empty(len(cloud), dtype=[("x", "f4"), ("y", "f4"), ("z", "f4"), ("red", "u1"), ("green", "u1"),
                                          ("blue", "u1"), ("truth", "u1"), ("predicted", "u1")])
    for i, axis in enumerate("xyz"):
        vertex[axis] = cloud.xyz[:, i]
    for i, channel in enumerate(("red", "green", "blue")):
        vertex[channel] = colors[:, i]
    vertex["truth"], vertex["predicted"] = cloud.truth, cloud.predicted
    data = PlyData([PlyElement.describe(vertex, "vertex")], text=False, byte_order="<", comments=list(comments))
    write_atomic(path, data.write)


def encode_points(cloud: PointCloud) -> bytes:
    """The cloud for the browser: ``b"EGP1"``, uint32 N, N x 3 float32 xyz, N x 4 uint8 (r, g, b, flags).

    Little-endian; flags bit 0 = labelled, bit 1 = predicted; the colours are
    the frame's own (the page marks the points itself).
    """
    flags = cloud.truth.astype(np.uint8) | (cloud.predicted.astype(np.uint8) << 1)
    rgba = np.concatenate([cloud.rgb, flags[:, None]], axis=1).astype(np.uint8)
    return POINTS_MAGIC + struct.pack("<I", len(cloud)) + cloud.xyz.astype("<f4").tobytes() + rgba.tobytes()
