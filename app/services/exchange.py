"""Exchanging action-object masks with other tools: PNG per frame and COCO JSON.

An export is a folder (or a zip holding the same files):

    masks/<activity>/<sequence>/<frame>.png   the frame's mask, binary 0/255, the union of its instances
    annotations.json                          COCO: one image per frame, one annotation per instance,
                                              masks as compressed RLE written by pycocotools

``<frame>`` is the frame's source name (its file stem when imported from a
folder); a name used twice in a sequence gets ``~`` and the start of the
frame's content hash. Each exported frame contributes one annotation: among
those with an exported status, an accepted one first, then the most recently
updated. COCO images carry the frame's identity (activity, sequence, name,
content hash) and the annotation's author, status, "no action-object" flag,
time spent and review under the ``egonet`` key; instances carry their kind
and label the same way.

``import_annotations`` reads either form back onto frames already in the
database (matched by content hash, else by name). An export imported into a
database with the same frames and exported again gives the same files, byte
for byte.
"""

import json
import os
import shutil
import tempfile
import zipfile
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import IO

import numpy as np
import pycocotools.mask as coco_mask
from sqlalchemy import case, func

from app.errors import Problem
from app.extensions import db
from app.models import Activity, Annotation, Frame, Instance, InstanceKind, Role, Sequence, Status, User
from app.services import media
from app.services.importing import unpacked
from app.services.labelling.masks import Rle, coco_decode, decode_rle
from app.validation import Invalid
from egonet import io

FORMATS = ("png", "coco", "both")
DEFAULT_STATUSES = (Status.DONE, Status.REVIEWED)
COCO_FILE = "annotations.json"
MASKS_DIR = "masks"
CATEGORY = {"id": 1, "name": "action-object", "supercategory": "object"}
# Which annotation of a frame is exported when several qualify.
_RANK = {Status.REVIEWED: 0, Status.DONE: 1, Status.IN_PROGRESS: 2, Status.REJECTED: 3, Status.TODO: 4}


class ExchangeProblem(Problem):
    """An export or import that cannot go ahead; the message names the file or option."""


@dataclass
class ExportReport:
    frames: int = 0
    instances: int = 0


@dataclass
class ImportReport:
    annotations: int = 0
    instances: int = 0
    skipped: int = 0
    missing: int = 0


# --------------------------------------------------------------------------
# Names


def _safe(name: str) -> str:
    """A name usable as one path component (no separators, not hidden)."""
    cleaned = "".join("_" if c in '/\\\0' else c for c in name).strip()
    return "_" + cleaned if not cleaned or cleaned.startswith(".") else cleaned


def _frame_names(frames: Iterable[Frame]) -> dict[int, str]:
    """``activity/sequence/frame`` (no suffix) for each frame, unique within the database."""
    frames = list(frames)
    seq_ids = {f.sequence_id for f in frames}
    doubled = set()
    if seq_ids:
        doubled = set(
            db.session.execute(
                db.select(Frame.sequence_id, Frame.source_name)
                .where(Frame.sequence_id.in_(seq_ids))
                .group_by(Frame.sequence_id, Frame.source_name)
                .having(func.count() > 1)
            ).all()
        )
    names = {}
    for f in frames:
        stem = f.source_name if (f.sequence_id, f.source_name) not in doubled else f"{f.source_name}~{f.content_hash[:12]}"
        names[f.id] = f"{_safe(f.sequence.activity.name)}/{_safe(f.sequence.name)}/{_safe(stem)}"
    return names


# --------------------------------------------------------------------------
# Export


def activity_names() -> list[str]:
    """The activities an export can be limited to."""
    return list(db.session.execute(db.select(Activity.name).order_by(Activity.name)).scalars())


