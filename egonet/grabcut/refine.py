"""Full-resolution refinement: the low-resolution cut brought back to the frame.

A fast guided filter (He & Sun 2015): its local linear coefficients are fitted
between the low-resolution image and label, upsampled, and applied to the
full-resolution colours, only in a narrow band along the boundary, so the edge
follows the image at full resolution. ``_Guide`` holds the ROI at low
resolution (the graph cut's image too) with the parts of the filter that do
not depend on the label.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import weakref

import cv2
import numpy as np

from egonet.grabcut.geometry import _Geometry
from egonet.grabcut.graph import _links
from egonet.grabcut.strokes import _polyline_distance_mask, _Stroke

_GF_RADIUS = 4  # guided-filter window radius, low-resolution pixels
_GF_EPS = 2e-4  # guided-filter regulariser, colours in [0, 1]
_BAND = 2  # refined band: low-resolution pixels this close to the boundary


@dataclasses.dataclass(frozen=True, eq=False)
class _Guide:
    """The ROI at low resolution, with the image-only parts of the guided filter.

    The window means and covariances of the colours do not depend on the
    label, so they are computed once per ROI and every stroke reuses them.

    Attributes:
        geom: The geometry this guide belongs to.
        image: uint8 ``(low_h, low_w, 3)``, the ROI scaled with area averaging.
        colour: float32 ``(low_h, low_w, 3)``, ``image`` in [0, 1].
        mean: float32 ``(low_h, low_w, 3)``, window mean of ``colour``.
        inverse: float32 ``(low_h, low_w, 6)``, the inverse of the window colour
            covariance plus ``eps``: entries rr, rg, rb, gg, gb, bb.
    """

    geom: _Geometry
    image: np.ndarray
    colour: np.ndarray
    mean: np.ndarray
    inverse: np.ndarray
    _footprints: weakref.WeakKeyDictionary = dataclasses.field(default_factory=weakref.WeakKeyDictionary)

    @functools.cached_property
    def pixels(self) -> np.ndarray:
        """float32 ``(low_h * low_w, 3)``: ``image``'s colours, flat (the colour cut's samples)."""
        return self.image.reshape(-1, 3).astype(np.float32)

    @functools.cached_property
    def links(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The colour cut's pairwise links of ``image`` (``graph._links``), made on first use."""
        return _links(self.image)

    def footprint(self, stroke: _Stroke) -> tuple[np.ndarray, tuple[int, int]] | None:
        """The stroke's pixels on the low-resolution grid (cached), or None.

        The radius is scaled to the grid but covers at least the nearest
        low-resolution pixel of every point (0.71 > sqrt(2) / 2).
        """
        if stroke not in self._footprints:
            geom = self.geom
            radius = max(stroke.radius * 0.5 * (geom.sx + geom.sy), 0.71)
            self._footprints[stroke] = _polyline_distance_mask((geom.low_h, geom.low_w),
                                                               geom.to_low(stroke.points), radius)
        return self._footprints[stroke]

    @classmethod
    def build(cls, geom: _Geometry, frame: np.ndarray) -> _Guide:
        rx0, ry0, rx1, ry1 = geom.roi
        crop = frame[ry0:ry1, rx0:rx1]
        if (geom.low_w, geom.low_h) == (geom.roi_w, geom.roi_h):
            image = np.ascontiguousarray(crop)
        else:
            image = cv2.resize(crop, (geom.low_w, geom.low_h), interpolation=cv2.INTER_AREA)
        colour = image.astype(np.float32) * (1 / 255)
        r, g, b = colour[..., 0], colour[..., 1], colour[..., 2]
        m = _box_mean(np.dstack([colour, r * r, r * g, r * b, g * g, g * b, b * b]))
        mr, mg, mb = m[..., 0], m[..., 1], m[..., 2]
        vrr = m[..., 3] - mr * mr + _GF_EPS
        vrg = m[..., 4] - mr * mg
        vrb = m[..., 5] - mr * mb
        vgg = m[..., 6] - mg * mg + _GF_EPS
        vgb = m[..., 7] - mg * mb
        vbb = m[..., 8] - mb * mb + _GF_EPS
        # Inverse of the symmetric 3x3 covariance via its adjugate.
        adj = np.stack([vgg * vbb - vgb * vgb, vgb * vrb - vrg * vbb, vrg * vgb - vgg * vrb,
                        vrr * vbb - vrb * vrb, vrb * vrg - vrr * vgb, vrr * vgg - vrg * vrg], axis=-1)
        det = vrr * adj[..., 0] + vrg * adj[..., 1] + vrb * adj[..., 2]
        return cls(geom, image, colour, np.ascontiguousarray(m[..., :3]), adj / det[..., None])


def _box_mean(x: np.ndarray) -> np.ndarray:
    size = 2 * _GF_RADIUS + 1
    return cv2.blur(x, (size, size), borderType=cv2.BORDER_REFLECT)


