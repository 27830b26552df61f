"""Benchmark: interactive GrabCut session against plain full-resolution GrabCut.

A simulated annotator draws a slightly loose box around a known object (3-8 %
of its size each side), then places corrective strokes, each on the largest
error region of the current mask: a foreground stroke through the largest
connected component of false negatives, or a background stroke through the
largest one of false positives, along the component's long axis through the
point where its distance transform peaks, with a radius (at most 8 px) that
keeps the stroke inside the component. Both methods get the same policy; the
strokes each receives depend on its own errors, as they would for a person.
Each method is also replayed with the other's box and strokes ("same
strokes"), so the comparison holds for identical input too. Each also gets a
box through the object (the left 60 % of its loose box), scored by IoU with
the object's part inside that box.

* session: ``egonet.grabcut.GrabCutSession`` (``box``, then ``stroke``).
* plain: ``cv2.grabCut`` on the whole frame, ``GC_INIT_WITH_RECT`` with 5
  iterations for the box; after each stroke the stroke pixels are set to
  ``GC_FGD``/``GC_BGD`` and ``GC_INIT_WITH_MASK`` runs 2 iterations (what
  OpenCV's interactive sample does).

Frames with a known true object:

* ``synthetic``: 1280x960 renders made here (textured background and a table
  edge, an irregular textured and shaded object with a thick curved arm whose
  colours are partly a background colour moved a little, clutter of the same
  colours, sometimes a skin-coloured occluder over the object's edge, camera
  blur and noise), a few seeds;
* ``real``: the first-person frames in ``shared/data/egonet-samples/rgb``
  (514x386) upscaled to 1280x960 with a synthetic textured object pasted in;
  its mask is the truth (the real frames have no masks of their own); skipped
  when the folder is missing;
* ``demo``: ``egonet.synth.render_frame`` frames at 1280x960, when that module
  exists (truth: the action-object mask; the frames change when that module's
  renderer does);
* one 1920x1440 synthetic frame ("and larger").

Then the speed targets on real frames (``real_cases``): the real RGB-D frame
``shared/data/rgbd-primesense`` 00001 (a white chair before a white wall;
truth drawn by hand) with and without its depth, and the first-person frames
with a pasted object, at 640x480 and 1408x1408, each with a loose box, a
tight box (2 px each side) and a box through the object, then up to 5
strokes; plain ``cv2.grabCut`` on the same boxes.

And NoC@90 on thin objects (``--noc``): the protocol of interactive
segmentation papers (RITM, SAM) on ``tests/thin_objects.py``'s frames (real
first-person frames with a fork, a knife and a spoon laid in; real video
with legs and wheels), 1408x1408: the box is the first interaction, each
next one a short stroke at the interior-most point of the largest error
region, up to 20. It runs the engine of this tree and, in a subprocess on
the same frames, the engine of ``--before`` (a git revision, default
``main``: its ``egonet/`` taken out with ``git archive``), and prints per
object the interactions to IoU 0.9, the mean (a miss counts 20), CPU ms,
and how many strokes changed pixels far from themselves (more than
``FAR`` px from the stroke and not joined to it through changed pixels).
The mean is given for the nine frames of the goal and, apart, for the 20
later frames of the same videos (``thin_objects.later_cases``), which no
parameter was tuned on.

Latency runs on one thread (``cv2.setNumThreads(1)``, one BLAS thread; the
target is per core) and is reported twice: wall clock, and this process's CPU
time, which other load on a shared machine inflates far less; the load
average is printed at the start and the end.

Run from the repository root::

    .venv/bin/python bench/bench_grabcut.py            # everything (minutes)
    .venv/bin/python bench/bench_grabcut.py --cross    # + plain on the session's strokes
    .venv/bin/python bench/bench_grabcut.py --quick    # 2 synthetic frames
    .venv/bin/python bench/bench_grabcut.py --no-plain # session only (seconds)
    .venv/bin/python bench/bench_grabcut.py --real-only --no-plain  # real frames, depth, speed targets
    .venv/bin/python bench/bench_grabcut.py --noc      # NoC@90 on thin objects, this tree against main
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib.util
import os
import sys
import time

# One thread for numpy's BLAS too (set before numpy loads): the targets are per core.
for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_name, "1")
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))
if os.environ.get("EGONET_BENCH_ENGINE"):
    # ``--noc``'s run of the older engine: its egonet/ first, the tests' frames from this tree.
    sys.path.insert(0, os.environ["EGONET_BENCH_ENGINE"])

from egonet.grabcut import GrabCutSession, stroke_footprint  # noqa: E402
from tests import thin_objects  # noqa: E402
from tests.realdata import chair_truth  # noqa: E402

SHARED = Path(__file__).resolve().parents[1].parent / "shared"
REAL_FRAMES = SHARED / "data" / "egonet-samples" / "rgb"
RGBD_FRAMES = SHARED / "data" / "rgbd-primesense"
BIG = (1408, 1408)  # the large real-frame case (w, h)


@dataclasses.dataclass
class Frame:
    """A test image with its true object."""

    name: str
    rgb: np.ndarray  # (H, W, 3) uint8
    truth: np.ndarray  # (H, W) bool
    depth: np.ndarray | None = None  # (H, W) float metres, NaN where missing


@dataclasses.dataclass
class Stroke:
    """One simulated annotator stroke in full-resolution pixel coordinates."""

    points: list[tuple[float, float]]
    label: str
    radius: float


# --------------------------------------------------------------------------
# Scenes


def _noise(rng: np.random.Generator, h: int, w: int, cell: float) -> np.ndarray:
    """Smooth value noise in [0, 1], features about ``cell`` pixels wide."""
    gh, gw = int(h / cell) + 3, int(w / cell) + 3
    grid = rng.random((gh, gw)).astype(np.float32)
    big = cv2.resize(grid, (int(gw * cell), int(gh * cell)), interpolation=cv2.INTER_CUBIC)
    oy, ox = rng.integers(0, int(cell) + 1, size=2)
    out = big[oy : oy + h, ox : ox + w]
    lo, hi = out.min(), out.max()
    return (out - lo) / max(hi - lo, 1e-6)


def _textured(rng: np.random.Generator, h: int, w: int, colours: np.ndarray, cell: float,
              grain: float) -> np.ndarray:
    """A float (H, W, 3) texture blending ``colours`` (K, 3) by noise fields."""
    weights = np.stack([_noise(rng, h, w, cell) ** 2 for _ in colours], axis=-1)
    weights /= weights.sum(axis=-1, keepdims=True) + 1e-6
    img = np.einsum("hwk,kc->hwc", weights, colours.astype(np.float32))
    fine = (_noise(rng, h, w, 3.0) - 0.5)[..., None] * grain
    return img + fine


def _blob(rng: np.random.Generator, h: int, w: int, cx: float, cy: float, radius: float,
          wobble: float) -> np.ndarray:
    """An irregular star-convex shape as a bool (H, W) mask."""
    theta = np.linspace(0, 2 * np.pi, 360, endpoint=False)
    r = np.ones_like(theta)
    for k in range(2, 8):
        r += wobble * rng.normal() / k * np.cos(k * theta + rng.uniform(0, 2 * np.pi))
    r = radius * np.clip(r, 0.35, None)
    aspect = rng.uniform(0.7, 1.3)
    pts = np.stack([cx + r * np.cos(theta) * aspect, cy + r * np.sin(theta) / aspect], axis=1)
    mask = np.zeros((h, w), np.uint8)
    cv2.fillPoly(mask, [np.round(pts * 16).astype(np.int32)], 1, cv2.LINE_8, shift=4)
    return mask.astype(bool)


def _object_mask(rng: np.random.Generator, h: int, w: int, cx: float, cy: float,
                 radius: float) -> np.ndarray:
    """Body blob plus a handle (a thick curved arm) so the shape is irregular."""
    mask = _blob(rng, h, w, cx, cy, radius, wobble=0.5)
    angle = rng.uniform(0, 2 * np.pi)
    length = radius * rng.uniform(0.9, 1.4)
    thick = max(6, int(radius * rng.uniform(0.10, 0.2)))
    bend = rng.uniform(-0.6, 0.6)
    t = np.linspace(0.3, 1.0, 20)
    ang = angle + bend * t
    pts = np.stack([cx + length * t * np.cos(ang), cy + length * t * np.sin(ang)], axis=1)
    arm = np.zeros((h, w), np.uint8)
    cv2.polylines(arm, [np.round(pts).astype(np.int32)], False, 1, thick)
    return mask | arm.astype(bool)


def _composite(base: np.ndarray, layer: np.ndarray, mask: np.ndarray, soft: float) -> np.ndarray:
    alpha = cv2.GaussianBlur(mask.astype(np.float32), (0, 0), soft)[..., None]
    return base * (1 - alpha) + layer * alpha


def _paint_object(rng: np.random.Generator, img: np.ndarray, bg_colours: np.ndarray,
                  cx: float, cy: float, radius: float, soft: float) -> tuple[np.ndarray, np.ndarray]:
    """Paint a textured, shaded object; return the image and its true mask."""
    h, w = img.shape[:2]
    mask = _object_mask(rng, h, w, cx, cy, radius)
    # Distinct but not trivially separable: one object colour is a background
    # colour moved by a modest offset, the other is its own.
    near = bg_colours[rng.integers(len(bg_colours))] + rng.normal(0, 45, 3)
    own = rng.uniform(40, 220, 3)
    colours = np.clip(np.stack([near, own, 0.6 * near + 0.4 * own]), 0, 255)
    tex = _textured(rng, h, w, colours, cell=rng.uniform(20, 60), grain=25)
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    light = 0.8 + 0.35 * np.clip(((xx - cx) * 0.6 - (yy - cy) * 0.8) / (radius * 2) + 0.5, 0, 1)
    tex *= light[..., None]
    img = _composite(img, tex, mask, soft)
    truth = mask.copy()
    # Sometimes a skin-coloured occluder (a hand) covers part of the edge.
    if rng.random() < 0.6:
        a = rng.uniform(0, 2 * np.pi)
        hx, hy = cx + radius * np.cos(a), cy + radius * np.sin(a)
        hand = _blob(rng, h, w, hx, hy, radius * 0.35, wobble=0.3)
        skin = np.array([[200, 150, 120], [170, 120, 95]], np.float32) + rng.normal(0, 10, (2, 3))
        img = _composite(img, _textured(rng, h, w, skin, 30, 12), hand, soft)
        truth &= ~hand
    return img, truth


def _clutter(rng: np.random.Generator, img: np.ndarray, avoid: np.ndarray, colours: np.ndarray,
             count: int, size: float, soft: float) -> np.ndarray:
    h, w = img.shape[:2]
    for _ in range(count):
        for _try in range(20):
            cx, cy = rng.uniform(0, w), rng.uniform(0, h)
            r = size * rng.uniform(0.3, 1.0)
            m = _blob(rng, h, w, cx, cy, r, wobble=0.4)
            if not (m & avoid).any():
                break
        else:
            continue
        c = colours[rng.integers(len(colours))] + rng.normal(0, 20, 3)
        cols = np.clip(np.stack([c, c * rng.uniform(0.6, 0.9)]), 0, 255)
        img = _composite(img, _textured(rng, h, w, cols, 25, 15), m, soft)
    return img


def _finish(img: np.ndarray, rng: np.random.Generator, blur: float) -> np.ndarray:
    img = cv2.GaussianBlur(img.astype(np.float32), (0, 0), blur)
    img = img + rng.normal(0, 3.0, img.shape).astype(np.float32)
    return np.clip(np.round(img), 0, 255).astype(np.uint8)


def synthetic_frame(seed: int, width: int = 1280, height: int = 960) -> Frame:
    """Render a cluttered textured scene with one irregular object."""
    rng = np.random.default_rng(seed)
    h, w = height, width
    s = w / 1280
    bg_colours = rng.uniform(30, 230, (3, 3))
    img = _textured(rng, h, w, bg_colours, cell=180 * s, grain=30)
    img = img * (0.85 + 0.3 * _noise(rng, h, w, 400 * s))[..., None]
    # A table edge: a big polygon with its own texture.
    table = np.zeros((h, w), np.uint8)
    y0 = int(h * rng.uniform(0.3, 0.6))
    cv2.fillPoly(table, [np.array([[0, y0], [w, y0 + int(rng.uniform(-0.2, 0.2) * h)], [w, h], [0, h]],
                                   np.int32)], 1)
    table_colours = rng.uniform(30, 230, (2, 3))
    img = _composite(img, _textured(rng, h, w, table_colours, 90 * s, 20), table.astype(bool), 1.0)
    cx, cy = rng.uniform(0.35, 0.65) * w, rng.uniform(0.35, 0.65) * h
    radius = rng.uniform(0.13, 0.2) * min(w, h) * 1.3
    keep_out = _blob(rng, h, w, cx, cy, radius * 1.8, wobble=0.0)
    clutter_colours = np.concatenate([bg_colours, table_colours, rng.uniform(30, 230, (2, 3))])
    img = _clutter(rng, img, keep_out, clutter_colours, count=10, size=90 * s, soft=0.8)
    img, truth = _paint_object(rng, img, np.concatenate([bg_colours, table_colours]), cx, cy,
                               radius, soft=0.8 * s)
    # Similar-coloured clutter near (not on) the object, inside the box margin.
    ring = cv2.dilate(truth.astype(np.uint8), np.ones((int(60 * s), int(60 * s)), np.uint8)).astype(bool)
    img = _clutter(rng, img, ring, clutter_colours, count=3, size=45 * s, soft=0.8)
    return Frame(f"synthetic-{seed}" + ("" if w == 1280 else f"-{w}x{h}"), _finish(img, rng, 0.6), truth)


def real_frame(path: Path, seed: int, size: tuple[int, int] = (1280, 960)) -> Frame:
    """A real frame scaled to ``size`` (w, h) with a synthetic object pasted in."""
    rng = np.random.default_rng(seed)
    bgr = cv2.imread(str(path), cv2.IMREAD_COLOR)
    rgb = cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
    w, h = size
    img = cv2.resize(rgb, (w, h), interpolation=cv2.INTER_CUBIC).astype(np.float32)
    # Object colours borrowed from the frame itself so they are plausible.
    small = rgb.reshape(-1, 3).astype(np.float32)
    picks = small[rng.integers(0, len(small), 4)]
    cx, cy = rng.uniform(0.35, 0.65) * w, rng.uniform(0.4, 0.65) * h
    radius = rng.uniform(0.12, 0.18) * min(w, h) * 1.3
    # The upscaled frame is soft (2.5x), so the pasted object gets a softer edge.
    img, truth = _paint_object(rng, img, picks, cx, cy, radius, soft=1.2)
    suffix = "" if size == (1280, 960) else f"@{w}x{h}"
    return Frame(f"real-{path.stem}{suffix}", _finish(img, rng, 0.5), truth)


def demo_frames() -> list[Frame]:
    """Frames from ``egonet.synth`` when that module exists, else none."""
    if importlib.util.find_spec("egonet.synth") is None:
        return []
    from egonet import synth  # noqa: PLC0415 (optional module)

    frames = []
    render = getattr(synth, "render_frame", None)
    activities = getattr(synth, "ACTIVITIES", ())
    if render is None:
        return []
    for i, activity in enumerate(a for a in ("cooking", "desk work", "dining") if a in activities):
        f = render(activity, i, seed=i, width=1280, height=960)
        if f.mask.any():
            frames.append(Frame(f"demo-{activity.replace(' ', '-')}", np.ascontiguousarray(f.rgb),
                                f.mask.astype(bool)))
    return frames


# --------------------------------------------------------------------------
# The simulated annotator


def annotator_box(truth: np.ndarray, rng: np.random.Generator) -> tuple[int, int, int, int]:
    """A slightly loose box: the object's bounds plus 3-8 % of its size each side."""
    ys, xs = np.nonzero(truth)
    h, w = truth.shape
    bw, bh = xs.max() - xs.min() + 1, ys.max() - ys.min() + 1
    pad = rng.uniform(0.03, 0.08, 4) * np.array([bw, bh, bw, bh])
    x0 = int(max(0, xs.min() - pad[0]))
    y0 = int(max(0, ys.min() - pad[1]))
    x1 = int(min(w, xs.max() + 1 + pad[2]))
    y1 = int(min(h, ys.max() + 1 + pad[3]))
    return x0, y0, x1, y1


