"""Thin objects with true masks, and the NoC@90 protocol of interactive segmentation papers.

Used by ``tests/unit/test_grabcut_thin.py`` and ``bench/bench_grabcut.py --noc``.

Frames, every one 1408x1408 (the app's egocentric frame size):

* ``utensil_cases``: the three real first-person frames of
  ``../shared/data/egonet-samples/rgb`` (skipped when absent) with a metal
  utensil laid in: a fork (four tines), a knife, a spoon, and a pair of
  chopsticks on the third frame again, shaded across their width like
  metal, the edge softened as a camera's. The pasted shape is the true mask,
  exact to the pixel, so the thin parts (chopsticks 8-10 px wide; tines 9 px
  wide, 8 px apart; handles 18-24 px) are scored as they are;
* ``davis_cases``: the first frame of each window of ``tests/data/real_video``
  (real video with person-drawn masks: a camel's, a goat's, a dog's and
  cows' legs, a soapbox with its wheels and driver), upscaled.

``all_cases`` is those nine, the set issue 36's goal is measured on (and
the engine was tuned on). ``later_cases`` are the four later frames of
each window (20 frames, the same objects a few video frames on, never
tuned on): a check that a change helps the engine, not the nine frames.

``noc`` runs the protocol RITM and SAM report (NoC@90): the box is the first
interaction; each next one is a click at the interior-most point (the
distance transform's peak) of the largest error region, foreground if it is
missed object, background if it is a false positive; up to 20 interactions.
A click is a short brush stroke there (what a labeller drags in the
browser): the labelling page's brush (radius 1/80 of the frame's short side,
18 px at 1408x1408), narrowed to fit inside the region, dragged along the
region's long axis at most two radii each way while it stays inside.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np

from tests.realdata import EGONET_SAMPLES

REAL_VIDEO = Path(__file__).resolve().parent / "data" / "real_video"
SIZE = 1408
MAX_CLICKS = 20
TARGET = 0.9


@dataclasses.dataclass
class Case:
    """A frame with one true object."""

    name: str
    rgb: np.ndarray  # (H, W, 3) uint8
    truth: np.ndarray  # (H, W) bool


@dataclasses.dataclass
class Click:
    """One corrective interaction: a short stroke."""

    points: list[tuple[float, float]]
    label: str  # "fg" or "bg"
    radius: float


# ----------------------------------------------------------------- frames


def _utensil(kind: str, h: int, w: int, cx: float, cy: float, angle: float) -> np.ndarray:
    """A fork, knife or spoon lying at ``angle`` (radians) centred on ``(cx, cy)``: its bool mask ``(h, w)``."""
    # Drawn along +x in a local frame (length 640 px), then rotated into place.
    local = np.zeros((200, 800), np.uint8)
    y = 100
    if kind == "fork":
        cv2.line(local, (80, y), (470, y), 1, 22)  # handle
        cv2.fillPoly(local, [np.array([(470, y - 11), (540, y - 30), (560, y - 30), (560, y + 30), (540, y + 30),
                                       (470, y + 11)], np.int32)], 1)  # neck widening to the head
        for k in range(4):  # tines: 9 px wide, 8 px apart
            t = y - 30 + k * 17
            local[t : t + 9, 560:680] = 1
    elif kind == "knife":
        cv2.line(local, (80, y), (380, y), 1, 24)  # handle
        cv2.fillPoly(local, [np.array([(380, y - 8), (700, y - 14), (720, y - 4), (700, y + 10), (380, y + 8)],
                                      np.int32)], 1)  # blade, its back straight, its point rounded
    elif kind == "spoon":
        cv2.line(local, (80, y), (520, y), 1, 18)  # handle
        cv2.ellipse(local, (600, y), (85, 38), 0, 0, 360, 1, -1)  # bowl
    elif kind == "chopsticks":  # a pair, 8-10 px wide, their tips 10 px apart
        cv2.line(local, (60, y - 40), (740, y - 6), 1, 10)
        cv2.line(local, (60, y + 36), (740, y + 4), 1, 8)
    else:
        raise ValueError(kind)
    rot = cv2.getRotationMatrix2D((400, 100), np.degrees(angle), 1.0)
    rot[:, 2] += (cx - 400, cy - 100)
    return cv2.warpAffine(local, rot, (w, h), flags=cv2.INTER_NEAREST).astype(bool)


def _metal(rng: np.random.Generator, mask: np.ndarray, angle: float, base: np.ndarray) -> np.ndarray:
    """Metal-like colours: ``base`` shaded across the utensil's width, with a highlight and grain."""
    h, w = mask.shape
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    # Distance across the utensil's long axis (the axis runs along (cos a, -sin a) in image rows and columns).
    across = np.sin(angle) * xx + np.cos(angle) * yy
    shade = 0.8 + 0.3 * np.cos(across / 9.0) ** 2
    grain = rng.normal(0, 6, (h, w)).astype(np.float32)
    return np.clip(base[None, None, :] * shade[..., None] + grain[..., None], 0, 255)


