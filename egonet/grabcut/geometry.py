"""Geometry: box -> region of interest (ROI) -> low-resolution grid.

All of a session's work happens in the ROI, the box plus a margin, scaled so
its long side is at most the session's ``work_size``; this module maps between
the full-resolution frame and that grid, and moves boxes and masks between
them.
"""

from __future__ import annotations

import dataclasses
import math

import cv2
import numpy as np

_MARGIN = 0.15  # ROI margin around the box, fraction of its long side (at least 16 px)


@dataclasses.dataclass(frozen=True)
class _Geometry:
    """Where the work happens for a box: the ROI and its low-resolution grid.

    Low-resolution pixel ``(i, j)`` covers full-resolution ROI pixels
    ``[j / sx, (j + 1) / sx)`` by ``[i / sy, (i + 1) / sy)`` (area averaging);
    centres map by ``(x + 0.5) * sx - 0.5``.
    """

    box: tuple[int, int, int, int]  # x0, y0, x1, y1 (full resolution, half-open)
    roi: tuple[int, int, int, int]  # x0, y0, x1, y1
    low_w: int
    low_h: int

    @classmethod
    def for_box(cls, box: tuple[int, int, int, int], height: int, width: int, work_size: int) -> _Geometry:
        x0, y0, x1, y1 = box
        # The margin supplies the background samples, like the frame outside
        # the rectangle does for plain grabCut, but local to the object.
        margin = max(16, round(_MARGIN * max(x1 - x0, y1 - y0)))
        roi = (max(0, x0 - margin), max(0, y0 - margin), min(width, x1 + margin), min(height, y1 + margin))
        rw, rh = roi[2] - roi[0], roi[3] - roi[1]
        scale = min(1.0, work_size / max(rw, rh))
        return cls(box, roi, max(1, round(rw * scale)), max(1, round(rh * scale)))

    @property
    def roi_w(self) -> int:
        return self.roi[2] - self.roi[0]

    @property
    def roi_h(self) -> int:
        return self.roi[3] - self.roi[1]

    @property
    def sx(self) -> float:
        return self.low_w / self.roi_w

    @property
    def sy(self) -> float:
        return self.low_h / self.roi_h

    def box_low(self) -> tuple[slice, slice]:
        """Low-resolution pixels whose footprint overlaps the box (rows, cols)."""
        bx0, by0, bx1, by1 = self.box
        rx0, ry0 = self.roi[:2]
        c0 = math.floor((bx0 - rx0) * self.sx)
        c1 = math.ceil((bx1 - rx0) * self.sx)
        r0 = math.floor((by0 - ry0) * self.sy)
        r1 = math.ceil((by1 - ry0) * self.sy)
        return slice(max(r0, 0), min(r1, self.low_h)), slice(max(c0, 0), min(c1, self.low_w))

    def to_low(self, points: np.ndarray) -> np.ndarray:
        """Full-resolution (x, y) -> low-resolution grid coordinates."""
        rx0, ry0 = self.roi[:2]
        return np.stack([(points[:, 0] - rx0 + 0.5) * self.sx - 0.5,
                         (points[:, 1] - ry0 + 0.5) * self.sy - 0.5], axis=1)

    def to_full(self, points: np.ndarray) -> np.ndarray:
        """Low-resolution grid (x, y) -> full-resolution coordinates (``to_low``'s inverse)."""
        rx0, ry0 = self.roi[:2]
        return np.stack([(points[:, 0] + 0.5) / self.sx - 0.5 + rx0,
                         (points[:, 1] + 0.5) / self.sy - 0.5 + ry0], axis=1)


def _grow_box(box: tuple[int, int, int, int], crop: np.ndarray, origin: tuple[int, int], radius: float,
              shape: tuple[int, int]) -> tuple[int, int, int, int]:
    """Grow ``box`` to take in a stroke footprint, with room beyond it.

    Only the sides the footprint crosses move, each to the footprint plus a
    pad of ``max(8, 2 * radius)`` pixels (the object likely goes on there).
    """
    y0, x0 = origin
    y1, x1 = y0 + crop.shape[0], x0 + crop.shape[1]
    pad = max(8, round(2 * radius))
    h, w = shape
    bx0, by0, bx1, by1 = box
    return (max(0, x0 - pad) if x0 < bx0 else bx0, max(0, y0 - pad) if y0 < by0 else by0,
            min(w, x1 + pad) if x1 > bx1 else bx1, min(h, y1 + pad) if y1 > by1 else by1)

def _downsample(mask: np.ndarray, geom: _Geometry) -> np.ndarray:
    """The full-resolution mask on the low-resolution grid of ``geom``."""
    rx0, ry0, rx1, ry1 = geom.roi
    crop = mask[ry0:ry1, rx0:rx1].astype(np.float32)
    return cv2.resize(crop, (geom.low_w, geom.low_h), interpolation=cv2.INTER_AREA) > 0.5


def _clip_to_box(mask: np.ndarray, box: tuple[int, int, int, int]) -> None:
    """Clear everything outside ``box`` (as plain grabCut's rectangle does)."""
    x0, y0, x1, y1 = box
    mask[:y0] = False
    mask[y1:] = False
    mask[:, :x0] = False
    mask[:, x1:] = False
