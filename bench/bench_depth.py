"""How good the monocular depth network is, and how much data it needs: AbsRel and delta<1.25 against a constant depth.

Usage::

    .venv/bin/python -m bench.bench_depth                       # from the repository root
    .venv/bin/python -m bench.bench_depth --sizes 25,100 --steps 100 --size 160x120

For each training-set size N, renders N demo frames (``egonet.synth``, seed
0, spread over the seven activities, RGB-D) and trains
``egonet.depth.fit_depth`` for about the same number of optimiser steps
(``--steps``, batch 4, whole epochs, at ``--size``; the run holds out the last 20 % of each
activity as usual, so fewer frames train). Each network is then scored at full
resolution on two held-out sets:

* 35 demo frames rendered with another seed (5 per activity: new rooms);
* the three real RGB-D frames of ``../shared/data/rgbd-primesense`` (a
  real room and sensor, never seen in training; skipped when absent).

Every row gives AbsRel and delta<1.25 as predicted (metric scale) and after
median scaling per frame, beside the constant baseline: the training frames'
median depth everywhere (its median-scaled form is each frame's own median
depth). CPU seconds (``time.process_time``) of each training are printed.
"""

from __future__ import annotations

import argparse
import math
import platform
import sys
import time
from pathlib import Path

import numpy as np
import torch

from egonet import io
from egonet.depth import DepthConfig, DepthErrors, DepthPredictor, DepthSample, depth_errors, fit_depth
from egonet.checkpoint import load_checkpoint
from egonet.synth import ACTIVITIES, render_activity
from egonet.train import make_folds

PRIMESENSE = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "rgbd-primesense"


def demo_frames(n: int, *, seed: int, width: int, height: int) -> list[DepthSample]:
    """``n`` demo frames spread over the activities (the first ones get one more when ``n`` does not divide)."""
    samples = []
    for i, activity in enumerate(ACTIVITIES):
        count = n // len(ACTIVITIES) + (i < n % len(ACTIVITIES))
        for f in render_activity(activity, count, seed=seed, width=width, height=height):
            samples.append(DepthSample(rgb=f.rgb, depth=f.depth_m, key=f"{activity}/{f.index}", group=activity))
    return samples


def real_frames() -> list[DepthSample]:
    if not PRIMESENSE.is_dir():
        return []
    return [DepthSample(rgb=io.read_image(p), depth=io.read_depth(PRIMESENSE / "depth" / f"{p.stem}.png"), key=p.stem)
            for p in sorted((PRIMESENSE / "color").glob("*.jpg"))]


def score(predict, frames: list[DepthSample], constant: float) -> dict[str, float]:
    """AbsRel / delta<1.25 of ``predict`` and of the constant, raw and median-scaled, pooled over the frames' pixels."""
    sums = {k: DepthErrors() for k in ("net", "net_ms", "const", "const_ms")}
    for s in frames:
        pred = predict(s.rgb)
        flat = np.full(s.depth.shape, constant, np.float32)
        sums["net"] += depth_errors(pred, s.depth)
        sums["net_ms"] += depth_errors(pred, s.depth, median_scaling=True)
        sums["const"] += depth_errors(flat, s.depth)
        sums["const_ms"] += depth_errors(flat, s.depth, median_scaling=True)
    return {k: (v.abs_rel, v.delta1) for k, v in sums.items()}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", default="25,100,400", help="training-set sizes N (demo frames)")
    parser.add_argument("--steps", type=int, default=200, help="optimiser steps per size (batch 4), about")
    parser.add_argument("--size", default="128x96", help="training size WIDTHxHEIGHT (default 128x96)")
    parser.add_argument("--threads", type=int, default=1,
                        help="torch threads (default 1: on a loaded machine a second thread spins and triples the CPU time)")
    parser.add_argument("--out", type=Path, default=Path("/tmp/bench_depth"), help="checkpoints go here")
    args = parser.parse_args(argv)
    torch.set_num_threads(args.threads)
    width, height = (int(v) for v in args.size.lower().split("x"))
    sizes = [int(v) for v in args.sizes.split(",")]
    print(f"# bench_depth: {platform.processor() or platform.machine()}, torch {torch.__version__}, "
          f"{args.threads} threads, {args.steps} steps of 4 at {width}x{height}")
    synthetic = demo_frames(35, seed=1, width=320, height=240)
    real = real_frames()
    sets = [("demo (seed 1, 35 frames)", synthetic)] + ([("rgbd-primesense (3 real frames)", real)] if real else [])
    print("| train frames (rendered / trained) | held-out set | AbsRel | delta<1.25 | AbsRel med.-scaled | delta med.-scaled "
          "| constant AbsRel | constant delta | constant med.-scaled AbsRel / delta | CPU s |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for n in sizes:
        train = demo_frames(n, seed=0, width=320, height=240)
        trained = len(make_folds([s.group for s in train], mode="single", test_fraction=0.2)[0].train)
        epochs = max(1, round(args.steps / math.ceil(trained / 4)))  # about --steps steps whatever n
        config = DepthConfig(epochs=epochs, width=width, height=height, batch_size=4, device="cpu")
        out = args.out / f"depth-{n}.pt"
        cpu = time.process_time()
        result = fit_depth(train, config, out_path=out)
        cpu = time.process_time() - cpu
        predictor = DepthPredictor(load_checkpoint(out))
        constant = result.metrics["constant_depth_m"]
        steps = epochs * math.ceil(trained / 4)
        for name, frames in sets:
            s = score(predictor.predict, frames, constant)
            print(f"| {n} / {trained} ({epochs} epochs, {steps} steps) | {name} | {s['net'][0]:.3f} | {s['net'][1]:.3f} "
                  f"| {s['net_ms'][0]:.3f} | {s['net_ms'][1]:.3f} | {s['const'][0]:.3f} | {s['const'][1]:.3f} "
                  f"| {s['const_ms'][0]:.3f} / {s['const_ms'][1]:.3f} | {cpu:.0f} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
