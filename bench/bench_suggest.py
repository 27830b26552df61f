"""Benchmark: Suggest's sources that need no trained run, side by side with a plain box.

On frames with a known object (the PrimeSense chair frame with its
hand-drawn truth, and demo frames as ``flask egonet demo`` renders them at
320x240 with their renderer's truth), each source proposes as Suggest does
(``egonet.proposals.source_map``, the regions of the map at 0.5 through
``app.services.labelling.regions``, each refined by a GrabCut session from
its mask with the frame's depth). The annotator accepts the proposal that
overlaps the truth most and rejects the others; then the scripted annotator
of ``bench_grabcut.py`` corrects it, a stroke at a time on the largest error,
until IoU 0.9. The box is that annotator's loose box in the same session.

Printed per frame set and source: mean IoU of the accepted proposal before
any stroke (0 when nothing is proposed), the hit rate (IoU >= 0.5), and the
strokes to IoU 0.9 (median over the frames that got there within
``MAX_STROKES``, and how many did).

Run from the repository root::

    .venv/bin/python bench/bench_suggest.py            # chair + 28 demo frames (about a minute)
    .venv/bin/python bench/bench_suggest.py --demo 2   # 2 demo frames per activity
"""

from __future__ import annotations

import argparse
import os
import sys
import time

for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_name, "1")
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from app.services.labelling.regions import proposal_regions  # noqa: E402
from bench.bench_grabcut import RGBD_FRAMES, annotator_box, annotator_stroke, chair_frame, iou  # noqa: E402
from egonet import io, proposals, synth  # noqa: E402
from egonet.grabcut import GrabCutSession  # noqa: E402

MAX_STROKES = 20
TARGET = 0.9


def demo_cases(per_activity: int) -> list[tuple[str, np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
    """``(name, rgb, depth, K, truth)`` of the demo's first frames of each activity (seed 0, 320x240)."""
    out = []
    for activity in synth.ACTIVITIES:
        for f in synth.render_activity(activity, per_activity, seed=0, width=320, height=240):
            out.append((f"{activity}-{f.index}", f.rgb, f.depth_m, f.K, f.mask.astype(bool)))
    return out


def chair_cases() -> list[tuple[str, np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
    if not RGBD_FRAMES.exists():
        return []
    f = chair_frame()
    return [(f.name, f.rgb, np.nan_to_num(f.depth), io.read_intrinsics(RGBD_FRAMES / "camera_primesense.json"), f.truth)]


def corrected(session: GrabCutSession, mask: np.ndarray, truth: np.ndarray) -> int | None:
    """Strokes until IoU >= TARGET (None: not within MAX_STROKES)."""
    for n in range(MAX_STROKES + 1):
        if iou(mask, truth) >= TARGET:
            return n
        stroke = annotator_stroke(mask, truth)
        if stroke is None or n == MAX_STROKES:
            return None
        mask = session.stroke(stroke.points, stroke.label, stroke.radius)
    return None


def accepted(source: str, rgb, depth, K, truth) -> tuple[float, int | None, int]:
    """The best proposal's IoU before any stroke, the strokes it needs, and how many were offered."""
    regions, _ = proposal_regions(proposals.source_map(source, rgb, depth, K), proposals.THRESHOLD)
    best, best_session = 0.0, None
    for region in regions:
        session = GrabCutSession(rgb, depth)
        mask = region.mask if region.mask.all() else session.seed_mask(region.mask, band=region.band)
        if iou(mask, truth) > best:
            best, best_session = iou(mask, truth), session
    strokes = corrected(best_session, best_session.mask, truth) if best_session is not None else None
    return best, strokes, len(regions)


def boxed(rgb, depth, truth) -> tuple[float, int | None, int]:
    session = GrabCutSession(rgb, depth)
    mask = session.box(*annotator_box(truth, np.random.default_rng(0)))
    return iou(mask, truth), corrected(session, mask, truth), 1


def report(title: str, cases: list) -> None:
    if not cases:
        print(f"{title}: no frames")
        return
    print(f"\n{title}: {len(cases)} frames")
    print(f"{'source':<10} {'IoU before strokes':>19} {'hit (>=0.5)':>12} {'strokes to 0.9':>16} {'offered':>8} {'s/frame':>8}")
    for source in (*proposals.SOURCES, "box"):
        t = time.process_time()
        rows = [boxed(rgb, depth, truth) if source == "box" else accepted(source, rgb, depth, K, truth)
                for _, rgb, depth, K, truth in cases]
        cpu = (time.process_time() - t) / len(cases)
        ious = np.array([r[0] for r in rows])
        reached = [r[1] for r in rows if r[1] is not None]
        strokes = f"{np.median(reached):.0f} (n={len(reached)})" if reached else f"- (n=0)"
        print(f"{source:<10} {ious.mean():>19.3f} {np.mean(ious >= 0.5):>12.0%} {strokes:>16} "
              f"{np.mean([r[2] for r in rows]):>8.1f} {cpu:>8.2f}")
        if len(cases) <= 3:
            print("           per frame: " + ", ".join(f"{name} {r[0]:.3f}" for (name, *_), r in zip(cases, rows)))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--demo", type=int, default=4, help="demo frames per activity (default 4)")
    args = parser.parse_args()
    cv2.setNumThreads(1)
    print(f"{time.strftime('%Y-%m-%d')}, load average {os.getloadavg()[0]:.1f}")
    report("PrimeSense chair (real RGB-D, hand-drawn truth)", chair_cases())
    report("demo (rendered, seed 0, 320x240)", demo_cases(args.demo))


if __name__ == "__main__":
    main()
