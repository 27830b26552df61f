"""Handled+Viewed-Obj, the paper's "handled + viewed object" baseline.

The object region nearest the hands, else nearest the image centre.
:class:`HandledViewedObject` scores Felzenszwalb-Huttenlocher regions by
their distance to hands the caller gives (``near``; Suggest's "handled"
proposer gives none: the centre); :class:`HandledViewedObj`, the scored row,
finds the hands itself with a hand detector fitted per fold on frames with
``hand`` instances (:mod:`egonet.hands`), never with the scored frame's labels.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import cv2
import numpy as np

from egonet.baselines.protocol import Summary, TrainedBaseline, TrainingFrame
from egonet.baselines.simple import CenterPrior, check_positive
from egonet.errors import EgonetError
from egonet.hands import HAND_LABEL, HandModel
from egonet.saliency import check_frame as _check_frame

__all__ = ["HandledViewedObj", "HandledViewedObject"]


class HandledViewedObject:
    """"Handled + viewed object" (the paper's baseline): the object region nearest the hands, else nearest the centre.

    Object regions are Felzenszwalb-Huttenlocher segments (scikit-image) of
    a copy ``width`` pixels wide, kept when they cover between
    ``min_area`` and ``max_area`` of the frame (smaller are specks, larger
    are the floor, walls and tables). Each kept region scores
    ``exp(-d^2 / (2 sigma^2))``, ``d`` being its nearest pixel's distance to
    ``near`` (the hands, or what they hold) or, without it, to the image
    centre, as a fraction of the diagonal: the nearest object scores about
    1 and farther ones less, which gives a ranking for the PR curve.

    Args:
        width: Width of the working copy, pixels.
        scale: Felzenszwalb's ``scale`` (larger: larger segments).
        min_area: Smallest region kept, a fraction of the frame.
        max_area: Largest region kept, a fraction of the frame.
        sigma: Fall-off of the score with distance, a fraction of the diagonal.

    Example:
        >>> rgb = np.full((48, 64, 3), 200, np.uint8); rgb[18:30, 26:38] = (200, 40, 40)
        >>> p = HandledViewedObject().predict(rgb)
        >>> float(p[24, 32]), float(p[2, 2])
        (1.0, 0.0)
    """

    name, version = "Handled+Viewed-Obj", 1

    def __init__(
        self, *, width: int = 160, scale: float = 50.0, min_area: float = 0.002, max_area: float = 0.05, sigma: float = 0.1
    ) -> None:
        if isinstance(width, bool) or not isinstance(width, (int, np.integer)) or width < 16:
            raise EgonetError(f"width must be an int >= 16, got {width!r}", field="width")
        self.width = int(width)
        self.scale = check_positive(scale, "scale")
        self.min_area, self.max_area = check_positive(min_area, "min_area"), check_positive(max_area, "max_area")
        if not self.min_area < self.max_area <= 1:
            raise EgonetError(f"need 0 < min_area < max_area <= 1, got {min_area}, {max_area}", field="max_area")
        self.sigma = check_positive(sigma, "sigma")

    def regions(self, rgb: np.ndarray) -> np.ndarray:
        """The object regions' labels on the working copy, int32 ``(h, w)``; -1 where no object region is."""
        from skimage.segmentation import felzenszwalb

        h, w = rgb.shape[:2]
        ww = min(self.width, w)
        small = cv2.resize(rgb, (ww, max(1, round(h * ww / w))), interpolation=cv2.INTER_AREA)
        labels = felzenszwalb(small, scale=self.scale, sigma=0.8, min_size=max(4, round(self.min_area * small[..., 0].size)))
        area = np.bincount(labels.ravel()) / labels.size
        keep = (area >= self.min_area) & (area <= self.max_area)
        return np.where(keep[labels], labels, -1).astype(np.int32)

    def predict(
        self, rgb: np.ndarray, dhg: np.ndarray | None = None, *, near: np.ndarray | None = None, exclude: np.ndarray | None = None
    ) -> np.ndarray:
        """Score every object region by its distance to ``near`` (or the centre), float32 ``(H, W)`` in [0, 1].

        Args:
            rgb: uint8 ``(H, W, 3)``.
            dhg: Ignored; may be None.
            near: bool ``(H, W)``: the hands (a detector's, :class:`HandledViewedObj`);
                None or empty: the centre.
            exclude: bool ``(H, W)`` of pixels that are no object (the hands
                themselves): a region at least half inside it is dropped.

        Raises:
            EgonetError: A bad frame, or a mask not bool ``(H, W)``.
        """
        h, w = _check_frame(rgb, dhg)
        for name, mask in (("near", near), ("exclude", exclude)):
            if mask is not None and (not isinstance(mask, np.ndarray) or mask.dtype != np.bool_ or mask.shape != (h, w)):
                raise EgonetError(f"{name} must be None or a bool ({h}, {w}) mask", field=name)
        labels = self.regions(rgb)
        sh, sw = labels.shape
        shrink = lambda m: cv2.resize(m.astype(np.uint8), (sw, sh), interpolation=cv2.INTER_NEAREST).astype(bool)  # noqa: E731
        target = np.zeros((sh, sw), bool)
        if near is not None and near.any():
            target = shrink(near) | _shrunk_points(near, (sh, sw))
        else:
            target[(sh - 1) // 2 : sh // 2 + 1, (sw - 1) // 2 : sw // 2 + 1] = True
        distance = cv2.distanceTransform((~target).astype(np.uint8), cv2.DIST_L2, 5) / float(np.hypot(sh, sw))
        n = int(labels.max()) + 1
        if n == 0:
            return np.zeros((h, w), np.float32)
        inside = labels >= 0
        nearest = np.full(n, np.inf)
        np.minimum.at(nearest, labels[inside], distance[inside])
        score = np.exp(-(nearest**2) / (2 * self.sigma**2))
        if exclude is not None and exclude.any():
            covered = np.bincount(labels[inside], weights=shrink(exclude)[inside], minlength=n)
            score[covered >= 0.5 * np.bincount(labels[inside], minlength=n)] = 0.0
        out = np.where(inside, score[np.maximum(labels, 0)], 0.0).astype(np.float32)
        return cv2.resize(out, (w, h), interpolation=cv2.INTER_NEAREST)


def _shrunk_points(mask: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """A mask's pixels on a smaller grid (a thin mask can vanish under nearest-neighbour resizing)."""
    ys, xs = np.nonzero(mask)
    out = np.zeros(size, bool)
    out[(ys * size[0]) // mask.shape[0], (xs * size[1]) // mask.shape[1]] = True
    return out


class HandledViewedObj(TrainedBaseline):
    """The paper's Handled+Viewed-Obj: "objects around detected hands, else near the centre", hands from a detector.

    The paper (Table 2) describes the row as a method that "detects objects
    around hands; if no hands are detected it predicts objects near the
    center". Here the hands come from :class:`egonet.hands.HandModel`, a
    pixel-level hand detector after Li & Kitani (CVPR 2013) fitted on the
    training activities' frames whose instances are labelled ``hand`` (each
    fold its own; never the scored frame's labels); :meth:`detect_hands`
    keeps its confident blobs that enter from the frame's edge. The objects
    are :class:`HandledViewedObject`'s regions: with hands in view, those
    nearest the hands' tips rank first and those nearest the centre next (a
    region mostly made of hand pixels is no object); without, those nearest
    the centre (:meth:`predict`).

    Without hand labels (fewer than ``min_frames`` training frames with a
    ``hand`` instance) the detector is the skin-colour prior
    (:func:`egonet.hands.skin_probability`); :attr:`hands` says which, and the
    score table's row name repeats it.

    What is faithful: objects near the detected hands, else near the centre;
    a learned, pixel-level hand detector. What stands in (the paper gives no
    detail): the object regions (Felzenszwalb segments), the detector's
    classifier and features (see :mod:`egonet.hands`), the blobs kept and
    their tips, the distance fall-off ``sigma``, viewed objects ranked below
    handled ones (:data:`VIEWED_WEIGHT`) rather than left out, and the floor
    (:data:`FLOOR`).

    Args:
        width, scale, min_area, max_area, sigma: The object regions and their
            scores (:class:`HandledViewedObject`).
        hand_width, hidden, pixels_per_frame, min_frames, max_iter, seed:
            The hand detector (:class:`egonet.hands.HandModel`).
        hand_threshold: Hand probability from which a pixel is a hand.
        min_hand_area: Smallest hand blob kept, a fraction of the frame.
    """

    name = "Handled+Viewed-Obj"
    version = 1
    # Measured on the demo (280 frames, 320x240, 7 folds; docs/benchmarks.md): 73 ms and 42 ms CPU a frame.
    fit_seconds_per_frame = 0.08
    predict_seconds_per_frame = 0.05

    def __init__(
        self, *, width: int = 160, scale: float = 50.0, min_area: float = 0.002, max_area: float = 0.05, sigma: float = 0.1,
        hand_width: int = 80, hidden: int = 24, pixels_per_frame: int = 240, min_frames: int = 5, max_iter: int = 40,
        seed: int = 0, hand_threshold: float = 0.5, min_hand_area: float = 0.002,
    ) -> None:  # fmt: skip
        self.width, self.scale, self.min_area, self.max_area, self.sigma = width, scale, min_area, max_area, sigma
        self.hand_width, self.hidden, self.pixels_per_frame = hand_width, hidden, pixels_per_frame
        self.min_frames, self.max_iter, self.seed = min_frames, max_iter, seed
        self.hand_threshold, self.min_hand_area = hand_threshold, min_hand_area
        if not 0 < check_positive(hand_threshold, "hand_threshold") < 1:
            raise EgonetError(f"hand_threshold must be in (0, 1), got {hand_threshold}", field="hand_threshold")
        check_positive(min_hand_area, "min_hand_area")
        self._objects = HandledViewedObject(width=width, scale=scale, min_area=min_area, max_area=max_area, sigma=sigma)
        self._detector = HandModel(width=hand_width, hidden=hidden, pixels_per_frame=pixels_per_frame,
                                   min_frames=min_frames, max_iter=max_iter, seed=seed)  # fmt: skip

    @property
    def hands(self) -> str:
        """Where the hands come from: ``"skin colour"`` or ``"learned, n frames"`` (after fitting)."""
        self.check_fitted()
        return self._detector.name

    def summarize(self, frame: TrainingFrame) -> Summary:
        """The frame's sampled hand and non-hand pixels (none when it has no ``hand`` instance)."""
        hands = frame.masks_labelled(HAND_LABEL)
        union = np.logical_or.reduce(hands) if hands else None
        return self._detector.summarize(frame.rgb, frame.dhg, union)

    def fit_summaries(self, summaries: Sequence[Summary]) -> HandledViewedObj:
        self._detector.fit_summaries(summaries)
        for key, value in self._detector.state().items():
            setattr(self, f"hands_{key}_", value)
        return self

    def load_state(self, state: Mapping[str, np.ndarray]) -> HandledViewedObj:
        super().load_state(state)
        self._detector.load_state({k.removeprefix("hands_").removesuffix("_"): v for k, v in state.items()})
        return self

    def detect_hands(self, rgb: np.ndarray, dhg: np.ndarray | None = None) -> np.ndarray:
        """The detected hands, bool ``(H, W)``.

        The detector's probability from ``hand_threshold`` on, in blobs of at
        least ``min_hand_area`` of the frame that reach the bottom, left or
        right edge: in a first-person view the arms enter from there, and a
        skin-coloured speck in the middle of a table is no hand.
        """
        self.check_fitted()
        hands = self._detector.predict(rgb, dhg) >= self.hand_threshold
        h, w = hands.shape
        n, labels, stats, _ = cv2.connectedComponentsWithStats(hands.astype(np.uint8), connectivity=8)
        x, y, bw, bh, area = (stats[:, i] for i in range(5))
        keep = (area >= self.min_hand_area * hands.size) & ((y + bh >= h) | (x == 0) | (x + bw >= w))
        keep[0] = False
        return keep[labels]

    def predict(self, rgb: np.ndarray, dhg: np.ndarray | None = None) -> np.ndarray:
        """Handled objects first, then viewed ones, float32 ``(H, W)`` in [0, 1].

        With hands in view, each object region scores the larger of its score
        by distance to the hands' tips (each hand blob's top quarter of rows:
        where the fingers are when the arm comes up from the frame's edge)
        and half its score by distance to the centre (a viewed object ranks
        below a handled one); without hands, its score by distance to the
        centre. Every pixel keeps at least ``FLOOR`` times a centre Gaussian
        (:class:`CenterPrior`), so that the precision-recall curve reaches full
        recall instead of stopping at the regions' edge.
        """
        h, w = _check_frame(rgb, dhg)
        hands = self.detect_hands(rgb, dhg)
        viewed = self._objects.predict(rgb, None)
        out = viewed
        if hands.any():
            handled = self._objects.predict(rgb, None, near=_tips(hands), exclude=hands)
            out = np.maximum(handled, VIEWED_WEIGHT * viewed)
        return np.maximum(out, FLOOR * CenterPrior().predict(rgb, None)).astype(np.float32)


VIEWED_WEIGHT = 0.5
"""How a viewed object (near the centre) ranks against a handled one (near the hands), when hands are in view."""
FLOOR = 0.02
"""The floor of :meth:`HandledViewedObj.predict`, a fraction of the centre prior."""


def _tips(hands: np.ndarray) -> np.ndarray:
    """Each hand blob's pixels in its top quarter of rows (its fingers, the arm entering from below)."""
    n, labels = cv2.connectedComponents(hands.astype(np.uint8), connectivity=8)
    out = np.zeros_like(hands)
    for i in range(1, n):
        ys, xs = np.nonzero(labels == i)
        top = ys <= np.quantile(ys, 0.25)
        out[ys[top], xs[top]] = True
    return out
