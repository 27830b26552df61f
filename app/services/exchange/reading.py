"""Reading an export back: COCO JSON (every annotation and instance) or PNG masks."""

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from app.errors import Problem
from app.extensions import db
from app.models import Activity, Annotation, Frame, Instance, InstanceKind, Role, Sequence, Status, User, is_hand
from app.services import media
from app.services.exchange.selection import ANNOTATORS_DIR, COCO_FILE, MASKS_DIR, ExchangeProblem, frame_names
from app.services.importing import unpacked
from app.services.labelling.masks import Rle, decode_rle
from app.validation import Invalid
from egonet import io, rle


@dataclass
class ImportReport:
    annotations: int = 0
    instances: int = 0
    skipped: int = 0
    missing: int = 0


@dataclass
class _Item:
    """One annotation read from an export, before it is written."""

    where: str
    frame: Frame
    author: str
    status: Status
    masks: list[np.ndarray] = field(default_factory=list)
    kinds: list[InstanceKind | None] = field(default_factory=list)
    labels: list[str | None] = field(default_factory=list)
    no_action_object: bool | None = None  # None: when it has no instance
    time_spent_s: float = 0.0
    reviewer: str | None = None
    review_comment: str | None = None
    frame_mask: bool = False  # the one the export put in masks/


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
            present, else ``annotators/``, else ``masks/``), a COCO JSON file,
            or a folder of PNG masks laid out as ``<activity>/<sequence>/<frame>.png``.
        author: The annotations' author; by default the one recorded (the
            COCO file's annotator, the ``annotators/`` folder's name), or
            "import" for plain PNG masks. Missing users are created as
            inactive annotators without a password. An export with several
            annotators of one frame cannot be given one author.
        status: The annotations' status; by default the recorded one, or
            done for PNG masks (which record none).
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
        found, missing = _read_coco(path, author=author, status=status, skip_missing=skip_missing)
    elif (path / COCO_FILE).is_file():
        found, missing = _read_coco(path / COCO_FILE, author=author, status=status, skip_missing=skip_missing)
    elif (path / ANNOTATORS_DIR).is_dir():
        found, missing = _read_annotator_trees(path, author=author, status=status or Status.DONE,
                                               skip_missing=skip_missing)
    else:
        masks = path / MASKS_DIR if (path / MASKS_DIR).is_dir() else path
        found, missing = _read_png_tree(masks, author=author or "import", status=status or Status.DONE,
                                        skip_missing=skip_missing)
    found = _in_writing_order(found)
    if on_start:
        on_start(len(found))
    report = ImportReport(missing=len(missing))
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


def _in_writing_order(items: list[_Item]) -> list[_Item]:
    """Each frame's annotations in reverse export order, its ``masks/`` one last.

    An export lists a frame's annotations best first and breaks ties by the
    latest update, so writing them in reverse makes the next export rank
    them as this one did.

    Raises:
        ExchangeProblem: two annotations of a frame by one author (``--author``).
    """
    by_frame: dict[int, list[_Item]] = {}
    for item in items:
        group = by_frame.setdefault(item.frame.id, [])
        if any(other.author == item.author for other in group):
            raise ExchangeProblem(f"{item.where}: a second annotation of this frame by {item.author!r} "
                                  "(leave --author out to keep each annotator's own)", field="author")
        group.append(item)
    return [item for group in by_frame.values() for item in sorted(reversed(group), key=lambda i: i.frame_mask)]


def _frames_by_name() -> dict[str, Frame]:
    frames = {f.id: f for f in db.session.execute(db.select(Frame)).scalars()}
    return {name: frames[fid] for fid, name in frame_names(frames.values()).items()}


def _png_files(root: Path) -> list[Path]:
    return sorted(p for p in root.rglob("*.png") if not any(part.startswith(".") for part in p.relative_to(root).parts))