def _guided_coefficients(guide: _Guide, label: np.ndarray, rows: slice, cols: slice) -> np.ndarray:
    """Window-mean guided-filter coefficients ``(h, w, 4)``: a (3 colours), b.

    Args:
        guide: The low-resolution guide.
        label: float32 ``(h, w)``, the label over ``guide[rows, cols]``.
        rows: Rows of the guide the label covers.
        cols: Columns of the guide the label covers.
    """
    colour = guide.colour[rows, cols]
    m = _box_mean(np.dstack([label[..., None], colour * label[..., None]]))
    mp = m[..., 0]
    mi = guide.mean[rows, cols]
    c = m[..., 1:] - mi * mp[..., None]
    inv = guide.inverse[rows, cols]
    coef = np.empty(label.shape + (4,), np.float32)
    coef[..., 0] = inv[..., 0] * c[..., 0] + inv[..., 1] * c[..., 1] + inv[..., 2] * c[..., 2]
    coef[..., 1] = inv[..., 1] * c[..., 0] + inv[..., 3] * c[..., 1] + inv[..., 4] * c[..., 2]
    coef[..., 2] = inv[..., 2] * c[..., 0] + inv[..., 4] * c[..., 1] + inv[..., 5] * c[..., 2]
    coef[..., 3] = mp - (coef[..., 0] * mi[..., 0] + coef[..., 1] * mi[..., 1] + coef[..., 2] * mi[..., 2])
    return _box_mean(coef)


def _upsample_mask(guide: _Guide, frame: np.ndarray, low: np.ndarray,
                   window: tuple[int, int, int, int] | None = None) -> tuple[np.ndarray, tuple[int, int]]:
    """Bring the low-resolution label back to full resolution over a window.

    Away from the boundary a full-resolution pixel takes the label of its
    nearest low-resolution pixel; in a band along the boundary it takes the
    guided filter's output (upsampled coefficients applied to its own colour)
    thresholded at 0.5.

    Args:
        guide: The low-resolution guide of the session's geometry.
        frame: Full frame, uint8 ``(H, W, 3)``.
        low: Low-resolution label, bool ``(low_h, low_w)``.
        window: Low-resolution pixels ``(r0, r1, c0, c1)`` to redo, or None
            for the whole ROI.

    Returns:
        ``(mask, (y, x))``: the full-resolution bool mask of the window and
        its origin in frame coordinates.
    """
    geom = guide.geom
    lh, lw = low.shape
    r0, r1, c0, c1 = window if window is not None else (0, lh, 0, lw)
    sx, sy = geom.sx, geom.sy
    rx0, ry0 = geom.roi[:2]
    # Full-resolution pixels (ROI coordinates) whose low-res position lies in the window.
    fx0 = max(0, math.floor(c0 / sx))
    fx1 = min(geom.roi_w, math.ceil(c1 / sx))
    fy0 = max(0, math.floor(r0 / sy))
    fy1 = min(geom.roi_h, math.ceil(r1 / sy))
    xs = np.arange(fx0, fx1)
    ys = np.arange(fy0, fy1)
    # Nearest low-res pixel of every full-res pixel (half-pixel centres).
    near_c = np.minimum(((xs + 0.5) * sx).astype(np.intp), lw - 1)
    near_r = np.minimum(((ys + 0.5) * sy).astype(np.intp), lh - 1)
    # Work on the window plus the filter's support so the window is exact.
    pad = 2 * _GF_RADIUS + 2
    rows = slice(max(0, int(near_r[0]) - pad), min(lh, int(near_r[-1]) + pad + 1))
    cols = slice(max(0, int(near_c[0]) - pad), min(lw, int(near_c[-1]) + pad + 1))
    low_u8 = low[rows, cols].view(np.uint8)
    kernel = np.ones((3, 3), np.uint8)
    edge = cv2.dilate(low_u8, kernel) != cv2.erode(low_u8, kernel)
    band_low = cv2.dilate(edge.view(np.uint8), np.ones((2 * _BAND - 1, 2 * _BAND - 1), np.uint8))
    lr = near_r - rows.start
    lc = near_c - cols.start
    out = np.take(np.take(low_u8, lr, 0), lc, 1).view(bool)
    band = np.take(np.take(band_low, lr, 0), lc, 1).view(bool)
    by, bx = np.nonzero(band)
    if len(by):
        coef = _guided_coefficients(guide, low_u8.astype(np.float32), rows, cols)
        ab = _bilinear_at(coef, (xs[bx] + 0.5) * sx - 0.5 - cols.start, (ys[by] + 0.5) * sy - 0.5 - rows.start)
        colours = frame[ry0 + fy0 + by, rx0 + fx0 + bx].astype(np.float32) * (1 / 255)
        q = (ab[:, :3] * colours).sum(axis=1) + ab[:, 3]
        out[by, bx] = q > 0.5
    return out, (ry0 + fy0, rx0 + fx0)


def _bilinear_at(coef: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Bilinear samples ``(n, 4)`` of ``coef`` at the points ``(u[k], v[k])`` (grid coordinates).

    ``cv2.remap`` does the sampling, with the points laid out as rows of 512
    (remap wants fewer than 32767 rows).
    """
    n = len(u)
    uu = np.zeros(-(-n // 512) * 512, np.float32)
    vv = np.zeros_like(uu)
    uu[:n] = u
    vv[:n] = v
    return cv2.remap(coef, uu.reshape(-1, 512), vv.reshape(-1, 512), cv2.INTER_LINEAR,
                     borderMode=cv2.BORDER_REPLICATE).reshape(-1, 4)[:n]