def utensil_cases() -> list[Case]:
    """The first-person frames, each with a pasted utensil; none when ``../shared`` is absent."""
    folder = EGONET_SAMPLES / "rgb"
    if not folder.is_dir():
        return []
    cases = []
    frames = sorted(folder.glob("*.jpg"))
    for kind, seed, path in (("fork", 1, frames[0]), ("knife", 2, frames[1]), ("spoon", 3, frames[2]),
                             ("chopsticks", 4, frames[2])):
        rng = np.random.default_rng(seed)
        rgb = cv2.cvtColor(cv2.imread(str(path), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
        img = cv2.resize(rgb, (SIZE, SIZE), interpolation=cv2.INTER_CUBIC).astype(np.float32)
        angle = rng.uniform(-0.6, 0.6)
        cx, cy = rng.uniform(0.4, 0.6) * SIZE, rng.uniform(0.45, 0.65) * SIZE
        truth = _utensil(kind, SIZE, SIZE, cx, cy, angle)
        # A grey of the frame's own brightness, a little tinted: steel under the room's light.
        base = np.clip(img[truth].mean(axis=0) * 0.4 + rng.uniform(110, 170) + rng.normal(0, 8, 3), 0, 255)
        alpha = cv2.GaussianBlur(truth.astype(np.float32), (0, 0), 0.8)[..., None]
        img = img * (1 - alpha) + _metal(rng, truth, angle, base) * alpha
        img = cv2.GaussianBlur(img, (0, 0), 0.6) + rng.normal(0, 2.0, img.shape).astype(np.float32)
        cases.append(Case(f"{kind}-{path.stem}", np.clip(np.round(img), 0, 255).astype(np.uint8), truth))
    return cases


def davis_case(folder: Path, frame: int = 0) -> Case:
    """A frame of a real-video window (the first by default), upscaled, with its person-drawn mask.

    The first frame's case is named after the object (``camel``), a later one's
    after the object and the frame (``camel-00025``).
    """
    path = sorted(folder.glob("*.jpg"))[frame]
    rgb = cv2.cvtColor(cv2.imread(str(path), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
    mask = cv2.imread(str(path.with_suffix(".png")), cv2.IMREAD_GRAYSCALE)
    rgb = cv2.resize(rgb, (SIZE, SIZE), interpolation=cv2.INTER_CUBIC)
    truth = cv2.resize(mask, (SIZE, SIZE), interpolation=cv2.INTER_LINEAR) >= 128
    name = folder.name.split("-")[0]
    return Case(name if frame == 0 else f"{name}-{path.stem}", rgb, truth)


def _windows() -> list[Path]:
    return sorted(p for p in REAL_VIDEO.iterdir() if p.is_dir())


def davis_cases() -> list[Case]:
    """Every real-video window's first frame (``davis_case``)."""
    return [davis_case(p) for p in _windows()]


def all_cases() -> list[Case]:
    """The nine frames of the NoC@90 goal: the utensils (with ``../shared``) and the windows' first frames."""
    return utensil_cases() + davis_cases()


def later_cases() -> list[Case]:
    """Every later frame of each real-video window (20): the untuned check."""
    return [davis_case(p, k) for p in _windows() for k in range(1, len(list(p.glob("*.jpg"))))]


# ---------------------------------------------------------------- protocol


def loose_box(truth: np.ndarray, pad: float = 0.05) -> tuple[int, int, int, int]:
    """The object's bounds plus ``pad`` of its size each side (clipped to the frame)."""
    ys, xs = np.nonzero(truth)
    h, w = truth.shape
    px = pad * (xs.max() - xs.min() + 1)
    py = pad * (ys.max() - ys.min() + 1)
    return (max(0, int(xs.min() - px)), max(0, int(ys.min() - py)), min(w, int(xs.max() + 1 + px)),
            min(h, int(ys.max() + 1 + py)))


def click(mask: np.ndarray, truth: np.ndarray) -> Click | None:
    """The next click of the protocol, or None when the mask is exact."""
    max_radius = max(3, round(min(truth.shape) / 80))  # the labelling page's brush (static/js/label_state.js)
    max_half_length = 2 * max_radius
    best = None
    for label, err in (("fg", truth & ~mask), ("bg", mask & ~truth)):
        n, lab, stats, _ = cv2.connectedComponentsWithStats(err.view(np.uint8), connectivity=8)
        if n > 1:
            k = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
            area = int(stats[k, cv2.CC_STAT_AREA])
            if best is None or area > best[0]:
                x, y, bw, bh = (int(v) for v in stats[k, :4])
                best = (area, label, lab[y : y + bh, x : x + bw] == k, (x, y))
    if best is None:
        return None
    _, label, comp, (ox, oy) = best
    dist = cv2.distanceTransform(np.pad(comp, 1).view(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)[1:-1, 1:-1]
    y, x = np.unravel_index(int(np.argmax(dist)), dist.shape)
    radius = float(np.clip(dist[y, x] - 1.0, 0.5, max_radius))
    ys, xs = np.nonzero(comp)
    centre = (float(x + ox), float(y + oy))
    if len(xs) < 3:
        return Click([centre], label, radius)
    direction = np.linalg.eigh(np.cov(np.stack([xs, ys])))[1][:, -1]
    ends = []
    for sign in (-1.0, 1.0):
        end = centre
        for step in range(1, max_half_length + 1):
            px, py = x + sign * step * direction[0], y + sign * step * direction[1]
            ix, iy = int(round(px)), int(round(py))
            if not (0 <= iy < dist.shape[0] and 0 <= ix < dist.shape[1]) or dist[iy, ix] < radius + 0.5:
                break
            end = (float(px + ox), float(py + oy))
        ends.append(end)
    return Click([ends[0], centre, ends[1]], label, radius)


def iou(a: np.ndarray, b: np.ndarray) -> float:
    union = np.count_nonzero(a | b)
    return 1.0 if union == 0 else np.count_nonzero(a & b) / union


@dataclasses.dataclass
class NocRun:
    """One object's run: interactions to reach the target (None: not within ``MAX_CLICKS``) and the IoUs."""

    noc: int | None
    ious: list[float]
    clicks: list[Click]
    masks: list[np.ndarray]  # after each interaction (only when asked to keep them)


def noc(box: Callable[[tuple[int, int, int, int]], np.ndarray],
        stroke: Callable[[Click], np.ndarray], truth: np.ndarray, *, keep_masks: bool = False) -> NocRun:
    """Interactions to IoU ``TARGET`` (the box first), at most ``MAX_CLICKS``.

    Args:
        box: Starts the object from a box, returns the mask.
        stroke: Applies a click, returns the mask.
        truth: The true bool mask.
        keep_masks: Keep the mask after every interaction.
    """
    mask = box(loose_box(truth))
    ious, clicks, masks = [iou(mask, truth)], [], [mask] if keep_masks else []
    while ious[-1] < TARGET and len(ious) < MAX_CLICKS:
        c = click(mask, truth)
        if c is None:
            break
        clicks.append(c)
        mask = stroke(c)
        ious.append(iou(mask, truth))
        if keep_masks:
            masks.append(mask)
    reached = next((i + 1 for i, v in enumerate(ious) if v >= TARGET), None)
    return NocRun(reached, ious, clicks, masks)


def noc_score(run: NocRun) -> int:
    """The run's NoC as the papers average it: ``MAX_CLICKS`` when the target was not reached."""
    return MAX_CLICKS if run.noc is None else run.noc
