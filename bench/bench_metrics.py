"""Throughput of egonet.metrics.score_maps against a loop over thresholds.

Scores 50 maps of 481x641 float32 (the EgoNet output size) with the
default 99 thresholds, once with continuous probabilities (a softmax output)
and once with probabilities quantised to k/255 (a map stored as 8-bit PNG),
where more pixels sit on threshold boundaries and take the exact path.
The naive reference thresholds every map once per threshold (``prob >= t``)
and counts with ``np.count_nonzero``.

Run: ``.venv/bin/python bench/bench_metrics.py``. Prints medians in
megapixels per second and the speed-up over the naive loop.
"""

from __future__ import annotations

import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from egonet.metrics import score_maps, threshold_values  # noqa: E402

N_MAPS = 50
H, W = 481, 641
REPEATS = 5
NAIVE_REPEATS = 3


def make_maps(rng: np.random.Generator, *, quantised: bool) -> tuple[list[np.ndarray], list[np.ndarray]]:
    yy, xx = np.mgrid[0:H, 0:W]
    probs, masks = [], []
    for _ in range(N_MAPS):
        cy, cx = rng.uniform(0.3, 0.7) * H, rng.uniform(0.3, 0.7) * W
        blob = np.exp(-((yy - cy) ** 2 + (xx - cx) ** 2) / (2 * 80.0**2))
        prob = np.clip(0.7 * blob + 0.3 * rng.random((H, W)), 0, 1).astype(np.float32)
        if quantised:
            prob = (np.round(prob * 255) / 255).astype(np.float32)
        masks.append(blob > 0.5)
        probs.append(prob)
    return probs, masks


def naive_score(probs: list[np.ndarray], masks: list[np.ndarray]) -> float:
    t = threshold_values()
    tp = np.zeros(t.size)
    fp = np.zeros(t.size)
    fn = np.zeros(t.size)
    for prob, mask in zip(probs, masks):
        n_pos = np.count_nonzero(mask)
        for k, tk in enumerate(t):
            pred = prob >= tk  # tk is np.float64: the comparison is exact
            hits = np.count_nonzero(pred & mask)
            tp[k] += hits
            fp[k] += np.count_nonzero(pred) - hits
            fn[k] += n_pos - hits
    p = np.divide(tp, tp + fp, out=np.ones_like(tp), where=(tp + fp) > 0)
    r = np.divide(tp, tp + fn, out=np.zeros_like(tp), where=(tp + fn) > 0)
    f = np.divide(2 * p * r, p + r, out=np.zeros_like(p), where=(p + r) > 0)
    return float(f.max())


def median_seconds(fn, repeats: int) -> tuple[float, object]:
    times = []
    result = None
    for _ in range(repeats):
        start = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times), result


def main() -> None:
    rng = np.random.default_rng(0)
    mpx = N_MAPS * H * W / 1e6
    print(f"score_maps: {N_MAPS} maps of {H}x{W} float32, 99 thresholds ({mpx:.1f} Mpx per run)")
    for quantised in (False, True):
        probs, masks = make_maps(rng, quantised=quantised)
        fast_s, score = median_seconds(lambda: score_maps(probs, masks), REPEATS)
        naive_s, naive_mf = median_seconds(lambda: naive_score(probs, masks), NAIVE_REPEATS)
        if abs(score.max_f - naive_mf) > 1e-12:
            raise SystemExit(f"mismatch: score_maps MF {score.max_f} vs naive {naive_mf}")
        label = "quantised k/255" if quantised else "continuous     "
        print(
            f"  {label}: score_maps {mpx / fast_s:7.1f} Mpx/s ({fast_s * 1e3:6.1f} ms), "
            f"naive loop {mpx / naive_s:5.1f} Mpx/s ({naive_s * 1e3:7.1f} ms), "
            f"ratio {naive_s / fast_s:5.1f}x  (median of {REPEATS} / {NAIVE_REPEATS} runs)"
        )


if __name__ == "__main__":
    main()
