"""Depth -> height above the floor (gravity aligned), and the DHG image codec.

The H of EgoNet's DHG input is the height of every pixel above the floor,
measured along gravity, as in Gupta et al. 2014 (HHA). This module estimates
gravity from the depth map alone and encodes depth, height and grayscale as
one 3-channel 8-bit image.

Conventions:
    * Camera coordinates are OpenCV's: x right, y down, z forward. ``up`` is
      the unit vector pointing against gravity in those coordinates, so a
      level camera has ``up = (0, -1, 0)`` and a camera looking straight down
      has ``up = (0, 0, -1)``.
    * Depth is z-depth in metres along the optical axis, missing where it is
      0, negative, NaN or infinite.
    * Pitch is positive when the camera looks down; roll is positive when the
      camera turns clockwise about its optical axis (as seen from behind):
      ``up = (-sin(roll) cos(pitch), -cos(roll) cos(pitch), -sin(pitch))``.

How gravity is found (``estimate_height``):
    1. Surface normals: in square windows of side 1/12 of min(H, W) (41
       pixels at 640x480), on a grid of about 20,000 windows, fit the plane
       ``1/z = a x + b y + c`` to the valid pixels, where
       ``(x, y, 1) = K^-1 (u, v, 1)``. Inverse depth is
       exactly affine over a plane, so this is an ordinary linear least
       squares with the noise in the fitted variable only; its normal is
       ``(a, b, c)``, turned to face the camera. Missing pixels simply drop
       out of the sums; windows with less than half their pixels valid, or
       whose fit leaves a residual above 3 % of the inverse depth (a depth
       edge, a curved or rough surface) give no normal, so holes and
       occlusion boundaries cannot poison the estimate.
    2. Gravity, as in Gupta et al.: from an initial up, two passes of five
       iterations with thresholds 45 then 15 degrees; floor-like normals lie
       within the threshold of the up axis (either sign, so ceilings help),
       wall-like normals within the threshold of perpendicular to it; the new
       up is the eigenvector with the smallest eigenvalue of
       ``N_wall N_wall^T - N_floor N_floor^T``, signed to agree with the
       previous estimate. A tiny pull towards a level camera (0.1 % of the
       normal count times ``I - l l^T``, ``l = (0, -1, 0)``) changes nothing
       measurable when the normals determine gravity, and picks the most
       level solution when they do not (a single wall direction and no
       horizontal surface leave the roll about the wall normal free).
    3. Steep pitch. Starting from the camera's -y axis, as Gupta et al. do,
       fails when a first-person camera looks down at the hands: from 45
       degrees down the floor normal sits at or beyond the first threshold
       and counts as a wall, while the line of a wall facing the camera is
       closer to -y than the floor normal, so the iteration locks onto
       "looking up at a ceiling". So the iteration runs from 25 initial ups
       covering pitch -30 to 90 degrees and roll -30 to 30 degrees (all at
       once, vectorised, on a subsample of 3,000 normals), and the converged
       candidates are scored:

       ``score = support + 0.15 (up-facing - down-facing) - pose penalty``

       where support is the share of normals that are wall-like or
       horizontal within 15 degrees, up-facing / down-facing the shares of
       horizontal normals facing +up (floors, table tops) or -up (ceilings),
       and the pose penalty is 1 per 60 degrees of pitch outside -20..70
       degrees or of sideways tilt (roll) beyond 30 degrees; a candidate
       whose floor would lie more than 2.5 m below the camera (a far wall
       taken for the floor) loses 1, and a cost of 0.02 per 90 degrees from
       level settles exact ties. Support rejects the junk; in a box room
       it ties between the room's axes, and the other terms settle the tie:
       the pose penalty rejects "a side wall is the floor" and "upside down",
       and prefers "level, facing a wall" over "straight down at a floor";
       the orientation term prefers "looking down at floor and table" over
       "looking up at a ceiling that is really the wall ahead". The best
       candidate is refined by a last 15-degree pass on all normals.

How height is found:
    Height is the distance along ``up`` above the floor. The floor is taken as
    the lowest substantial horizontal, upward-facing surface: among the
    normals within 15 degrees of up (facing up), the lowest 5 cm height bin
    that, with its two neighbours, holds at least ``min_floor_fraction`` of
    all fitted windows. Its height is refined as the median height of those
    windows (within 10 cm of the bin). This plays the role of Gupta's
    "lowest point", made robust: the single lowest pixel is set by noise,
    flying pixels at depth edges and reflections in glossy floors, and even a
    low percentile (say the 1st) of all pixel heights sits about two noise
    standard deviations below the true floor; the median of a detected floor
    plane is unbiased.

    The floor counts as *not in view* when no such surface exists, when it
    is less than ``min_camera_height_m`` (0.3 m) below the camera, or when
    more than 2 % of the valid pixels lie more than 20 cm below it (then it
    is a table or counter top with things below it, not the floor). Then, as
    in Gupta et al., the floor is assumed ``assumed_camera_height_m`` (1.3 m)
    below the camera, or at the robust lowest point (the 1st percentile of
    the heights of all valid pixels) if that is lower still, so that heights
    are never far below 0.

DHG encoding (``encode_dhg`` / ``decode_dhg``), uint8 (H, W, 3), in the
channel order of the authors' DHG files (read as RGB: gray, height, depth;
their released ``predict.py`` flips it so the network sees depth first):
    * channel 0 (``GRAY``): the grayscale image, unchanged;
    * channel 1 (``HEIGHT``), height: code ``1 + round(254 * (h - HEIGHT_MIN_M) /
      (HEIGHT_MAX_M - HEIGHT_MIN_M))``, h clipped to [HEIGHT_MIN_M,
      HEIGHT_MAX_M] = [-0.2, 2.34] m: 1 cm a code; the floor is code 21, so
      the floor is dark and things get brighter with height up to above head
      height (ceilings saturate at 255);
    * channel 2 (``DEPTH``), depth: code ``1 + round(254 * d / DEPTH_MAX_M)``,
      d clipped to [0, DEPTH_MAX_M] = [0, 7.62] m: 3 cm a code, near enough
      for the arm's-reach objects, and far enough for rooms (stereo depth from
      a 10 cm baseline is unreliable beyond that anyway).
    Code 0 is reserved for missing depth or height, so missing stays missing:
    the decoder returns NaN there. The authors' own depth and height scales
    are not published; their files decode with ours into the right channels.
    Before issue 16 our DHG images were stored the other way round (depth,
    height, gray); migration 0007 rewrote stored ones.
"""

