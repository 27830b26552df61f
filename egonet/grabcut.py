"""Interactive GrabCut: a box, corrective strokes, undo, and a resumable state.

``GrabCutSession`` segments one object in one RGB frame the way an annotator
works: a box gives the first mask, each brush stroke ("fg" or "bg") corrects
it, ``undo`` steps back. The session is fast enough to feel interactive on
1280x960 frames and larger, on one CPU core:

* All work happens in a region of interest (ROI): the box plus a margin. The
  graph cut runs on the ROI scaled so its long side is ``work_size`` pixels
  (``cv2.grabCut`` in ``GC_EVAL`` mode, with colour models that the session
  keeps between calls, so a stroke costs one re-estimation and one cut).
* The low-resolution label is brought back to full resolution with a fast
  guided filter (He & Sun 2015): its local linear coefficients are fitted
  between the low-resolution image and label, upsampled, and applied to the
  full-resolution colours, only in a narrow band along the boundary, so the
  edge follows the image at full resolution.
* After a stroke only the part of the ROI whose low-resolution label changed is
  brought back again; the rest of the full-resolution mask is kept.
* Strokes are hard constraints: pixels under a foreground stroke are in the
  returned mask and pixels under a background stroke are out, exactly. A
  stroke changes the mask only its own way (a foreground stroke only adds
  pixels, a background stroke only removes them).

Pixel conventions: points are ``(x, y)`` with ``x`` the column and ``y`` the
row, in full-resolution pixel units, and pixel ``(x, y)`` sits at integer
coordinates. A box ``(x0, y0, x1, y1)`` covers columns ``x0 <= x < x1`` and
rows ``y0 <= y < y1`` (slice convention). A stroke covers the pixels whose
distance to its polyline is at most ``radius`` (see ``stroke_footprint``).

Example:
    >>> import numpy as np
    >>> image = np.zeros((120, 160, 3), np.uint8)
    >>> image[...] = (40, 120, 40)
    >>> image[40:80, 50:110] = (200, 60, 60)
    >>> session = GrabCutSession(image)
    >>> mask = session.box(40, 30, 120, 90)
    >>> bool(mask[60, 80]), bool(mask[10, 10])
    (True, False)
    >>> mask = session.stroke([(80, 60)], "bg", 3)
    >>> bool(mask[60, 80])
    False
    >>> bool(session.undo()[60, 80])
    True
"""

from __future__ import annotations

import dataclasses
import math
import weakref
from collections.abc import Mapping, Sequence

import cv2
import numpy as np

from egonet.errors import EgonetError

__all__ = ["GrabCutSession", "stroke_footprint", "LABELS", "STATE_FORMAT"]

#: Stroke labels accepted by ``GrabCutSession.stroke``.
LABELS = ("fg", "bg")
#: The ``format`` entry of ``GrabCutSession.state()``.
STATE_FORMAT = "egonet.grabcut/1"

_COMPONENTS = 5  # OpenCV's grabCut uses 5 Gaussians per colour model
_MODEL_SIZE = 13 * _COMPONENTS  # weights (5), means (5x3), covariances (5x3x3)
_BOX_ITERATIONS = 5  # graph-cut iterations for a new box (as plain GC_INIT_WITH_RECT)
_STROKE_ITERATIONS = 1  # re-estimation + cut per stroke
_CONVERGED = 0.005  # stop iterating when a cut changes at most this fraction of undecided pixels
_SAMPLES = 4000  # pixels per class for the initial k-means
_SPARSE = 0.25  # a box whose first cut keeps less than this fraction of it is cut again (``_rescue``)
_OUTSIDE_SAMPLES = 100_000  # most frame pixels read for the background model of that cut
_GF_RADIUS = 4  # guided-filter window radius, low-resolution pixels
_GF_EPS = 2e-4  # guided-filter regulariser, colours in [0, 1]
_BAND = 2  # refined band: low-resolution pixels this close to the boundary
_MARGIN = 0.15  # ROI margin around the box, fraction of its long side (at least 16 px)


# --------------------------------------------------------------------------
# Strokes