def select_annotations(*, activities: list[str], statuses: list[Status]) -> list[Annotation]:
    """One annotation per frame (see module doc), in dataset order.

    Raises:
        ExchangeProblem: an unknown activity name.
    """
    query = (
        db.select(Annotation)
        .join(Frame, Annotation.frame_id == Frame.id)
        .join(Sequence, Frame.sequence_id == Sequence.id)
        .join(Activity, Sequence.activity_id == Activity.id)
        .where(Annotation.status.in_(statuses))
    )
    if activities:
        known = set(db.session.execute(db.select(Activity.name).where(Activity.name.in_(activities))).scalars())
        unknown = [a for a in activities if a not in known]
        if unknown:
            raise ExchangeProblem(f"--activity: no activity named {unknown[0]!r}")
        query = query.where(Activity.name.in_(activities))
    rank = case(*((Annotation.status == s, r) for s, r in _RANK.items()), else_=9)
    rows = db.session.execute(
        query.order_by(Activity.name, Sequence.name, Frame.index, Frame.id, rank, Annotation.updated_at.desc(),
                       Annotation.id.desc())
    ).scalars()
    chosen: dict[int, Annotation] = {}
    for annotation in rows:
        chosen.setdefault(annotation.frame_id, annotation)
    return list(chosen.values())


def _instance_masks(annotation: Annotation) -> list[np.ndarray]:
    return [io.read_mask(media.absolute_path(i.mask_path)) for i in annotation.instances]


def _union(annotation: Annotation, masks: list[np.ndarray]) -> np.ndarray:
    union = np.zeros((annotation.frame.height, annotation.frame.width), bool)
    for mask in masks:
        union |= mask
    return union


def write_export(
    write: Callable[[str, bytes], None],
    *,
    fmt: str,
    activities: list[str],
    statuses: list[Status],
    on_start: Callable[[int], None] | None = None,
    on_progress: Callable[[int], None] | None = None,
) -> ExportReport:
    """Produce the export's files through ``write(relative_path, data)``."""
    if fmt not in FORMATS:
        raise ExchangeProblem(f"--format must be one of {', '.join(FORMATS)}, got {fmt!r}")
    annotations = select_annotations(activities=activities, statuses=statuses)
    names = _frame_names(a.frame for a in annotations)
    if on_start:
        on_start(len(annotations))
    report = ExportReport()
    images, objects = [], []
    for image_id, annotation in enumerate(annotations, start=1):
        frame = annotation.frame
        masks = _instance_masks(annotation)
        name = names[frame.id]
        if fmt in ("png", "both"):
            write(f"{MASKS_DIR}/{name}.png", io.encode_png(_union(annotation, masks)))
        if fmt in ("coco", "both"):
            images.append(_coco_image(image_id, annotation, name))
            for instance, mask in zip(annotation.instances, masks):
                objects.append(_coco_object(len(objects) + 1, image_id, instance, mask))
        report.frames += 1
        report.instances += len(masks)
        if on_progress:
            on_progress(1)
    if fmt in ("coco", "both"):
        coco = {
            "info": {"description": "EgoNet Studio action-object masks", "version": "1"},
            "images": images,
            "annotations": objects,
            "categories": [CATEGORY],
        }
        write(COCO_FILE, json.dumps(coco, indent=1, ensure_ascii=False).encode())
    return report


def _coco_image(image_id: int, annotation: Annotation, name: str) -> dict:
    frame = annotation.frame
    return {
        "id": image_id,
        "file_name": name + Path(frame.rgb_path).suffix,
        "width": frame.width,
        "height": frame.height,
        "egonet": {
            "activity": frame.sequence.activity.name,
            "sequence": frame.sequence.name,
            "source_name": frame.source_name,
            "index": frame.index,
            "content_hash": frame.content_hash,
            "mask_file": f"{MASKS_DIR}/{name}.png",
            "author": annotation.author.username,
            "status": annotation.status.value,
            "no_action_object": annotation.no_action_object,
            "time_spent_s": annotation.time_spent_s,
            "reviewer": annotation.reviewer.username if annotation.reviewer else None,
            "review_comment": annotation.review_comment,
        },
    }


def _coco_object(object_id: int, image_id: int, instance: Instance, mask: np.ndarray) -> dict:
    rle = coco_mask.encode(np.asfortranarray(mask.astype(np.uint8)))
    return {
        "id": object_id,
        "image_id": image_id,
        "category_id": CATEGORY["id"],
        "iscrowd": 0,
        "segmentation": {"size": [int(v) for v in rle["size"]], "counts": rle["counts"].decode("ascii")},
        "area": int(coco_mask.area(rle)),
        "bbox": [float(v) for v in coco_mask.toBbox(rle)],
        "egonet": {"kind": instance.kind.value if instance.kind else None, "label": instance.label},
    }


