"""Judd: a linear classifier on per-pixel features (Judd, Ehinger, Durand & Torralba, ICCV 2009).

"Learning to predict where humans look" trains a linear SVM on low-,
mid- and high-level features of pixels inside (positives) and outside
(negatives) the fixated regions. The EgoNet paper trains it on its own
frames with the action-object masks as the positives; so do we, inside each
leave-one-activity-out fold.

Every feature is computed on a copy ``work_width`` pixels wide (160 by
default, 160 x 120 for 4:3 frames; the paper worked at 200 x 200), one row
per pixel of that grid (:data:`FEATURES` names the columns):

* **Low-level, faithful in kind.** Oriented subbands at three scales and
  four orientations plus the low-pass residual (13, as the paper's
  steerable pyramid): *stand-in*, the energies of quadrature Gabor pairs
  on a Gaussian pyramid (``egonet.saliency.feature_maps``) instead of a
  steerable pyramid's subbands. Itti-Koch intensity, colour and orientation
  conspicuity (3): centre-surround differences of the same pyramid
  (centres at levels 0-1, surrounds 2-3 levels coarser), each normalised by
  a simplified N(.) (scaled to peak 1, then weighted by ``(1 - mean)^2``,
  which favours maps with few peaks). Colour: the R, G, B values (3) and
  the rarity ``-log p`` of the pixel's colour in the 8x8x8 colour histogram
  of the image median-filtered at three scales (3), as the paper's colour
  histograms at several scales. Torralba's saliency: *stand-in*,
  spectral-residual saliency (Hou & Zhang), another bottom-up map.
* **Mid-level.** The paper's horizon line came from a gist regressor;
  *stand-in*: the row position ``y`` and ``y^2`` (the classifier learns
  where along the rows action-objects sit).
* **High-level.** Faces: a boosted cascade of the Viola-Jones family,
  scikit-image's multi-block LBP detector with OpenCV's trained frontal-face
  cascade (the paper: Viola-Jones with Haar features; OpenCV 5, installed
  here, no longer ships its Haar cascades or the HOG people detector). The
  paper's people and car detectors (Felzenszwalb's deformable parts) are
  **left out**: no trained detector for them is installed.
* **Centre.** The distance to the image centre, over the half-diagonal.

The classifier: the paper's linear SVM; here *logistic regression*
(scikit-learn, balanced class weights) on standardised features, also
linear, whose probability is the map (an SVM's score would need squashing
into [0, 1] anyway). Per training frame up to ``samples`` pixels inside the
mask and as many outside are drawn (the paper: 10 + 10 per image from the
top 20 % and bottom 70 % of the fixation map). What is fitted is the
scaler's mean and scale and the weights: plain arrays.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import lru_cache

import cv2
import numpy as np

from egonet.baselines.protocol import Summary, TrainedBaseline, TrainingFrame
from egonet.baselines.simple import SpectralResidualSaliency
from egonet.errors import EgonetError
from egonet.saliency import check_frame, feature_maps

__all__ = ["FEATURES", "Judd", "judd_features"]

_LEVELS = (0, 1, 2, 3, 4)
_CENTRE_SURROUND = ((0, 2), (0, 3), (1, 3), (1, 4))
_MEDIAN_SIZES = (1, 5, 11)
FEATURES = (
    *(f"subband s{s} {o}deg" for s in range(3) for o in (0, 45, 90, 135)),
    "subband low-pass",
    "itti-koch intensity", "itti-koch colour", "itti-koch orientation",
    "spectral residual (for Torralba)",
    "red", "green", "blue",
    *(f"colour rarity median {k}" for k in _MEDIAN_SIZES),
    "row y", "row y^2",
    "faces",
    "distance to centre",
)  # fmt: skip
"""The per-pixel features, in column order."""


def _normalised(m: np.ndarray) -> np.ndarray:
    """Itti-Koch's N(.), simplified: peak 1, weighted by (1 - mean)^2 (few strong peaks weigh more than many)."""
    top = float(m.max())
    if top <= 1e-9:
        return np.zeros_like(m)
    m = m / top
    return m * (1.0 - float(m.mean())) ** 2


