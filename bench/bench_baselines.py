"""Fit and predict time of every learned baseline under leave-one-activity-out on the demo, against refitting without sharing.

Builds the demo (``flask egonet demo --no-train``: 40 frames per activity,
320x240; ``--unlabelled-fraction 0`` by default here, so all 280 frames are
labelled) in a temporary instance, then for each learned baseline of
``egonet.baselines.BASELINES``:

* **fit**: ``app.services.scoring.fitting.fit_missing``, as the scoring
  service and the worker call it: every labelled frame read and summarized
  once, the 7 folds fitted on the other activities' summaries and cached;
  CPU seconds in all and per labelled frame;
* **cached**: the same call again, which only reads the 7 fitted folds back;
* **predict**: the median CPU time of one fold's ``predict`` on ``--predict``
  frames (what scoring a frame costs once its fold is fitted);
* **naive**: fitting each fold from its own frames, without sharing the
  frames' summaries between folds (each frame summarized 6 times instead of
  once), timed on one fold and multiplied by 7 folds; and refitting a fold
  for every scored frame instead of caching it (280 fits).

CPU time is ``time.process_time`` (all threads of the process). The machine
is shared: the load average is printed before and after.

Run: ``.venv/bin/python bench/bench_baselines.py [--frames-per-activity 40] [--predict 20]``.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from flask_migrate import upgrade  # noqa: E402

from app import create_app  # noqa: E402
from app.services.demo import create_demo  # noqa: E402
from app.services.scoring import fitting, sources  # noqa: E402
from egonet.baselines import BASELINES, build_baseline, is_trained  # noqa: E402


def cpu(fn):
    start = time.process_time()
    result = fn()
    return time.process_time() - start, result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--frames-per-activity", type=int, default=40)
    parser.add_argument("--unlabelled-fraction", type=float, default=0.0)
    parser.add_argument("--predict", type=int, default=20, help="frames whose prediction is timed")
    args = parser.parse_args()
    print(f"load average before: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    with tempfile.TemporaryDirectory() as tmp:
        app = create_app({"TESTING": True, "SECRET_KEY": "bench", "SQLALCHEMY_DATABASE_URI": f"sqlite:///{tmp}/bench.sqlite3",
                          "STORAGE_URL": tmp, "CACHE_ROOT": f"{tmp}/cache"})  # fmt: skip
        with app.app_context():
            upgrade()
            create_demo(frames_per_activity=args.frames_per_activity, unlabelled_fraction=args.unlabelled_fraction)
            truth = sources.load_truth()
            n = len(truth.frames)
            by_activity = truth.by_activity()
            print(f"{n} labelled frames in {len(by_activity)} activities (folds)\n")
            print(f"{'baseline':<14} {'fit 7 folds':>12} {'per frame':>10} {'cached':>8} {'predict/frame':>14} "
                  f"{'naive: no sharing':>18} {'naive: refit per frame':>23}")  # fmt: skip
            total = 0.0
            for key in (k for k in BASELINES if is_trained(k)):
                fit_s, folds = cpu(lambda key=key: fitting.fit_missing(key, truth))
                cached_s, _ = cpu(lambda key=key: fitting.fit_missing(key, truth))
                total += fit_s
                held_out, frames = next(iter(by_activity.items()))
                sample = [fitting.training_frame(f, truth.annotations[f.id]) for f in frames[: args.predict]]
                times = [cpu(lambda f=f: folds[held_out].predict(f.rgb, f.dhg))[0] for f in sample]
                # One fold fitted from its own frames, read and summarized for it alone.
                others = [f for a, fs in by_activity.items() if a != held_out for f in fs]
                one_fold_s, _ = cpu(lambda key=key, others=others: build_baseline(key).fit(
                    fitting.training_frame(f, truth.annotations[f.id]) for f in others))  # fmt: skip
                naive = one_fold_s * len(by_activity)
                print(f"{BASELINES[key].name:<14} {fit_s:10.1f} s {fit_s / n * 1000:7.0f} ms {cached_s:6.2f} s "
                      f"{statistics.median(times) * 1000:11.0f} ms {naive:13.1f} s ({naive / fit_s:.1f}x) "
                      f"{one_fold_s * n:15.0f} s ({one_fold_s * n / (fit_s + cached_s):.0f}x)")  # fmt: skip
            print(f"\nall learned baselines, 7 folds: {total:.1f} s CPU ({total / n * 1000:.0f} ms per labelled frame)")
    print(f"load average after: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()
