"""Importing frames: folders of images, videos, depth, DHG, intrinsics and masks.

One import is one transaction. Every file is decoded and checked before its
row is added (frames are at most MAX_FRAME_SIDE pixels a side, read from the
header before decoding); media are written atomically under their content
hash; if anything fails, the transaction is rolled back and the media files
this run created are removed, so nothing is half-imported. Re-importing the same
files adds nothing (the RGB file's hash is unique within a sequence).

DHG images are read and stored in the authors' channel order (gray, height,
depth: ``egonet.io.read_dhg``), so the authors' own DHG files import as they
are and decode to the right depth and height; a frame with depth and
intrinsics but no DHG image gets one computed in that order.
"""

import contextlib
import re
import shutil
import stat
import tempfile
import zipfile
import zlib
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath

import cv2
import numpy as np
from flask import current_app
from sqlalchemy.exc import IntegrityError

from app.errors import Problem
from app.extensions import db
from app.models import HAND_LABEL, Activity, Annotation, Frame, Instance, Role, Sequence, Status, User
from app.models.frames import DEPTH_PREDICTED
from app.services import media, storage
from egonet import io

# Zip archives are unpacked to a temporary folder first, within these limits.
ZIP_MAX_BYTES = 20 * 1024**3
ZIP_MAX_MEMBERS = 200_000
ZIP_MAX_RATIO = 200  # a member inflating more than this is a zip bomb, not a photo

# Sub-folders recognised inside an import folder.
RGB_DIRS = ("rgb", "color", "colour", "images")
DEPTH_DIRS = ("depth",)
DEPTH_SOURCES = ("measured", DEPTH_PREDICTED)
"""``--depth-source``: a sensor's depth, or one a network estimated from the RGB."""
DHG_DIRS = ("dhg",)
MASK_DIRS = ("masks", "mask")


class ImportProblem(Problem):
    """An import that cannot go ahead; the message names the file or option."""


@dataclass
class FrameItem:
    """One frame ready to be added, whatever its source.

    ``rgb`` is either the original encoded file (bytes, stored as they are) or
    an array (encoded as PNG). The optional arrays follow ``egonet.io``'s
    conventions.
    """

    source_name: str
    index: int
    origin: str
    rgb: bytes | np.ndarray
    rgb_suffix: str = ".png"
    timestamp_s: float | None = None
    depth_m: np.ndarray | None = None
    dhg: np.ndarray | None = None
    K: np.ndarray | None = None
    mask: np.ndarray | None = None
    meta: dict = field(default_factory=dict)
    hands: np.ndarray | None = None  # bool (H, W): stored with the mask as an instance labelled "hand"


@dataclass
class ImportReport:
    activity: str
    sequence: str
    added: int = 0
    skipped: int = 0
    annotations: int = 0
    depth: int = 0
    """Of the frames added, those with depth, with a DHG image (given or computed from depth and intrinsics), with intrinsics."""
    dhg: int = 0
    intrinsics: int = 0

    def summary(self) -> str:
        """``"3 frames added (depth: 3, DHG: 3, intrinsics: found), 0 already present, 0 masks imported"``."""
        def found(n: int) -> str:
            return "none" if n == 0 else "found" if n == self.added else f"{n} of {self.added}"

        def count(n: int, what: str) -> str:
            return f"{n} {what}{'' if n == 1 else 's'}"

        return (f"{count(self.added, 'frame')} added (depth: {self.depth}, DHG: {self.dhg}, "
                f"intrinsics: {found(self.intrinsics)}), {self.skipped} already present, "
                f"{count(self.annotations, 'mask')} imported")


@dataclass
class Source:
    """What an import path holds, found by ``discover``."""

    name: str
    images: list[Path] | None = None
    video: Path | None = None
    depth_dir: Path | None = None
    dhg_dir: Path | None = None
    masks_dir: Path | None = None
    intrinsics: Path | None = None