import numbers
from dataclasses import dataclass
from typing import NamedTuple

import cv2
import numpy as np

from egonet.errors import EgonetError

# --- DHG codec --------------------------------------------------------------

DEPTH_MAX_M = 7.62
"""Depth encoded linearly over [0, DEPTH_MAX_M] metres onto codes 1..255: 3 cm a code."""

HEIGHT_MIN_M = -0.2
"""Lowest height encoded (code 1): a little below the floor, for noise."""

HEIGHT_MAX_M = 2.34
"""Highest height encoded (code 255): above head height. With HEIGHT_MIN_M, 1 cm a code."""

MISSING_CODE = 0
"""The code of a missing depth or height."""

GRAY, HEIGHT, DEPTH = 0, 1, 2
"""Channel indices of a DHG image (the authors' file order)."""

# --- gravity and height -----------------------------------------------------

ASSUMED_CAMERA_HEIGHT_M = 1.3
"""Camera height above the floor assumed when the floor is not in view (Gupta et al.)."""

_WINDOW_FRACTION = 1 / 12  # plane-fit window side, as a fraction of min(H, W)
_TARGET_WINDOWS = 20_000  # about this many windows are fitted (sets the stride)
_MIN_VALID_FRACTION = 0.5  # a window needs this fraction of valid pixels
_MAX_PLANE_RESIDUAL = 0.03  # RMS residual of 1/z, relative to the mean of 1/z
_MIN_NORMALS = 50  # fewer planar windows than this: gravity cannot be estimated
_CANDIDATE_NORMALS = 3_000  # subsample size for the multi-start search
_PASSES = ((45.0, 5), (15.0, 5))  # (threshold in degrees, iterations), Gupta et al.
_ORIENTATION_WEIGHT = 0.15  # score bonus per upward-facing minus downward-facing share
_COMFORT_PITCH_DEG = (-20.0, 70.0)  # usual first-person pitch range (positive: down)
_COMFORT_TILT_DEG = 30.0  # usual sideways tilt of up (roll, scaled by cos(pitch))
_PENALTY_DEG = 60.0  # pose penalty: 1 score unit per this many degrees outside
_MAX_CAMERA_HEIGHT_M = 2.5  # a floor further below the camera is implausible
_LEVEL_TIE_BREAK = 0.02  # score cost per 90 degrees from level: settles exact ties
_REGULARISATION = 1e-3  # pull towards a level camera, relative to the normal count
_FLOOR_BIN_M = 0.05  # height bin of the floor search
_FLOOR_BAND_M = 0.10  # windows within this of the floor bin refine the floor height
_MAX_MEDIAN_DEPTH_M = 100.0  # a larger median depth is taken for millimetres
_LOW_PERCENTILE = 1.0  # robust "lowest point" when the floor is not in view
_BELOW_FLOOR_M = 0.2  # pixels further than this below a floor candidate ...
_MAX_BELOW_FLOOR_FRACTION = 0.02  # ... may be at most this share of the valid pixels

