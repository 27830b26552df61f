"""Region proposals scored by a learned regressor: what FP-MCG and salObj+depth share.

Both baselines rank *segments*: the regions of a hierarchy, each given a
predicted overlap (IoU) with the action-object by a random forest trained
on the training frames' regions and their true overlaps; the map gives
every pixel the **largest** predicted overlap of the proposals that contain
it (with a hierarchy, one region per level: the best level wins), resized
to the frame with nearest neighbour.

* Proposals: the click study's region hierarchy
  (``egonet.clicks.region_hierarchy``: fine watershed regions of the colour
  boundary map merged along their weakest boundaries), cut at ``levels``
  on a copy ``work_width`` pixels wide; every region of every level is a
  proposal (duplicates across levels are kept: a region that survives
  several levels is a stable one).
* Region statistics are computed with ``bincount`` over the label maps
  (area, moments, bounding box, border and interior boundary strength,
  means of any per-pixel map) and a region's *surround* is its neighbours
  in the same level, weighted by the length of the shared border.
* The forest is scikit-learn's ``RandomForestRegressor``; what is kept is
  its trees as plain arrays (:func:`forest_state`), evaluated by
  :func:`forest_predict`, which gives scikit-learn's predictions exactly.

A subclass says which features a region has (:meth:`RegionRegressor.features`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from egonet.baselines.protocol import Summary, TrainedBaseline, TrainingFrame
from egonet.clicks import boundary_strength, region_hierarchy
from egonet.dhg import decode_dhg
from egonet.errors import EgonetError
from egonet.saliency import check_frame

__all__ = ["MISSING", "Proposals", "RegionRegressor", "forest_predict", "forest_state"]

MISSING = -10.0
"""What a missing feature (no depth) becomes for the forest: a value no real feature takes, so trees can split it off."""


def forest_state(forest) -> dict[str, np.ndarray]:
    """A fitted scikit-learn forest (or tree) regressor's trees as plain arrays, all trees' nodes end to end.

    ``left``/``right`` are global node indices (-1 at leaves), ``feature``
    and ``threshold`` the split (``x[feature] <= threshold`` goes left),
    ``value`` the node's prediction, ``roots`` each tree's first node.
    """
    trees = [est.tree_ for est in getattr(forest, "estimators_", [forest])]
    offsets = np.cumsum([0] + [t.node_count for t in trees])[:-1]
    left = np.concatenate([np.where(t.children_left >= 0, t.children_left + o, -1) for t, o in zip(trees, offsets, strict=True)])
    right = np.concatenate([np.where(t.children_right >= 0, t.children_right + o, -1) for t, o in zip(trees, offsets, strict=True)])
    return {
        "left": left.astype(np.int32),
        "right": right.astype(np.int32),
        "feature": np.concatenate([np.maximum(t.feature, 0) for t in trees]).astype(np.int32),
        "threshold": np.concatenate([t.threshold for t in trees]).astype(np.float64),
        "value": np.concatenate([t.value.reshape(t.node_count, -1)[:, 0] for t in trees]).astype(np.float64),
        "roots": offsets.astype(np.int32),
    }


def forest_predict(state: dict[str, np.ndarray], x: np.ndarray) -> np.ndarray:
    """The forest's prediction for each row of ``x`` (N, F): the mean over trees of the leaf each row reaches.

    Example:
        >>> state = {"left": np.array([1, -1, -1]), "right": np.array([2, -1, -1]), "feature": np.array([0, 0, 0]),
        ...          "threshold": np.array([0.5, 0, 0]), "value": np.array([0.0, 10.0, 20.0]), "roots": np.array([0])}
        >>> forest_predict(state, np.array([[0.2], [0.9]])).tolist()
        [10.0, 20.0]
    """
    x = np.asarray(x, np.float32)  # scikit-learn's trees compare float32 features with float64 thresholds
    node = np.broadcast_to(state["roots"], (x.shape[0], state["roots"].size)).copy()
    rows = np.arange(x.shape[0])[:, None]
    while True:
        inner = state["left"][node] >= 0
        if not inner.any():
            break
        go_left = x[rows, state["feature"][node]] <= state["threshold"][node]
        step = np.where(go_left, state["left"][node], state["right"][node])
        node = np.where(inner, step, node)
    return state["value"][node].mean(axis=1)


@dataclass
class Proposals:
    """A frame's region proposals on the working grid.

    Attributes:
        levels: One label map per level, int32 (h, w), labels 0..n_l-1.
        first: Index of each level's first proposal (proposal ``first[l] + label``).
        strength: The colour boundary map, float (h, w).
        rgb: The working copy, uint8 (h, w, 3).
        depth, height: Metres (h, w) from the DHG, NaN where missing; None without DHG.
    """

    levels: list[np.ndarray]
    first: np.ndarray
    strength: np.ndarray
    rgb: np.ndarray
    depth: np.ndarray | None
    height: np.ndarray | None

    @property
    def n(self) -> int:
        return int(self.first[-1] + self.levels[-1].max() + 1)

    def sums(self, values: np.ndarray) -> np.ndarray:
        """Each proposal's sum of a per-pixel map (h, w), (n,)."""
        return np.concatenate([np.bincount(lab.ravel(), weights=values.ravel(), minlength=int(lab.max()) + 1) for lab in self.levels])

    def area(self) -> np.ndarray:
        return self.sums(np.ones(self.levels[0].shape))

    def mean(self, values: np.ndarray) -> np.ndarray:
        """Each proposal's mean of a per-pixel map; NaNs (missing depth) left out (NaN where all are)."""
        valid = np.isfinite(values)
        total = self.sums(np.where(valid, values, 0.0))
        count = self.sums(valid.astype(np.float64))
        return np.where(count > 0, total / np.maximum(count, 1), np.nan)

    def median(self, values: np.ndarray) -> np.ndarray:
        """Each proposal's median of a per-pixel map, NaNs left out (NaN where all are)."""
        out = []
        for lab in self.levels:
            n = int(lab.max()) + 1
            labels, flat = lab.ravel(), values.ravel()
            keep = np.isfinite(flat)
            labels, flat = labels[keep], flat[keep]
            order = np.lexsort((flat, labels))
            labels, flat = labels[order], flat[order]
            start = np.searchsorted(labels, np.arange(n))
            count = np.bincount(labels, minlength=n)
            lo = flat[np.minimum(start + (count - 1) // 2, max(flat.size - 1, 0))] if flat.size else np.zeros(n)
            hi = flat[np.minimum(start + count // 2, max(flat.size - 1, 0))] if flat.size else np.zeros(n)
            out.append(np.where(count > 0, (lo + hi) / 2, np.nan))
        return np.concatenate(out)

    def border(self) -> tuple[np.ndarray, np.ndarray]:
        """Each proposal's border length and its mean boundary strength along the border."""
        length, strength = [], []
        for lab in self.levels:
            edge = np.zeros(lab.shape, bool)
            edge[:-1] |= lab[:-1] != lab[1:]
            edge[1:] |= lab[1:] != lab[:-1]
            edge[:, :-1] |= lab[:, :-1] != lab[:, 1:]
            edge[:, 1:] |= lab[:, 1:] != lab[:, :-1]
            n = int(lab.max()) + 1
            count = np.bincount(lab[edge], minlength=n).astype(np.float64)
            length.append(count)
            strength.append(np.bincount(lab[edge], weights=self.strength[edge], minlength=n) / np.maximum(count, 1))
        return np.concatenate(length), np.concatenate(strength)

    def surround(self, per_proposal: np.ndarray) -> np.ndarray:
        """Each proposal's neighbours' mean of a per-proposal value, weighted by shared border (its own value when alone)."""
        out = np.array(per_proposal, dtype=np.float64, copy=True)
        for lab, first in zip(self.levels, self.first, strict=True):
            a = np.concatenate([lab[:, :-1].ravel(), lab[:-1].ravel()])
            b = np.concatenate([lab[:, 1:].ravel(), lab[1:].ravel()])
            apart = a != b
            a, b = np.concatenate([a[apart], b[apart]]), np.concatenate([b[apart], a[apart]])
            value = per_proposal[first + b]
            valid = np.isfinite(value)
            n = int(lab.max()) + 1
            weight = np.bincount(a[valid], minlength=n).astype(np.float64)
            total = np.bincount(a[valid], weights=value[valid], minlength=n)
            out[first : first + n] = np.where(weight > 0, total / np.maximum(weight, 1), per_proposal[first : first + n])
        return out

    def shape(self) -> np.ndarray:
        """Per proposal: area (share of the frame), centroid x and y, bbox width and height, bbox fill, (n, 6)."""
        h, w = self.levels[0].shape
        y, x = np.mgrid[0:h, 0:w].astype(np.float64)
        area = self.area()
        cx, cy = self.sums(x) / area / w, self.sums(y) / area / h
        boxes = []
        for lab in self.levels:
            n = int(lab.max()) + 1
            lo_x, hi_x = np.full(n, w, np.float64), np.zeros(n)
            lo_y, hi_y = np.full(n, h, np.float64), np.zeros(n)
            np.minimum.at(lo_x, lab.ravel(), x.ravel())
            np.maximum.at(hi_x, lab.ravel(), x.ravel())
            np.minimum.at(lo_y, lab.ravel(), y.ravel())
            np.maximum.at(hi_y, lab.ravel(), y.ravel())
            boxes.append(np.stack([(hi_x - lo_x + 1) / w, (hi_y - lo_y + 1) / h], axis=1))
        box = np.concatenate(boxes)
        fill = area / (box[:, 0] * w * box[:, 1] * h)
        return np.column_stack([area / (h * w), cx, cy, box, fill])

    def spread(self, score: np.ndarray) -> np.ndarray:
        """A per-pixel map (h, w): the largest score of the proposals containing each pixel."""
        out = np.full(self.levels[0].shape, -np.inf)
        for lab, first in zip(self.levels, self.first, strict=True):
            np.maximum(out, score[first + lab], out=out)
        return out


class RegionRegressor(TrainedBaseline):
    """Proposals from the region hierarchy, ranked by a random forest's predicted IoU (see the module docstring).

    Args:
        work_width: Width of the working copy, pixels.
        levels: The hierarchy's cuts (``egonet.clicks.region_hierarchy``), increasing.
        fine_regions: Watershed regions before merging.
        trees: Trees of the forest.
        depth: Their largest depth.
        seed: The forest's seed.
    """

    fit_seconds_per_frame = 0.08
    predict_seconds_per_frame = 0.08

    def __init__(
        self,
        *,
        work_width: int = 160,
        levels: tuple[float, ...] = (0.15, 0.3, 0.5, 0.8),
        fine_regions: int = 200,
        trees: int = 30,
        depth: int = 10,
        seed: int = 0,
    ) -> None:
        for key, value, low in (("work_width", work_width, 16), ("fine_regions", fine_regions, 2), ("trees", trees, 1),
                                ("depth", depth, 1), ("seed", seed, 0)):  # fmt: skip
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
                raise EgonetError(f"{key} must be an int >= {low}, got {value!r}", field=key)
        levels = tuple(float(v) for v in levels)
        if not levels or list(levels) != sorted(levels) or levels[0] <= 0:
            raise EgonetError(f"levels must be positive and increasing, got {levels!r}", field="levels")
        self.work_width, self.levels, self.fine_regions = int(work_width), levels, int(fine_regions)
        self.trees, self.depth, self.seed = int(trees), int(depth), int(seed)

    def proposals(self, rgb: np.ndarray, dhg: np.ndarray | None) -> Proposals:
        """The frame's proposals on a copy ``work_width`` wide."""
        h, w = check_frame(rgb, dhg)
        ww = min(self.work_width, w)
        wh = max(2, round(h * ww / w))
        work = cv2.resize(rgb, (ww, wh), interpolation=cv2.INTER_AREA)
        strength = boundary_strength(work)
        levels = [_contiguous(lab) for lab in region_hierarchy(work, levels=self.levels, fine_regions=self.fine_regions, strength=strength)]
        first = np.cumsum([0] + [int(lab.max()) + 1 for lab in levels])[:-1]
        depth = height = None
        if dhg is not None:
            decoded = decode_dhg(cv2.resize(dhg, (ww, wh), interpolation=cv2.INTER_NEAREST))  # codes are not averaged
            depth, height = decoded.depth.astype(np.float64), decoded.height.astype(np.float64)
        return Proposals(levels, first, strength, work, depth, height)

    def features(self, proposals: Proposals) -> np.ndarray:
        """Each proposal's features, float (n, F); a subclass says which."""
        raise NotImplementedError

    def summarize(self, frame: TrainingFrame) -> Summary:
        """The frame's proposals' features and their IoU with its action-object mask."""
        props = self.proposals(frame.rgb, frame.dhg)
        h, w = props.levels[0].shape
        mask = cv2.resize(frame.mask.astype(np.float32), (w, h), interpolation=cv2.INTER_AREA) >= 0.5
        inter = props.sums(mask.astype(np.float64))
        iou = inter / np.maximum(props.area() + mask.sum() - inter, 1.0)
        return {"x": self.features(props).astype(np.float32), "y": iou.astype(np.float32)}

    def fit_summaries(self, summaries: Sequence[Summary]) -> RegionRegressor:
        from sklearn.ensemble import RandomForestRegressor

        x = np.concatenate([s["x"] for s in summaries])
        y = np.concatenate([s["y"] for s in summaries])
        forest = RandomForestRegressor(n_estimators=self.trees, max_depth=self.depth, min_samples_leaf=5, max_features=0.5,
                                       max_samples=min(1.0, 20_000 / max(len(y), 1)), random_state=self.seed, n_jobs=1)  # fmt: skip
        forest.fit(np.nan_to_num(x, nan=MISSING), y)
        for key, value in forest_state(forest).items():
            setattr(self, f"forest_{key}_", value)
        return self

    def predict(self, rgb: np.ndarray, dhg: np.ndarray | None = None) -> np.ndarray:
        """Every pixel's largest predicted IoU among the proposals containing it, float32 (H, W) in [0, 1]."""
        self.check_fitted()
        h, w = check_frame(rgb, dhg)
        props = self.proposals(rgb, dhg)
        state = {key: getattr(self, f"forest_{key}_") for key in ("left", "right", "feature", "threshold", "value", "roots")}
        score = forest_predict(state, np.nan_to_num(self.features(props), nan=MISSING))
        out = np.clip(props.spread(score), 0.0, 1.0).astype(np.float32)
        return cv2.resize(out, (w, h), interpolation=cv2.INTER_NEAREST)


def _contiguous(labels: np.ndarray) -> np.ndarray:
    """Labels renumbered 0..n-1 in order."""
    _, inverse = np.unique(labels, return_inverse=True)
    return inverse.reshape(labels.shape).astype(np.int32)