def discover(
    path: Path,
    *,
    depth_dir: Path | None = None,
    dhg_dir: Path | None = None,
    masks_dir: Path | None = None,
    intrinsics: Path | None = None,
) -> Source:
    """Find the frames and their companions under ``path``.

    ``path`` is a video file, or a folder holding images directly or in a
    ``rgb``/``color``/``images`` sub-folder, with optional ``depth``,
    ``dhg`` and ``masks`` sub-folders and one ``*.json`` intrinsics file.
    Options override what is found.
    """
    path = Path(path)
    if not path.exists():
        raise ImportProblem(f"{path}: no such file or folder", field="path")
    if path.is_file():
        if path.suffix.lower() not in io.VIDEO_SUFFIXES:
            raise ImportProblem(
                f"{path}: unknown format {path.suffix!r} (give a folder of images, a .zip of one, or a video: "
                f"{', '.join(io.VIDEO_SUFFIXES)})",
                field="path",
            )
        source = Source(name=path.stem, video=path)
    else:
        image_dir = next((path / d for d in RGB_DIRS if (path / d).is_dir()), path)
        source = Source(name=path.name, images=_list_images(image_dir))
        source.depth_dir = _subdir(path, DEPTH_DIRS)
        source.dhg_dir = _subdir(path, DHG_DIRS)
        source.masks_dir = _subdir(path, MASK_DIRS)
        jsons = sorted(p for p in path.glob("*.json") if not p.name.startswith("."))
        if len(jsons) > 1 and intrinsics is None:
            raise ImportProblem(
                f"{path}: several JSON files {[p.name for p in jsons]}; name the intrinsics with --intrinsics", field="intrinsics"
            )
        source.intrinsics = jsons[0] if jsons else None
    for attr, value in (("depth_dir", depth_dir), ("dhg_dir", dhg_dir), ("masks_dir", masks_dir)):
        if value is not None:
            if not Path(value).is_dir():
                raise ImportProblem(f"{value}: not a folder (--{attr.replace('_dir', '')})", field=attr)
            setattr(source, attr, Path(value))
    if intrinsics is not None:
        if not Path(intrinsics).is_file():
            raise ImportProblem(f"{intrinsics}: no such file (--intrinsics)", field="intrinsics")
        source.intrinsics = Path(intrinsics)
    return source


def import_path(
    path: str | Path,
    *,
    activity: str,
    sequence: str | None = None,
    stride: int = 1,
    depth_dir: Path | None = None,
    dhg_dir: Path | None = None,
    masks_dir: Path | None = None,
    intrinsics: Path | None = None,
    depth_source: str = "measured",
    mask_author: str = "import",
    mask_status: Status = Status.DONE,
    on_start: Callable[[int], None] | None = None,
    on_progress: Callable[[int], None] | None = None,
) -> ImportReport:
    """Import a folder of images, a zip of one, or a video (see ``discover``) in one transaction.

    ``path`` may be in a bucket, ``s3://bucket/prefix/recording`` (a folder
    there, or one zip or video object): it is downloaded first (``downloaded``).
    Depth, DHG and mask files are matched to frames by file stem (for a
    video, by the frame number: ``12.png`` or ``000012.png`` is frame 12).
    ``depth_source="predicted"`` marks the depth and DHG of the imported
    frames as estimated from the RGB (``Frame.depth_predicted``); such
    depth without intrinsics gets its DHG with assumed intrinsics
    (``egonet.depth.assumed_intrinsics``), said in the frame's ``meta``.

    Raises:
        ImportProblem: bad options or layout, naming the option or path.
        egonet.io.MediaError: a file that cannot be used, naming the file.
        StorageUnavailable: the bucket to read from or to write to cannot be reached.
    """
    if stride < 1:
        raise ImportProblem(f"--stride must be >= 1, got {stride}", field="stride")
    if depth_source not in DEPTH_SOURCES:
        raise ImportProblem(f"--depth-source must be one of {', '.join(DEPTH_SOURCES)}, got {depth_source!r}",
                            field="depth_source")
    with contextlib.ExitStack() as stack:
        local = stack.enter_context(downloaded(str(path))) if str(path).startswith("s3://") else Path(path)
        if local.suffix.lower() == ".zip":
            sequence = sequence or local.stem
            local = stack.enter_context(unpacked(local))
        source = discover(local, depth_dir=depth_dir, dhg_dir=dhg_dir, masks_dir=masks_dir, intrinsics=intrinsics)
        total, items = _frame_items(source, local, stride)
        if depth_source == DEPTH_PREDICTED:
            items = _marked_predicted(items)
        if on_start:
            on_start(total)
        return add_frames(
            activity=activity,
            sequence=sequence or source.name,
            items=items,
            source=str(path),
            mask_author=mask_author,
            mask_status=mask_status,
            on_progress=on_progress,
        )