def export_folder(out: Path, **options) -> ExportReport:
    """Export into the folder ``out``, which must not exist or be empty.

    The files are written into a temporary folder beside ``out`` and moved
    into place at the end, so an export that fails leaves nothing behind.
    """
    out = Path(out)
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise ExchangeProblem(f"{out}: exists and is not an empty folder; choose a new one (--out)")
    out.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(dir=out.parent, prefix=f".{out.name}.tmp-"))

    def write(relative: str, data: bytes) -> None:
        path = staging / relative
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(data)

    try:
        report = write_export(write, **options)
        if out.exists():
            out.rmdir()
        os.replace(staging, out)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    return report


def export_zip(*, fmt: str, activities: list[str], statuses: list[Status]) -> tuple[IO[bytes], int]:
    """The export as a zip in a temporary file (rewound), and the number of frames."""
    spool = tempfile.SpooledTemporaryFile(max_size=32 * 1024 * 1024)
    try:
        with zipfile.ZipFile(spool, "w") as archive:

            def write(relative: str, data: bytes) -> None:
                # PNGs are compressed already; the JSON shrinks a lot.
                method = zipfile.ZIP_STORED if relative.endswith(".png") else zipfile.ZIP_DEFLATED
                archive.writestr(zipfile.ZipInfo(relative, date_time=(1980, 1, 1, 0, 0, 0)), data, compress_type=method)

            report = write_export(write, fmt=fmt, activities=activities, statuses=statuses)
    except BaseException:
        spool.close()
        raise
    spool.seek(0)
    return spool, report.frames


# --------------------------------------------------------------------------
# Import


@dataclass
class _Item:
    """One frame's annotation read from an export, before it is written."""

    where: str
    frame: Frame
    author: str
    status: Status
    masks: list[np.ndarray]
    kinds: list[InstanceKind | None]
    labels: list[str | None]
    no_action_object: bool
    time_spent_s: float = 0.0
    reviewer: str | None = None
    review_comment: str | None = None


def import_annotations(
    path: Path,
    *,
    author: str | None = None,
    status: Status | None = None,
    replace: bool = False,
    skip_missing: bool = False,
    on_start: Callable[[int], None] | None = None,
    on_progress: Callable[[int], None] | None = None,
) -> ImportReport:
    """Import an export (folder, zip, COCO JSON file or masks folder) in one transaction.

    Args:
        path: An export folder or zip (``annotations.json`` is read when
            present, else ``masks/``), a COCO JSON file, or a masks folder
            laid out as ``<activity>/<sequence>/<frame>.png``.
        author: The annotations' author; by default the one recorded in the
            COCO file, or "import" for PNG masks. Missing users are created
            as inactive annotators without a password.
        status: The annotations' status; by default the recorded one, or
            done for PNG masks.
        replace: Overwrite the author's existing annotation of a frame
            (otherwise it is kept and the import's is skipped).
        skip_missing: Skip masks of frames that are not in the database
            (otherwise the import stops).

    Raises:
        ExchangeProblem: bad layout or content, naming the file.
        egonet.io.MediaError: an unreadable mask file, or a zip that
            ``importing.unpacked`` refuses (naming the member).
    """
    path = Path(path)
    if not path.exists():
        raise ExchangeProblem(f"{path}: no such file or folder")
    if path.is_file() and path.suffix.lower() == ".zip":
        with unpacked(path) as folder:  # the frame import's checks: traversal, links, zip bombs
            return import_annotations(folder, author=author, status=status, replace=replace,
                                      skip_missing=skip_missing, on_start=on_start, on_progress=on_progress)
    if path.is_file():
        items = _read_coco(path, author=author, status=status, skip_missing=skip_missing)
    elif (path / COCO_FILE).is_file():
        items = _read_coco(path / COCO_FILE, author=author, status=status, skip_missing=skip_missing)
    else:
        masks = path / MASKS_DIR if (path / MASKS_DIR).is_dir() else path
        items = _read_png_tree(masks, author=author or "import", status=status or Status.DONE, skip_missing=skip_missing)
    found, missing = items
    if on_start:
        on_start(len(found))
    report = ImportReport(missing=missing)
    with media.transaction() as written:
        users: dict[str, User] = {}
        for item in found:
            if _write_item(item, replace=replace, users=users, written=written):
                report.annotations += 1
                report.instances += len(item.masks)
            else:
                report.skipped += 1
            if on_progress:
                on_progress(1)
    return report


