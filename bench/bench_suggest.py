"""Benchmark: Suggest's sources that need no trained run, side by side with a plain box.

On frames with a known object (the three PrimeSense frames with the
hand-drawn chair, and the demo's frames left to label, as ``flask egonet
demo`` renders them at 320x240, with their renderer's truth), each source
proposes as Suggest does (``egonet.proposals.source_map``, the regions of
the map at 0.5 through ``app.services.labelling.regions``, each refined by
a GrabCut session from its mask with the frame's depth). With
``--checkpoint`` a trained run's checkpoint proposes too ("model": its map
at its best-F threshold), such as the demo's quick-start run, which never
saw these frames. The annotator accepts the proposal that
overlaps the truth most and rejects the others; then the scripted annotator
of ``bench_grabcut.py`` corrects it, a stroke at a time on the largest error,
until IoU 0.9. The box is that annotator's loose box in the same session.

Printed per frame set and source: mean IoU of the accepted proposal before
any stroke (0 when nothing is proposed), the hit rate (IoU >= 0.5), and the
strokes to IoU 0.9 (median over the frames that got there within
``MAX_STROKES``, and how many did).

A third table is what Suggest's Auto falls back on for a real frame
without depth (``--rgb-only``): the handled source on the authors' three
RGB frames (``egonet-samples``, their DHG set aside) and on the chair's
colour images alone; per frame how many proposals, the largest one's share
of the frame after GrabCut, and on the chair the best IoU; "handled, as the
baseline draws it" is the map before 2026-12-04, whose neighbouring regions
merged into one proposal.

Run from the repository root::

    .venv/bin/python bench/bench_suggest.py            # chair + 28 demo frames (a few minutes)
    .venv/bin/python bench/bench_suggest.py --demo 2   # 2 demo frames per activity
    .venv/bin/python bench/bench_suggest.py --checkpoint instance/checkpoints/run-1/single.pt
    .venv/bin/python bench/bench_suggest.py --rgb-only                 # the RGB-only table alone (a minute)
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
from bench.bench_grabcut import RGBD_FRAMES, SHARED, annotator_box, annotator_stroke, iou  # noqa: E402
from egonet.baselines import HandledViewedObject  # noqa: E402
from egonet import io, proposals, synth  # noqa: E402
from egonet.dhg import dhg_from_depth, encode_dhg  # noqa: E402
from egonet.grabcut import GrabCutSession  # noqa: E402
from tests.realdata import chair_truth  # noqa: E402

MAX_STROKES = 20
TARGET = 0.9
FIRST_UNLABELLED = 30
"""The default demo (40 frames per activity) leaves frames 30-39 of each activity to label: no run trained on them."""


def demo_cases(per_activity: int) -> list[tuple]:
    """``(name, rgb, depth, K, dhg, truth)`` of the demo's first frames left to label in each activity."""
    out = []
    for activity in synth.ACTIVITIES:
        for i in range(FIRST_UNLABELLED, FIRST_UNLABELLED + per_activity):
            f = synth.render_frame(activity, i, seed=0, width=320, height=240)
            dhg = encode_dhg(f.depth_m, f.height_m, cv2.cvtColor(f.rgb, cv2.COLOR_RGB2GRAY))  # as the demo stores it
            out.append((f"{activity}-{i}", f.rgb, f.depth_m, f.K, dhg, f.mask.astype(bool)))
    return out


def chair_cases() -> list[tuple]:
    """The three PrimeSense frames: the camera barely moves, the hand-drawn chair fits them all."""
    if not RGBD_FRAMES.exists():
        return []
    K = io.read_intrinsics(RGBD_FRAMES / "camera_primesense.json")
    out = []
    for name in ("00000", "00001", "00002"):
        rgb = io.read_image(RGBD_FRAMES / "color" / f"{name}.jpg")
        depth = io.read_depth(RGBD_FRAMES / "depth" / f"{name}.png")
        out.append((f"chair-{name}", rgb, depth, K, dhg_from_depth(depth, K, rgb), chair_truth()))
    return out


def model_source(path: Path):
    """A checkpoint's map and threshold, as Suggest uses a run's: ``(rgb, dhg) -> map``, threshold."""
    from egonet.predictor import NetworkPredictor
    from egonet.checkpoint import load_checkpoint

    state = load_checkpoint(path)
    predictor = NetworkPredictor.from_checkpoint(state)
    return lambda rgb, dhg: predictor.predict(rgb, dhg if predictor.model.uses_dhg else None), state["metrics"]["threshold"]


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


def session_of(rgb: np.ndarray, depth: np.ndarray) -> GrabCutSession:
    """A GrabCut session with the frame's depth, missing as NaN (as the app's GrabCut service gives it)."""
    return GrabCutSession(rgb, np.where(depth > 0, depth, np.nan).astype(np.float32))


