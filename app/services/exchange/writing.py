"""Writing an export: through one ``write(relative_path, data)`` callback, into a folder (or a bucket) or a zip."""

import contextlib
import json
import os
import shutil
import tempfile
import zipfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import IO

import numpy as np

from app.models import Annotation, Frame, Instance
from app.services import media, storage
from app.services.exchange.selection import (
    CATEGORY,
    COCO_FILE,
    IMAGES_DIR,
    MASKS_DIR,
    ExchangeProblem,
    ExportOptions,
    FrameExport,
    annotator_file,
    frame_names,
    select_export,
)
from egonet import io, rle

Write = Callable[[str, bytes], None]


@dataclass
class ExportReport:
    frames: int = 0
    annotations: int = 0
    instances: int = 0
    images: int = 0

    def summary(self) -> str:
        images = f", {self.images} images" if self.images else ""
        return (f"{self.frames} frames, {self.annotations} annotations, {self.instances} action-objects"
                f"{images} exported")


def write_export(
    write: Write,
    options: ExportOptions,
    *,
    on_start: Callable[[int], None] | None = None,
    on_progress: Callable[[int], None] | None = None,
) -> ExportReport:
    """Produce the export's files through ``write(relative_path, data)``.

    ``on_start`` gets the number of frames, ``on_progress`` 1 after each.

    Raises:
        NothingToExport: the options select nothing (nothing is written).
        ExchangeProblem: an unknown activity or annotator.
    """
    groups = select_export(options)
    names = frame_names(g.frame for g in groups)
    if on_start:
        on_start(len(groups))
    report = ExportReport()
    images, objects = [], []
    for image_id, group in enumerate(groups, start=1):
        name = names[group.frame.id]
        records = [_write_annotation(write, options, a, name, image_id, objects, chosen=(rank == 0))
                   for rank, a in enumerate(group.annotations)]
        if options.writes_coco:
            images.append(_coco_image(image_id, group, name, records))
        if options.images:
            write(f"{IMAGES_DIR}/{_image_name(group.frame, name)}", media.read(group.frame.rgb_path))
            report.images += 1
        report.frames += 1
        report.annotations += len(group.annotations)
        report.instances += sum(len(a.instances) for a in group.annotations)
        if on_progress:
            on_progress(1)
    if options.writes_coco:
        coco = {
            "info": {"description": "EgoNet Studio action-object masks", "version": "2"},
            "images": images,
            "annotations": objects,
            "categories": [CATEGORY],
        }
        write(COCO_FILE, json.dumps(coco, indent=1, ensure_ascii=False).encode())
    return report


def _write_annotation(write: Write, options: ExportOptions, annotation: Annotation, name: str, image_id: int,
                      objects: list[dict], *, chosen: bool) -> dict:
    """Write one annotation's masks; add its instances to ``objects``; return its COCO record."""
    frame = annotation.frame
    author = annotation.author.username
    record = {
        "annotator": author,
        "status": annotation.status.value,
        "no_action_object": annotation.no_action_object,
        "time_spent_s": annotation.time_spent_s,
        "reviewer": annotation.reviewer.username if annotation.reviewer else None,
        "review_comment": annotation.review_comment,
        "frame_mask": chosen,
    }
    if options.writes_png:
        # The annotation keeps its union as the PNG this writes (egonet.io.encode_png): copied, not redrawn.
        if annotation.mask_path:
            png = media.read(annotation.mask_path)
        else:
            png = io.encode_png(np.zeros((frame.height, frame.width), bool))
        if chosen:
            write(f"{MASKS_DIR}/{name}.png", png)
        write(annotator_file(author, name), png)
        record["mask_file"] = annotator_file(author, name)
    if options.writes_coco:
        for instance in annotation.instances:
            mask = io.read_mask(media.local_path(instance.mask_path))
            objects.append(_coco_object(len(objects) + 1, image_id, annotation, instance, mask))
    return record


def _image_name(frame: Frame, name: str) -> str:
    return name + Path(frame.rgb_path).suffix