def through_box(box: tuple[int, int, int, int], fraction: float = 0.6) -> tuple[int, int, int, int]:
    """The left ``fraction`` of a loose box: a box that cuts through the object."""
    x0, y0, x1, y1 = box
    return x0, y0, x0 + max(4, int(fraction * (x1 - x0))), y1


def annotator_stroke(mask: np.ndarray, truth: np.ndarray, max_radius: float = 8.0,
                     max_half_length: float = 60.0) -> Stroke | None:
    """A stroke through the ridge of the largest error region, or None if none."""
    best = None
    for label, err in (("fg", truth & ~mask), ("bg", mask & ~truth)):
        n, lab, stats, _ = cv2.connectedComponentsWithStats(err.astype(np.uint8), connectivity=4)
        if n > 1:
            k = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
            area = int(stats[k, cv2.CC_STAT_AREA])
            if best is None or area > best[0]:
                best = (area, label, lab == k)
    if best is None:
        return None
    _, label, comp = best
    dist = cv2.distanceTransform(np.pad(comp, 1).astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)[1:-1, 1:-1]
    y, x = np.unravel_index(int(np.argmax(dist)), dist.shape)
    dmax = float(dist[y, x])
    radius = float(max(0.5, min(max_radius, dmax - 1.5)))
    ys, xs = np.nonzero(comp)
    pts = np.stack([xs, ys], 1).astype(np.float64)
    if len(pts) < 3:
        return Stroke([(float(x), float(y))], label, 0.5)
    cov = np.cov((pts - pts.mean(0)).T)
    direction = np.linalg.eigh(cov)[1][:, -1]
    ends = []
    for sign in (-1.0, 1.0):
        end = (float(x), float(y))
        for step in range(1, int(max_half_length) + 1):
            px, py = x + sign * step * direction[0], y + sign * step * direction[1]
            ix, iy = int(round(px)), int(round(py))
            if not (0 <= iy < dist.shape[0] and 0 <= ix < dist.shape[1]) or dist[iy, ix] < radius + 1.5:
                break
            end = (float(px), float(py))
        ends.append(end)
    return Stroke([ends[0], (float(x), float(y)), ends[1]], label, radius)