def accepted(probability: np.ndarray, threshold: float, rgb, depth, truth) -> tuple[float, int | None, int]:
    """The best proposal's IoU before any stroke, the strokes it needs, and how many were offered."""
    regions, _ = proposal_regions(probability, threshold)
    best, best_session = 0.0, None
    for region in regions:
        session = session_of(rgb, depth)
        mask = region.mask if region.mask.all() else session.seed_mask(region.mask, band=region.band)
        if iou(mask, truth) > best:
            best, best_session = iou(mask, truth), session
    strokes = corrected(best_session, best_session.mask, truth) if best_session is not None else None
    return best, strokes, len(regions)


def boxed(rgb, depth, truth) -> tuple[float, int | None, int]:
    session = session_of(rgb, depth)
    mask = session.box(*annotator_box(truth, np.random.default_rng(0)))
    return iou(mask, truth), corrected(session, mask, truth), 1


def row(source: str, case: tuple, model) -> tuple[float, int | None, int]:
    _, rgb, depth, K, dhg, truth = case
    if source == "box":
        return boxed(rgb, depth, truth)
    if source == "model":
        predict, threshold = model
        return accepted(predict(rgb, dhg), threshold, rgb, depth, truth)
    return accepted(proposals.source_map(source, rgb, depth, K), proposals.THRESHOLD, rgb, depth, truth)


def report(title: str, cases: list, model) -> None:
    if not cases:
        print(f"{title}: no frames")
        return
    print(f"\n{title}: {len(cases)} frames")
    print(f"{'source':<10} {'IoU before strokes':>19} {'hit (>=0.5)':>12} {'strokes to 0.9':>16} {'offered':>8} {'s/frame':>8}")
    for source in (*(["model"] if model else []), *proposals.SOURCES, "box"):
        t = time.process_time()
        rows = [row(source, case, model) for case in cases]
        cpu = (time.process_time() - t) / len(cases)
        ious = np.array([r[0] for r in rows])
        reached = [r[1] for r in rows if r[1] is not None]
        strokes = f"{np.median(reached):.0f} (n={len(reached)})" if reached else "- (n=0)"
        print(f"{source:<10} {ious.mean():>19.3f} {np.mean(ious >= 0.5):>12.0%} {strokes:>16} "
              f"{np.mean([r[2] for r in rows]):>8.1f} {cpu:>8.2f}")
        if len(cases) <= 3:
            print("           per frame: " + ", ".join(f"{name} {r[0]:.3f}" for (name, *_), r in zip(cases, rows)))


def rgb_only_report() -> None:
    """Handled on real frames without depth: proposals per frame, the largest one's share, the chair's best IoU."""
    samples = SHARED / "data" / "egonet-samples" / "rgb"
    cases = [(f"egonet {p.stem}", io.read_image(p), None) for p in sorted(samples.glob("*.jpg"))]
    cases += [(f"chair-{name}", io.read_image(RGBD_FRAMES / "color" / f"{name}.jpg"), chair_truth())
              for name in ("00000", "00001", "00002") if RGBD_FRAMES.exists()]
    if not cases:
        print("RGB-only real frames: no frames")
        return
    print(f"\nRGB-only real frames (no depth; egonet-samples without their DHG, the chair's colour images): {len(cases)}")
    for title, make in (("handled, as the baseline draws it", lambda rgb: HandledViewedObject().predict(rgb)),
                        ("handled, regions kept apart", lambda rgb: proposals.source_map("handled", rgb))):
        line = []
        for name, rgb, truth in cases:
            regions, _ = proposal_regions(make(rgb), proposals.THRESHOLD)
            masks = [r.mask if r.mask.all() else GrabCutSession(rgb).seed_mask(r.mask, band=r.band) for r in regions]
            largest = max((m.mean() for m in masks), default=0.0)
            best = f" IoU {max((iou(m, truth) for m in masks), default=0.0):.3f}" if truth is not None else ""
            line.append(f"{name} n={len(masks)} largest {largest:.1%}{best}")
        print(f"{title:<36} " + "; ".join(line))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--demo", type=int, default=4, help="demo frames per activity (default 4, at most 10)")
    parser.add_argument("--checkpoint", type=Path, help="a trained run's checkpoint (.pt) to propose as 'model' too")
    parser.add_argument("--rgb-only", action="store_true", help="only the table of real frames without depth")
    args = parser.parse_args()
    cv2.setNumThreads(1)
    if args.rgb_only:
        print(f"{time.strftime('%Y-%m-%d')}, load average {os.getloadavg()[0]:.1f}")
        rgb_only_report()
        return
    model = model_source(args.checkpoint) if args.checkpoint else None
    print(f"{time.strftime('%Y-%m-%d')}, load average {os.getloadavg()[0]:.1f}")
    report("PrimeSense chair (real RGB-D, hand-drawn truth)", chair_cases(), model)
    report("demo frames left to label (rendered, seed 0, 320x240)", demo_cases(args.demo), model)
    rgb_only_report()


if __name__ == "__main__":
    main()