def _polyline_distance_mask(
    shape: tuple[int, int], points: np.ndarray, radius: float
) -> tuple[np.ndarray, tuple[int, int]] | None:
    """Pixels within ``radius`` of a polyline, as a crop and its origin.

    Args:
        shape: ``(H, W)`` of the pixel grid.
        points: ``(K, 2)`` float ``(x, y)`` in grid coordinates.
        radius: Distance in grid pixels.

    Returns:
        ``(crop, (y0, x0))`` with ``crop`` a bool array placed at ``(y0, x0)``,
        or ``None`` when no pixel of the grid is covered.
    """
    h, w = shape
    lo = np.floor(points.min(axis=0) - radius).astype(int)
    hi = np.ceil(points.max(axis=0) + radius).astype(int) + 1
    x0, y0 = max(int(lo[0]), 0), max(int(lo[1]), 0)
    x1, y1 = min(int(hi[0]), w), min(int(hi[1]), h)
    if x0 >= x1 or y0 >= y1:
        return None
    crop = np.zeros((y1 - y0, x1 - x0), bool)
    r2 = radius * radius
    segments = [(points[0], points[0])] if len(points) == 1 else zip(points[:-1], points[1:])
    for a, b in segments:
        # Each segment only touches its own bounding box (plus the radius).
        sx0 = max(int(math.floor(min(a[0], b[0]) - radius)), x0)
        sy0 = max(int(math.floor(min(a[1], b[1]) - radius)), y0)
        sx1 = min(int(math.ceil(max(a[0], b[0]) + radius)) + 1, x1)
        sy1 = min(int(math.ceil(max(a[1], b[1]) + radius)) + 1, y1)
        if sx0 >= sx1 or sy0 >= sy1:
            continue
        xs = np.arange(sx0, sx1, dtype=np.float64)[None, :] - a[0]
        ys = np.arange(sy0, sy1, dtype=np.float64)[:, None] - a[1]
        d = b - a
        dd = float(d @ d)
        if dd > 0:
            t = np.clip((xs * d[0] + ys * d[1]) / dd, 0.0, 1.0)
            dist2 = (xs - t * d[0]) ** 2 + (ys - t * d[1]) ** 2
        else:
            dist2 = xs**2 + ys**2
        crop[sy0 - y0 : sy1 - y0, sx0 - x0 : sx1 - x0] |= dist2 <= r2
    if not crop.any():
        return None
    return crop, (y0, x0)


def _check_points(points: object, name: str = "points") -> np.ndarray:
    try:
        arr = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise EgonetError(f"{name}: expected a list of (x, y) pairs, got {points!r:.80}", field=name) from exc
    if arr.ndim == 1 and arr.size == 2:
        arr = arr[None, :]
    if arr.ndim != 2 or arr.shape[1] != 2:
        raise EgonetError(f"{name}: expected a list of (x, y) pairs, got shape {arr.shape}", field=name)
    if len(arr) == 0:
        raise EgonetError(f"{name}: a stroke needs at least one (x, y) point", field=name)
    if not np.isfinite(arr).all():
        raise EgonetError(f"{name}: coordinates must be finite numbers", field=name)
    return arr


def _check_radius(radius: object) -> float:
    if isinstance(radius, bool) or not isinstance(radius, (int, float, np.integer, np.floating)):
        raise EgonetError(f"radius: expected a number of pixels, got {radius!r}", field="radius")
    r = float(radius)
    if not math.isfinite(r) or r <= 0:
        raise EgonetError(f"radius: must be a positive number of pixels, got {radius!r}", field="radius")
    return r


def stroke_footprint(shape: tuple[int, int], points: Sequence[Sequence[float]] | np.ndarray,
                     radius: float) -> np.ndarray:
    """The pixels a brush stroke covers.

    A pixel ``(x, y)`` (column ``x``, row ``y``, at integer coordinates) is
    covered when its distance to the polyline through ``points`` is at most
    ``radius``. One point gives a disk.

    Args:
        shape: ``(H, W)`` of the frame.
        points: ``(x, y)`` pixel coordinates of the polyline, at least one.
        radius: Brush radius in pixels, > 0.

    Returns:
        Bool ``(H, W)`` mask of the covered pixels (all False if the stroke
        lies outside the frame).

    Example:
        >>> stroke_footprint((5, 5), [(2, 2)], 1).astype(int).tolist()[1:4]
        [[0, 0, 1, 0, 0], [0, 1, 1, 1, 0], [0, 0, 1, 0, 0]]
    """
    if len(shape) != 2 or min(int(shape[0]), int(shape[1])) <= 0:
        raise EgonetError(f"shape: expected (H, W) with H, W > 0, got {shape!r}", field="shape")
    pts = _check_points(points)
    r = _check_radius(radius)
    out = np.zeros((int(shape[0]), int(shape[1])), bool)
    hit = _polyline_distance_mask(out.shape, pts, r)
    if hit is not None:
        crop, (y0, x0) = hit
        out[y0 : y0 + crop.shape[0], x0 : x0 + crop.shape[1]] = crop
    return out


@dataclasses.dataclass(frozen=True, eq=False)
class _Stroke:
    """One stroke as given (compared and hashed by identity: undo levels share them)."""

    points: np.ndarray  # (K, 2) float64, (x, y) full resolution
    fg: bool
    radius: float


# --------------------------------------------------------------------------
# Geometry: box -> region of interest -> low-resolution grid


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


# --------------------------------------------------------------------------
# Colour models


def _kmeans_labels(x: np.ndarray, k: int, rng: np.random.Generator, iterations: int = 10) -> np.ndarray:
    """k-means++ then Lloyd iterations on ``(N, 3)`` samples; returns labels."""
    centres = [x[rng.integers(len(x))]]
    d2 = ((x - centres[0]) ** 2).sum(axis=1)
    for _ in range(1, k):
        total = d2.sum()
        if total <= 0:
            break
        centres.append(x[rng.choice(len(x), p=d2 / total)])
        d2 = np.minimum(d2, ((x - centres[-1]) ** 2).sum(axis=1))
    c = np.array(centres)
    labels = np.full(len(x), -1, np.intp)
    for _ in range(iterations):
        new = ((x[:, None, :] - c[None, :, :]) ** 2).sum(axis=2).argmin(axis=1)
        if np.array_equal(new, labels):
            break
        labels = new
        for j in range(len(c)):
            members = x[labels == j]
            if len(members):
                c[j] = members.mean(axis=0)
    return labels