def iou(a: np.ndarray, b: np.ndarray) -> float:
    union = np.count_nonzero(a | b)
    return 1.0 if union == 0 else np.count_nonzero(a & b) / union


# --------------------------------------------------------------------------
# Methods


class Method:
    """A segmentation method driven by the annotator."""

    name = "method"

    def box(self, rgb: np.ndarray, box: tuple[int, int, int, int]) -> np.ndarray:
        raise NotImplementedError

    def stroke(self, s: Stroke) -> np.ndarray:
        raise NotImplementedError


class SessionMethod(Method):
    name = "session"

    def __init__(self, work_size: int = 320, depth: np.ndarray | None = None):
        self.work_size = work_size
        self.depth = depth

    def box(self, rgb, box):
        self.session = GrabCutSession(rgb, self.depth, work_size=self.work_size)
        return self.session.box(*box)

    def stroke(self, s):
        return self.session.stroke(s.points, s.label, s.radius)


class PlainMethod(Method):
    """Plain full-resolution ``cv2.grabCut`` as a careful OpenCV user would run it."""

    name = "plain"

    def box(self, rgb, box):
        self.rgb = rgb
        self.gc = np.zeros(rgb.shape[:2], np.uint8)
        self.bgd = np.zeros((1, 65), np.float64)
        self.fgd = np.zeros((1, 65), np.float64)
        x0, y0, x1, y1 = box
        cv2.grabCut(rgb, self.gc, (x0, y0, x1 - x0, y1 - y0), self.bgd, self.fgd, 5, cv2.GC_INIT_WITH_RECT)
        return (self.gc & 1).astype(bool)

    def stroke(self, s):
        under = stroke_footprint(self.gc.shape, s.points, s.radius)
        self.gc[under] = cv2.GC_FGD if s.label == "fg" else cv2.GC_BGD
        cv2.grabCut(self.rgb, self.gc, None, self.bgd, self.fgd, 2, cv2.GC_INIT_WITH_MASK)
        return (self.gc & 1).astype(bool)


