"""Benchmark: carrying a mask to the adjacent frame (``egonet.grabcut.propagate``).

For each pair of adjacent frames with a known object mask on both, three
ways to get the next frame's mask from the previous one are scored against
the next frame's truth:

* ``copy``: the previous mask unchanged (what an annotator gets without help);
* ``flow``: the previous mask moved by the same DIS optical flow ``propagate``
  uses (``egonet.grabcut.propagation.warp_mask``), no cut;
* ``ours``: ``propagate`` (flow, then GrabCut seeded from the warped mask);
  ``ours+depth`` also gets both frames' depth where the data set has it.

Scores: IoU of the masks' bounding boxes (the issue's target: >= 0.9 for
every object, mean >= 0.95 on real 30 fps egocentric video, where copying
gives 0.77 / 0.90 and flow alone about 0.86 / 0.97), mask IoU, and time per
object on one core (``cv2.setNumThreads(1)``), wall clock and CPU.

Every sequence has three frames and is used both ways (0->1, 1->0, 1->2,
2->1): propagation must work backwards in time too. We have no real video
with per-frame truth, so the data sets are built from what exists:

* ``demo``: ``egonet.synth`` scenes at 1408x1408. Frames of an activity are
  independent scenes (each index is a new scene), so sequences are made here
  by rendering one scene three times with the action-object (and the hand
  holding it: hand prims near the palm) moved by a small rigid motion (1-2.5
  cm and 2-6 degrees per frame) and the head turned a little (0.3-1 degree,
  5 mm); truth is the renderer's own object mask. This uses the renderer's
  private pieces (``_valid_scene``, ``_cast``, ``_shade``), as a benchmark may.
* ``real``: the real first-person frames in ``shared/data/egonet-samples/rgb``
  (a centre square, upscaled to 1408x1408) with a real object pasted in: an
  irregular patch cut from another real frame (real texture, shaded, known
  mask), often held by a skin-coloured hand blob that occludes its edge and
  moves with it; per frame it moves 15-45 px, turns up to 5 degrees and
  scales up to 4 %, while the background shifts up to 10 px (head motion).
* ``rgbd``: the same on the real PrimeSense room frames (``rgbd-primesense``,
  centre square upscaled to 1408x1408), with depth: the real depth map with
  the object's own depth (0.5-0.9 m, a tilt, missing readings along its edge
  and 3 % at random) written in. Here ``ours+depth`` is scored too.
* ``chair``: the 3 consecutive real PrimeSense frames themselves (640x480,
  the camera moves a few pixels), the chair as the object. Its reference mask
  on every frame comes from depth alone (points more than 4 cm in front of
  the wall plane fitted above the chair and more than 1 cm above the floor
  from ``egonet.dhg.height_map``, inside a fixed box, largest part), so it is
  independent of colour; it misses the runners' last centimetre on the floor.
* ``video``: real video with a moving camera and a moving object, with a
  person-drawn mask on every frame: five 5-frame windows of DAVIS 2016
  (``tests/data/real_video``, see its README: source, licence, how the
  windows were chosen), each a 480x480 crop upscaled to 1408x1408. DAVIS is
  not first-person video (no public first-person or RGB-D sequence with a
  mask on every consecutive frame was found), but its hard pairs (a leg or
  a tail swinging out, a foot lifted, the camera panning) are the frames
  where carrying a mask fails.
  ``--dump`` writes overlays to look at.

Run from the repository root::

    .venv/bin/python bench/bench_propagate.py            # everything (a few minutes)
    .venv/bin/python bench/bench_propagate.py --quick    # fewer sequences
    .venv/bin/python bench/bench_propagate.py --real-video   # the video set alone (seconds)
    .venv/bin/python bench/bench_propagate.py --dump /tmp/prop   # + overlay PNGs
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
for path in (ROOT, ROOT / "bench"):
    if str(path) not in sys.path:
        sys.path.insert(0, str(path))

from bench_grabcut import _blob, _composite, _textured  # noqa: E402

from egonet.grabcut import Carried, GrabCutSession, carry  # noqa: E402
from egonet.grabcut.propagation import warp_mask  # noqa: E402

SHARED = ROOT.parent / "shared" / "data"
REAL_FRAMES = SHARED / "egonet-samples" / "rgb"
PRIMESENSE = SHARED / "rgbd-primesense"
REAL_VIDEO = ROOT / "tests" / "data" / "real_video"
SIZE = 1408  # the egocentric frames are 1408x1408
MAX_INSTANCES = 50  # app.services.labelling.MAX_INSTANCES: the most objects one propagation request carries


@dataclasses.dataclass
class Frame:
    rgb: np.ndarray  # (H, W, 3) uint8
    truth: np.ndarray  # (H, W) bool
    depth: np.ndarray | None = None  # (H, W) float32 metres, 0 missing


@dataclasses.dataclass
class Sequence:
    name: str
    frames: list[Frame]


def pairs(seq: Sequence) -> Iterator[tuple[str, Frame, Frame]]:
    """Adjacent pairs both ways: 0->1, 1->0, 1->2, 2->1, ..."""
    for i in range(len(seq.frames) - 1):
        yield f"{seq.name} {i}->{i + 1}", seq.frames[i], seq.frames[i + 1]
        yield f"{seq.name} {i + 1}->{i}", seq.frames[i + 1], seq.frames[i]


# --------------------------------------------------------------------------
# demo: egonet.synth scenes with the object and the camera moved


def _rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    axis = axis / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * k @ k


def demo_sequence(activity: str, index: int, *, frames: int = 3, size: int = SIZE) -> Sequence:
    """One synth scene rendered ``frames`` times with a moving held object and head."""
    from egonet.synth.raycast import _cast  # noqa: PLC0415 (private pieces, bench only)
    from egonet.synth.render import _valid_scene, intrinsics  # noqa: PLC0415
    from egonet.synth.sampling import _camera_rotation  # noqa: PLC0415
    from egonet.synth.scene import _HAND  # noqa: PLC0415
    from egonet.synth.shading import _shade  # noqa: PLC0415

    scene, _ = _valid_scene(activity, index, seed=0, width=size, height=size)
    K = intrinsics(width=size, height=size)
    rng = np.random.default_rng([index, len(activity)])
    obj = scene.objects[scene.action]
    moving = [i for i, p in enumerate(scene.prims) if p.obj == scene.action]
    # The hand that holds it moves with it (palm, fingers, thumb, forearm: prims near the palm).
    for hand in scene.hands:
        gap = np.maximum(np.maximum(obj.lo - hand.palm, hand.palm - obj.hi), 0)
        if np.linalg.norm(gap) < 0.08:
            moving += [i for i, p in enumerate(scene.prims)
                       if p.obj == _HAND and np.linalg.norm(p.centre - hand.palm) < 0.3]
    out = []
    for f in range(frames):
        if f:
            if scene.kind == "tactile":
                pivot = obj.centre.copy()
                step = rng.normal(size=3)
                t = step / np.linalg.norm(step) * rng.uniform(0.01, 0.025)
                rot = _rotation(rng.normal(size=3), math.radians(rng.uniform(2, 6)))
                for i in moving:
                    p = scene.prims[i]
                    p.centre = pivot + rot @ (p.centre - pivot) + t
                    p.axes = rot @ p.axes
                obj.centre, obj.lo, obj.hi = obj.centre + t, obj.lo + t, obj.hi + t
            scene.yaw += math.radians(rng.uniform(0.3, 1.0)) * rng.choice([-1, 1])
            scene.pitch += math.radians(rng.uniform(-0.5, 0.5))
            scene.R = _camera_rotation(scene.yaw, scene.pitch, scene.roll)
            scene.eye = scene.eye + rng.normal(0, 0.005, 3)
            scene.arrays = None  # the ray caster's cache of prim arrays
        cast = _cast(scene, K, size, size)
        rgb = _shade(scene, cast, np.random.default_rng([index, f]))
        depth = np.where(np.isfinite(cast.t), cast.t, 0).astype(np.float32)
        out.append(Frame(np.ascontiguousarray(rgb), cast.obj == scene.action, depth))
    return Sequence(f"demo-{activity.replace(' ', '-')}-{index}", out)


# --------------------------------------------------------------------------
# real and rgbd: a real patch pasted on real frames and moved


def _square(image: np.ndarray, interpolation: int) -> np.ndarray:
    """The centre square of ``image`` scaled to SIZE x SIZE."""
    h, w = image.shape[:2]
    s = min(h, w)
    y0, x0 = (h - s) // 2, (w - s) // 2
    return cv2.resize(image[y0 : y0 + s, x0 : x0 + s], (SIZE, SIZE), interpolation=interpolation)


def _read_rgb(path: Path) -> np.ndarray:
    return cv2.cvtColor(cv2.imread(str(path), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)


def pasted_sequence(name: str, background: np.ndarray, source: np.ndarray, seed: int, *,
                    depth: np.ndarray | None = None, frames: int = 3) -> Sequence:
    """A real texture patch (from ``source``) held and moved over ``background`` (both SIZE x SIZE)."""
    rng = np.random.default_rng(seed)
    n = SIZE
    radius = rng.uniform(110, 200)
    # The object in its own canvas, centred: a blob cut out of the source frame's texture.
    c = n // 2
    shape = _blob(rng, n, n, c, c, radius, wobble=0.5)
    sy, sx = rng.integers(-n // 5, n // 5 + 1, 2)
    patch = np.roll(source.astype(np.float32), (sy, sx), axis=(0, 1))
    yy, xx = np.mgrid[0:n, 0:n].astype(np.float32)
    light = 0.75 + 0.4 * np.clip(((xx - c) * 0.6 - (yy - c) * 0.8) / (radius * 2) + 0.5, 0, 1)
    patch = np.clip(patch * light[..., None] * rng.uniform(0.8, 1.2, 3), 0, 255)
    hand = None
    if rng.random() < 0.7:
        a = rng.uniform(0, 2 * np.pi)
        hand = _blob(rng, n, n, c + radius * math.cos(a), c + radius * math.sin(a), radius * 0.4, wobble=0.3)
        skin = np.array([[200, 150, 120], [170, 120, 95]], np.float32) + rng.normal(0, 10, (2, 3))
        skin_tex = _textured(rng, n, n, skin, 30, 12)
    obj_depth = rng.uniform(0.5, 0.9)
    tilt = rng.normal(0, 0.0004, 2)
    # Pose of the object canvas in the frame: centre, angle, scale; then per-frame motion.
    pos = np.array([rng.uniform(0.35, 0.65) * n, rng.uniform(0.35, 0.65) * n])
    angle, scale = rng.uniform(-20, 20), 1.0
    cam = np.zeros(2)
    out = []
    for f in range(frames):
        if f:
            step = rng.normal(size=2)
            pos = pos + step / np.linalg.norm(step) * rng.uniform(15, 45)
            angle += rng.uniform(-5, 5)
            scale *= rng.uniform(0.96, 1.04)
            cam = cam + rng.uniform(-10, 10, 2)
        A = cv2.getRotationMatrix2D((c, c), angle, scale)
        A[:, 2] += pos - c + cam
        warp = lambda img, interp=cv2.INTER_LINEAR: cv2.warpAffine(  # noqa: E731
            img, A, (n, n), flags=interp, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        C = np.float32([[1, 0, cam[0]], [0, 1, cam[1]]])
        img = cv2.warpAffine(background.astype(np.float32), C, (n, n), borderMode=cv2.BORDER_REFLECT)
        obj_mask = warp(shape.view(np.uint8), cv2.INTER_NEAREST).astype(bool)
        img = _composite(img, warp(patch), obj_mask, 1.2)
        truth = obj_mask.copy()
        if hand is not None:
            hand_mask = warp(hand.view(np.uint8), cv2.INTER_NEAREST).astype(bool)
            img = _composite(img, warp(skin_tex), hand_mask, 1.2)
            truth &= ~hand_mask
        img = cv2.GaussianBlur(img, (0, 0), 0.5) + rng.normal(0, 3.0, img.shape).astype(np.float32)
        d = None
        if depth is not None:
            d = cv2.warpAffine(depth, C, (n, n), flags=cv2.INTER_NEAREST, borderMode=cv2.BORDER_REFLECT)
            near = obj_mask | (hand_mask if hand is not None else False)
            d[near] = (obj_depth + tilt[0] * (xx - pos[0]) + tilt[1] * (yy - pos[1]))[near]
            # Sensors lose readings along depth edges and here and there.
            edge = cv2.morphologyEx(near.view(np.uint8), cv2.MORPH_GRADIENT, np.ones((9, 9), np.uint8)).astype(bool)
            d[edge | (rng.random((n, n)) < 0.03)] = 0
        out.append(Frame(np.clip(np.round(img), 0, 255).astype(np.uint8), truth, d))
    return Sequence(name, out)


def real_sequences(seeds_per_frame: int) -> list[Callable[[], Sequence]]:
    paths = sorted(REAL_FRAMES.glob("*.jpg"))
    makers = []
    for i, p in enumerate(paths):
        for k in range(seeds_per_frame):
            src = paths[(i + 1 + k) % len(paths)]
            makers.append(lambda p=p, src=src, s=100 + 10 * i + k: pasted_sequence(
                f"real-{p.stem}-{s}", _square(_read_rgb(p), cv2.INTER_CUBIC),
                _square(_read_rgb(src), cv2.INTER_CUBIC), s))
    return makers


def rgbd_sequences(count: int) -> list[Callable[[], Sequence]]:
    colours = sorted((PRIMESENSE / "color").glob("*.jpg"))
    sources = sorted(REAL_FRAMES.glob("*.jpg")) or colours
    makers = []
    for k in range(count):
        p = colours[k % len(colours)]
        src = sources[k % len(sources)]

        def make(p=p, src=src, s=200 + k):
            depth = cv2.imread(str(PRIMESENSE / "depth" / f"{p.stem}.png"), cv2.IMREAD_UNCHANGED)
            return pasted_sequence(f"rgbd-{p.stem}-{s}", _square(_read_rgb(p), cv2.INTER_CUBIC),
                                   _square(_read_rgb(src), cv2.INTER_CUBIC), s,
                                   depth=_square(depth.astype(np.float32) / 1000.0, cv2.INTER_NEAREST))
        makers.append(make)
    return makers


# --------------------------------------------------------------------------
# chair: the real consecutive PrimeSense frames, reference from depth


def chair_sequence() -> Sequence:
    """The 3 real frames with the chair's depth-derived reference mask on each."""
    from egonet.dhg import height_map  # noqa: PLC0415

    K = np.array([[525.0, 0, 319.5], [0, 525.0, 239.5], [0, 0, 1]])
    frames = []
    for p in sorted((PRIMESENSE / "color").glob("*.jpg")):
        rgb = _read_rgb(p)
        depth = cv2.imread(str(PRIMESENSE / "depth" / f"{p.stem}.png"), cv2.IMREAD_UNCHANGED).astype(np.float32)
        depth /= 1000.0
        height, _ = height_map(depth, K)
        h, w = depth.shape
        v, u = np.mgrid[0:h, 0:w]
        pts = np.stack([(u - K[0, 2]) / K[0, 0] * depth, (v - K[1, 2]) / K[1, 1] * depth, depth], -1)
        wall = pts[20:100, 300:600].reshape(-1, 3)
        wall = wall[wall[:, 2] > 0]
        centre = wall.mean(0)
        normal = np.linalg.svd(wall - centre, full_matrices=False)[2][2]
        normal = -normal if normal[2] > 0 else normal  # towards the camera
        chair = (depth > 0) & ((pts - centre) @ normal > 0.04) & (np.nan_to_num(height) > 0.01)
        box = np.zeros_like(chair)
        box[90:420, 320:615] = True
        n, labels, stats, _ = cv2.connectedComponentsWithStats((chair & box).view(np.uint8), connectivity=8)
        frames.append(Frame(rgb, labels == 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA])), depth))
    return Sequence("chair", frames)


