"""Timing of exports and of the review queue's mask thumbnails.

* An export (masks, COCO, the zip) of ``--frames`` frames at ``--size``
  (default 60 at 1280x960, the dataset's camera size), each annotated by two
  people with two objects each: CPU seconds per frame and per million mask
  pixels, which sets ``EXPORT_INLINE_MAX_PIXELS`` (what one request may
  build); against a zip that stores everything as it is, and one that
  deflates everything (the images again too).
* The same with the frames' images (``--images``, what the worker builds).
* A mask thumbnail (240 px wide) made, then served from its cache.

CPU time is ``time.process_time`` (this process, all threads); the machine
is shared, so the load average is printed.

Run: ``.venv/bin/python bench/bench_export.py [--frames 60] [--size 1280x960]``.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import cv2  # noqa: E402
import numpy as np  # noqa: E402
import pycocotools.mask as coco_mask  # noqa: E402


def rle(mask: np.ndarray) -> dict:
    encoded = coco_mask.encode(np.asfortranarray(mask.astype(np.uint8)))
    return {"size": [int(v) for v in encoded["size"]], "counts": encoded["counts"].decode()}


def dataset(n: int, width: int, height: int) -> None:
    """``n`` JPEG frames of a smooth scene with noise, two annotators with two objects each."""
    from app.extensions import db
    from app.models import Frame
    from app.services import labelling
    from app.services.importing import FrameItem, add_frames
    from app.services.users import create_user

    rng = np.random.default_rng(0)
    yy, xx = np.mgrid[0:height, 0:width]
    items = []
    for i in range(n):
        base = np.dstack([(xx * 255 // width), (yy * 255 // height), np.full_like(xx, 40 + i)]).astype(np.int16)
        rgb = np.clip(base + rng.integers(-20, 20, base.shape), 0, 255).astype(np.uint8)
        ok, jpeg = cv2.imencode(".jpg", rgb, [cv2.IMWRITE_JPEG_QUALITY, 90])
        items.append(FrameItem(f"{i:05d}", i, "bench", rgb=jpeg.tobytes(), rgb_suffix=".jpg"))
    add_frames(activity="bench", sequence="s", items=items)
    people = [create_user(name, "annotator", f"{name}-password-123")[0] for name in ("ann", "bob")]
    frames = db.session.execute(db.select(Frame).order_by(Frame.index)).scalars().all()
    for frame in frames:
        for k, person in enumerate(people):
            instances = []
            for j in range(2):
                mask = np.zeros((height, width), bool)
                cx, cy = rng.integers(width // 5, 4 * width // 5), rng.integers(height // 5, 4 * height // 5)
                cv2.ellipse(mask.view(np.uint8), (int(cx), int(cy)), (width // 10, height // 8), 0, 0, 360, 1, -1)
                instances.append({"key": f"k{j}", "kind": None, "label": None, "mask": rle(mask)})
            labelling.save_annotation(frame, person, {"version": 0, "instances": instances, "status": "done",
                                                      "no_action_object": False, "time_spent_delta_s": 0.0})


def timed(function, repeats: int) -> tuple[float, float, object]:
    """(median CPU seconds, median wall seconds, last result) of ``function()``."""
    cpu, wall, result = [], [], None
    for _ in range(repeats):
        c, w = time.process_time(), time.perf_counter()
        result = function()
        cpu.append(time.process_time() - c)
        wall.append(time.perf_counter() - w)
    return statistics.median(cpu), statistics.median(wall), result


def other_zip(options, method: int) -> int:
    """The export written into a zip that compresses every member with ``method``; its size."""
    from app.services.exchange import write_export

    with tempfile.TemporaryFile() as out:
        with zipfile.ZipFile(out, "w", method) as archive:
            write_export(lambda name, data: archive.writestr(name, data), options)
        return out.tell()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=60)
    parser.add_argument("--size", default="1280x960")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    width, height = (int(v) for v in args.size.split("x"))

    from app import create_app
    from app.extensions import db
    from app.models import Annotation
    from app.services import exchange, labelling
    from flask_migrate import upgrade

    folder = Path(tempfile.mkdtemp(prefix="bench-export-"))
    app = create_app({"SQLALCHEMY_DATABASE_URI": f"sqlite:///{folder / 'db.sqlite3'}", "SECRET_KEY": "bench",
                      "STORAGE_URL": str(folder), "CACHE_ROOT": str(folder / "cache"), "TESTING": True},
                     instance_path=str(folder / "instance"))
    with app.app_context():
        upgrade()
        dataset(args.frames, width, height)
        options = exchange.ExportOptions.of()
        plan = exchange.plan_export(options)
        mpx = plan.pixels / 1e6
        print(f"{plan.frames} frames at {width}x{height}, {plan.annotations} annotations (2 objects each): "
              f"{mpx:.0f} Mpx of masks; load average {os.getloadavg()[0]:.1f}")

        def ours(with_images: bool):
            chosen = exchange.ExportOptions.of(images=with_images)
            with tempfile.TemporaryFile() as out:
                exchange.write_zip(out, chosen)
                return out.tell()

        images = exchange.ExportOptions.of(images=True)
        for label, run in (("masks + COCO (a request's export)", lambda: ours(False)),
                           ("  zip storing everything", lambda: other_zip(options, zipfile.ZIP_STORED)),
                           ("with images (the worker's)", lambda: ours(True)),
                           ("  zip storing everything", lambda: other_zip(images, zipfile.ZIP_STORED)),
                           ("  zip deflating everything", lambda: other_zip(images, zipfile.ZIP_DEFLATED))):
            cpu, wall, size = timed(run, args.repeats)
            extra = f", zip {size / 1e6:.2f} MB"
            print(f"  {label:36s} CPU {cpu:6.2f} s ({1000 * cpu / plan.frames:5.1f} ms/frame, "
                  f"{1000 * cpu / mpx:5.1f} ms/Mpx), wall {wall:6.2f} s{extra}")
        inline = app.config["EXPORT_INLINE_MAX_PIXELS"] / 1e6
        cpu, _, _ = timed(lambda: ours(False), 1)
        print(f"  EXPORT_INLINE_MAX_PIXELS = {inline:.0f} Mpx: about {cpu / mpx * inline:.1f} s of CPU in the request")

        annotations = db.session.execute(db.select(Annotation)).scalars().all()
        made = []
        for annotation in annotations[:20]:
            c = time.process_time()
            labelling.mask_thumbnail(annotation)
            made.append(time.process_time() - c)
        hits = []
        for annotation in annotations[:20]:
            c = time.process_time()
            labelling.mask_thumbnail(annotation)
            hits.append(time.process_time() - c)
        print(f"  mask thumbnail: made {1000 * statistics.median(made):.1f} ms median, "
              f"cached {1000 * statistics.median(hits):.2f} ms median (20 annotations)")


if __name__ == "__main__":
    main()