@dataclasses.dataclass
class Run:
    box_ms: float  # wall clock
    stroke_ms: list[float]
    box_cpu_ms: float  # this process's CPU time: robust to other load on a shared machine
    stroke_cpu_ms: list[float]
    iou_box: float
    iou_final: float
    iou_steps: list[float]
    box: tuple[int, int, int, int]
    strokes: list[Stroke]
    mask: np.ndarray


def replay(method: Method, frame: Frame, box: tuple[int, int, int, int], strokes: list[Stroke]) -> float:
    """Final IoU of ``method`` given a fixed box and stroke sequence (not timed)."""
    mask = method.box(frame.rgb, box)
    for s in strokes:
        mask = method.stroke(s)
    return iou(mask, frame.truth)


def run_method(method: Method, frame: Frame, n_strokes: int, seed: int) -> Run:
    rng = np.random.default_rng(seed)
    return run_on_box(method, frame.rgb, frame.truth, annotator_box(frame.truth, rng), n_strokes)


def run_on_box(method: Method, rgb: np.ndarray, truth: np.ndarray, box: tuple[int, int, int, int],
               n_strokes: int) -> Run:
    """Time ``method`` on one box and up to ``n_strokes`` annotator strokes, scored against ``truth``."""
    t, c = time.perf_counter(), time.process_time()
    mask = method.box(rgb, box)
    box_ms, box_cpu = 1e3 * (time.perf_counter() - t), 1e3 * (time.process_time() - c)
    ious = [iou(mask, truth)]
    stroke_ms, stroke_cpu, strokes = [], [], []
    for _ in range(n_strokes):
        s = annotator_stroke(mask, truth)
        if s is None:
            break
        strokes.append(s)
        t, c = time.perf_counter(), time.process_time()
        mask = method.stroke(s)
        stroke_ms.append(1e3 * (time.perf_counter() - t))
        stroke_cpu.append(1e3 * (time.process_time() - c))
        ious.append(iou(mask, truth))
    return Run(box_ms, stroke_ms, box_cpu, stroke_cpu, ious[0], ious[-1], ious, box, strokes, mask)


# --------------------------------------------------------------------------
# Real frames, with and without depth: the speed targets