LEVEL_UP = np.array([0.0, -1.0, 0.0])
"""Gravity-up of a level camera in OpenCV camera coordinates."""


@dataclass(frozen=True, eq=False)
class HeightEstimate:
    """Result of :func:`estimate_height`.

    Attributes:
        height_m: (H, W) float32 metres above the floor, NaN where depth is missing.
        up: (3,) unit gravity-up vector in camera coordinates (x right, y down, z forward).
        camera_height_m: height of the camera centre above the floor (metres).
        floor_visible: whether a floor was detected; if not, the floor was assumed
            ``assumed_camera_height_m`` below the camera (or at the lowest point).
        floor_fraction: fraction of the fitted windows classified as floor (upward
            facing within 15 degrees of up and within 10 cm of the floor height);
            0 when the floor is not visible.
        n_normals: number of planar windows that gave a normal; below 50 gravity
            could not be estimated and ``up`` is that of a level camera.
    """

    height_m: np.ndarray
    up: np.ndarray
    camera_height_m: float
    floor_visible: bool
    floor_fraction: float
    n_normals: int

    @property
    def pitch_deg(self) -> float:
        """Camera pitch in degrees, positive when looking down."""
        return float(np.degrees(np.arcsin(np.clip(-self.up[2], -1.0, 1.0))))

    @property
    def roll_deg(self) -> float:
        """Camera roll in degrees, positive when turned clockwise (seen from behind)."""
        return float(np.degrees(np.arctan2(-self.up[0], -self.up[1])))


# --- validation ---------------------------------------------------------------


def _check_depth(depth_m: object, name: str = "depth_m", *, min_size: int = 1) -> np.ndarray:
    arr = np.asarray(depth_m)
    if arr.ndim != 2:
        raise EgonetError(f"{name} must be a 2-D map (H, W) in metres, got shape {arr.shape}", field=name)
    if arr.shape[0] < min_size or arr.shape[1] < min_size:
        raise EgonetError(f"{name} must be at least {min_size}x{min_size} pixels, got shape {arr.shape}", field=name)
    if not np.issubdtype(arr.dtype, np.floating):
        raise EgonetError(
            f"{name} must be floating point metres, got dtype {arr.dtype}; "
            "convert 16-bit millimetres with depth_mm.astype(np.float32) / 1000",
            field=name,
        )
    return arr


def _check_intrinsics(K: object) -> np.ndarray:
    try:
        arr = np.asarray(K, dtype=np.float64)
    except (TypeError, ValueError):
        raise EgonetError(f"K must be the 3x3 camera matrix, got {type(K).__name__}", field="K") from None
    if arr.shape != (3, 3):
        raise EgonetError(
            f"K must be the 3x3 camera matrix [[fx, 0, cx], [0, fy, cy], [0, 0, 1]], got shape {arr.shape}; "
            "a flat Open3D list of 9 is column-major: np.reshape(values, (3, 3)).T",
            field="K",
        )
    if not np.all(np.isfinite(arr)):
        raise EgonetError("K must contain only finite numbers", field="K")
    if not np.allclose(arr[2], (0.0, 0.0, 1.0), atol=1e-6):
        raise EgonetError(f"K's last row must be (0, 0, 1), got {tuple(arr[2])}; is K transposed?", field="K")
    if arr[0, 0] <= 0 or arr[1, 1] <= 0:
        raise EgonetError(
            f"K's focal lengths fx = K[0, 0] and fy = K[1, 1] must be positive, got {arr[0, 0]}, {arr[1, 1]}",
            field="K",
        )
    return arr


def _check_positive(value: float, name: str, *, at_most: float = np.inf) -> float:
    if not isinstance(value, numbers.Real) or isinstance(value, bool) or not 0 < value <= at_most:
        limit = "" if at_most == np.inf else f" and at most {at_most}"
        raise EgonetError(f"{name} must be a positive number{limit}, got {value!r}", field=name)
    return float(value)


# --- geometry -----------------------------------------------------------------


