"""AOP, the paper's Action-Object Prior: the mean of the training masks.

Faithful: the paper's AOP is the average action-object mask of the training
frames, a map that ignores the scored frame's content. Under
leave-one-activity-out it is fitted inside each fold, on the other
activities' masks only. The mean is taken on a small fixed grid (60 x 80 by
default, the frames' 4:3 aspect) and resized bilinearly to each frame.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import cv2
import numpy as np

from egonet.baselines.protocol import Summary, TrainedBaseline, TrainingFrame
from egonet.errors import EgonetError
from egonet.saliency import check_frame

__all__ = ["ActionObjectPrior"]


def check_size(size: Sequence[int], name: str) -> tuple[int, int]:
    if (
        not isinstance(size, (tuple, list))
        or len(size) != 2
        or any(isinstance(s, bool) or not isinstance(s, (int, np.integer)) or s < 1 for s in size)
    ):
        raise EgonetError(f"{name} must be (height, width) with positive ints, got {size!r}", field=name)
    return int(size[0]), int(size[1])


class ActionObjectPrior(TrainedBaseline):
    """Action-Object Prior (AOP): the mean training mask (see the module docstring).

    Args:
        size: The grid the masks are averaged on, as (height, width).

    Raises:
        EgonetError: If ``size`` is not two positive ints.

    Example:
        >>> masks = [np.eye(2, dtype=bool), np.ones((2, 2), dtype=bool)]
        >>> ActionObjectPrior(size=(2, 2)).fit_masks(masks).prior_
        array([[1. , 0.5],
               [0.5, 1. ]], dtype=float32)
    """

    name, version = "AOP", 1
    fit_seconds_per_frame = predict_seconds_per_frame = 0.001

    def __init__(self, *, size: tuple[int, int] = (60, 80)) -> None:
        self.size = check_size(size, "size")

    def _cover(self, mask: np.ndarray, i: int = 0) -> np.ndarray:
        mask = np.asarray(mask)
        if mask.dtype != np.bool_ or mask.ndim != 2 or mask.size == 0:
            raise EgonetError(f"masks[{i}] must be a non-empty bool (H, W) mask, got {mask.dtype} {mask.shape}", field="masks")
        h, w = self.size
        cover = mask.astype(np.float32)
        # Area interpolation: the fraction of each grid cell the mask covers.
        return cover if cover.shape == (h, w) else cv2.resize(cover, (w, h), interpolation=cv2.INTER_AREA)

    def summarize(self, frame: TrainingFrame) -> Summary:
        """The frame's mask on the grid, float32 (h, w)."""
        return {"cover": self._cover(frame.mask)}

    def fit_summaries(self, summaries: Sequence[Summary]) -> ActionObjectPrior:
        if not summaries:
            raise EgonetError("masks is empty: fit the prior on at least one training mask", field="masks")
        total = np.zeros(self.size, np.float64)
        for s in summaries:
            total += s["cover"]
        self.prior_ = np.clip(total / len(summaries), 0.0, 1.0).astype(np.float32)
        return self

    def fit_masks(self, masks: Iterable[np.ndarray]) -> ActionObjectPrior:
        """Fit on bare masks (bool (H_i, W_i) each, sizes may differ), consumed one at a time; returns self."""
        return self.fit_summaries([{"cover": self._cover(m, i)} for i, m in enumerate(masks)])

    def predict(self, rgb: np.ndarray, dhg: np.ndarray | None = None) -> np.ndarray:
        """The prior resized (bilinear) to the frame, float32 (H, W); only the frame's size is used."""
        self.check_fitted()
        h, w = check_frame(rgb, dhg)
        if self.prior_.shape == (h, w):
            return self.prior_.astype(np.float32, copy=True)
        out = cv2.resize(self.prior_.astype(np.float32), (w, h), interpolation=cv2.INTER_LINEAR)
        return np.clip(out, 0.0, 1.0, out=out)
