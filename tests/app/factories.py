"""Small makers of real files for import tests."""

import json
from pathlib import Path

import cv2
import numpy as np

from egonet import io


def rgb_image(seed: int, size=(48, 64)) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return rng.integers(0, 255, (*size, 3), dtype=np.uint8)


def image_folder(root: Path, n: int = 4, *, size=(48, 64), depth: bool = False, intrinsics: bool = False, masks: bool = False) -> Path:
    """A folder in the recognised layout: rgb/, depth/, masks/, camera.json."""
    (root / "rgb").mkdir(parents=True)
    for i in range(n):
        (root / "rgb" / f"{i:05d}.png").write_bytes(io.encode_png(rgb_image(i, size)))
        if depth:
            (root / "depth").mkdir(exist_ok=True)
            d = np.full(size, 1.0 + 0.25 * i, np.float32)
            d[0, 0] = 0.0
            (root / "depth" / f"{i:05d}.png").write_bytes(io.encode_depth_png(d))
        if masks:
            (root / "masks").mkdir(exist_ok=True)
            m = np.zeros(size, bool)
            m[10:20, 5 + i : 30] = True
            (root / "masks" / f"{i:05d}.png").write_bytes(io.encode_png(m))
    if intrinsics:
        h, w = size
        (root / "camera.json").write_text(json.dumps({"fx": 50.0, "fy": 50.0, "cx": w / 2, "cy": h / 2}))
    return root


def video_file(path: Path, n: int = 10, *, size=(48, 64)) -> Path:
    """An MJPG AVI of ``n`` frames, each a different flat colour."""
    h, w = size
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 10.0, (w, h))
    assert writer.isOpened(), "OpenCV cannot write MJPG AVI here"
    for i in range(n):
        frame = np.zeros((h, w, 3), np.uint8)
        frame[:] = (20 * i % 255, 100, 255 - 20 * i % 255)
        frame[: h // 2, : w // 2] = 255 - frame[0, 0]
        writer.write(frame)
    writer.release()
    return path