@contextlib.contextmanager
def downloaded(url: str) -> Iterator[Path]:
    """A copy of ``s3://bucket/prefix/name`` in a temporary folder, named ``name`` as there, removed afterwards.

    ``name`` is a folder in the bucket (every object under it is copied) or
    one object (a zip or a video).
    """
    bucket, name = storage.open_parent(url)
    with tempfile.TemporaryDirectory(prefix="egonet-import-") as tmp:
        if bucket.exists(name):
            (Path(tmp) / name).write_bytes(bucket.get(name))
        else:
            entries = [e for e in bucket.list(name) if not e.key.endswith("/")]  # some tools add folder markers
            if not entries:
                raise ImportProblem(f"{url}: no such folder or object in the bucket", field="path")

            def fetch(entry: storage.Entry) -> str:
                data = bucket.get(entry.key)  # refuses a key with "..", before it names a path
                target = Path(tmp, *PurePosixPath(entry.key).parts)
                target.parent.mkdir(parents=True, exist_ok=True)
                target.write_bytes(data)
                return entry.key

            storage.each(fetch, entries)
        yield Path(tmp) / name


def _marked_predicted(items: Iterator[FrameItem]) -> Iterator[FrameItem]:
    """The items, those with depth or DHG marked as predicted (``--depth-source predicted``)."""
    for item in items:
        if item.depth_m is not None or item.dhg is not None:
            item.meta["depth_source"] = DEPTH_PREDICTED
        yield item


def _frame_items(source: Source, path: Path, stride: int) -> tuple[int, Iterator[FrameItem]]:
    """How many frames ``source`` gives at ``stride``, and the frames with
    their companions (read one frame at a time, as they are added)."""
    K = io.read_intrinsics(source.intrinsics) if source.intrinsics else None
    companions = {
        "depth": _by_stem(source.depth_dir, io.DEPTH_SUFFIXES),
        "dhg": _by_stem(source.dhg_dir, io.IMAGE_SUFFIXES),
        "mask": _by_stem(source.masks_dir, (".png",)),
    }
    if source.video is not None:
        total, frames = _video_frames(source.video, stride)
        companions = {kind: {_frame_number(stem): p for stem, p in found.items()} for kind, found in companions.items()}
    else:
        kept = source.images[::stride]
        total = len(kept)
        frames = ((p.stem, str(p), i * stride, io.read_bytes(p), p.suffix.lower(), None) for i, p in enumerate(kept))
        if total == 0:
            raise ImportProblem(f"{path}: no images (jpg/png) found", field="path")
    return total, _with_companions(frames, companions, K=K, by_index=source.video is not None)