def _coco_image(image_id: int, group: FrameExport, name: str, records: list[dict]) -> dict:
    frame = group.frame
    meta = {
        "activity": frame.sequence.activity.name,
        "sequence": frame.sequence.name,
        "source_name": frame.source_name,
        "index": frame.index,
        "content_hash": frame.content_hash,
        # Where the frame's depth and DHG came from: "measured", "predicted" (a network's, from the RGB), or None.
        "depth": ("predicted" if frame.depth_predicted else "measured") if frame.depth_path or frame.dhg_path else None,
        "annotations": records,
    }
    if frame.depth_predicted:
        meta["depth_model"] = frame.meta.get("depth_model")
        meta["intrinsics_assumed"] = bool(frame.meta.get("intrinsics_assumed"))
    if "mask_file" in records[0]:  # PNG masks were written
        meta["mask_file"] = f"{MASKS_DIR}/{name}.png"
    return {"id": image_id, "file_name": _image_name(frame, name), "width": frame.width, "height": frame.height,
            "egonet": meta}


def _coco_object(object_id: int, image_id: int, annotation: Annotation, instance: Instance, mask: np.ndarray) -> dict:
    segmentation = rle.encode(mask)
    return {
        "id": object_id,
        "image_id": image_id,
        "category_id": CATEGORY["id"],
        "iscrowd": 0,
        "segmentation": segmentation,
        "area": rle.area(segmentation),
        "bbox": rle.bbox(segmentation),
        "attributes": {
            "annotator": annotation.author.username,
            "status": annotation.status.value,
            "kind": instance.kind.value if instance.kind else None,
            "label": instance.label,
        },
    }


# --------------------------------------------------------------------------
# Folders and zips


def export_folder(
    out: str | Path,
    options: ExportOptions,
    *,
    on_start: Callable[[int], None] | None = None,
    on_progress: Callable[[int], None] | None = None,
) -> ExportReport:
    """Export into the folder ``out``, which must not exist or be empty, or into
    ``s3://bucket/prefix/name``, which must hold nothing yet.

    A folder's files are written into a temporary folder beside ``out`` and
    moved into place at the end; a bucket's are deleted again if the export
    fails; so an export that fails (or matches nothing) leaves nothing behind.
    """
    if str(out).startswith("s3://"):
        bucket, name = storage.open_parent(str(out))
        if next(iter(bucket.list(name)), None) is not None:
            raise ExchangeProblem(f"{out}: holds files already; choose a new folder (--out)", field="out")
        try:
            return write_export(lambda relative, data: bucket.put(f"{name}/{relative}", data), options,
                                on_start=on_start, on_progress=on_progress)
        except BaseException:
            with contextlib.suppress(storage.StorageUnavailable):
                bucket.delete_prefix(name)
            raise
    out = Path(out)
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise ExchangeProblem(f"{out}: exists and is not an empty folder; choose a new one (--out)", field="out")
    out.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(dir=out.parent, prefix=f".{out.name}.tmp-"))

    def write(relative: str, data: bytes) -> None:
        path = staging / relative
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(data)

    try:
        report = write_export(write, options, on_start=on_start, on_progress=on_progress)
        if out.exists():
            out.rmdir()
        os.replace(staging, out)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    return report


def write_zip(
    target: IO[bytes],
    options: ExportOptions,
    *,
    on_start: Callable[[int], None] | None = None,
    on_progress: Callable[[int], None] | None = None,
) -> ExportReport:
    """Write the export as a zip into the open binary file ``target``.

    The frames' images are stored as they are (deflating JPEGs again costs a
    quarter more CPU for half a per cent less); the masks and the JSON are
    deflated (the zip of masks comes out 60 % smaller for 1 % more CPU;
    bench/bench_export.py). Members carry a fixed date,
    so the same export gives the same bytes.
    """
    with zipfile.ZipFile(target, "w") as archive:

        def write(relative: str, data: bytes) -> None:
            method = zipfile.ZIP_STORED if relative.startswith(f"{IMAGES_DIR}/") else zipfile.ZIP_DEFLATED
            archive.writestr(zipfile.ZipInfo(relative, date_time=(1980, 1, 1, 0, 0, 0)), data, compress_type=method)

        return write_export(write, options, on_start=on_start, on_progress=on_progress)


def export_zip(options: ExportOptions) -> tuple[IO[bytes], ExportReport]:
    """The export as a zip in a temporary file (rewound), and its report (a download made in the request)."""
    spool = tempfile.SpooledTemporaryFile(max_size=32 * 1024 * 1024)
    try:
        report = write_zip(spool, options)
    except BaseException:
        spool.close()
        raise
    spool.seek(0)
    return spool, report