def chair_frame(size: tuple[int, int] | None = None) -> Frame:
    """rgbd-primesense 00001 with its depth (metres) and hand-drawn chair, optionally scaled to ``size`` (w, h)."""
    rgb = cv2.cvtColor(cv2.imread(str(RGBD_FRAMES / "color" / "00001.jpg"), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
    raw = cv2.imread(str(RGBD_FRAMES / "depth" / "00001.png"), cv2.IMREAD_UNCHANGED)
    depth = np.where(raw > 0, raw.astype(np.float32) / 1000, np.nan).astype(np.float32)
    truth = chair_truth()
    name = "rgbd-chair"
    if size is not None:
        rgb = cv2.resize(rgb, size, interpolation=cv2.INTER_CUBIC)
        depth = cv2.resize(depth, size, interpolation=cv2.INTER_NEAREST)  # no depths mixed across edges
        truth = cv2.resize(truth.view(np.uint8), size, interpolation=cv2.INTER_NEAREST).view(bool)
        name += f"@{size[0]}x{size[1]}"
    return Frame(name, rgb, truth, depth)


def tight_box(truth: np.ndarray, pad: int = 2) -> tuple[int, int, int, int]:
    """The object's bounds plus ``pad`` pixels each side (edges within a few pixels of it)."""
    ys, xs = np.nonzero(truth)
    h, w = truth.shape
    return (max(0, int(xs.min()) - pad), max(0, int(ys.min()) - pad), min(w, int(xs.max()) + 1 + pad),
            min(h, int(ys.max()) + 1 + pad))


def real_cases(work_size: int, n_strokes: int, plain: bool, large: bool) -> None:
    """Box and stroke latency on real frames, 640x480 to 1408x1408, with and without depth.

    Frames: the real RGB-D frame (the chair, with its depth) at 640x480 and
    scaled to 1408x1408, and the first-person frames (no depth) at 640x480 and
    1408x1408 with an object pasted in. Boxes: loose (3-8 % each side),
    tight (2 px each side) and through the object (the left 60 % of the loose
    box, scored against the object's part inside it). The session runs
    without depth and, where the frame has depth, with it; plain
    ``cv2.grabCut`` on the same box and its own strokes.
    """
    frames: list[Callable[[], Frame]] = []
    if RGBD_FRAMES.is_dir():
        frames.append(chair_frame)
        if large:
            frames.append(lambda: chair_frame(BIG))
    else:
        print(f"(no RGB-D frames at {RGBD_FRAMES}: skipped)")
    if REAL_FRAMES.is_dir():
        for i, p in enumerate(sorted(REAL_FRAMES.glob("*.jpg"))):
            frames.append(lambda p=p, i=i: real_frame(p, 200 + i, (640, 480)))
            if large:
                frames.append(lambda p=p, i=i: real_frame(p, 200 + i, BIG))
    if not frames:
        return
    print()
    print("Real frames: box -> mask and stroke -> mask, one core (targets: box <= 300 ms, stroke p95 <= 60 ms)")
    print(f"{'frame':28s} {'box':8s} {'method':14s} {'box ms':>7s} {'cpu':>5s} {'stroke ms (each, wall)':>36s}  "
          "IoU box -> strokes")
    runs: dict[str, list[tuple[str, str, Run]]] = {}
    for make in frames:
        frame = make()
        loose = annotator_box(frame.truth, np.random.default_rng(0))
        for kind, box in (("loose", loose), ("tight", tight_box(frame.truth)), ("through", through_box(loose))):
            x0, y0, x1, y1 = box
            truth = np.zeros_like(frame.truth)
            truth[y0:y1, x0:x1] = frame.truth[y0:y1, x0:x1]
            methods: list[tuple[str, Method]] = [("session", SessionMethod(work_size))]
            if frame.depth is not None:
                methods.append(("session+depth", SessionMethod(work_size, frame.depth)))
            if plain:
                methods.append(("plain", PlainMethod()))
            for label, m in methods:
                r = run_on_box(m, frame.rgb, truth, box, n_strokes)
                runs.setdefault(label, []).append((frame.name, kind, r))
                strokes = " ".join(f"{v:6.0f}" for v in r.stroke_ms)
                steps = " ".join(f"{v:.3f}" for v in r.iou_steps)
                print(f"{frame.name:28s} {kind:8s} {label:14s} {r.box_ms:7.0f} {r.box_cpu_ms:5.0f} {strokes:>36s}  "
                      f"{steps}", flush=True)
    print()
    for clock, box_key, stroke_key in (("wall", "box_ms", "stroke_ms"), ("cpu", "box_cpu_ms", "stroke_cpu_ms")):
        for label, rows in runs.items():
            box = [getattr(r, box_key) for _, _, r in rows]
            strokes = [v for _, _, r in rows for v in getattr(r, stroke_key)]
            met = _pct(box, 50) <= 300 and _pct(box, 95) <= 300 and _pct(strokes, 95) <= 60
            by_kind = "  ".join(f"{k} {_pct([getattr(r, box_key) for _, kk, r in rows if kk == k], 50):.0f}"
                                for k in ("loose", "tight", "through"))
            print(f"real {clock:4s} {label:14s} box p50 {_pct(box, 50):6.0f} ms  p95 {_pct(box, 95):6.0f} ms | "
                  f"stroke p50 {_pct(strokes, 50):6.1f} ms  p95 {_pct(strokes, 95):6.1f} ms (n={len(strokes)}) | "
                  f"box p50 by kind: {by_kind} | targets {'met' if met else 'NOT met'}")
        if "plain" in runs:
            for label in (k for k in runs if k != "plain"):
                # Plain on the same frames and boxes only (depth runs exist only where the frame has depth).
                cases = {(f, k) for f, k, _ in runs[label]}
                plain_rows = [r for f, k, r in runs["plain"] if (f, k) in cases]
                pb = [getattr(r, box_key) for r in plain_rows]
                ps = [v for r in plain_rows for v in getattr(r, stroke_key)]
                sb = [getattr(r, box_key) for _, _, r in runs[label]]
                ss = [v for _, _, r in runs[label] for v in getattr(r, stroke_key)]
                print(f"real {clock:4s} ratio plain/{label}: box p50 {_pct(pb, 50) / _pct(sb, 50):.1f}x  "
                      f"p95 {_pct(pb, 95) / _pct(sb, 95):.1f}x | stroke p50 {_pct(ps, 50) / _pct(ss, 50):.1f}x  "
                      f"p95 {_pct(ps, 95) / _pct(ss, 95):.1f}x  (plain on the same boxes, its own strokes)")
    for label, rows in runs.items():
        print(f"real IoU {label:14s} after box {np.mean([r.iou_box for _, _, r in rows]):.4f}  "
              f"final {np.mean([r.iou_final for _, _, r in rows]):.4f}  (mean of {len(rows)} runs)")
    if "session+depth" in runs:
        # Colour alone against colour and depth on the frames with depth, box by box.
        plain_rows = {(f, k): r for f, k, r in runs["session"]}
        pairs = [(plain_rows[(f, k)], r) for f, k, r in runs["session+depth"]]
        for (f, k, _), (c, r) in zip(runs["session+depth"], pairs):
            print(f"real depth on {f} {k:8s}: IoU after box {c.iou_box:.3f} -> {r.iou_box:.3f}, "
                  f"final {c.iou_final:.3f} -> {r.iou_final:.3f}")
        print(f"real depth, mean of {len(pairs)} runs: IoU after box {np.mean([c.iou_box for c, _ in pairs]):.3f} -> "
              f"{np.mean([r.iou_box for _, r in pairs]):.3f}, final {np.mean([c.iou_final for c, _ in pairs]):.3f} -> "
              f"{np.mean([r.iou_final for _, r in pairs]):.3f} (colour only -> with depth)")


# --------------------------------------------------------------------------
# NoC@90 on thin objects, this tree's engine against an older one

FAR = 16  # px: a stroke's neighbourhood, for counting changes far from it


def far_changes(before: np.ndarray, after: np.ndarray, footprint: np.ndarray) -> int:
    """Pixels that changed more than ``FAR`` px from the stroke and are not joined to it through changed pixels."""
    changed = (before != after).view(np.uint8)
    if not changed.any():
        return 0
    near = cv2.dilate(footprint.view(np.uint8), cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * FAR + 1,) * 2))
    _, parts = cv2.connectedComponents(changed, connectivity=8)
    joined = np.unique(parts[(near > 0) & (changed > 0)])
    return int(np.count_nonzero(changed.view(bool) & ~np.isin(parts, joined)))


