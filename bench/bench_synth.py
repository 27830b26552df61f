"""Timing of egonet.synth, the demo-data renderer.

* 7 activities x ``--frames`` frames (default 40) at 320x240, the size the
  demo imports: frames per second and median milliseconds per frame, overall
  and per activity. Target: the whole set well under a minute on one core.
* ``--large`` frames (default 3) at the dataset's native 1280x960.

Also reports the share of tactile frames and the mean retries per frame (a
configuration is resampled when its action-object would be too small).

Run: ``.venv/bin/python bench/bench_synth.py [--frames 40] [--large 3]``.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from egonet.synth import ACTIVITIES, render_frame  # noqa: E402


def time_frames(activity: str, indices: range, *, width: int, height: int) -> tuple[list[float], list[dict]]:
    """Render frames one by one; return seconds per frame and their metadata."""
    seconds, metas = [], []
    for index in indices:
        start = time.perf_counter()
        frame = render_frame(activity, index, seed=0, width=width, height=height)
        seconds.append(time.perf_counter() - start)
        metas.append(frame.meta)
    return seconds, metas


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=40, help="frames per activity at 320x240")
    parser.add_argument("--large", type=int, default=3, help="frames at 1280x960 (cooking)")
    args = parser.parse_args()

    print(f"320x240, {len(ACTIVITIES)} activities x {args.frames} frames")
    everything: list[float] = []
    all_metas: list[dict] = []
    for activity in ACTIVITIES:
        seconds, metas = time_frames(activity, range(args.frames), width=320, height=240)
        everything += seconds
        all_metas += metas
        tactile = sum(m["kind"] == "tactile" for m in metas) / max(len(metas), 1)
        print(
            f"  {activity:12s} median {1000 * statistics.median(seconds):6.1f} ms/frame"
            f"  tactile {tactile:4.0%}  retries {statistics.mean(m['attempt'] for m in metas):.2f}"
        )
    total = sum(everything)
    print(
        f"  all          {len(everything)} frames in {total:.1f} s: {len(everything) / total:.1f} frames/s,"
        f" median {1000 * statistics.median(everything):.1f} ms/frame"
    )
    if args.large:
        seconds, _ = time_frames("cooking", range(args.large), width=1280, height=960)
        print(
            f"1280x960, {args.large} frames: median {1000 * statistics.median(seconds):.0f} ms/frame,"
            f" {len(seconds) / sum(seconds):.2f} frames/s"
        )


if __name__ == "__main__":
    main()