def _read_png_tree(root: Path, *, author: str, status: Status, skip_missing: bool,
                   by_name: dict[str, Frame] | None = None) -> tuple[list[_Item], set[str]]:
    files = _png_files(root)
    if not files:
        raise ExchangeProblem(f"{root}: no {COCO_FILE} and no PNG masks (<activity>/<sequence>/<frame>.png)")
    by_name = by_name if by_name is not None else _frames_by_name()
    items, missing = [], set()
    for p in files:
        name = p.relative_to(root).with_suffix("").as_posix()
        frame = by_name.get(name)
        if frame is None:
            if skip_missing:
                missing.add(name)
                continue
            raise ExchangeProblem(f"{p}: no frame {name!r} in the database (import the frames first, or --skip-missing)")
        mask = io.read_mask(p)
        _check_size(p, mask, frame)
        item = _Item(str(p), frame, author, status)
        if mask.any():
            item.masks, item.kinds, item.labels = [mask], [None], [None]
        items.append(item)
    return items, missing


def _read_annotator_trees(root: Path, *, author: str | None, status: Status,
                          skip_missing: bool) -> tuple[list[_Item], set[str]]:
    """``annotators/<name>/<activity>/<sequence>/<frame>.png``, each folder one author's masks.

    The annotation whose mask is the file in ``masks/`` (same bytes) is the
    frame's mask again after the import.
    """
    by_name = _frames_by_name()
    items, missing = [], set()
    for folder in sorted(p for p in (root / ANNOTATORS_DIR).iterdir() if p.is_dir() and not p.name.startswith(".")):
        found, lost = _read_png_tree(folder, author=author or folder.name, status=status, skip_missing=skip_missing,
                                     by_name=by_name)
        for item in found:
            union = root / MASKS_DIR / Path(item.where).relative_to(folder)
            item.frame_mask = union.is_file() and union.read_bytes() == Path(item.where).read_bytes()
        items += found
        missing |= lost
    return items, missing


def _read_coco(path: Path, *, author: str | None, status: Status | None,
               skip_missing: bool) -> tuple[list[_Item], set[str]]:
    try:
        coco = io.decode_json(io.read_bytes(path))
    except ValueError as exc:
        raise ExchangeProblem(f"{path}: not valid JSON ({exc})") from None
    if not isinstance(coco, dict) or not isinstance(coco.get("images"), list) or not isinstance(coco.get("annotations", []), list):
        raise ExchangeProblem(f"{path}: not a COCO file (needs an 'images' list and an 'annotations' list)")
    objects: dict[object, list[dict]] = {}
    for obj in coco.get("annotations", []):
        if not isinstance(obj, dict) or "image_id" not in obj or "segmentation" not in obj:
            raise ExchangeProblem(f"{path}: every annotation needs 'image_id' and 'segmentation'")
        objects.setdefault(obj["image_id"], []).append(obj)
    by_name = None
    items, missing = [], set()
    for image in coco["images"]:
        if not isinstance(image, dict) or "id" not in image:
            raise ExchangeProblem(f"{path}: every image needs an 'id'")
        where = f"{path} image {image['id']}"
        meta = image.get("egonet") if isinstance(image.get("egonet"), dict) else {}
        frame = _match_frame(meta)
        if frame is None:
            by_name = by_name if by_name is not None else _frames_by_name()
            stem = str(image.get("file_name", ""))
            frame = by_name.get(stem.rsplit(".", 1)[0] if "." in Path(stem).name else stem)
        if frame is None:
            if skip_missing:
                missing.add(where)
                continue
            raise ExchangeProblem(f"{where}: no matching frame in the database (import the frames first, or --skip-missing)")
        if (image.get("height"), image.get("width")) != (frame.height, frame.width):
            raise ExchangeProblem(f"{where}: size {image.get('width')}x{image.get('height')} does not match "
                                  f"the frame's {frame.width}x{frame.height}")
        groups = _coco_annotations(where, frame, meta, objects.get(image["id"], []), default_author=author)
        if author is not None and len(groups) > 1:
            raise ExchangeProblem(f"{where}: {len(groups)} annotators' annotations of one frame cannot all be "
                                  f"given --author {author!r} (leave --author out)", field="author")
        for item in groups:
            item.author = author or item.author
            item.status = status or item.status
        items += groups
    return items, missing