def _rarity(rgb: np.ndarray, k: int) -> np.ndarray:
    """-log p(colour) in the 8x8x8 colour histogram of the image median-filtered with a k x k window."""
    image = cv2.medianBlur(rgb, k) if k > 1 else rgb
    bins = (image // 32).astype(np.int32)
    index = (bins[..., 0] * 8 + bins[..., 1]) * 8 + bins[..., 2]
    p = np.bincount(index.ravel(), minlength=512) / index.size
    return -np.log(p[index] + 1e-6).astype(np.float32)


@lru_cache(maxsize=1)
def _face_cascade():
    import skimage.data
    from skimage.feature import Cascade

    return Cascade(skimage.data.lbp_frontal_face_cascade_filename())


def _faces(gray: np.ndarray) -> np.ndarray:
    """1 inside detected frontal faces, blurred a little; 0 elsewhere."""
    h, w = gray.shape
    out = np.zeros((h, w), np.float32)
    side = min(h, w)
    if side >= 24:
        found = _face_cascade().detect_multi_scale(img=gray, scale_factor=1.25, step_ratio=1, min_size=(20, 20), max_size=(side, side))
        for box in found:
            out[box["r"] : box["r"] + box["height"], box["c"] : box["c"] + box["width"]] = 1.0
    return cv2.GaussianBlur(out, (0, 0), 2.0) if out.any() else out


def judd_features(rgb: np.ndarray, *, work_width: int = 160) -> np.ndarray:
    """Judd's per-pixel features on a copy ``work_width`` wide, float32 ``(h, w, len(FEATURES))``.

    Example:
        >>> judd_features(np.zeros((30, 40, 3), np.uint8), work_width=40).shape
        (30, 40, 27)
    """
    h, w = check_frame(rgb, None)
    ww = min(work_width, w)
    wh = max(1, round(h * ww / w))
    work = cv2.resize(rgb, (ww, wh), interpolation=cv2.INTER_AREA)

    def grid(m: np.ndarray) -> np.ndarray:
        return cv2.resize(m.astype(np.float32), (ww, wh), interpolation=cv2.INTER_LINEAR)

    maps = feature_maps(work, work_width=ww, levels=_LEVELS)
    columns = [grid(m) for m in maps["orientation"][:12]]  # levels 0-2, four orientations each
    columns.append(grid(maps["intensity"][-1]))
    for channel, per_level in (("intensity", 1), ("color", 2), ("orientation", 4)):
        conspicuity = np.zeros((wh, ww), np.float32)
        for c, s in _CENTRE_SURROUND:
            for i in range(per_level):
                centre, surround = maps[channel][c * per_level + i], maps[channel][s * per_level + i]
                up = cv2.resize(surround, centre.shape[::-1], interpolation=cv2.INTER_LINEAR)
                conspicuity += grid(_normalised(np.abs(centre - up)))
        columns.append(conspicuity)
    columns.append(SpectralResidualSaliency().predict(work))
    columns += [work[..., c].astype(np.float32) / 255.0 for c in range(3)]
    columns += [_rarity(work, k) for k in _MEDIAN_SIZES]
    y, x = np.mgrid[0:wh, 0:ww].astype(np.float32)
    row = (y + 0.5) / wh
    columns += [row, row**2]
    columns.append(_faces(cv2.cvtColor(work, cv2.COLOR_RGB2GRAY)))
    columns.append(np.hypot(x - (ww - 1) / 2, y - (wh - 1) / 2) / (0.5 * np.hypot(ww, wh)))
    return np.stack(columns, axis=-1).astype(np.float32)


class Judd(TrainedBaseline):
    """Judd et al. (ICCV 2009), trained on the project's frames; see the module docstring.

    Args:
        work_width: Width of the feature grid, pixels.
        samples: Pixels drawn inside the mask, and as many outside, per training frame.
        C: Inverse regularisation strength of the logistic regression.
        seed: Seed of the pixel draws.

    Raises:
        EgonetError: A setting out of range (named).

    Example:
        >>> rgb = np.zeros((30, 40, 3), np.uint8); rgb[10:20, 10:20] = (200, 30, 30)
        >>> mask = np.zeros((30, 40), bool); mask[10:20, 10:20] = True
        >>> model = Judd(work_width=40).fit([TrainingFrame(rgb, None, mask)])
        >>> p = model.predict(rgb)
        >>> bool(p[15, 15] > 0.5 > p[2, 35])
        True
    """

    name, version = "Judd", 1
    fit_seconds_per_frame = 0.06
    predict_seconds_per_frame = 0.06

    def __init__(self, *, work_width: int = 160, samples: int = 50, C: float = 1.0, seed: int = 0) -> None:
        for key, value, low in (("work_width", work_width, 16), ("samples", samples, 1), ("seed", seed, 0)):
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
                raise EgonetError(f"{key} must be an int >= {low}, got {value!r}", field=key)
        if isinstance(C, bool) or not isinstance(C, (int, float)) or not C > 0:
            raise EgonetError(f"C must be a positive number, got {C!r}", field="C")
        self.work_width, self.samples, self.C, self.seed = int(work_width), int(samples), float(C), int(seed)

    def summarize(self, frame: TrainingFrame) -> Summary:
        """Features of up to ``samples`` pixels inside the mask and as many outside, and their labels."""
        features = judd_features(frame.rgb, work_width=self.work_width)
        wh, ww = features.shape[:2]
        inside = cv2.resize(frame.mask.astype(np.float32), (ww, wh), interpolation=cv2.INTER_AREA).ravel() >= 0.5
        rng = np.random.default_rng(self.seed)
        chosen = []
        for where in (np.flatnonzero(inside), np.flatnonzero(~inside)):
            chosen.append(rng.choice(where, size=min(self.samples, where.size), replace=False) if where.size else where)
        index = np.concatenate(chosen)
        return {"x": features.reshape(-1, len(FEATURES))[index], "y": inside[index]}

    def fit_summaries(self, summaries: Sequence[Summary]) -> Judd:
        from sklearn.linear_model import LogisticRegression

        x = np.concatenate([s["x"] for s in summaries]).astype(np.float64)
        y = np.concatenate([s["y"] for s in summaries])
        if y.all() or not y.any():
            raise EgonetError("Judd needs training pixels both inside and outside the masks", field="frames")
        mean, scale = x.mean(0), x.std(0)
        scale[scale < 1e-9] = 1.0
        model = LogisticRegression(C=self.C, class_weight="balanced", max_iter=500).fit((x - mean) / scale, y)
        self.mean_, self.scale_ = mean, scale
        self.coef_, self.intercept_ = model.coef_.ravel().astype(np.float64), np.asarray(model.intercept_, np.float64).ravel()
        return self

    def predict(self, rgb: np.ndarray, dhg: np.ndarray | None = None) -> np.ndarray:
        """The classifier's probability of every pixel of the grid, resized (bilinear) to the frame."""
        self.check_fitted()
        h, w = check_frame(rgb, dhg)
        features = judd_features(rgb, work_width=self.work_width)
        score = ((features - self.mean_) / self.scale_) @ self.coef_ + self.intercept_[0]
        p = (1.0 / (1.0 + np.exp(-score))).astype(np.float32)
        return np.clip(cv2.resize(p, (w, h), interpolation=cv2.INTER_LINEAR), 0.0, 1.0)