def noc_engine(masks_of: str | None = None) -> dict:
    """NoC@90 of the engine on ``sys.path`` over the thin-object frames: per object, and the masks of one.

    The nine frames of the goal first (``set`` "nine"), then the untuned later frames of the video ("later").
    """
    rows = []
    kept = {}
    cases = [("nine", c) for c in thin_objects.all_cases()] + [("later", c) for c in thin_objects.later_cases()]
    for group, case in cases:
        session = GrabCutSession(case.rgb)
        box_cpu: list[float] = []
        stroke_cpu: list[float] = []
        far: list[int] = []
        current = {}

        def box(b, session=session, box_cpu=box_cpu, current=current):
            c = time.process_time()
            current["mask"] = session.box(*b)
            box_cpu.append(1e3 * (time.process_time() - c))
            return current["mask"]

        def stroke(k, session=session, stroke_cpu=stroke_cpu, far=far, current=current):
            c = time.process_time()
            mask = session.stroke(k.points, k.label, k.radius)
            stroke_cpu.append(1e3 * (time.process_time() - c))
            far.append(far_changes(current["mask"], mask, stroke_footprint(mask.shape, k.points, k.radius)))
            current["mask"] = mask
            return mask

        run = thin_objects.noc(box, stroke, case.truth, keep_masks=case.name == masks_of)
        rows.append({"name": case.name, "set": group, "noc": run.noc, "ious": run.ious, "box_cpu_ms": box_cpu[0],
                     "stroke_cpu_ms": stroke_cpu, "far": far})
        if run.masks:
            kept = {"name": case.name, "masks": np.stack(run.masks), "clicks": run.clicks}
        print(f"  {case.name:20s} NoC {run.noc if run.noc else '>20':>3} IoU " + " ".join(f"{v:.2f}" for v in run.ious),
              flush=True)
    return {"rows": rows, "kept": kept}


def _engine_at(rev: str, into: Path) -> Path:
    """``egonet/`` of git revision ``rev``, taken out under ``into``."""
    import subprocess  # noqa: PLC0415
    import tarfile  # noqa: PLC0415
    import io  # noqa: PLC0415

    tar = subprocess.run(["git", "-C", str(ROOT), "archive", rev, "egonet"], check=True, capture_output=True).stdout
    with tarfile.open(fileobj=io.BytesIO(tar)) as t:
        t.extractall(into, filter="data")
    return into


def noc_cases(before: str, figure: Path | None, figure_case: str) -> None:
    """NoC@90 of this tree's engine and of ``before``'s, on the same frames, in one run."""
    import json  # noqa: PLC0415
    import pickle  # noqa: PLC0415
    import subprocess  # noqa: PLC0415
    import tempfile  # noqa: PLC0415

    if not (thin_objects.EGONET_SAMPLES / "rgb").is_dir():
        print(f"(no first-person frames at {thin_objects.EGONET_SAMPLES}: the utensils are skipped)")
    with tempfile.TemporaryDirectory() as tmp:
        engine = _engine_at(before, Path(tmp) / "engine")
        out = Path(tmp) / "before.pkl"
        print(f"NoC@90 on thin objects, engine of {before} (subprocess):", flush=True)
        subprocess.run([sys.executable, __file__, "--noc-engine-only", str(out), "--figure-case", figure_case],
                       check=True, env={**os.environ, "EGONET_BENCH_ENGINE": str(engine)})
        old = pickle.loads(out.read_bytes())
    print("NoC@90 on thin objects, this tree's engine:", flush=True)
    new = noc_engine(figure_case)
    print()
    print(f"{'object':20s} {'NoC before':>10s} {'after':>6s}   {'box cpu ms':>12s}   {'stroke cpu p50':>14s}   "
          f"far strokes before/after")
    for a, b in zip(old["rows"], new["rows"]):
        print(f"{a['name']:20s} {a['noc'] or '>20':>10} {b['noc'] or '>20':>6}   "
              f"{a['box_cpu_ms']:5.0f} {b['box_cpu_ms']:5.0f}"
              f"   {_pct(a['stroke_cpu_ms'], 50):6.1f} {_pct(b['stroke_cpu_ms'], 50):6.1f}   "
              f"{sum(v > 0 for v in a['far'])}/{len(a['far'])} -> {sum(v > 0 for v in b['far'])}/{len(b['far'])}")
    summary = {}
    for label, res in (("before", old), ("after", new)):
        rows = [r for r in res["rows"] if r.get("set", "nine") == "nine"]
        later = [thin_objects.MAX_CLICKS if r["noc"] is None else r["noc"] for r in res["rows"] if r.get("set") == "later"]
        scores = [thin_objects.MAX_CLICKS if r["noc"] is None else r["noc"] for r in rows]
        strokes = [v for r in rows for v in r["stroke_cpu_ms"]]
        far = [v for r in rows for v in r["far"]]
        summary[label] = {"mean_noc": float(np.mean(scores)), "missed": sum(r["noc"] is None for r in rows),
                          "box_cpu_p50": _pct([r["box_cpu_ms"] for r in rows], 50),
                          "stroke_cpu_p50": _pct(strokes, 50), "stroke_cpu_p95": _pct(strokes, 95),
                          "far_strokes": sum(v > 0 for v in far), "strokes": len(far), "far_max": max(far, default=0),
                          "later_mean_noc": float(np.mean(later)) if later else None,
                          "later_missed": sum(v >= thin_objects.MAX_CLICKS for v in later)}
        print(f"{label:6s} mean NoC@90 {np.mean(scores):5.2f} over {len(rows)} objects, {summary[label]['missed']} not "
              f"within {thin_objects.MAX_CLICKS} | box cpu p50 {summary[label]['box_cpu_p50']:.0f} ms | stroke cpu "
              f"p50 {summary[label]['stroke_cpu_p50']:.1f} / p95 {summary[label]['stroke_cpu_p95']:.1f} ms | strokes "
              f"with far changes {summary[label]['far_strokes']} of {len(far)} "
              f"(largest {summary[label]['far_max']} px)")
        if later:
            print(f"{'':6s} untuned later frames of the video: mean NoC@90 {np.mean(later):5.2f} over {len(later)}")
    print("json " + json.dumps(summary))
    if figure is not None and old["kept"] and new["kept"]:
        _noc_figure(figure, old["kept"], new["kept"])