def _coco_annotations(where: str, frame: Frame, meta: dict, objects: list[dict], *,
                      default_author: str | None) -> list[_Item]:
    """An image's annotations: one per annotator (ours), or one for the image (our version 1, other tools)."""
    records = meta.get("annotations")
    groups: dict[str | None, _Item] = {}
    if isinstance(records, list):
        for record in records:
            if not isinstance(record, dict) or not isinstance(record.get("annotator"), str) or not record["annotator"]:
                raise ExchangeProblem(f"{where}: every egonet.annotations entry needs an 'annotator'")
            groups[record["annotator"]] = _Item(
                where, frame, record["annotator"], _status(record.get("status"), where),
                no_action_object=bool(record.get("no_action_object")),
                time_spent_s=float(record.get("time_spent_s") or 0.0),
                reviewer=record.get("reviewer"), review_comment=record.get("review_comment"),
                frame_mask=bool(record.get("frame_mask")),
            )
    else:
        groups[None] = _Item(
            where, frame, meta.get("author") or default_author or "import", _status(meta.get("status"), where),
            no_action_object=meta.get("no_action_object"), time_spent_s=float(meta.get("time_spent_s") or 0.0),
            reviewer=meta.get("reviewer"), review_comment=meta.get("review_comment"),
        )
    for obj in objects:
        extra = obj.get("attributes") or obj.get("egonet") or {}
        extra = extra if isinstance(extra, dict) else {}
        key = extra.get("annotator") if isinstance(records, list) else None
        if key not in groups:  # an instance whose annotator has no entry of its own
            groups[key] = _Item(where, frame, key or default_author or "import", _status(extra.get("status"), where))
        item = groups[key]
        item.masks.append(_decode_segmentation(obj["segmentation"], frame, f"{where} annotation {obj.get('id')}"))
        item.kinds.append(_kind(extra.get("kind"), where))
        item.labels.append(extra.get("label") or None)
    return list(groups.values())


def _status(value: object, where: str) -> Status:
    try:
        return Status(value or Status.DONE.value)
    except ValueError:
        raise ExchangeProblem(f"{where}: unknown status {value!r}") from None


def _match_frame(meta: dict) -> Frame | None:
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
            return rle.from_polygons(segmentation, h, w)
        except (TypeError, ValueError, IndexError) as exc:
            raise ExchangeProblem(f"{where}: unreadable polygon ({exc})") from None
    if not isinstance(segmentation, dict) or set(segmentation) != {"size", "counts"}:
        raise ExchangeProblem(f"{where}: segmentation must be RLE {{'size', 'counts'}} or polygons")
    try:
        return decode_rle(Rle().check(segmentation), (h, w), field="segmentation")
    except Invalid as exc:
        raise ExchangeProblem(f"{where}: segmentation: {exc.message}") from None
    except Problem as exc:
        raise ExchangeProblem(f"{where}: {exc.message}") from None


def _kind(value: object, where: str) -> InstanceKind | None:
    if value in (None, ""):
        return None
    try:
        return InstanceKind(value)
    except (ValueError, TypeError):
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
        if not is_hand(label):
            union |= mask
    annotation.mask_path = media.store(io.encode_png(union), ".png", written=written) if union.any() else None
    empty = item.no_action_object if item.no_action_object is not None else not item.masks
    annotation.no_action_object = bool(empty) and not union.any()
    annotation.status = item.status
    annotation.time_spent_s = item.time_spent_s
    annotation.review_comment = item.review_comment
    annotation.reviewer = _user(item.reviewer, users) if item.reviewer else None
    db.session.flush()
    return True