def _frames_by_name() -> dict[str, Frame]:
    frames = {f.id: f for f in db.session.execute(db.select(Frame)).scalars()}
    return {name: frames[fid] for fid, name in _frame_names(frames.values()).items()}


def _read_png_tree(root: Path, *, author: str, status: Status, skip_missing: bool) -> tuple[list[_Item], int]:
    files = sorted(p for p in root.rglob("*.png") if not any(part.startswith(".") for part in p.relative_to(root).parts))
    if not files:
        raise ExchangeProblem(f"{root}: no {COCO_FILE} and no PNG masks (<activity>/<sequence>/<frame>.png)")
    by_name = _frames_by_name()
    items, missing = [], 0
    for p in files:
        name = p.relative_to(root).with_suffix("").as_posix()
        frame = by_name.get(name)
        if frame is None:
            if skip_missing:
                missing += 1
                continue
            raise ExchangeProblem(f"{p}: no frame {name!r} in the database (import the frames first, or --skip-missing)")
        mask = io.read_mask(p)
        _check_size(p, mask, frame)
        drawn = bool(mask.any())
        items.append(_Item(str(p), frame, author, status, [mask] if drawn else [], [None] if drawn else [],
                           [None] if drawn else [], not drawn))
    return items, missing


def _read_coco(path: Path, *, author: str | None, status: Status | None, skip_missing: bool) -> tuple[list[_Item], int]:
    try:
        coco = json.loads(io.read_bytes(path))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ExchangeProblem(f"{path}: not valid JSON ({exc})") from None
    if not isinstance(coco, dict) or not isinstance(coco.get("images"), list) or not isinstance(coco.get("annotations", []), list):
        raise ExchangeProblem(f"{path}: not a COCO file (needs an 'images' list and an 'annotations' list)")
    objects: dict[object, list[dict]] = {}
    for obj in coco.get("annotations", []):
        if not isinstance(obj, dict) or "image_id" not in obj or "segmentation" not in obj:
            raise ExchangeProblem(f"{path}: every annotation needs 'image_id' and 'segmentation'")
        objects.setdefault(obj["image_id"], []).append(obj)
    by_name = None
    items, missing = [], 0
    for image in coco["images"]:
        if not isinstance(image, dict) or "id" not in image:
            raise ExchangeProblem(f"{path}: every image needs an 'id'")
        where = f"{path} image {image['id']}"
        meta = image.get("egonet") or {}
        frame = _match_frame(image, meta)
        if frame is None:
            by_name = by_name if by_name is not None else _frames_by_name()
            stem = str(image.get("file_name", ""))
            frame = by_name.get(stem.rsplit(".", 1)[0] if "." in Path(stem).name else stem)
        if frame is None:
            if skip_missing:
                missing += 1
                continue
            raise ExchangeProblem(f"{where}: no matching frame in the database (import the frames first, or --skip-missing)")
        if (image.get("height"), image.get("width")) != (frame.height, frame.width):
            raise ExchangeProblem(f"{where}: size {image.get('width')}x{image.get('height')} does not match "
                                  f"the frame's {frame.width}x{frame.height}")
        masks, kinds, labels = [], [], []
        for obj in objects.get(image["id"], []):
            masks.append(_decode_segmentation(obj["segmentation"], frame, f"{where} annotation {obj.get('id')}"))
            extra = obj.get("egonet") or obj.get("attributes") or {}
            kinds.append(_kind(extra.get("kind"), where))
            labels.append(extra.get("label") or None)
        try:
            recorded = Status(meta.get("status") or Status.DONE.value)
        except ValueError:
            raise ExchangeProblem(f"{where}: unknown status {meta.get('status')!r}") from None
        items.append(_Item(
            where, frame, author or meta.get("author") or "import", status or recorded, masks, kinds, labels,
            no_action_object=bool(meta.get("no_action_object", not masks)),
            time_spent_s=float(meta.get("time_spent_s") or 0.0),
            reviewer=meta.get("reviewer"),
            review_comment=meta.get("review_comment"),
        ))
    return items, missing


