"""salObj+depth: segments ranked by fixation, shape and depth features (Li, Hou, Koch, Rehg & Yuille, CVPR 2014).

"The secrets of salient object segmentation" ranks CPMC segments with a
random forest regressor trained to predict each segment's overlap with the
salient object, from fixation-map features (a fixation prediction model's
map inside and around the segment) and shape features. The EgoNet paper
"adapted [it] to also handle a depth input"; so do we, with depth features,
trained per leave-one-activity-out fold on the project's frames.

* Faithful: segments scored by a random forest's predicted overlap (IoU)
  with the action-object; fixation features from a fixation-prediction
  map, GBVS (one of the models the paper uses) inside the segment (mean,
  peak, its share of the map's mass) and around it (the neighbouring
  segments' mean, the contrast); shape features (area, centroid, bounding
  box, fill, compactness); the map is every pixel's largest predicted IoU.
* Depth (the EgoNet paper's adaptation, whose details it does not give):
  the segment's median depth, its contrast to the neighbouring segments'
  depth, and its median height above the floor (from the DHG's height
  channel); NaN, a value of its own to the forest, without depth.
* Stand-ins: the segments are the click study's region hierarchy
  (``egonet.baselines.regions``, shared with FP-MCG) instead of CPMC's
  figure-ground segments; GBVS only, not the paper's several fixation models.
"""

from __future__ import annotations

import cv2
import numpy as np

from egonet.baselines.regions import Proposals, RegionRegressor
from egonet.saliency import GraphSaliency

__all__ = ["FEATURES", "SalientObjectDepth"]

FEATURES = ("area", "centroid x", "centroid y", "bbox width", "bbox height", "bbox fill", "border / sqrt(area)",
            "GBVS mean", "GBVS peak", "GBVS mass share", "GBVS around", "GBVS contrast",
            "median depth", "depth contrast to neighbours", "median height above floor")  # fmt: skip
"""A segment's features, in column order (the last three NaN without depth)."""


class SalientObjectDepth(RegionRegressor):
    """salObj+depth (Li et al., CVPR 2014, with depth as in the EgoNet paper); see the module docstring.

    Example:
        >>> from egonet.baselines import TrainingFrame
        >>> rgb = np.full((48, 64, 3), 200, np.uint8); rgb[16:32, 20:40] = (30, 30, 200)
        >>> mask = np.zeros((48, 64), bool); mask[16:32, 20:40] = True
        >>> model = SalientObjectDepth(work_width=64, trees=5).fit([TrainingFrame(rgb, None, mask)] * 2)
        >>> p = model.predict(rgb)
        >>> bool(p[24, 30] > p[2, 2])
        True
    """

    name, version = "salObj+depth", 1
    fit_seconds_per_frame = predict_seconds_per_frame = 0.12

    def features(self, proposals: Proposals) -> np.ndarray:
        shape = proposals.shape()
        area = proposals.area()
        length, _ = proposals.border()
        fixation = GraphSaliency().predict(proposals.rgb).astype(np.float64)
        inside = proposals.mean(fixation)
        peak = np.concatenate([_region_max(lab, fixation) for lab in proposals.levels])
        share = proposals.sums(fixation) / max(float(fixation.sum()), 1e-9)
        around = proposals.surround(inside)
        if proposals.depth is not None:
            depth = proposals.median(proposals.depth)
            contrast = depth - proposals.surround(depth)
            height = proposals.median(proposals.height)
        else:
            depth = contrast = height = np.full(proposals.n, np.nan)
        return np.column_stack([shape, length / np.sqrt(area), inside, peak, share, around, inside - around,
                                depth, contrast, height])  # fmt: skip


def _region_max(labels: np.ndarray, values: np.ndarray) -> np.ndarray:
    out = np.full(int(labels.max()) + 1, -np.inf)
    np.maximum.at(out, labels.ravel(), values.ravel())
    return out