def normalised_coords(K: np.ndarray, shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """(x, y) of every pixel, with (x, y, 1) = K^-1 (u, v, 1); each (H, W) float64."""
    h, w = shape
    kinv = np.linalg.inv(K)
    u = np.arange(w, dtype=np.float64)[None, :]
    v = np.arange(h, dtype=np.float64)[:, None]
    x = kinv[0, 0] * u + kinv[0, 1] * v + kinv[0, 2]
    y = kinv[1, 0] * u + kinv[1, 1] * v + kinv[1, 2]
    return np.broadcast_to(x, shape), np.broadcast_to(y, shape)


def _plane_normals(
    z: np.ndarray, valid: np.ndarray, x: np.ndarray, y: np.ndarray
) -> tuple[np.ndarray, np.ndarray, int]:
    """Fit 1/z = a x + b y + c in windows on a grid; keep the planar ones.

    Returns:
        normals (M, 3), unit, facing the camera; points (M, 3), the fitted
        plane's point at each window's mean pixel; the number of windows with
        enough valid pixels (planar or not).
    """
    h, w = z.shape
    k = 2 * max(2, round(min(h, w) * _WINDOW_FRACTION / 2)) + 1
    stride = max(1, int(np.ceil(np.sqrt(h * w / _TARGET_WINDOWS))))
    rows = np.arange(stride // 2, h, stride)
    cols = np.arange(stride // 2, w, stride)

    m = valid.astype(np.float64)
    t = np.where(valid, 1.0 / np.where(valid, z, 1.0), 0.0)
    # Sums over each window of the normal-equation terms, via box filters
    # evaluated at full resolution and sampled on the grid.
    terms = (m, m * x, m * y, m * x * x, m * x * y, m * y * y, t, t * x, t * y, t * t)
    sums = np.empty((len(rows), len(cols), len(terms)))
    for i, term in enumerate(terms):
        box = cv2.boxFilter(term, cv2.CV_64F, (k, k), normalize=False, borderType=cv2.BORDER_CONSTANT)
        sums[:, :, i] = box[np.ix_(rows, cols)]
    sums = sums.reshape(-1, len(terms))
    n, sx, sy, sxx, sxy, syy, st, stx, sty, stt = sums.T

    enough = n >= _MIN_VALID_FRACTION * k * k
    n_windows = int(enough.sum())
    n, sx, sy, sxx, sxy, syy, st, stx, sty, stt = (s[enough] for s in (n, sx, sy, sxx, sxy, syy, st, stx, sty, stt))
    # Centre the regressors on each window's mean (x', y' = x - cx, y - cy):
    # the normal equations then split into a 2x2 system for (a, b), and
    # c' = mean(t), which keeps the solve well conditioned.
    cx, cy, ct = sx / n, sy / n, st / n
    vxx = sxx - n * cx * cx
    vxy = sxy - n * cx * cy
    vyy = syy - n * cy * cy
    vxt = stx - cx * st
    vyt = sty - cy * st
    det = vxx * vyy - vxy * vxy
    ok = det > 1e-12 * np.maximum(vxx * vyy, 1e-300)
    det = np.where(ok, det, 1.0)
    a = (vyy * vxt - vxy * vyt) / det
    b = (vxx * vyt - vxy * vxt) / det
    # Residual sum of squares of t about the fitted plane.
    rss = (stt - n * ct * ct) - a * vxt - b * vyt
    with np.errstate(invalid="ignore", divide="ignore"):
        rel = np.sqrt(np.maximum(rss, 0.0) / n) / ct
    c = ct - a * cx - b * cy
    beta = np.stack([a, b, c], axis=1)
    norm = np.linalg.norm(beta, axis=1)
    planar = ok & (ct > 0) & (rel <= _MAX_PLANE_RESIDUAL) & (norm > 0)
    normals = -beta[planar] / norm[planar, None]
    # Point of the fitted plane at the window's mean pixel: 1/z = ct there.
    centre = np.stack([cx, cy, np.ones_like(cx)], axis=1)[planar]
    zc = 1.0 / ct[planar]
    good = np.isfinite(zc)
    return normals[good], centre[good] * zc[good, None], n_windows


def _iterate_gravity(normals: np.ndarray, ups: np.ndarray, passes: tuple[tuple[float, int], ...]) -> np.ndarray:
    """Gupta et al.'s iteration, run from several initial ups at once. (C, 3) -> (C, 3)."""
    outer = (normals[:, :, None] * normals[:, None, :]).reshape(-1, 9)
    ups = ups / np.linalg.norm(ups, axis=1, keepdims=True)
    # The pull towards a level camera: (I - l l^T) costs every direction but l.
    prior = np.eye(3) - np.outer(LEVEL_UP, LEVEL_UP)
    for threshold_deg, iterations in passes:
        cos_t = np.cos(np.radians(threshold_deg))
        sin_t = np.sin(np.radians(threshold_deg))
        for _ in range(iterations):
            dots = np.abs(normals @ ups.T)  # (M, C)
            floor = (dots > cos_t).astype(np.float64)
            wall = (dots < sin_t).astype(np.float64)
            a = ((wall - floor).T @ outer).reshape(-1, 3, 3)
            count = (wall + floor).sum(axis=0)
            a += (_REGULARISATION * count)[:, None, None] * prior
            _, vecs = np.linalg.eigh(a)
            new = vecs[:, :, 0]
            sign = np.sign(np.einsum("ci,ci->c", new, ups))
            ups = new * np.where(sign == 0, 1.0, sign)[:, None]
    return ups


def _initial_ups() -> np.ndarray:
    """Initial up candidates over pitch -30..90 and roll -30..30 degrees. (C, 3)."""
    ups = []
    for pitch in np.radians(np.arange(-30.0, 91.0, 15.0)):
        for roll in np.radians((-30.0, 0.0, 30.0)):
            ups.append((-np.sin(roll) * np.cos(pitch), -np.cos(roll) * np.cos(pitch), -np.sin(pitch)))
            if pitch > np.radians(89.0):
                break
    return np.asarray(ups)


def _pose_penalty(ups: np.ndarray) -> np.ndarray:
    """Prior cost of each up as a first-person camera pose (0 inside the usual range)."""
    # Pitch in the camera's y-z plane: 0 level, 90 straight down, 180 upside down.
    pitch = np.degrees(np.arctan2(-ups[:, 2], -ups[:, 1]))
    sideways = np.degrees(np.arcsin(np.clip(np.abs(ups[:, 0]), 0.0, 1.0)))
    lo, hi = _COMFORT_PITCH_DEG
    excess = np.maximum(pitch - hi, 0.0) + np.maximum(lo - pitch, 0.0) + np.maximum(sideways - _COMFORT_TILT_DEG, 0.0)
    return excess / _PENALTY_DEG


def _scores(normals: np.ndarray, ups: np.ndarray) -> np.ndarray:
    """Score of each candidate up: support + orientation bonus - pose penalty."""
    dots = normals @ ups.T
    cos_t, sin_t = np.cos(np.radians(15.0)), np.sin(np.radians(15.0))
    facing_up = (dots > cos_t).mean(axis=0)
    facing_down = (dots < -cos_t).mean(axis=0)
    wall = (np.abs(dots) < sin_t).mean(axis=0)
    support = wall + facing_up + facing_down
    from_level = np.degrees(np.arccos(np.clip(ups @ LEVEL_UP, -1.0, 1.0)))
    return (
        support
        + _ORIENTATION_WEIGHT * (facing_up - facing_down)
        - _pose_penalty(ups)
        - _LEVEL_TIE_BREAK * from_level / 90.0
    )


def _estimate_up(normals: np.ndarray, points: np.ndarray, *, min_floor_fraction: float) -> np.ndarray:
    """Gravity-up from surface normals: multi-start search, then a final pass."""
    step = max(1, len(normals) // _CANDIDATE_NORMALS)
    subset, subset_points = normals[::step], points[::step]
    ups = _iterate_gravity(subset, _initial_ups(), _PASSES)
    scores = _scores(subset, ups)
    for i, up in enumerate(ups):
        # A "floor" far below the camera means this up turned a distant wall
        # into the floor: not a first-person pose.
        level, _ = _find_floor(subset, subset_points, up, len(subset), min_floor_fraction=min_floor_fraction)
        if level is not None and -level > _MAX_CAMERA_HEIGHT_M:
            scores[i] -= 1.0
    best = ups[np.argmax(scores)][None, :]
    return _iterate_gravity(normals, best, ((15.0, 5),))[0]


def _find_floor(
    normals: np.ndarray, points: np.ndarray, up: np.ndarray, n_windows: int, *, min_floor_fraction: float
) -> tuple[float | None, float]:
    """Height along up of the lowest substantial upward-facing surface, and its share of windows."""
    facing_up = normals @ up > np.cos(np.radians(15.0))
    heights = points[facing_up] @ up
    if heights.size == 0:
        return None, 0.0
    lo = heights.min()
    bins = np.floor((heights - lo) / _FLOOR_BIN_M).astype(np.int64)
    counts = np.bincount(bins)
    support = np.convolve(counts, np.ones(3), mode="same")
    enough = np.flatnonzero(support >= min_floor_fraction * n_windows)
    if enough.size == 0:
        return None, 0.0
    centre = lo + (enough[0] + 0.5) * _FLOOR_BIN_M
    band = np.abs(heights - centre) <= _FLOOR_BAND_M
    level = float(np.median(heights[band]))
    inliers = np.abs(heights - level) <= _FLOOR_BAND_M
    return level, float(inliers.sum()) / max(n_windows, 1)


def _metric_depth(depth: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Depth as float64 and where it is valid; refuses a map with no valid
    pixel, or one that looks like millimetres."""
    z = depth.astype(np.float64)
    with np.errstate(invalid="ignore"):
        valid = np.isfinite(z) & (z > 0)
    if not valid.any():
        raise EgonetError("depth_m has no valid pixel (all 0, negative or NaN): a height map needs depth", field="depth_m")
    if np.median(z[valid][:: max(1, int(valid.sum()) // 10_000)]) > _MAX_MEDIAN_DEPTH_M:
        raise EgonetError(
            f"depth_m has a median depth above {_MAX_MEDIAN_DEPTH_M:g} m: it looks like millimetres; "
            "pass metres (depth / 1000)",
            field="depth_m",
        )
    return z, valid


def _place_floor(
    raw_valid: np.ndarray,
    normals: np.ndarray,
    points: np.ndarray,
    up: np.ndarray,
    n_windows: int,
    *,
    assumed_camera_height_m: float,
    min_camera_height_m: float,
    min_floor_fraction: float,
) -> tuple[float, float, bool]:
    """The floor's height along up relative to the camera, its share of the
    windows and whether it is in view; if it is not, the assumed floor (see
    the module docstring). ``raw_valid`` holds the valid pixels' heights
    relative to the camera."""
    floor = None
    floor_fraction = 0.0
    if len(normals) >= _MIN_NORMALS:
        floor, floor_fraction = _find_floor(normals, points, up, n_windows, min_floor_fraction=min_floor_fraction)
    floor_visible = (
        floor is not None
        and -floor >= min_camera_height_m
        # Nothing substantial may lie below the floor (else it is a table top).
        and np.count_nonzero(raw_valid < floor - _BELOW_FLOOR_M) <= _MAX_BELOW_FLOOR_FRACTION * raw_valid.size
    )
    if not floor_visible:
        floor_fraction = 0.0
        lowest = float(np.percentile(raw_valid, _LOW_PERCENTILE))
        floor = min(lowest, -assumed_camera_height_m)
    return floor, floor_fraction, floor_visible


def estimate_height(
    depth_m: np.ndarray,
    K: np.ndarray,
    *,
    assumed_camera_height_m: float = ASSUMED_CAMERA_HEIGHT_M,
    min_camera_height_m: float = 0.3,
    min_floor_fraction: float = 0.02,
) -> HeightEstimate:
    """Estimate gravity and the height of every pixel above the floor.

    See the module docstring for the method (plane-fit normals, Gupta et al.'s
    iteration from several initial ups, floor detection).

    Args:
        depth_m: (H, W) float z-depth in metres; 0, negative, NaN or inf where missing.
        K: (3, 3) camera matrix ``[[fx, s, cx], [0, fy, cy], [0, 0, 1]]``.
        assumed_camera_height_m: camera height above the floor assumed when the
            floor is not in view.
        min_camera_height_m: a horizontal surface less than this below the camera
            is never taken for the floor (a desk or counter seen from above).
        min_floor_fraction: fraction of the fitted windows the floor must cover to
            count as visible.

    Returns:
        A :class:`HeightEstimate`.

    Raises:
        ValueError: if an argument has the wrong shape, type or range, or if no
            pixel has a valid depth.

    Example:
        >>> import numpy as np
        >>> K = np.array([[100.0, 0, 32], [0, 100.0, 24], [0, 0, 1]])
        >>> v = np.arange(48.0)[:, None].repeat(64, axis=1)
        >>> depth = np.where(v > 24, 1.5 * 100.0 / np.maximum(v - 24, 1), 0)  # floor 1.5 m below
        >>> est = estimate_height(depth, K)
        >>> bool(np.allclose(est.up, (0, -1, 0), atol=1e-3)), round(est.camera_height_m, 2)
        (True, 1.5)
    """
    depth = _check_depth(depth_m, min_size=8)
    K = _check_intrinsics(K)
    assumed_camera_height_m = _check_positive(assumed_camera_height_m, "assumed_camera_height_m")
    min_camera_height_m = _check_positive(min_camera_height_m, "min_camera_height_m")
    min_floor_fraction = _check_positive(min_floor_fraction, "min_floor_fraction", at_most=1.0)

    z, valid = _metric_depth(depth)
    x, y = normalised_coords(K, z.shape)

    normals, points, n_windows = _plane_normals(z, valid, x, y)
    if len(normals) >= _MIN_NORMALS:
        up = _estimate_up(normals, points, min_floor_fraction=min_floor_fraction)
    else:
        up = LEVEL_UP.copy()

    # Height along up of every pixel, relative to the camera centre.
    along = up[0] * x + up[1] * y + up[2]
    raw = np.where(valid, np.where(valid, z, 0.0) * along, np.nan)

    floor, floor_fraction, floor_visible = _place_floor(
        raw[valid],
        normals,
        points,
        up,
        n_windows,
        assumed_camera_height_m=assumed_camera_height_m,
        min_camera_height_m=min_camera_height_m,
        min_floor_fraction=min_floor_fraction,
    )
    height = (raw - floor).astype(np.float32)
    return HeightEstimate(
        height_m=height,
        up=up,
        camera_height_m=-float(floor),
        floor_visible=floor_visible,
        floor_fraction=float(floor_fraction),
        n_normals=len(normals),
    )


def height_map(
    depth_m: np.ndarray,
    K: np.ndarray,
    *,
    assumed_camera_height_m: float = ASSUMED_CAMERA_HEIGHT_M,
    min_camera_height_m: float = 0.3,
    min_floor_fraction: float = 0.02,
) -> tuple[np.ndarray, np.ndarray]:
    """Height above the floor of every pixel, and the gravity-up vector.

    A thin wrapper over :func:`estimate_height` (see it and the module
    docstring for the method and the options).

    Args:
        depth_m: (H, W) float z-depth in metres; 0, negative, NaN or inf where missing.
        K: (3, 3) camera matrix.
        assumed_camera_height_m: see :func:`estimate_height`.
        min_camera_height_m: see :func:`estimate_height`.
        min_floor_fraction: see :func:`estimate_height`.

    Returns:
        ``(height_m, up)``: (H, W) float32 metres above the floor, NaN where depth
        is missing; (3,) unit up vector in camera coordinates (x right, y down,
        z forward; a level camera has (0, -1, 0)).

    Raises:
        ValueError: on bad input or when no pixel has a valid depth.

    Example:
        >>> import numpy as np
        >>> K = np.array([[100.0, 0, 32], [0, 100.0, 24], [0, 0, 1]])
        >>> v = np.arange(48.0)[:, None].repeat(64, axis=1)
        >>> depth = np.where(v > 24, 1.5 * 100.0 / np.maximum(v - 24, 1), 0)
        >>> height, up = height_map(depth, K)
        >>> round(float(np.nanmax(np.abs(height))), 3)
        0.0
    """
    est = estimate_height(
        depth_m,
        K,
        assumed_camera_height_m=assumed_camera_height_m,
        min_camera_height_m=min_camera_height_m,
        min_floor_fraction=min_floor_fraction,
    )
    return est.height_m, est.up


# --- DHG codec -------------------------------------------------------------------


def _encode_linear(values: np.ndarray, lo: float, hi: float) -> np.ndarray:
    with np.errstate(invalid="ignore"):
        missing = ~np.isfinite(values)
        scaled = np.clip((np.where(missing, lo, values) - lo) / (hi - lo), 0.0, 1.0)
    codes = (1 + np.rint(scaled * 254)).astype(np.uint8)
    codes[missing] = MISSING_CODE
    return codes


def _decode_linear(codes: np.ndarray, lo: float, hi: float) -> np.ndarray:
    step = (hi - lo) / 254
    zero_code = 1 - lo / step  # the (fractional) code of the value 0
    values = ((codes.astype(np.float64) - zero_code) * step).astype(np.float32)
    values[codes == MISSING_CODE] = np.nan
    return values


def encode_dhg(depth_m: np.ndarray, height_m: np.ndarray, gray: np.ndarray) -> np.ndarray:
    """Encode depth, height and grayscale as a DHG image, in the authors' channel order.

    Scaling (module constants): depth linear over [0, ``DEPTH_MAX_M``] onto codes
    1..255, height linear over [``HEIGHT_MIN_M``, ``HEIGHT_MAX_M``] onto codes
    1..255, values outside clipped to the end codes; code 0 marks a missing
    value (depth 0, negative or not finite; height not finite), and a pixel
    with missing depth gets a missing height too.

    Args:
        depth_m: (H, W) float z-depth in metres.
        height_m: (H, W) float metres above the floor (NaN where missing).
        gray: (H, W) uint8 grayscale image.

    Returns:
        (H, W, 3) uint8: channel 0 grayscale, 1 height, 2 depth (``GRAY``,
        ``HEIGHT``, ``DEPTH``), as the authors' DHG files.

    Raises:
        ValueError: on wrong shapes or dtypes.

    Example:
        >>> import numpy as np
        >>> image = encode_dhg(np.full((2, 2), 4.0), np.zeros((2, 2)), np.full((2, 2), 7, np.uint8))
        >>> image[0, 0].tolist()  # gray, height (the floor), depth (4 m)
        [7, 21, 134]
    """
    depth = _check_depth(depth_m)
    height = _check_depth(height_m, "height_m")
    gray_arr = np.asarray(gray)
    if height.shape != depth.shape:
        raise EgonetError(
            f"height_m has shape {height.shape} but depth_m has shape {depth.shape}; they must match", field="height_m"
        )
    if gray_arr.shape != depth.shape:
        raise EgonetError(
            f"gray must be a (H, W) image matching depth_m {depth.shape}, got shape {gray_arr.shape}; "
            "convert RGB with cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)",
            field="gray",
        )
    if gray_arr.dtype != np.uint8:
        raise EgonetError(f"gray must be uint8, got dtype {gray_arr.dtype}", field="gray")
    with np.errstate(invalid="ignore"):
        depth_missing = ~(np.isfinite(depth) & (depth > 0))
    depth_f = np.where(depth_missing, np.nan, depth)
    height_f = np.where(depth_missing, np.nan, height)
    channels = {
        GRAY: gray_arr,
        HEIGHT: _encode_linear(height_f, HEIGHT_MIN_M, HEIGHT_MAX_M),
        DEPTH: _encode_linear(depth_f, 0.0, DEPTH_MAX_M),
    }
    return np.stack([channels[c] for c in (0, 1, 2)], axis=-1)


class DecodedDHG(NamedTuple):
    """A decoded DHG image, by name (and in this order when unpacked)."""

    depth: np.ndarray
    """(H, W) float32 metres, NaN where missing."""
    height: np.ndarray
    """(H, W) float32 metres above the floor, NaN where missing."""
    gray: np.ndarray
    """(H, W) uint8."""


def decode_dhg(dhg: np.ndarray) -> DecodedDHG:
    """Decode a DHG image made by :func:`encode_dhg` (or an authors' DHG file, read as RGB).

    Exact up to quantisation for values inside the encoded ranges: the error
    is at most half a code, ``DEPTH_MAX_M / 254`` = 3 cm for depth and
    ``(HEIGHT_MAX_M - HEIGHT_MIN_M) / 254`` = 1 cm for height. Values that
    were clipped come back at the range ends. Missing values (code 0) come
    back as NaN.

    Args:
        dhg: (H, W, 3) uint8 image: gray, height, depth.

    Returns:
        ``DecodedDHG(depth, height, gray)``: (H, W) float32 metres, (H, W)
        float32 metres, (H, W) uint8.

    Raises:
        ValueError: on a wrong shape or dtype.

    Example:
        >>> import numpy as np
        >>> decoded = decode_dhg(np.array([[[7, 21, 134], [9, 0, 0]]], np.uint8))
        >>> round(float(decoded.depth[0, 0]), 2), float(decoded.height[0, 0]), decoded.gray.tolist()
        (3.99, 0.0, [[7, 9]])
        >>> bool(np.isnan(decoded.depth[0, 1]) and np.isnan(decoded.height[0, 1]))
        True
    """
    arr = np.asarray(dhg)
    if arr.ndim != 3 or arr.shape[2] != 3:
        raise EgonetError(f"dhg must be a (H, W, 3) image (gray, height, depth), got shape {arr.shape}", field="dhg")
    if arr.dtype != np.uint8:
        raise EgonetError(f"dhg must be uint8, got dtype {arr.dtype}", field="dhg")
    return DecodedDHG(
        depth=_decode_linear(arr[:, :, DEPTH], 0.0, DEPTH_MAX_M),
        height=_decode_linear(arr[:, :, HEIGHT], HEIGHT_MIN_M, HEIGHT_MAX_M),
        gray=arr[:, :, GRAY].copy(),
    )


def dhg_from_depth(depth_m: np.ndarray, K: np.ndarray, rgb: np.ndarray) -> np.ndarray:
    """Make the DHG image of a frame from its depth, intrinsics and RGB image.

    Runs :func:`height_map` with its defaults, converts RGB to grayscale
    (ITU-R BT.601 weights, OpenCV's) and encodes with :func:`encode_dhg`.

    Args:
        depth_m: (H, W) float z-depth in metres; 0 or NaN where missing.
        K: (3, 3) camera matrix.
        rgb: (H, W, 3) uint8 image in RGB order, the same size as the depth.

    Returns:
        (H, W, 3) uint8 DHG image: gray, height, depth (the authors' order).

    Raises:
        ValueError: on bad input or when no pixel has a valid depth.
    """
    depth = _check_depth(depth_m)
    image = np.asarray(rgb)
    if image.ndim != 3 or image.shape[2] != 3 or image.shape[:2] != depth.shape:
        raise EgonetError(f"rgb must be a (H, W, 3) image matching depth_m {depth.shape}, got shape {image.shape}", field="rgb")
    if image.dtype != np.uint8:
        raise EgonetError(f"rgb must be uint8, got dtype {image.dtype}", field="rgb")
    height, _ = height_map(depth, K)
    gray = cv2.cvtColor(np.ascontiguousarray(image), cv2.COLOR_RGB2GRAY)
    return encode_dhg(depth, height, gray)