def _match_frame(image: dict, meta: dict) -> Frame | None:
    """The frame with the image's content hash (within its activity and sequence when given)."""
    digest = meta.get("content_hash")
    if not digest:
        return None
    query = db.select(Frame).join(Sequence).join(Activity).where(Frame.content_hash == digest)
    if meta.get("sequence"):
        query = query.where(Sequence.name == meta["sequence"])
    if meta.get("activity"):
        query = query.where(Activity.name == meta["activity"])
    found = db.session.execute(query.limit(2)).scalars().all()
    return found[0] if len(found) == 1 else None


def _decode_segmentation(segmentation: object, frame: Frame, where: str) -> np.ndarray:
    h, w = frame.height, frame.width
    if isinstance(segmentation, list):  # polygons
        try:
            rles = coco_mask.frPyObjects([list(map(float, p)) for p in segmentation], h, w)
            return coco_decode(coco_mask.merge(rles))
        except (TypeError, ValueError, IndexError) as exc:
            raise ExchangeProblem(f"{where}: unreadable polygon ({exc})") from None
    if not isinstance(segmentation, dict) or set(segmentation) != {"size", "counts"}:
        raise ExchangeProblem(f"{where}: segmentation must be RLE {{'size', 'counts'}} or polygons")
    try:
        return decode_rle(Rle().check(segmentation), (h, w), field="segmentation")
    except Invalid as exc:
        raise ExchangeProblem(f"{where}: segmentation: {exc.reason}") from None
    except Problem as exc:
        raise ExchangeProblem(f"{where}: {exc.message}") from None


def _kind(value: object, where: str) -> InstanceKind | None:
    if value in (None, ""):
        return None
    try:
        return InstanceKind(value)
    except ValueError:
        raise ExchangeProblem(f"{where}: unknown kind {value!r} (use tactile or visual)") from None


def _check_size(path: Path, mask: np.ndarray, frame: Frame) -> None:
    if mask.shape != (frame.height, frame.width):
        raise ExchangeProblem(f"{path}: size {mask.shape[1]}x{mask.shape[0]} does not match the frame's "
                              f"{frame.width}x{frame.height}")


def _user(name: str, users: dict[str, User]) -> User:
    """The named user, created as an inactive annotator without a password when missing."""
    if name not in users:
        user = db.session.execute(db.select(User).filter_by(username=name)).scalar_one_or_none()
        if user is None:
            user = User(username=name, role=Role.ANNOTATOR, password_hash=None, active=False)
            db.session.add(user)
            db.session.flush()
        users[name] = user
    return users[name]


def _write_item(item: _Item, *, replace: bool, users: dict[str, User], written: list[Path]) -> bool:
    """Add (or replace) the item's annotation; False when an existing one is kept."""
    author = _user(item.author, users)
    annotation = db.session.execute(
        db.select(Annotation).filter_by(frame_id=item.frame.id, author_id=author.id)
    ).scalar_one_or_none()
    if annotation is not None and not replace:
        return False
    if annotation is None:
        annotation = Annotation(frame=item.frame, author=author)
        db.session.add(annotation)
    else:
        annotation.instances.clear()
        db.session.flush()
    union = np.zeros((item.frame.height, item.frame.width), bool)
    for position, (mask, kind, label) in enumerate(zip(item.masks, item.kinds, item.labels)):
        path = media.store(io.encode_png(mask), ".png", written=written)
        annotation.instances.append(Instance(position=position, kind=kind, label=label, mask_path=path))
        union |= mask
    annotation.mask_path = media.store(io.encode_png(union), ".png", written=written) if union.any() else None
    annotation.no_action_object = item.no_action_object and not union.any()
    annotation.status = item.status
    annotation.time_spent_s = item.time_spent_s
    annotation.review_comment = item.review_comment
    annotation.reviewer = _user(item.reviewer, users) if item.reviewer else None
    db.session.flush()
    return True