def _fit_model(pixels: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """A 5-component colour GMM in OpenCV grabCut's (1, 65) layout."""
    if len(pixels) > _SAMPLES:
        pixels = pixels[rng.choice(len(pixels), _SAMPLES, replace=False)]
    x = pixels.astype(np.float64)
    labels = _kmeans_labels(x, min(_COMPONENTS, len(x)), rng)
    weights = np.zeros(_COMPONENTS)
    means = np.zeros((_COMPONENTS, 3))
    covs = np.zeros((_COMPONENTS, 3, 3))
    for j in range(_COMPONENTS):
        members = x[labels == j]
        if len(members) == 0:
            covs[j] = np.eye(3)
            continue
        weights[j] = len(members) / len(x)
        means[j] = members.mean(axis=0)
        centred = members - means[j]
        covs[j] = centred.T @ centred / len(members) + 0.01 * np.eye(3)
    return np.concatenate([weights, means.ravel(), covs.ravel()])[None, :]


def _first_models(image: np.ndarray, gc: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """``(2, 65)`` background and foreground models of a box's first cut, from
    its ``GC_BGD`` and ``GC_PR_FGD`` pixels."""
    pixels = image.reshape(-1, 3)
    flat = gc.ravel()
    return np.concatenate([_fit_model(pixels[flat == cv2.GC_BGD], rng), _fit_model(pixels[flat == cv2.GC_PR_FGD], rng)])


# --------------------------------------------------------------------------
# Full-resolution refinement (fast guided filter, band only)


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
        # Bilinear coefficients at the band pixels: remap with the band laid
        # out as rows of 512 (remap wants fewer than 32767 rows).
        n = len(by)
        u = np.zeros(-(-n // 512) * 512, np.float32)
        v = np.zeros_like(u)
        u[:n] = (xs[bx] + 0.5) * sx - 0.5 - cols.start
        v[:n] = (ys[by] + 0.5) * sy - 0.5 - rows.start
        ab = cv2.remap(coef, u.reshape(-1, 512), v.reshape(-1, 512), cv2.INTER_LINEAR,
                       borderMode=cv2.BORDER_REPLICATE).reshape(-1, 4)[:n]
        colours = frame[ry0 + fy0 + by, rx0 + fx0 + bx].astype(np.float32) * (1 / 255)
        q = (ab[:, :3] * colours).sum(axis=1) + ab[:, 3]
        out[by, bx] = q > 0.5
    return out, (ry0 + fy0, rx0 + fx0)


# --------------------------------------------------------------------------
# Session


@dataclasses.dataclass(frozen=True, eq=False)
class _Snapshot:
    """Everything that defines the session at one undo level."""

    box: tuple[int, int, int, int] | None = None
    strokes: tuple[_Stroke, ...] = ()
    models: np.ndarray | None = None  # (2, 65) float64: background, foreground
    low: np.ndarray | None = None  # (low_h, low_w) bool, the low-resolution cut
    mask_bits: np.ndarray | None = None  # packed bits of the mask inside the box (outside is False)


def _check_image(image: object) -> np.ndarray:
    if not isinstance(image, np.ndarray):
        raise EgonetError(f"image: expected a numpy array, got {type(image).__name__}", field="image")
    if image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] != 3:
        raise EgonetError(f"image: expected RGB uint8 of shape (H, W, 3), got {image.dtype} {image.shape}", field="image")
    if image.shape[0] < 2 or image.shape[1] < 2:
        raise EgonetError(f"image: needs at least 2x2 pixels, got {image.shape[1]}x{image.shape[0]}", field="image")
    return np.ascontiguousarray(image).copy()


def _as_int(value: object, name: str) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise EgonetError(f"{name}: expected a number, got {value!r}", field=name)
    if not math.isfinite(float(value)):
        raise EgonetError(f"{name}: must be finite, got {value!r}", field=name)
    return int(round(float(value)))


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


def _cut(image: np.ndarray, gc: np.ndarray, models: np.ndarray, iterations: int) -> tuple[np.ndarray, np.ndarray]:
    """Run the graph cut on the low-resolution ROI.

    Each iteration re-estimates the colour models from the current labels
    (starting from ``models``, so their components carry over) and cuts.
    Stops early once an iteration changes at most ``_CONVERGED`` of the
    undecided pixels: later iterations only nudge the boundary.

    Args:
        image: uint8 ``(h, w, 3)`` low-resolution ROI.
        gc: uint8 ``(h, w)`` OpenCV GC_* labels; updated in place.
        models: ``(2, 65)`` background and foreground models.
        iterations: Most iterations to run.

    Returns:
        ``(label, models)``: the bool foreground label and the new models.
    """
    bgd = models[0:1].copy()
    fgd = models[1:2].copy()
    undecided = max(1, np.count_nonzero(gc >= cv2.GC_PR_BGD))
    for _ in range(iterations):
        is_fg = (gc & 1).astype(bool)
        # Re-estimating a model from no pixels is undefined (OpenCV asserts),
        # so the models stay fixed when one side is empty.
        mode = cv2.GC_EVAL if is_fg.any() and not is_fg.all() else cv2.GC_EVAL_FREEZE_MODEL
        cv2.grabCut(image, gc, None, bgd, fgd, 1, mode)
        if mode != cv2.GC_EVAL or np.count_nonzero(is_fg != (gc & 1)) <= _CONVERGED * undecided:
            break
    return (gc & 1).astype(bool), np.concatenate([bgd, fgd])


class GrabCutSession:
    """Interactive GrabCut segmentation of one object in one RGB frame.

    Args:
        image: RGB uint8 ``(H, W, 3)`` frame at full resolution (copied).
        work_size: Long side, in pixels, of the region of interest when the
            graph cut runs (smaller is faster, coarser before refinement).
        max_undo: Undo levels kept (and serialised by ``state``).

    Raises:
        ValueError: If ``image`` is not RGB uint8 ``(H, W, 3)`` or a setting
            is out of range.

    Example:
        >>> import numpy as np
        >>> image = np.full((90, 120, 3), 30, np.uint8)
        >>> image[30:60, 40:80] = 220
        >>> s = GrabCutSession(image)
        >>> int(s.box(30, 20, 90, 70).sum())
        1200
    """

    def __init__(self, image: np.ndarray, *, work_size: int = 272, max_undo: int = 20) -> None:
        self._image = _check_image(image)
        if isinstance(work_size, bool) or not isinstance(work_size, (int, np.integer)) or work_size < 32:
            raise EgonetError(f"work_size: expected an integer >= 32, got {work_size!r}", field="work_size")
        if isinstance(max_undo, bool) or not isinstance(max_undo, (int, np.integer)) or max_undo < 0:
            raise EgonetError(f"max_undo: expected an integer >= 0, got {max_undo!r}", field="max_undo")
        self._work_size = int(work_size)
        self._max_undo = int(max_undo)
        self._history: list[_Snapshot] = []
        self._now = _Snapshot()
        self._mask = np.zeros(self._image.shape[:2], bool)
        self._guide: _Guide | None = None
        # Full-resolution stroke footprints: (crop, origin), per stroke.
        self._footprints: weakref.WeakKeyDictionary[_Stroke, tuple[np.ndarray, tuple[int, int]] | None] = (
            weakref.WeakKeyDictionary())

    # ---------------------------------------------------------------- public

    @property
    def shape(self) -> tuple[int, int]:
        """``(H, W)`` of the frame."""
        return self._mask.shape  # type: ignore[return-value]

    @property
    def mask(self) -> np.ndarray:
        """The current bool ``(H, W)`` mask (a copy)."""
        return self._mask.copy()

    @property
    def box_coords(self) -> tuple[int, int, int, int] | None:
        """The current box ``(x0, y0, x1, y1)``, or None before ``box``."""
        return self._now.box

    @property
    def can_undo(self) -> bool:
        """Whether ``undo`` has a previous state to restore."""
        return bool(self._history)

    @property
    def strokes(self) -> list[tuple[np.ndarray, str, float]]:
        """The current object's strokes since its box, oldest first: ``(points (K, 2), label, radius)``."""
        return [(s.points.copy(), "fg" if s.fg else "bg", s.radius) for s in self._now.strokes]

    @property
    def nbytes(self) -> int:
        """Bytes held in the session's arrays: the frame's copy, the mask, the
        ROI's guide, the undo levels and the cached stroke footprints."""
        arrays = [self._image, self._mask]
        if self._guide is not None:
            g = self._guide
            arrays += [g.image, g.colour, g.mean, g.inverse]
            arrays += [hit[0] for hit in g._footprints.values() if hit is not None]
        for snap in self._history + [self._now]:
            arrays += [snap.models, snap.low, snap.mask_bits] + [s.points for s in snap.strokes]
        arrays += [hit[0] for hit in self._footprints.values() if hit is not None]
        unique = {id(a): a.nbytes for a in arrays if a is not None}  # undo levels share their strokes
        return sum(unique.values())

    def box(self, x0: float, y0: float, x1: float, y1: float) -> np.ndarray:
        """Start a new object from a box and return its first mask.

        Clears the strokes and colour models of the previous object (``undo``
        brings them back). Coordinates are rounded to whole pixels.

        Args:
            x0: Left column (inclusive).
            y0: Top row (inclusive).
            x1: Right column (exclusive), ``x0 < x1 <= W``.
            y1: Bottom row (exclusive), ``y0 < y1 <= H``.

        Returns:
            Bool ``(H, W)`` mask; nothing outside the box is selected.

        Raises:
            ValueError: If the box is empty or not inside the frame (clip it
                to the frame first), or leaves no background around it.
        """
        h, w = self.shape
        bx0, by0 = _as_int(x0, "x0"), _as_int(y0, "y0")
        bx1, by1 = _as_int(x1, "x1"), _as_int(y1, "y1")
        if not (0 <= bx0 < bx1 <= w and 0 <= by0 < by1 <= h):
            raise EgonetError(
                f"box: ({bx0}, {by0}, {bx1}, {by1}) must satisfy 0 <= x0 < x1 <= {w} and "
                f"0 <= y0 < y1 <= {h} (clip it to the {w}x{h} frame and keep it non-empty)", field="box"
            )
        box = (bx0, by0, bx1, by1)
        guide = self._guide_for(box)
        rows, cols = guide.geom.box_low()
        gc = np.full((guide.geom.low_h, guide.geom.low_w), cv2.GC_BGD, np.uint8)
        gc[rows, cols] = cv2.GC_PR_FGD
        if not (gc == cv2.GC_BGD).any():
            raise EgonetError("box: leaves no background in the frame around it; draw a tighter box", field="box")
        # Initial colour models from k-means on a fixed-seed sample of each side
        # (plain grabCut runs k-means on every pixel, which is most of its cost).
        initial = _first_models(guide.image, gc, np.random.default_rng(0))
        start = gc.copy()
        low, models = _cut(guide.image, gc, initial, _BOX_ITERATIONS)
        if low[rows, cols].mean() < _SPARSE:
            low, models = self._rescue(box, guide, start, initial, low, models)
        snap = _Snapshot(box=box, strokes=(), models=models, low=low)
        self._commit(guide, snap, self._full_mask(guide, snap))
        return self.mask

    def stroke(self, points: Sequence[Sequence[float]] | np.ndarray, label: str, radius: float) -> np.ndarray:
        """Add a corrective brush stroke and return the updated mask.

        Pixels under a ``"fg"`` stroke are in the returned mask, pixels under a
        ``"bg"`` stroke are out, exactly (later strokes win where strokes
        overlap). The colour models are re-estimated with the stroke, so
        similar pixels elsewhere can follow it, but only in the stroke's
        direction: a foreground stroke never removes pixels from the mask and
        a background stroke never adds any. (Without that rule, re-estimating
        the models can drop an unrelated part far from the stroke, such as a
        thin part of the object the low-resolution cut finds costly.) A
        foreground stroke that reaches outside the box grows the box to take
        it in.

        Args:
            points: ``(x, y)`` pixel coordinates of the polyline, at least one
                (one point paints a disk).
            label: ``"fg"`` (object) or ``"bg"`` (background).
            radius: Brush radius in pixels, > 0.

        Returns:
            Bool ``(H, W)`` mask.

        Raises:
            ValueError: If there is no box yet, or ``points``, ``label`` or
                ``radius`` is invalid, or the stroke misses the frame.
        """
        prev = self._now
        if prev.box is None:
            raise EgonetError("box: stroke() needs an object first; call box(x0, y0, x1, y1)", field="box")
        pts = _check_points(points)
        if label not in LABELS:
            raise EgonetError(f"label: expected one of {LABELS}, got {label!r}", field="label")
        r = _check_radius(radius)
        footprint = _polyline_distance_mask(self.shape, pts, r)
        if footprint is None:
            raise EgonetError(f"points: the stroke covers no pixel of the {self.shape[1]}x{self.shape[0]} frame", field="points")
        new = _Stroke(pts, label == "fg", r)
        self._footprints[new] = footprint
        strokes = prev.strokes + (new,)
        box = _grow_box(prev.box, *footprint, r, self.shape) if new.fg else prev.box
        guide = self._guide_for(box)
        if box != prev.box:
            # A new ROI: start the cut from the current mask, keep the models.
            prior = _downsample(self._mask, guide.geom)
            snap = self._recut(guide, prev.models, box, strokes, prior)
            # Both masks honour every stroke, so their union does too.
            self._commit(guide, snap, self._mask | self._full_mask(guide, snap))
            return self.mask
        snap = self._recut(guide, prev.models, box, strokes, prev.low)
        mask = self._mask.copy()
        changed = np.nonzero(snap.low != prev.low)
        if len(changed[0]):
            # Only the part of the ROI whose low-resolution label changed (plus
            # the filter's reach) is brought back to full resolution again.
            geom = guide.geom
            d = 2 * _GF_RADIUS + _BAND + 2
            window = (max(0, int(changed[0].min()) - d), min(geom.low_h, int(changed[0].max()) + d + 1),
                      max(0, int(changed[1].min()) - d), min(geom.low_w, int(changed[1].max()) + d + 1))
            part, (oy, ox) = _upsample_mask(guide, self._image, snap.low, window)
            view = mask[oy : oy + part.shape[0], ox : ox + part.shape[1]]
            if new.fg:
                x0, y0, x1, y1 = box
                view[max(0, y0 - oy) : max(0, y1 - oy), max(0, x0 - ox) : max(0, x1 - ox)] |= (
                    part[max(0, y0 - oy) : max(0, y1 - oy), max(0, x0 - ox) : max(0, x1 - ox)])
            else:
                view &= part
        self._apply_strokes(mask, strokes)
        self._commit(guide, snap, mask)
        return self.mask

    def undo(self) -> np.ndarray:
        """Restore the previous mask and state, and return the mask.

        Raises:
            RuntimeError: If there is nothing to undo (see ``can_undo``).
        """
        if not self._history:
            raise RuntimeError("undo: nothing to undo")
        self._restore(self._history.pop())
        return self.mask

    def state(self) -> dict[str, np.ndarray | int | float | str]:
        """A small, serialisable description of the session (undo levels too).

        Every value is a numpy array, int, float or str, so the dict can go
        through ``np.savez`` (or a database blob) and back into
        ``from_state``. The image itself is not included.

        Returns:
            Dict with ``format``, the frame size, the settings, and per undo
            level (oldest first, the current one last) the box, the strokes,
            the two colour models (OpenCV grabCut's bgdModel/fgdModel layout),
            the low-resolution cut (packed bits) and the mask inside the box
            (run lengths, row-major, starting with a background run).
        """
        levels = self._history + [self._now]
        n = len(levels)
        boxes = np.full((n, 4), -1, np.int64)
        models = np.zeros((n, 2, _MODEL_SIZE), np.float64)
        low_shape = np.zeros((n, 2), np.int64)
        low_bits: list[np.ndarray] = []
        runs: list[np.ndarray] = []
        index: dict[_Stroke, int] = {}  # strokes shared between levels are stored once
        level_strokes: list[int] = []
        level_offsets = [0]
        for i, snap in enumerate(levels):
            if snap.box is not None:
                boxes[i] = snap.box
                models[i] = snap.models
                low_shape[i] = snap.low.shape
                low_bits.append(np.packbits(snap.low, axis=None))
                runs.append(_rle_encode(self._unpack(snap)))
            else:
                low_bits.append(np.zeros(0, np.uint8))
                runs.append(np.zeros(0, np.uint32))
            level_strokes.extend(index.setdefault(s, len(index)) for s in snap.strokes)
            level_offsets.append(len(level_strokes))
        table = list(index)
        return {
            "format": STATE_FORMAT,
            "height": int(self.shape[0]),
            "width": int(self.shape[1]),
            "work_size": self._work_size,
            "max_undo": self._max_undo,
            "box": boxes,
            "models": models,
            "low_shape": low_shape,
            "low_bits": np.concatenate(low_bits),
            "low_offsets": _offsets(low_bits),
            "mask_rle": np.concatenate(runs),
            "mask_offsets": _offsets(runs),
            "stroke_points": np.concatenate([s.points for s in table]) if table else np.zeros((0, 2)),
            "stroke_point_offsets": _offsets([s.points for s in table]),
            "stroke_fg": np.asarray([s.fg for s in table], np.bool_),
            "stroke_radius": np.asarray([s.radius for s in table], np.float64),
            "level_strokes": np.asarray(level_strokes, np.int64),
            "level_stroke_offsets": np.asarray(level_offsets, np.int64),
        }

    @classmethod
    def from_state(cls, image: np.ndarray, state: Mapping[str, object]) -> GrabCutSession:
        """Resume a session from ``state()`` and the same image.

        Args:
            image: The RGB uint8 ``(H, W, 3)`` frame the state was made on.
            state: A dict from ``state()``, possibly after ``np.savez`` and
                ``np.load`` (0-d arrays are accepted for the scalars).

        Returns:
            A session that continues exactly where the saved one stopped,
            undo levels included.

        Raises:
            ValueError: If ``image`` is invalid, or ``state`` is malformed or
                was made on a frame of another size.

        Example:
            >>> import numpy as np
            >>> image = np.full((90, 120, 3), 30, np.uint8)
            >>> image[30:60, 40:80] = 220
            >>> s = GrabCutSession(image)
            >>> _ = s.box(30, 20, 90, 70)
            >>> t = GrabCutSession.from_state(image, s.state())
            >>> bool((t.stroke([(50, 40)], "bg", 4) == s.stroke([(50, 40)], "bg", 4)).all())
            True
        """
        _check_image(image)
        if not isinstance(state, Mapping):
            raise EgonetError(f"state: expected the dict from GrabCutSession.state(), got {type(state).__name__}", field="state")
        try:
            return cls._from_state(image, state)
        except (KeyError, IndexError, TypeError, ValueError) as exc:
            if str(exc).startswith("state:"):
                raise
            raise EgonetError(f"state: malformed GrabCut session state ({type(exc).__name__}: {exc})", field="state") from exc

    @classmethod
    def _from_state(cls, image: np.ndarray, state: Mapping[str, object]) -> GrabCutSession:
        def scalar(key: str) -> object:
            return np.asarray(state[key]).item()

        if scalar("format") != STATE_FORMAT:
            raise EgonetError(f"state: format {scalar('format')!r} is not {STATE_FORMAT!r}", field="state")
        session = cls(image, work_size=int(scalar("work_size")), max_undo=int(scalar("max_undo")))
        h, w = session.shape
        if (int(scalar("height")), int(scalar("width"))) != (h, w):
            raise EgonetError(f"state: made on a {scalar('width')}x{scalar('height')} frame, the image is {w}x{h}", field="state")
        a = {k: np.asarray(state[k]) for k in (
            "box", "models", "low_shape", "low_bits", "low_offsets", "mask_rle", "mask_offsets",
            "stroke_points", "stroke_point_offsets", "stroke_fg", "stroke_radius",
            "level_strokes", "level_stroke_offsets")}
        n = len(a["box"])
        if n < 1 or a["models"].shape != (n, 2, _MODEL_SIZE) or a["low_shape"].shape != (n, 2):
            raise EgonetError("state: its arrays disagree on the number of undo levels", field="state")
        points, p_off = a["stroke_points"].astype(np.float64), a["stroke_point_offsets"]
        strokes = [_Stroke(points[p_off[i] : p_off[i + 1]].copy(), bool(a["stroke_fg"][i]),
                           float(a["stroke_radius"][i])) for i in range(len(p_off) - 1)]
        levels = []
        for i in range(n):
            ids = a["level_strokes"][a["level_stroke_offsets"][i] : a["level_stroke_offsets"][i + 1]]
            snap_strokes = tuple(strokes[j] for j in ids)
            if a["box"][i][0] < 0:
                levels.append(_Snapshot(strokes=snap_strokes))
                continue
            box = tuple(int(v) for v in a["box"][i])
            if not (0 <= box[0] < box[2] <= w and 0 <= box[1] < box[3] <= h):
                raise EgonetError(f"state: box {box} lies outside the {w}x{h} frame", field="state")
            lh, lw = (int(v) for v in a["low_shape"][i])
            bits = a["low_bits"][a["low_offsets"][i] : a["low_offsets"][i + 1]].astype(np.uint8)
            low = np.unpackbits(bits, count=lh * lw).astype(bool).reshape(lh, lw)
            inside = _rle_decode(a["mask_rle"][a["mask_offsets"][i] : a["mask_offsets"][i + 1]],
                                 (box[3] - box[1], box[2] - box[0]))
            levels.append(_Snapshot(box=box, strokes=snap_strokes, models=a["models"][i].astype(np.float64),
                                    low=low, mask_bits=np.packbits(inside, axis=None)))
        session._history = levels[:-1]
        session._restore(levels[-1])
        return session

    # --------------------------------------------------------------- helpers

    def _rescue(self, box: tuple[int, int, int, int], guide: _Guide, start: np.ndarray, initial: np.ndarray,
                low: np.ndarray, models: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Cut a box whose first cut kept little of it again; the cut that keeps most wins.

        That usually happens when the box cuts through an object that goes on
        into the margin: the margin's colours, the background model, then
        include the object's. Plain grabCut takes its background from the whole
        frame outside the box, where that continuation is a small part. So:
        first one cut with such a background model held fixed (and the box's
        first foreground model); if that too keeps little, plain grabCut on the
        whole frame at the work size, brought onto the ROI's grid.
        """
        geom = guide.geom
        rows, cols = geom.box_low()
        h, w = self.shape
        rng = np.random.default_rng(0)
        step = max(1, round(1 / min(geom.sx, geom.sy)), math.ceil(math.sqrt(h * w / _OUTSIDE_SAMPLES)))
        outside = np.ones((h, w), bool)
        outside[box[1] : box[3], box[0] : box[2]] = False
        bgd = _fit_model(self._image[::step, ::step][outside[::step, ::step]], rng)
        fgd = initial[1:2].copy()
        gc = start.copy()
        cv2.grabCut(guide.image, gc, None, bgd, fgd, 1, cv2.GC_EVAL_FREEZE_MODEL)
        candidates = [(low, models), ((gc & 1).astype(bool), np.concatenate([bgd, fgd]))]
        if candidates[1][0][rows, cols].mean() < _SPARSE:
            scale = min(1.0, self._work_size / max(h, w))
            whole = _Geometry(box, (0, 0, w, h), max(1, round(w * scale)), max(1, round(h * scale)))
            image = cv2.resize(self._image, (whole.low_w, whole.low_h), interpolation=cv2.INTER_AREA)
            r, c = whole.box_low()
            gc = np.full((whole.low_h, whole.low_w), cv2.GC_BGD, np.uint8)
            gc[r, c] = cv2.GC_PR_FGD
            if (gc == cv2.GC_BGD).any():  # else the box covers the whole reduced frame
                cut, whole_models = _cut(image, gc, _first_models(image, gc, rng), _BOX_ITERATIONS)
                full = cv2.resize(cut.view(np.uint8), (w, h), interpolation=cv2.INTER_NEAREST)
                rx0, ry0, rx1, ry1 = geom.roi
                share = cv2.resize(full[ry0:ry1, rx0:rx1] * np.uint8(255), (geom.low_w, geom.low_h),
                                   interpolation=cv2.INTER_AREA)
                candidates.append((share >= 128, whole_models))
        return max(candidates, key=lambda c: np.count_nonzero(c[0]))

    def _guide_for(self, box: tuple[int, int, int, int]) -> _Guide:
        """The low-resolution guide of ``box``'s ROI (cached for the current one)."""
        geom = _Geometry.for_box(box, *self.shape, self._work_size)
        if self._guide is not None and self._guide.geom == geom:
            return self._guide
        return _Guide.build(geom, self._image)

    def _recut(self, guide: _Guide, models: np.ndarray, box: tuple[int, int, int, int],
               strokes: tuple[_Stroke, ...], prior: np.ndarray) -> _Snapshot:
        """The snapshot after cutting with ``strokes``, starting from ``prior``."""
        geom = guide.geom
        rows, cols = geom.box_low()
        gc = np.full((geom.low_h, geom.low_w), cv2.GC_BGD, np.uint8)
        gc[rows, cols] = np.where(prior[rows, cols], cv2.GC_PR_FGD, cv2.GC_PR_BGD)
        for s in strokes:
            hit = guide.footprint(s)
            if hit is not None:
                crop, (y0, x0) = hit
                view = gc[y0 : y0 + crop.shape[0], x0 : x0 + crop.shape[1]]
                view[crop] = cv2.GC_FGD if s.fg else cv2.GC_BGD
        low, models = _cut(guide.image, gc, models, _STROKE_ITERATIONS)
        # A stroke only moves the label its own way (see ``stroke``).
        low = (low | prior) if strokes[-1].fg else (low & prior)
        return _Snapshot(box=box, strokes=strokes, models=models, low=low)

    def _full_mask(self, guide: _Guide, snap: _Snapshot) -> np.ndarray:
        """The full-resolution mask of ``snap``, computed over the whole ROI."""
        mask = np.zeros(self.shape, bool)
        part, (oy, ox) = _upsample_mask(guide, self._image, snap.low)
        mask[oy : oy + part.shape[0], ox : ox + part.shape[1]] = part
        _clip_to_box(mask, snap.box)
        self._apply_strokes(mask, snap.strokes)
        return mask

    def _apply_strokes(self, mask: np.ndarray, strokes: tuple[_Stroke, ...]) -> None:
        """Make every stroke's pixels its label, in order (later ones win)."""
        for s in strokes:
            if s not in self._footprints:
                self._footprints[s] = _polyline_distance_mask(mask.shape, s.points, s.radius)
            hit = self._footprints[s]
            if hit is not None:
                crop, (y0, x0) = hit
                view = mask[y0 : y0 + crop.shape[0], x0 : x0 + crop.shape[1]]
                view[crop] = s.fg

    def _commit(self, guide: _Guide, snap: _Snapshot, mask: np.ndarray) -> None:
        """Make ``snap`` current (the old current goes on the undo stack)."""
        x0, y0, x1, y1 = snap.box
        self._history.append(self._now)
        del self._history[: max(0, len(self._history) - self._max_undo)]
        self._now = dataclasses.replace(snap, mask_bits=np.packbits(mask[y0:y1, x0:x1], axis=None))
        self._mask = mask
        self._guide = guide

    def _restore(self, snap: _Snapshot) -> None:
        """Make ``snap`` current without touching the undo stack."""
        self._now = snap
        self._mask = np.zeros(self.shape, bool)
        if snap.box is not None:
            x0, y0, x1, y1 = snap.box
            self._mask[y0:y1, x0:x1] = self._unpack(snap)
            self._guide = self._guide_for(snap.box)

    @staticmethod
    def _unpack(snap: _Snapshot) -> np.ndarray:
        x0, y0, x1, y1 = snap.box
        size = (y1 - y0) * (x1 - x0)
        return np.unpackbits(snap.mask_bits, count=size).view(bool).reshape(y1 - y0, x1 - x0)


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


def _offsets(parts: Sequence[np.ndarray]) -> np.ndarray:
    return np.cumsum([0] + [len(p) for p in parts]).astype(np.int64)


def _rle_encode(mask: np.ndarray) -> np.ndarray:
    """Run lengths of a bool array in row-major order, starting with a False run."""
    flat = mask.ravel()
    if flat.size == 0:
        return np.zeros(0, np.uint32)
    change = np.flatnonzero(flat[1:] != flat[:-1]) + 1
    runs = np.diff(np.concatenate([[0], change, [flat.size]]))
    if flat[0]:
        runs = np.concatenate([[0], runs])
    return runs.astype(np.uint32)


def _rle_decode(runs: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    values = np.arange(len(runs)) % 2 == 1
    flat = np.repeat(values, runs.astype(np.int64))
    if flat.size != shape[0] * shape[1]:
        raise EgonetError(f"state: mask run lengths sum to {flat.size}, expected {shape[0] * shape[1]}", field="state")
    return flat.reshape(shape)