def _with_companions(
    frames: Iterator[tuple], companions: dict[str, dict], *, K: np.ndarray | None, by_index: bool
) -> Iterator[FrameItem]:
    """One FrameItem per frame, with the depth, DHG and mask files matched to
    it by frame number (``by_index``, a video's) or by file stem."""
    for stem, origin, index, data, suffix, timestamp in frames:
        key = index if by_index else stem
        item = FrameItem(stem, index, origin, rgb=data, rgb_suffix=suffix, timestamp_s=timestamp, K=K)
        if (p := companions["depth"].get(key)) is not None:
            item.depth_m = io.read_depth(p)
            item.meta["depth_file"] = p.name
        if (p := companions["dhg"].get(key)) is not None:
            item.dhg = io.read_dhg(p)
        if (p := companions["mask"].get(key)) is not None:
            item.mask = io.read_mask(p)
        yield item


@contextlib.contextmanager
def unpacked(archive: Path) -> Iterator[Path]:
    """Unpack a zip archive to a temporary folder, refusing anything unsafe.

    Refused: members with absolute paths or ``..`` (path traversal), links,
    more than ZIP_MAX_MEMBERS members, more than ZIP_MAX_BYTES in all, a
    member that inflates more than ZIP_MAX_RATIO times (a zip bomb), or one
    whose data does not match its header (zipfile reads no more than the
    header's size, so the limits above hold). The folder is removed
    afterwards. A single top-level folder is entered.
    """
    try:
        zf = zipfile.ZipFile(archive)
    except (zipfile.BadZipFile, OSError) as exc:
        raise io.MediaError(archive, f"not a readable zip archive ({exc})") from None
    with zf, tempfile.TemporaryDirectory(prefix="egonet-import-") as tmp:
        members = zf.infolist()
        if len(members) > ZIP_MAX_MEMBERS:
            raise io.MediaError(archive, f"holds {len(members)} files, more than {ZIP_MAX_MEMBERS}")
        total = 0
        for info in members:
            name = PurePosixPath(info.filename)
            if name.is_absolute() or ".." in name.parts or re.match(r"^[A-Za-z]:", info.filename):
                raise io.MediaError(archive, f"unsafe path {info.filename!r} in the archive")
            if stat.S_ISLNK(info.external_attr >> 16):
                raise io.MediaError(archive, f"{info.filename!r} is a link; links are not imported")
            total += info.file_size
            if total > ZIP_MAX_BYTES:
                raise io.MediaError(archive, f"unpacks to more than {ZIP_MAX_BYTES} bytes")
            if info.file_size > 1024**2 and info.file_size > ZIP_MAX_RATIO * max(info.compress_size, 1):
                raise io.MediaError(archive, f"{info.filename!r} inflates {info.file_size // max(info.compress_size, 1)}x: refused")
        for info in members:
            if info.is_dir() or PurePosixPath(info.filename).name.startswith(("__MACOSX", ".")):
                continue
            if "__MACOSX" in PurePosixPath(info.filename).parts:
                continue
            target = Path(tmp, *PurePosixPath(info.filename).parts)
            target.parent.mkdir(parents=True, exist_ok=True)
            try:
                with zf.open(info) as src, open(target, "wb") as dst:
                    shutil.copyfileobj(src, dst, 1 << 20)
            except (zipfile.BadZipFile, zlib.error, EOFError) as exc:
                raise io.MediaError(archive, f"{info.filename!r} does not match its header ({exc})") from None
        entries = [p for p in Path(tmp).iterdir()]
        yield entries[0] if len(entries) == 1 and entries[0].is_dir() else Path(tmp)


