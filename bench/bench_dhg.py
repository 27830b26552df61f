"""Benchmark and eyeball check of egonet.dhg (height from depth, DHG images).

Run from the repository root::

    .venv/bin/python bench/bench_dhg.py [--repeats 7]

It times ``height_map`` on one core (median of several runs) on a synthetic
1280x960 floor and on the real 640x480 PrimeSense frames in
``../shared/data/rgbd-primesense`` (next to the repository), prints the
gravity, tilt, camera height and floor share found on each real frame, and
writes DHG images to ``bench/out/`` (git-ignored) for a look: the floor must
be dark in the height channel and things brighter the higher they are. When
the shared data are missing, the real-frame part is skipped with a message.
"""

import os

# One core, as the budget says: set before numpy and OpenCV start their pools.
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from egonet import dhg  # noqa: E402

DATA = REPO.parent / "shared" / "data" / "rgbd-primesense"
OUT = REPO / "bench" / "out"


def median_time(fn, repeats: int) -> tuple[float, float]:
    """Median wall time and median CPU time of this process, in seconds.

    The CPU time is the steadier figure on a machine shared with other work.
    """
    fn()  # warm up
    wall, cpu = [], []
    for _ in range(repeats):
        start, start_cpu = time.perf_counter(), time.process_time()
        fn()
        wall.append(time.perf_counter() - start)
        cpu.append(time.process_time() - start_cpu)
    return float(np.median(wall)), float(np.median(cpu))


def ms(times: tuple[float, float]) -> str:
    return f"{times[0] * 1000:.0f} ms wall / {times[1] * 1000:.0f} ms CPU"


def synthetic_floor(h: int, w: int, *, pitch_deg: float = 30.0, cam_h: float = 1.5):
    """z-depth of an infinite floor cam_h below a camera pitched down, and K."""
    f = 525.0 * w / 640
    K = np.array([[f, 0, (w - 1) / 2], [0, f, (h - 1) / 2], [0, 0, 1.0]])
    v = np.arange(h, dtype=np.float64)[:, None]
    y = (v - K[1, 2]) / f  # normalised image row, the same for every column
    p = np.radians(pitch_deg)
    # Height of the ray (x, y, 1) per unit z-depth: up . (x, y, 1), up = (0, -cos p, -sin p).
    drop = y * np.cos(p) + np.sin(p)
    with np.errstate(divide="ignore"):
        depth = np.where(drop > 0, cam_h / np.where(drop > 0, drop, 1.0), 0.0)
    return np.broadcast_to(depth, (h, w)).astype(np.float32), K


def load_intrinsics(path: Path) -> np.ndarray:
    """K from an Open3D camera JSON: 'intrinsic_matrix' is 9 numbers, column-major."""
    values = json.loads(path.read_text())["intrinsic_matrix"]
    return np.asarray(values, dtype=np.float64).reshape(3, 3).T


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7, help="timed runs per case (median reported)")
    args = parser.parse_args()
    cv2.setNumThreads(1)

    depth, K = synthetic_floor(960, 1280)
    t = median_time(lambda: dhg.height_map(depth, K), args.repeats)
    est = dhg.estimate_height(depth, K)
    print(
        f"synthetic floor 1280x960, pitch 30, camera 1.5 m: height_map median {ms(t)}; "
        f"found pitch {est.pitch_deg:.2f}, roll {est.roll_deg:.2f}, camera {est.camera_height_m:.3f} m"
    )
    depth, K = synthetic_floor(480, 640)
    t = median_time(lambda: dhg.height_map(depth, K), args.repeats)
    print(f"synthetic floor 640x480: height_map median {ms(t)}")

    if not DATA.is_dir():
        print(f"skipping the real frames: {DATA} is missing (the shared data live next to the repository)")
        return 0
    K = load_intrinsics(DATA / "camera_primesense.json")
    OUT.mkdir(parents=True, exist_ok=True)
    print(f"real frames from {DATA}")
    print("frame  time (wall / CPU)   up (camera coords)          pitch   roll  camera  floor(win)  floor(px)")
    for depth_path in sorted((DATA / "depth").glob("*.png")):
        depth_mm = cv2.imread(str(depth_path), cv2.IMREAD_UNCHANGED)
        bgr = cv2.imread(str(DATA / "color" / (depth_path.stem + ".jpg")), cv2.IMREAD_COLOR)
        if depth_mm is None or bgr is None:
            print(f"{depth_path.stem}: unreadable depth or colour image, skipped")
            continue
        depth = depth_mm.astype(np.float32) / 1000.0
        t = median_time(lambda: dhg.height_map(depth, K), args.repeats)
        est = dhg.estimate_height(depth, K)
        with np.errstate(invalid="ignore"):
            floor_px = float(np.mean(np.abs(est.height_m[depth > 0]) < 0.05))
        up = ", ".join(f"{c:+.3f}" for c in est.up)
        seen = "" if est.floor_visible else " (floor not in view: assumed)"
        print(
            f"{depth_path.stem}  {t[0] * 1000:4.0f} / {t[1] * 1000:4.0f} ms  ({up})"
            f"  {est.pitch_deg:+5.1f}  {est.roll_deg:+5.1f}"
            f"  {est.camera_height_m:5.2f} m  {est.floor_fraction:9.1%}  {floor_px:8.1%}{seen}"
        )
        rgb = cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
        image = dhg.dhg_from_depth(depth, K, rgb)
        # Stored as an RGB PNG whose red, green, blue are gray, height, depth (the authors' order).
        cv2.imwrite(str(OUT / f"dhg_{depth_path.stem}.png"), cv2.cvtColor(image, cv2.COLOR_RGB2BGR))
        cv2.imwrite(str(OUT / f"height_{depth_path.stem}.png"), image[:, :, 1])
    print(f"DHG images written to {OUT}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
