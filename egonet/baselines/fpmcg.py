"""FP-MCG: MCG's region proposals ranked by a regressor trained on first-person frames (Arbeláez et al., CVPR 2014).

Multiscale Combinatorial Grouping builds a hierarchy of regions from
multiscale contours, combines them into proposals, and ranks them with a
random forest regressor trained to predict each proposal's overlap with an
object from its features (size, location, shape, contour strength). The
EgoNet paper's FP-MCG trains that ranking on its own first-person frames
with the action-objects as the objects; so do we, per leave-one-activity-out
fold (``egonet.baselines.regions`` holds the shared machinery).

* Faithful: proposals from a region hierarchy cut at several levels; a
  random forest regressing each proposal's IoU with the action-object from
  size, position, bounding box, boundary strength and colour features; the
  map is every pixel's largest predicted IoU among its proposals.
* Stand-ins: the hierarchy is the click study's
  (``egonet.clicks.region_hierarchy``: watershed regions of a single-scale
  colour gradient merged along weak boundaries) instead of MCG's multiscale
  gPb-style contours and ultrametric contour map, and proposals are its
  regions only, not MCG's combinations of two to four of them. Depth, where
  the frame has it, adds two features (the region's mean depth and its
  contrast to the neighbouring regions), as "depth where present".
"""

from __future__ import annotations

import cv2
import numpy as np

from egonet.baselines.regions import Proposals, RegionRegressor

__all__ = ["FEATURES", "FirstPersonMCG"]

FEATURES = ("area", "centroid x", "centroid y", "bbox width", "bbox height", "bbox fill", "border / sqrt(area)",
            "border strength", "interior strength", "border - interior strength", "L", "a", "b",
            "colour contrast to neighbours", "level", "mean depth", "depth contrast to neighbours")  # fmt: skip
"""A proposal's features, in column order (the last two NaN without depth)."""


class FirstPersonMCG(RegionRegressor):
    """FP-MCG (Arbeláez et al., CVPR 2014), its ranking trained on the project's frames; see the module docstring.

    Example:
        >>> from egonet.baselines import TrainingFrame
        >>> rgb = np.full((48, 64, 3), 200, np.uint8); rgb[16:32, 20:40] = (30, 30, 200)
        >>> mask = np.zeros((48, 64), bool); mask[16:32, 20:40] = True
        >>> model = FirstPersonMCG(work_width=64, trees=5).fit([TrainingFrame(rgb, None, mask)] * 2)
        >>> p = model.predict(rgb)
        >>> bool(p[24, 30] > p[2, 2])
        True
    """

    name, version = "FP-MCG", 1

    def features(self, proposals: Proposals) -> np.ndarray:
        shape = proposals.shape()
        area = proposals.area()
        length, border = proposals.border()
        interior = proposals.mean(proposals.strength)
        lab = cv2.cvtColor(proposals.rgb, cv2.COLOR_RGB2LAB).astype(np.float64)
        colour = np.column_stack([proposals.mean(lab[..., c]) for c in range(3)])
        around = np.column_stack([proposals.surround(colour[:, c]) for c in range(3)])
        level = np.concatenate([np.full(int(lab_.max()) + 1, i, np.float64) for i, lab_ in enumerate(proposals.levels)])
        if proposals.depth is not None:
            depth = proposals.mean(proposals.depth)
            depth_contrast = depth - proposals.surround(depth)
        else:
            depth = depth_contrast = np.full(proposals.n, np.nan)
        return np.column_stack([shape, length / np.sqrt(area), border, interior, border - interior, colour,
                                np.linalg.norm(colour - around, axis=1), level, depth, depth_contrast])  # fmt: skip
