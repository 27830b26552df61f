"""CPU forward time of the faithful EgoNet and EgoNet-lite on one 481x641 frame.

Usage::

    .venv/bin/python -m bench.bench_network             # from the repository root
    .venv/bin/python -m bench.bench_network --lite-runs 20 --threads 4

Each model is built with random weights (the time does not depend on them),
put in eval mode, warmed up once, then timed on batch 1 under
``torch.no_grad``, the two models in alternation; the median is reported,
and the best run (the better estimate on a busy machine). The goal (issue 4)
is a lite model at least 30x faster than the faithful one with 2 threads.
Exit status 1 when the ratio misses ``--goal``.

Run it when the CPU is otherwise idle. With other processes on the same
cores, two-thread timings of the lite model (about 200 short operators, each
ending in a thread barrier) inflate several times more than those of the
faithful one (a few long GEMMs), so the ratio drops.
"""

from __future__ import annotations

import argparse
import platform
import statistics
import sys
import time
from collections.abc import Sequence

import torch

from egonet.network.builders import build_model


def interleaved_times(
    names: Sequence[str], runs: Sequence[int], *, height: int, width: int
) -> dict[str, list[float]]:
    """Seconds per forward pass of each model on one random ``(1, 3, height, width)`` frame.

    The models are timed in alternation (round robin), so a change in the
    machine's background load during the bench affects them alike.

    Args:
        names: Keys of ``egonet.network.builders.MODELS``.
        runs: Timed runs of each model, after one warm-up run each.
        height: Frame height.
        width: Frame width.

    Returns:
        ``{name: [seconds, ...]}``.
    """
    torch.manual_seed(0)
    models = {name: build_model(name).eval() for name in names}
    rgb = torch.rand(1, 3, height, width)
    dhg = torch.rand(1, 3, height, width)
    times: dict[str, list[float]] = {name: [] for name in names}
    with torch.no_grad():
        for model in models.values():
            model(rgb, dhg)  # warm-up: allocator and oneDNN primitive caches
        rounds = max(runs)
        for r in range(rounds):
            for name, n in zip(names, runs, strict=True):
                # Spread a model's n runs evenly over the rounds.
                for _ in range((r + 1) * n // rounds - r * n // rounds):
                    start = time.perf_counter()
                    models[name](rgb, dhg)
                    times[name].append(time.perf_counter() - start)
    return times


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--threads", type=int, default=2, help="torch.set_num_threads (default 2)")
    parser.add_argument("--egonet-runs", type=int, default=3, help="timed runs of the faithful model")
    parser.add_argument("--lite-runs", type=int, default=10, help="timed runs of egonet-lite (default 10)")
    parser.add_argument("--height", type=int, default=481)
    parser.add_argument("--width", type=int, default=641)
    parser.add_argument("--goal", type=float, default=30.0, help="required speed-up of the lite model")
    args = parser.parse_args(argv)
    if min(args.threads, args.egonet_runs, args.lite_runs) < 1:
        parser.error("--threads, --egonet-runs and --lite-runs must be >= 1")

    torch.set_num_threads(args.threads)
    print(f"torch {torch.__version__}, {platform.processor() or platform.machine()}, "
          f"{torch.get_num_threads()} threads, frame {args.height}x{args.width}, batch 1, eval, no_grad")
    names, runs = ("egonet-lite", "egonet"), (args.lite_runs, args.egonet_runs)
    times = interleaved_times(names, runs, height=args.height, width=args.width)
    medians = {name: statistics.median(times[name]) for name in names}
    for name in names:
        print(f"{name:12s} median {medians[name] * 1000:9.1f} ms/frame, best {min(times[name]) * 1000:9.1f}  "
              f"(runs: {', '.join(f'{t * 1000:.0f}' for t in times[name])} ms)")
    ratio = medians["egonet"] / medians["egonet-lite"]
    verdict = "meets" if ratio >= args.goal else "MISSES"
    print(f"speed-up egonet / egonet-lite: {ratio:.1f}x ({verdict} the {args.goal:g}x goal)")
    return 0 if ratio >= args.goal else 1


if __name__ == "__main__":
    sys.exit(main())