def add_frames(
    *,
    activity: str,
    sequence: str,
    items: Iterable[FrameItem],
    source: str | None = None,
    mask_author: str = "import",
    mask_status: Status = Status.DONE,
    on_progress: Callable[[int], None] | None = None,
) -> ImportReport:
    """Add frames to ``activity``/``sequence`` in one transaction (see module doc)."""
    activity = activity.strip()
    sequence = sequence.strip()
    if not activity:
        raise ImportProblem("--activity must not be empty", field="activity")
    if not sequence:
        raise ImportProblem("--sequence must not be empty", field="sequence")
    report = ImportReport(activity=activity, sequence=sequence)
    with media.transaction() as written:
        act = db.session.execute(db.select(Activity).filter_by(name=activity)).scalar_one_or_none()
        if act is None:
            act = Activity(name=activity)
            db.session.add(act)
        seq = None
        if act.id is not None:
            seq = db.session.execute(db.select(Sequence).filter_by(activity_id=act.id, name=sequence)).scalar_one_or_none()
        if seq is None:
            seq = Sequence(activity=act, name=sequence, source=source)
            db.session.add(seq)
            db.session.flush()
        known = set(db.session.execute(db.select(Frame.content_hash).filter_by(sequence_id=seq.id)).scalars())
        author = None
        for item in items:
            frame = _add_frame(seq, item, known, written)
            if frame is None:
                report.skipped += 1
            else:
                report.added += 1
                report.depth += frame.depth_path is not None
                report.dhg += frame.dhg_path is not None
                report.intrinsics += item.K is not None
                if item.mask is not None:
                    author = author or system_user(mask_author)
                    _add_mask_annotation(frame, item, author, mask_status, written)
                    report.annotations += 1
            if on_progress:
                on_progress(1)
    return report


def _add_frame(seq: Sequence, item: FrameItem, known: set[str], written: list[Path]) -> Frame | None:
    name = item.source_name
    if isinstance(item.rgb, np.ndarray):
        rgb = item.rgb
        _check_side(rgb.shape[1], rgb.shape[0], item.origin)
        data, suffix = io.encode_png(rgb), ".png"
    else:
        data, suffix = item.rgb, item.rgb_suffix
        _check_side(*io.image_size(data, path=item.origin), item.origin)
        rgb = io.decode_image(data, path=item.origin)
    digest = media.sha256(data)
    if digest in known:
        return None
    known.add(digest)
    height, width = rgb.shape[:2]
    frame = Frame(
        sequence=seq,
        index=item.index,
        timestamp_s=item.timestamp_s,
        source_name=name,
        width=width,
        height=height,
        content_hash=digest,
        rgb_path=media.store(data, suffix, written=written),
        meta=dict(item.meta),
    )
    if item.K is not None:
        frame.fx, frame.fy = float(item.K[0, 0]), float(item.K[1, 1])
        frame.cx, frame.cy = float(item.K[0, 2]), float(item.K[1, 2])
    if item.depth_m is not None:
        _check_size(item.depth_m, rgb, f"depth for {item.origin}")
        frame.depth_path = media.store(io.encode_depth_png(item.depth_m), ".png", written=written)
    dhg, K = item.dhg, item.K
    if dhg is None and item.depth_m is not None and K is None and frame.depth_predicted:
        from egonet.depth import assumed_intrinsics, intrinsics_record

        K = assumed_intrinsics(width, height)
        frame.meta = frame.meta | {"intrinsics_assumed": True, "assumed_intrinsics": intrinsics_record(K)}
    if dhg is None and item.depth_m is not None and K is not None:
        from egonet.dhg import dhg_from_depth

        dhg = dhg_from_depth(item.depth_m, K, rgb)
    if dhg is not None:
        _check_size(dhg, rgb, f"DHG for {item.origin}")
        frame.dhg_path = media.store(io.encode_png(dhg), ".png", written=written)
    if item.mask is not None:
        _check_size(item.mask, rgb, f"mask for {item.origin}")
    if item.hands is not None:
        _check_size(item.hands, rgb, f"hand mask for {item.origin}")
    db.session.add(frame)
    return frame


def _add_mask_annotation(frame: Frame, item: FrameItem, author: User, status: Status, written: list[Path]) -> None:
    path = media.store(io.encode_png(item.mask), ".png", written=written)
    empty = not item.mask.any()
    annotation = Annotation(
        frame=frame,
        author=author,
        status=status,
        mask_path=None if empty else path,
        no_action_object=empty,
    )
    if not empty:
        kind = item.meta.get("kind")
        annotation.instances.append(Instance(position=0, kind=kind, label=item.meta.get("object"), mask_path=path))
    if item.hands is not None and item.hands.any():  # not part of the action-object mask (models.is_hand)
        hands = media.store(io.encode_png(item.hands), ".png", written=written)
        annotation.instances.append(Instance(position=len(annotation.instances), label=HAND_LABEL, mask_path=hands))
    db.session.add(annotation)