def _noc_figure(path: Path, old: dict, new: dict) -> None:
    """Before (top row) and after (bottom row): the mask after the box and after four clicks.

    The clicks are those where the older engine changed most pixels far
    from the stroke (the same click numbers in both rows).

    The truth's outline is red, the mask green, the click's stroke yellow
    (object) or blue (background), and pixels the click changed far from
    itself (``far_changes``) magenta.
    """
    case = next(c for c in thin_objects.all_cases() if c.name == new["name"])
    ys, xs = np.nonzero(case.truth | new["masks"][0] | old["masks"][0])
    pad = 30
    y0, y1 = max(0, ys.min() - pad), min(case.truth.shape[0], ys.max() + pad)
    x0, x1 = max(0, xs.min() - pad), min(case.truth.shape[1], xs.max() + pad)
    edge, _ = cv2.findContours(case.truth.view(np.uint8), cv2.RETR_LIST, cv2.CHAIN_APPROX_NONE)
    # The box, then the clicks where the older engine changed most far from the stroke (in order).
    count = min(len(old["masks"]), len(new["masks"]))
    far = [far_changes(old["masks"][i - 1], old["masks"][i], stroke_footprint(
        case.truth.shape, old["clicks"][i - 1].points, old["clicks"][i - 1].radius)) for i in range(1, count)]
    columns = [0] + sorted(1 + int(i) for i in np.argsort(far)[::-1][:4])
    rows = []
    for kept in (old, new):
        tiles = []
        for i in columns:
            img = cv2.cvtColor(case.rgb, cv2.COLOR_RGB2BGR)
            mask = kept["masks"][i]
            img[mask] = (0.45 * img[mask] + np.array([0, 140, 0])).astype(np.uint8)
            cv2.drawContours(img, edge, -1, (0, 0, 255), 3)
            if i > 0:
                k = kept["clicks"][i - 1]
                under = stroke_footprint(mask.shape, k.points, k.radius)
                before, after = kept["masks"][i - 1], mask
                far = (before != after).view(np.uint8)
                if far_changes(before, after, under):
                    _, parts = cv2.connectedComponents(far, connectivity=8)
                    near = cv2.dilate(under.view(np.uint8), cv2.getStructuringElement(
                        cv2.MORPH_ELLIPSE, (2 * FAR + 1,) * 2)) > 0
                    far_px = (far > 0) & ~np.isin(parts, np.unique(parts[near & (far > 0)]))
                    img[cv2.dilate(far_px.view(np.uint8), np.ones((5, 5), np.uint8)) > 0] = (255, 0, 255)
                cv2.polylines(img, [np.round(np.array(k.points)).astype(np.int32)], False,
                              (0, 255, 255) if k.label == "fg" else (255, 128, 0), max(6, round(2 * k.radius)))
            tile = img[y0:y1, x0:x1]
            scale = 170 / max(tile.shape[:2])
            tile = cv2.resize(tile, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
            tiles.append(np.pad(tile, ((2, 2), (2, 2), (0, 0)), constant_values=255))
        rows.append(np.hstack(tiles))
    path.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(path), np.vstack(rows), [cv2.IMWRITE_PNG_COMPRESSION, 9])
    print(f"figure: {path}")


def _pct(values: list[float], q: float) -> float:
    return float(np.percentile(values, q)) if values else float("nan")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="two synthetic frames only")
    parser.add_argument("--no-plain", action="store_true", help="skip plain full-resolution grabCut")
    parser.add_argument("--strokes", type=int, default=5, help="corrective strokes per frame")
    parser.add_argument("--seeds", type=int, nargs="*", default=[1, 2, 3, 4], help="synthetic seeds")
    parser.add_argument("--no-large", action="store_true", help="skip the 1920x1440 frame")
    parser.add_argument("--cross", action="store_true",
                        help="also replay the session's strokes into plain grabCut (slow)")
    parser.add_argument("--work-size", type=int, default=272, help="session work_size")
    parser.add_argument("--dump", type=Path, help="write image/truth/mask PNGs for inspection here")
    parser.add_argument("--real-only", action="store_true",
                        help="only the real-frame cases (RGB-D chair, first-person frames; speed targets)")
    parser.add_argument("--no-real", action="store_true", help="skip the real-frame cases")
    parser.add_argument("--noc", action="store_true",
                        help="only NoC@90 on thin objects, this tree's engine against --before's")
    parser.add_argument("--before", default="main", help="git revision of the engine to compare with (--noc)")
    parser.add_argument("--figure", type=Path, help="--noc: write the before/after figure (PNG) here")
    parser.add_argument("--figure-case", default="camel", help="--noc: the object of the figure")
    parser.add_argument("--noc-engine-only", type=Path, help=argparse.SUPPRESS)  # the subprocess of --noc
    args = parser.parse_args(argv)
    if args.noc_engine_only is not None:
        import pickle  # noqa: PLC0415

        cv2.setNumThreads(1)
        args.noc_engine_only.write_bytes(pickle.dumps(noc_engine(args.figure_case)))
        return 0
    cv2.setNumThreads(1)
    print(f"start: {_load()}")
    try:
        return _run(args)
    finally:
        print(f"end: {_load()}")


def _load() -> str:
    return "load average " + ", ".join(f"{v:.2f}" for v in os.getloadavg()) + f" on {os.cpu_count()} CPUs"