# --------------------------------------------------------------------------
# video: real video windows with a drawn mask on every frame


def video_sequences() -> list[Callable[[], Sequence]]:
    """The ``tests/data/real_video`` windows, frames and masks scaled to SIZE x SIZE."""
    def make(folder: Path) -> Sequence:
        frames = [Frame(_square(_read_rgb(p), cv2.INTER_CUBIC),
                        _square(cv2.imread(str(p.with_suffix(".png")), cv2.IMREAD_GRAYSCALE), cv2.INTER_NEAREST) > 127)
                  for p in sorted(folder.glob("*.jpg"))]
        return Sequence(f"video-{folder.name}", frames)
    return [lambda f=f: make(f) for f in sorted(REAL_VIDEO.iterdir()) if f.is_dir()]


# --------------------------------------------------------------------------
# Scoring


def box_iou(a: np.ndarray, b: np.ndarray) -> float:
    if not a.any() or not b.any():
        return float(a.any() == b.any())
    boxes = []
    for m in (a, b):
        rows, cols = np.flatnonzero(m.any(1)), np.flatnonzero(m.any(0))
        boxes.append((cols[0], rows[0], cols[-1] + 1, rows[-1] + 1))
    (ax0, ay0, ax1, ay1), (bx0, by0, bx1, by1) = boxes
    iw, ih = max(0, min(ax1, bx1) - max(ax0, bx0)), max(0, min(ay1, by1) - max(ay0, by0))
    inter = iw * ih
    return inter / ((ax1 - ax0) * (ay1 - ay0) + (bx1 - bx0) * (by1 - by0) - inter)


