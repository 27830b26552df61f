"""Time per training iteration on the CPU: egonet-lite, the faithful EgoNet and DeepLab-Obj.

Usage::

    .venv/bin/python -m bench.bench_train                 # from the repository root
    .venv/bin/python -m bench.bench_train --threads 4 --egonet-runs 5

One iteration is what ``egonet.train.train_one_epoch`` does per batch:
forward in train mode, per-pixel cross-entropy (mean), backward, an SGD step
(momentum 0.9, weight decay 5e-4). Each model trains at its own size and
batch: egonet-lite at the demo's training size (320x240, batch 2 by
default), the faithful model at the released input size (641x481, batch 1),
DeepLab-Obj with the paper's 41 classes at the demo's size (batch 2; its
iteration is DeepLab-RGB's but for fc10's 42 outputs).
Inputs are random (the time does not depend on them); one warm-up iteration
is not timed; the median and the best are printed, per iteration and per
frame. Run it when the CPU is otherwise idle.
"""

from __future__ import annotations

import argparse
import platform
import statistics
import sys
import time

import torch
import torch.nn.functional as F

from egonet.checkpoint import DEFAULT_LR
from egonet.network.builders import build_model


def iteration_times(name: str, *, runs: int, batch: int, height: int, width: int, classes: int = 0) -> list[float]:
    """Seconds per training iteration of ``name`` on random ``(batch, 3, height, width)`` frames (``classes``: DeepLab-Obj's)."""
    torch.manual_seed(0)
    model = build_model(name, **({"classes": [f"class {k}" for k in range(classes)]} if classes else {})).train()
    optimizer = torch.optim.SGD(model.parameters(), lr=DEFAULT_LR[name], momentum=0.9, weight_decay=5e-4)
    rgb, dhg = torch.rand(batch, 3, height, width), torch.rand(batch, 3, height, width)
    target = (torch.rand(batch, height, width) * (classes or 1) * 10).long().clamp(max=classes or 1)  # ~10 % foreground
    times = []
    for i in range(runs + 1):
        start = time.perf_counter()
        loss = F.cross_entropy(model(rgb, dhg), target)
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        optimizer.step()
        if i:  # the first iteration warms the allocator and oneDNN's caches
            times.append(time.perf_counter() - start)
    return times


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--threads", type=int, default=2, help="torch.set_num_threads (default 2)")
    parser.add_argument("--lite-runs", type=int, default=10)
    parser.add_argument("--lite-batch", type=int, default=2)
    parser.add_argument("--lite-size", default="320x240", help="WIDTHxHEIGHT (default 320x240)")
    parser.add_argument("--egonet-runs", type=int, default=3, help="0 skips the faithful model")
    parser.add_argument("--egonet-batch", type=int, default=1)
    parser.add_argument("--egonet-size", default="641x481", help="WIDTHxHEIGHT (default 641x481)")
    parser.add_argument("--obj-runs", type=int, default=2, help="DeepLab-Obj iterations (0 skips it)")
    args = parser.parse_args(argv)
    if args.threads < 1 or args.lite_runs < 1 or args.egonet_runs < 0:
        parser.error("--threads and --lite-runs must be >= 1, --egonet-runs >= 0")

    def size(text: str, option: str) -> tuple[int, int]:
        try:
            width, height = (int(v) for v in text.lower().split("x"))
        except ValueError:
            parser.error(f"{option} must be WIDTHxHEIGHT, e.g. 320x240")
        return height, width

    torch.set_num_threads(args.threads)
    print(f"torch {torch.__version__}, {platform.processor() or platform.machine()}, {torch.get_num_threads()} threads, "
          "train mode, SGD step included")
    plan = [("egonet-lite", args.lite_runs, args.lite_batch, size(args.lite_size, "--lite-size"), 0)]
    if args.egonet_runs:
        plan.append(("egonet", args.egonet_runs, args.egonet_batch, size(args.egonet_size, "--egonet-size"), 0))
    if args.obj_runs:
        plan.append(("deeplab-obj", args.obj_runs, args.lite_batch, size(args.lite_size, "--lite-size"), 41))
    for name, runs, batch, (height, width), classes in plan:
        times = iteration_times(name, runs=runs, batch=batch, height=height, width=width, classes=classes)
        median = statistics.median(times)
        print(f"{name:12s} {width}x{height} batch {batch}: median {median:7.2f} s/iteration, "
              f"{median / batch:7.2f} s/frame, best {min(times):7.2f} s  ({runs} runs)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
