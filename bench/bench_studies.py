"""Timing of the study service's soft-mask path at the dataset's native 1280x960.

* first use of a frame: superpixels computed and written to the cache;
* later uses: the cached labels read back (compressed .npz), then
  ``egonet.clicks.soft_mask`` (three clicks, sigma 60 px): what the admin's
  overlays, the exports and the scorer pay per trial (target for soft_mask
  with cached superpixels: <= 50 ms);
* the admin's overlay PNG (640 px wide) and the 16-bit mask PNG of an export.

Medians in milliseconds. Run: ``.venv/bin/python bench/bench_studies.py``.
"""

import statistics
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from app import create_app  # noqa: E402
from app.models import Frame  # noqa: E402
from app.services import media, studies  # noqa: E402
from egonet import clicks as egonet_clicks  # noqa: E402
from egonet import io  # noqa: E402

H, W = 960, 1280
CLICKS = [(640.0, 480.0), (300.0, 700.0), (1100.0, 200.0)]


def frame_image() -> np.ndarray:
    sample = sorted((ROOT.parent / "shared" / "data" / "egonet-samples" / "rgb").glob("*.jpg"))
    if sample:
        rgb = cv2.cvtColor(cv2.imread(str(sample[0]), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
        return cv2.resize(rgb, (W, H), interpolation=cv2.INTER_CUBIC)
    rng = np.random.default_rng(0)
    return cv2.resize(rng.integers(0, 256, (12, 16, 3), dtype=np.uint8), (W, H), interpolation=cv2.INTER_CUBIC)


def median_ms(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times) * 1e3


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        app = create_app({"TESTING": True, "SQLALCHEMY_DATABASE_URI": "sqlite://", "STORAGE_URL": tmp, "CACHE_ROOT": f"{tmp}/cache"})
        with app.app_context():
            data = io.encode_png(frame_image())
            frame = Frame(width=W, height=H, content_hash=media.sha256(data), rgb_path=media.store(data, ".png"))
            settings = studies.DEFAULT_SUPERPIXELS
            egonet_clicks.superpixels(frame_image()[:64, :64].copy())  # import scikit-image outside the timings

            start = time.perf_counter()
            labels = studies.superpixel_labels(frame, settings)
            first = (time.perf_counter() - start) * 1e3
            size_kb = studies.masks.labels_path(frame, settings).stat().st_size / 1024
            read = median_ms(lambda: studies.superpixel_labels(frame, settings), 15)
            project = median_ms(lambda: egonet_clicks.soft_mask((H, W), CLICKS, sigma=60.0, labels=labels), 15)

            def trial_mask():
                return egonet_clicks.soft_mask((H, W), CLICKS, sigma=60.0, labels=studies.superpixel_labels(frame, settings))

            whole = median_ms(trial_mask, 15)
            mask = trial_mask()
            overlay = median_ms(lambda: studies.overlay_png(frame, mask, points=CLICKS), 7)
            png = median_ms(lambda: studies.mask_png(mask), 7)

    print(f"study soft masks at {W}x{H} ({int(labels.max()) + 1} regions, {settings['method']})")
    print(f"  first use: superpixels computed and cached in {first:.0f} ms ({size_kb:.0f} KiB .npz)")
    print(f"  cached labels read back: median {read:.1f} ms")
    print(f"  soft_mask on cached labels, {len(CLICKS)} clicks: median {project:.1f} ms (target <= 50 ms)")
    print(f"  per trial, read + soft_mask: median {whole:.1f} ms")
    print(f"  overlay PNG (640 px wide): median {overlay:.1f} ms; 16-bit mask PNG: median {png:.1f} ms")


if __name__ == "__main__":
    main()
