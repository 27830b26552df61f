"""Timing of egonet.clicks at the dataset's native 1280x960.

* ``superpixels`` (SLIC, default options; Felzenszwalb for comparison):
  median seconds per frame. Target: <= 1.5 s.
* ``soft_mask`` with cached superpixels, three clicks, sigma 60 px: median
  milliseconds, against a naive version that evaluates the 2-D Gaussian
  directly and loops over regions with boolean masks. Target: <= 50 ms.

Frames are the sample RGB images in ``shared/data/egonet-samples/rgb``
upscaled to 1280x960 when present, else a synthetic frame.

Run: ``.venv/bin/python bench/bench_clicks.py``.
"""

from __future__ import annotations

import statistics
import sys
import time
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from egonet.clicks import soft_mask, superpixels  # noqa: E402

SHARED = ROOT.parent / "shared"
H, W = 960, 1280
CLICKS = [(640.0, 480.0), (300.0, 700.0), (1100.0, 200.0)]
SIGMA = 60.0


def load_frames(limit: int = 3) -> tuple[list[np.ndarray], str]:
    paths = sorted((SHARED / "data" / "egonet-samples" / "rgb").glob("*.jpg"))[:limit]
    frames = []
    for p in paths:
        bgr = cv2.imread(str(p), cv2.IMREAD_COLOR)
        if bgr is not None:
            rgb = cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
            frames.append(cv2.resize(rgb, (W, H), interpolation=cv2.INTER_CUBIC))
    if frames:
        return frames, f"{len(frames)} sample frames upscaled to {W}x{H}"
    rng = np.random.default_rng(0)
    small = rng.integers(0, 256, size=(12, 16, 3), dtype=np.uint8)
    frame = cv2.resize(small, (W, H), interpolation=cv2.INTER_CUBIC)
    frame = np.clip(frame + rng.normal(0, 8, frame.shape), 0, 255).astype(np.uint8)
    return [frame], f"a synthetic {W}x{H} frame"


def naive_soft_mask(shape: tuple[int, int], clicks: list[tuple[float, float]], sigma: float, labels: np.ndarray) -> np.ndarray:
    rows, cols = np.mgrid[0 : shape[0], 0 : shape[1]]
    gauss = np.zeros(shape)
    for x, y in clicks:
        gauss = np.maximum(gauss, np.exp(-((cols - x) ** 2 + (rows - y) ** 2) / (2 * sigma**2)))
    out = np.zeros(shape, dtype=np.float32)
    for region in range(int(labels.max()) + 1):
        inside = labels == region
        if inside.any():
            out[inside] = gauss[inside].mean()
    return out


def timed(fn, repeats: int) -> tuple[float, object]:
    times, result = [], None
    for _ in range(repeats):
        start = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times), result


def main() -> None:
    frames, source = load_frames()
    print(f"clicks benchmark on {source}")
    superpixels(frames[0][:64, :64].copy())  # import scikit-image outside the timings

    for method in ("hierarchical", "slic", "felzenszwalb"):
        times = []
        for frame in frames:
            t, labels = timed(lambda f=frame, m=method: superpixels(f, method=m), 2)
            times.append(t)
        print(
            f"  superpixels({method!r}) at {W}x{H}: median {statistics.median(times):.3f} s "
            f"({int(labels.max()) + 1} regions on the last frame; target <= 1.5 s)"
        )

    labels = superpixels(frames[0])
    fast_s, fast = timed(lambda: soft_mask((H, W), CLICKS, sigma=SIGMA, labels=labels), 15)
    naive_s, naive = timed(lambda: naive_soft_mask((H, W), CLICKS, SIGMA, labels), 2)
    err = float(np.max(np.abs(fast - naive)))
    if err > 1e-5:
        raise SystemExit(f"mismatch between soft_mask and the naive version: {err}")
    print(
        f"  soft_mask, {len(CLICKS)} clicks, {int(labels.max()) + 1} cached regions: median {fast_s * 1e3:.1f} ms "
        f"(target <= 50 ms); naive region loop {naive_s * 1e3:.0f} ms; ratio {naive_s / fast_s:.0f}x "
        f"(max abs difference {err:.1e})"
    )


if __name__ == "__main__":
    main()