def _run(args: argparse.Namespace) -> int:
    if args.noc:
        noc_cases(args.before, args.figure, args.figure_case)
        return 0
    if args.real_only:
        real_cases(args.work_size, args.strokes, not args.no_plain, not args.no_large)
        return 0

    seeds = args.seeds[:2] if args.quick else args.seeds
    makers: list[Callable[[], Frame]] = [lambda s=s: synthetic_frame(s) for s in seeds]
    if not args.quick:
        if REAL_FRAMES.is_dir():
            for i, p in enumerate(sorted(REAL_FRAMES.glob("*.jpg"))):
                makers.append(lambda p=p, i=i: real_frame(p, 100 + i))
        else:
            print(f"(no real frames at {REAL_FRAMES}: skipped)")
        makers.extend(lambda f=f: f for f in demo_frames())
        if not args.no_large:
            makers.append(lambda: synthetic_frame(7, 1920, 1440))

    methods: list[Method] = [SessionMethod(args.work_size)] + ([] if args.no_plain else [PlainMethod()])
    results: dict[str, list[Run]] = {m.name: [] for m in methods}
    print(f"{'frame':28s} {'method':8s} {'box ms':>8s} {'stroke ms (each, wall)':>36s}  IoU box -> strokes")
    same: list[tuple[float, float, float, float]] = []
    # Boxes over the object's left 60 %: IoU with the object's part in the box, per method.
    through: dict[str, list[float]] = {m.name: [] for m in methods}
    for make in makers:
        frame = make()
        for m in methods:
            r = run_method(m, frame, args.strokes, seed=0)
            results[m.name].append(r)
            x0, y0, x1, y1 = part_box = through_box(r.box)
            part = np.zeros_like(frame.truth)
            part[y0:y1, x0:x1] = frame.truth[y0:y1, x0:x1]
            through[m.name].append(iou(m.box(frame.rgb, part_box), part))
            strokes = " ".join(f"{v:6.0f}" for v in r.stroke_ms)
            steps = " ".join(f"{v:.3f}" for v in r.iou_steps)
            print(f"{frame.name:28s} {m.name:8s} {r.box_ms:8.0f} {strokes:>36s}  {steps}", flush=True)
            if args.dump is not None:
                args.dump.mkdir(parents=True, exist_ok=True)
                cv2.imwrite(str(args.dump / f"{frame.name}.png"), cv2.cvtColor(frame.rgb, cv2.COLOR_RGB2BGR))
                cv2.imwrite(str(args.dump / f"{frame.name}-truth.png"), frame.truth.astype(np.uint8) * 255)
                cv2.imwrite(str(args.dump / f"{frame.name}-{m.name}.png"), r.mask.astype(np.uint8) * 255)
        if "plain" in results:
            # Same box and same strokes: each method on the other's stroke sequence.
            ses, pla = results["session"][-1], results["plain"][-1]
            s_on_p = replay(SessionMethod(args.work_size), frame, pla.box, pla.strokes)
            p_on_s = replay(PlainMethod(), frame, ses.box, ses.strokes) if args.cross else float("nan")
            same.append((s_on_p, pla.iou_final, p_on_s, ses.iou_final))
            print(f"{'':28s} same strokes: plain's -> session {s_on_p:.3f} vs plain {pla.iou_final:.3f}"
                  + (f"; session's -> plain {p_on_s:.3f} vs session {ses.iou_final:.3f}" if args.cross else ""),
                  flush=True)

    print()
    for clock, box_key, stroke_key in (("wall", "box_ms", "stroke_ms"), ("cpu", "box_cpu_ms", "stroke_cpu_ms")):
        summary = {}
        for name, runs in results.items():
            box = [getattr(r, box_key) for r in runs]
            strokes = [v for r in runs for v in getattr(r, stroke_key)]
            summary[name] = (box, strokes)
            print(f"{clock:4s} {name:8s} box p50 {_pct(box, 50):7.0f} ms  p95 {_pct(box, 95):7.0f} ms | "
                  f"stroke p50 {_pct(strokes, 50):7.1f} ms  p95 {_pct(strokes, 95):7.1f} ms "
                  f"(n={len(strokes)})")
        if "plain" in summary:
            (sb, ss), (pb, ps) = summary["session"], summary["plain"]
            print(f"{clock:4s} ratio plain/session: box p50 {_pct(pb, 50) / _pct(sb, 50):.1f}x  "
                  f"p95 {_pct(pb, 95) / _pct(sb, 95):.1f}x | stroke p50 {_pct(ps, 50) / _pct(ss, 50):.1f}x  "
                  f"p95 {_pct(ps, 95) / _pct(ss, 95):.1f}x")
    for name, runs in results.items():
        print(f"IoU {name:8s} after box {np.mean([r.iou_box for r in runs]):.4f}  "
              f"final {np.mean([r.iou_final for r in runs]):.4f}  (mean of {len(runs)} frames)")
    for name, ious in through.items():
        print(f"IoU {name:8s} box through the object (left 60 %) {np.mean(ious):.4f}, worst {min(ious):.3f}, "
              f"{sum(v < 0.5 for v in ious)} of {len(ious)} below 0.5")
    if "plain" in results:
        diffs = [a.iou_final - b.iou_final for a, b in zip(results["session"], results["plain"])]
        print(f"final IoU session - plain: mean {np.mean(diffs):+.4f}, worst {min(diffs):+.4f}, "
              f"frames where session >= plain: {sum(d >= 0 for d in diffs)}/{len(diffs)}")
        same_arr = np.array(same)
        print(f"same box and strokes (plain's): session {same_arr[:, 0].mean():.4f} vs plain "
              f"{same_arr[:, 1].mean():.4f}, worst frame {np.min(same_arr[:, 0] - same_arr[:, 1]):+.4f}")
        if args.cross:
            print(f"same box and strokes (session's): plain {same_arr[:, 2].mean():.4f} vs session "
                  f"{same_arr[:, 3].mean():.4f}, worst frame {np.min(same_arr[:, 3] - same_arr[:, 2]):+.4f}")
        box_diffs = [a.iou_box - b.iou_box for a, b in zip(results["session"], results["plain"])]
        print(f"IoU after the box alone (same box), session - plain: mean {np.mean(box_diffs):+.4f}, "
              f"worst {min(box_diffs):+.4f}")
    if not (args.quick or args.no_real):
        real_cases(args.work_size, args.strokes, not args.no_plain, not args.no_large)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