def mask_iou(a: np.ndarray, b: np.ndarray) -> float:
    return np.count_nonzero(a & b) / max(1, np.count_nonzero(a | b))


METHODS: dict[str, Callable[[Frame, Frame], np.ndarray]] = {
    "copy": lambda a, b: a.truth.copy(),
    "flow": lambda a, b: warp_mask(a.rgb, a.truth, b.rgb),
    "ours": lambda a, b: carry(a.rgb, a.truth, b.rgb),
    "ours+depth": lambda a, b: carry(a.rgb, a.truth, b.rgb, prev_depth=a.depth, next_depth=b.depth),
}


def _overlay(rgb: np.ndarray, truth: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Truth edge green, result edge red, result area tinted: BGR for cv2.imwrite."""
    out = cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)
    out[mask] = (0.6 * out[mask] + (0, 0, 100)).astype(np.uint8)
    k = np.ones((3, 3), np.uint8)
    for m, colour in ((truth, (0, 255, 0)), (mask, (0, 0, 255))):
        out[cv2.morphologyEx(m.view(np.uint8), cv2.MORPH_GRADIENT, k).astype(bool)] = colour
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="a few sequences per data set")
    parser.add_argument("--dump", type=Path, help="write overlay PNGs (truth green, result red) here")
    parser.add_argument("--real-video", action="store_true", help="only the real video windows (tests/data/real_video)")
    args = parser.parse_args(argv)
    cv2.setNumThreads(1)

    demo = [("cooking", 1), ("desk work", 2), ("dining", 3), ("dishwashing", 4), ("grocery", 5),
            ("hotel", 6), ("shopping", 7), ("cooking", 8)]
    sets: dict[str, list[Callable[[], Sequence]]] = {}
    if not args.real_video:
        sets["demo"] = [lambda a=a, i=i: demo_sequence(a, i) for a, i in demo[: 2 if args.quick else len(demo)]]
        if REAL_FRAMES.is_dir():
            sets["real"] = real_sequences(1 if args.quick else 3)
        else:
            print(f"(no real frames at {REAL_FRAMES}: skipped)")
        if PRIMESENSE.is_dir():
            sets["rgbd"] = rgbd_sequences(2 if args.quick else 6)
            sets["chair"] = [chair_sequence]
        else:
            print(f"(no PrimeSense frames at {PRIMESENSE}: skipped)")
    if REAL_VIDEO.is_dir():
        sets["video"] = video_sequences()
    else:
        print(f"(no real video windows at {REAL_VIDEO}: skipped)")

    print(f"{'pair':34s} " + " ".join(f"{m:>17s}" for m in METHODS) + "   (box IoU / mask IoU)")
    summary = []
    checks = []
    for set_name, makers in sets.items():
        scores: dict[str, list[tuple[float, float]]] = {m: [] for m in METHODS}
        times: dict[str, list[tuple[float, float]]] = {m: [] for m in METHODS}
        seeding: dict[str, list[tuple[float, float]]] = {"ours": [], "ours+depth": []}
        unsure: dict[str, list[bool]] = {"ours": [], "ours+depth": []}
        confidence: dict[str, list[float]] = {"ours": [], "ours+depth": []}
        objects: dict[tuple[str, str], list[float]] = {}  # (method, sequence): box IoU of each carried mask
        for make in makers:
            seq = make()
            for name, a, b in pairs(seq):
                cells = []
                for m, fn in METHODS.items():
                    if m == "ours+depth" and a.depth is None:
                        cells.append(f"{'-':>17s}")
                        continue
                    t, c = time.perf_counter(), time.process_time()
                    mask = fn(a, b)
                    times[m].append((1e3 * (time.perf_counter() - t), 1e3 * (time.process_time() - c)))
                    if isinstance(mask, Carried):
                        unsure[m].append(mask.unsure)
                        confidence[m].append(mask.confidence)
                        mask = mask.mask
                    scores[m].append((box_iou(mask, b.truth), mask_iou(mask, b.truth)))
                    objects.setdefault((m, seq.name), []).append(scores[m][-1][0])
                    cells.append(f"{scores[m][-1][0]:8.3f} {scores[m][-1][1]:8.3f}")
                    if m in ("ours", "ours+depth") and mask.any() and not mask.all():
                        # What the app adds per object: a GrabCut session started from the mask.
                        t, c = time.perf_counter(), time.process_time()
                        GrabCutSession(b.rgb, b.depth if m == "ours+depth" else None).seed_mask(mask)
                        seeding[m].append((1e3 * (time.perf_counter() - t), 1e3 * (time.process_time() - c)))
                    if args.dump is not None and m in ("ours", "ours+depth"):
                        args.dump.mkdir(parents=True, exist_ok=True)
                        file = f"{name.replace(' ', '_').replace('->', '-to-')}-{m}.png"
                        cv2.imwrite(str(args.dump / file), _overlay(b.rgb, b.truth, mask))
                print(f"{name:34s} " + " ".join(cells), flush=True)
        summary.append((set_name, scores, times, seeding))
        checks.append((set_name, scores, unsure, confidence, objects))

    print()
    print(f"{'set':6s} {'method':10s} {'n':>3s} {'box IoU min':>11s} {'mean':>6s} {'>=0.9':>6s} "
          f"{'mask IoU mean':>13s} {'min':>6s} {'ms p50':>7s} {'p95':>6s} {'cpu p50':>8s} {'p95':>6s}")
    for set_name, scores, times, _ in summary:
        for m in METHODS:
            if not scores[m]:
                continue
            box, msk = np.array(scores[m]).T
            wall, cpu = np.array(times[m]).T
            print(f"{set_name:6s} {m:10s} {len(box):3d} {box.min():11.3f} {box.mean():6.3f} "
                  f"{np.mean(box >= 0.9):6.0%} {msk.mean():13.3f} {msk.min():6.3f} "
                  f"{np.percentile(wall, 50):7.0f} {np.percentile(wall, 95):6.0f} "
                  f"{np.percentile(cpu, 50):8.0f} {np.percentile(cpu, 95):6.0f}")
    # Ratios against the naive ways: how many times smaller the mean box error (1 - box IoU) is.
    print()
    print("per object in the app: propagate, then a GrabCut session started from its mask (seed_mask), so "
          "strokes correct it at once; CPU ms on one core")
    everything = []
    for set_name, _, times, seeding in summary:
        for m, seeds in seeding.items():
            if not seeds:
                continue
            cpu = np.array(times[m])[:, 1]
            seed_cpu = np.array(seeds)[:, 1]
            total = cpu[: len(seed_cpu)] + seed_cpu if len(seed_cpu) == len(cpu) else np.concatenate([cpu, seed_cpu])
            if len(seed_cpu) == len(cpu):
                everything.append(total)
            print(f"{set_name:6s} {m:10s} propagate p50 {np.percentile(cpu, 50):5.0f} p95 {np.percentile(cpu, 95):5.0f} | "
                  f"session p50 {np.percentile(seed_cpu, 50):5.0f} p95 {np.percentile(seed_cpu, 95):5.0f} | "
                  f"both p95 {np.percentile(total, 95):5.0f}")
    if everything:
        p95 = float(np.percentile(np.concatenate(everything), 95))
        print(f"all sets: propagate + session p95 {p95:.0f} ms CPU per object: a request carrying 3 objects "
              f"~{3 * p95 / 1e3:.1f} s, the limit of {MAX_INSTANCES} objects at most ~{MAX_INSTANCES * p95 / 1e3:.1f} s")
    for set_name, scores, _, _ in summary:
        err = {m: 1 - np.mean([b for b, _ in v]) for m, v in scores.items() if v}
        best = "ours+depth" if "ours+depth" in err else "ours"
        print(f"{set_name:6s} mean box error (1 - IoU): copy {err['copy']:.3f}, flow {err['flow']:.3f}, "
              f"ours {err['ours']:.3f}" + (f", ours+depth {err[best]:.3f}" if best != "ours" else "")
              + f"; copy/ours {err['copy'] / max(err['ours'], 1e-9):.1f}x, "
              f"flow/ours {err['flow'] / max(err['ours'], 1e-9):.1f}x")
    # The guarantee: never worse than the flow it starts from. Per carried mask (pair and
    # direction) and per object (a sequence's mean over its pairs, both ways); and how many were unsure.
    print()
    for set_name, scores, unsure, confidence, objects in checks:
        flow = np.array([b for b, _ in scores["flow"]])
        for m in ("ours", "ours+depth"):
            if not scores[m]:
                continue
            ours = np.array([b for b, _ in scores[m]])
            below = [(k[1], np.mean(v) - np.mean(objects[("flow", k[1])])) for k, v in objects.items() if k[0] == m]
            worst_object = min(below, key=lambda x: x[1])
            print(f"{set_name:6s} {m:10s} vs flow: carried masks below it {np.sum(ours < flow - 1e-9)}/{len(ours)} "
                  f"(worst {np.min(ours - flow):+.3f}); objects whose mean is below it "
                  f"{sum(d < -1e-9 for _, d in below)}/{len(below)} (worst {worst_object[1]:+.3f} {worst_object[0]}); "
                  f"unsure {sum(unsure[m])}/{len(unsure[m])}, confidence min {min(confidence[m]):.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