def system_user(name: str) -> User:
    """The author of imported masks: an annotator account without a password."""
    user = db.session.execute(db.select(User).filter_by(username=name)).scalar_one_or_none()
    if user is None:
        user = User(username=name, role=Role.ANNOTATOR, password_hash=None, active=False)
        db.session.add(user)
        try:
            with db.session.begin_nested():
                db.session.flush()
        except IntegrityError:  # created concurrently by another import
            user = db.session.execute(db.select(User).filter_by(username=name)).scalar_one()
    return user


def _check_side(width: int, height: int, origin: str) -> None:
    side = current_app.config["MAX_FRAME_SIDE"]
    if max(width, height) > side:
        raise io.MediaError(origin, f"image of {width}x{height} pixels is larger than the limit of {side} pixels "
                                    "a side (MAX_FRAME_SIDE)")


def _check_size(array: np.ndarray, rgb: np.ndarray, what: str) -> None:
    if array.shape[:2] != rgb.shape[:2]:
        h, w = array.shape[:2]
        raise io.MediaError(what, f"size {w}x{h} does not match the frame's {rgb.shape[1]}x{rgb.shape[0]}")


def _video_frames(path: Path, stride: int) -> tuple[int, Iterator]:
    capture = cv2.VideoCapture(str(path))
    if not capture.isOpened():
        raise io.MediaError(path, "cannot open the video (corrupt or unsupported codec)")
    count = int(capture.get(cv2.CAP_PROP_FRAME_COUNT))
    fps = capture.get(cv2.CAP_PROP_FPS) or 0.0

    def frames():
        index = 0
        try:
            while True:
                ok, bgr = capture.read()
                if not ok:
                    break
                if index % stride == 0:
                    rgb = cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
                    name = f"{path.stem}#{index}"
                    yield name, f"{path} frame {index}", index, rgb, ".png", (index / fps if fps > 0 else None)
                index += 1
        finally:
            capture.release()
        if index == 0:
            raise io.MediaError(path, "no frames could be decoded")

    return max(0, -(-count // stride)), frames()


def _list_images(folder: Path) -> list[Path]:
    files = []
    for p in sorted(folder.iterdir(), key=lambda p: _natural_key(p.name)):
        if p.name.startswith(".") or p.is_dir() or p.suffix.lower() == ".json":
            continue
        if p.suffix.lower() not in io.IMAGE_SUFFIXES:
            raise io.MediaError(p, f"unknown format {p.suffix!r} in an image folder (use {', '.join(io.IMAGE_SUFFIXES)})")
        files.append(p)
    return files


def _by_stem(folder: Path | None, suffixes: tuple[str, ...]) -> dict[str, Path]:
    if folder is None:
        return {}
    found: dict[str, Path] = {}
    for p in sorted(folder.iterdir()):
        if p.name.startswith(".") or p.is_dir():
            continue
        if p.suffix.lower() not in suffixes:
            raise io.MediaError(p, f"unknown format {p.suffix!r} (use {', '.join(suffixes)})")
        if p.stem in found:
            raise io.MediaError(p, f"two files with the stem {p.stem!r} ({found[p.stem].name})")
        found[p.stem] = p
    return found


def _frame_number(stem: str) -> int | None:
    match = re.fullmatch(r"\D*?(\d+)", stem)
    return int(match.group(1)) if match else None


def _natural_key(name: str) -> list:
    return [int(part) if part.isdigit() else part.lower() for part in re.split(r"(\d+)", name)]


def _subdir(folder: Path, names: tuple[str, ...]) -> Path | None:
    return next((folder / n for n in names if (folder / n).is_dir()), None)
