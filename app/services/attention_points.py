"""Ground truth from attention points: the paper's Table 4 (``flask egonet import-points``).

The paper scores its Social Children Interaction frames against "a fixed
size Gaussian around the ground truth attention location". A CSV of points
(``frame,x,y``: the frame's file stem, then the point in its pixels; several
rows per frame allowed) becomes, for every frame of the activity, a
finished annotation, so ground truth stays the one thing it is everywhere
(``app.services.ground_truth``):

* its mask is the Gaussian binarised within one sigma of a point
  (``egonet.clicks.points_mask``); a frame without a row is a finished
  "no action-object" annotation;
* sigma is the click study's: the paper's 60 px at 1280 px wide scaled to
  each frame's width (``studies.scaled_sigma``), or ``--sigma`` in the
  frames' pixels;
* an :class:`~app.models.AttentionPoints` row beside it keeps the points,
  sigma and the file, so the frame page and every score report say
  "attention points, sigma N px" (:func:`describe`, :func:`activity_sources`).

The annotations are the ``author``'s (default ``import``), reviewed, so
they are the frames' ground truth. Importing again replaces that author's
points-based annotations of the activity (the old points are gone, the
annotation rows are updated in place); an annotation of that author that
did not come from points (masks from ``flask egonet import --masks``) is
never overwritten: the import stops and says to choose another author.
One import is one transaction: any bad row (an unknown frame, a point
outside its frame, a value that is not a number) stops it with the file and
line, and nothing is kept.
"""

from __future__ import annotations

import math
import tempfile
from collections import defaultdict
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

from werkzeug.datastructures import FileStorage
from werkzeug.utils import secure_filename

from app.errors import Problem
from app.extensions import db
from app.models import Activity, Annotation, AttentionPoints, Frame, Instance, Sequence, Status
from app.services import ground_truth, media
from app.services.importing import system_user
from app.spreadsheet import csv_rows
from egonet import io
from egonet.clicks import DEFAULT_SIGMA, REFERENCE_WIDTH, points_mask, scaled_sigma

COLUMNS = ("frame", "x", "y")
MAX_BYTES = 64 * 1024**2


class PointsProblem(Problem):
    """A points file or option that cannot be imported; the message names the file and line."""


@dataclass
class PointsReport:
    activity: str
    frames: int = 0
    with_points: int = 0
    points: int = 0
    replaced: int = 0
    sigma: str = ""

    @property
    def without_points(self) -> int:
        return self.frames - self.with_points

    def summary(self) -> str:
        def count(n: int, noun: str) -> str:
            return f"{n} {noun}{'' if n == 1 else 's'}"

        return (f"{self.activity}: {count(self.points, 'point')} on {count(self.with_points, 'frame')}, "
                f"{count(self.without_points, 'frame')} without a point (no action-object), "
                f"{count(self.replaced, 'earlier point annotation')} replaced; {self.sigma}")


def sigma_words(sigma_px: float, scaled: bool) -> str:
    """The Gaussian's width as the frame page and the reports write it."""
    if scaled:
        return f"sigma {sigma_px:g} px ({DEFAULT_SIGMA:g} px at {REFERENCE_WIDTH} px wide, scaled to the frame)"
    return f"sigma {sigma_px:g} px"


def describe(record: AttentionPoints) -> str:
    """One frame's ground-truth source: ``attention points (2), sigma 15 px; binarised within one sigma``."""
    n = len(record.points)
    what = f"attention points ({n})" if n else "attention points (none: no action-object)"
    return f"{what}, {sigma_words(record.sigma_px, record.sigma_scaled)}; binarised within one sigma, from {record.source}"


def import_points(path: Path, *, activity: str, sigma: float | None = None, author: str = "import") -> PointsReport:
    """Make every frame of ``activity`` a points-based ground truth from the CSV at ``path`` (see the module).

    Raises:
        PointsProblem: an unknown activity, a bad sigma or author, or a bad row (naming the file and line).
    """
    path = Path(path)
    if sigma is not None and (isinstance(sigma, bool) or not math.isfinite(sigma) or sigma <= 0):
        raise PointsProblem(f"--sigma must be a positive number of pixels, got {sigma}", field="sigma")
    act = db.session.execute(db.select(Activity).filter_by(name=activity.strip())).scalar_one_or_none()
    if act is None:
        raise PointsProblem(f"no activity {activity!r}: import its frames first (flask egonet import)", field="activity")
    frames = list(db.session.execute(
        db.select(Frame).join(Sequence).where(Sequence.activity_id == act.id).order_by(Sequence.name, Frame.index, Frame.id)
    ).scalars())  # fmt: skip
    points = read_points(path, frames, activity=act.name)
    report = PointsReport(activity=act.name)
    scaled = sigma is None
    with media.transaction() as written:
        user = system_user(author)
        existing = {a.frame_id: a for a in db.session.execute(
            db.select(Annotation).where(Annotation.author_id == user.id, Annotation.frame_id.in_([f.id for f in frames]))
        ).scalars()}  # fmt: skip
        for frame in frames:
            if frame.id in existing and existing[frame.id].attention_points is None:
                raise PointsProblem(
                    f"frame {frame.source_name!r} already has an annotation by {author!r} that did not come from points "
                    "(its masks were imported or drawn): give another --author", field="author")
        for frame in frames:
            frame_sigma = scaled_sigma(frame.width) if scaled else float(sigma)
            mine = points.get(frame.id, [])
            mask = points_mask((frame.height, frame.width), mine, sigma=frame_sigma)
            annotation = existing.get(frame.id)
            if annotation is None:
                annotation = Annotation(frame=frame, author=user)
                db.session.add(annotation)
            else:  # importing again: the same row, its old points and mask gone
                report.replaced += 1
                annotation.instances.clear()
                db.session.delete(annotation.attention_points)
                db.session.flush()
            annotation.status, annotation.no_action_object, annotation.mask_path = Status.REVIEWED, not mine, None
            if mine:
                annotation.mask_path = media.store(io.encode_png(mask), ".png", written=written)
                annotation.instances.append(Instance(position=0, mask_path=annotation.mask_path))
            annotation.attention_points = AttentionPoints(points=[list(p) for p in mine], sigma_px=frame_sigma,
                                                          sigma_scaled=scaled, source=path.name[:200])
            report.frames += 1
            report.with_points += bool(mine)
            report.points += len(mine)
        widest = max(frames, key=lambda f: f.width)
        report.sigma = sigma_words(scaled_sigma(widest.width) if scaled else float(sigma), scaled)
    return report


def import_upload(upload: FileStorage, *, activity: str, sigma: float | None = None) -> PointsReport:
    """:func:`import_points` of a file sent from the activity page (its name kept, made safe, for the messages)."""
    if not isinstance(upload, FileStorage):
        raise PointsProblem("choose a CSV file of points (frame,x,y)", field="points")
    name = secure_filename(upload.filename or "") or "points.csv"
    with tempfile.TemporaryDirectory(prefix="egonet-points-") as folder:
        path = Path(folder) / name
        upload.save(path)
        return import_points(path, activity=activity, sigma=sigma)


def read_points(path: Path, frames: list[Frame], *, activity: str) -> dict[int, list[tuple[float, float]]]:
    """The CSV's points by frame id, every row checked (see the module); raises PointsProblem naming the line."""
    name = path.name
    if not path.is_file():
        raise PointsProblem(f"{path}: no such file", field="path")
    if path.stat().st_size > MAX_BYTES:
        raise PointsProblem(f"{name}: larger than {MAX_BYTES // 1024**2} MB", field="path")
    try:
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError:
        raise PointsProblem(f"{name}: not UTF-8 text (save the CSV as UTF-8)", field="path") from None
    if "\x00" in text:
        raise PointsProblem(f"{name}: holds a NUL character: not a CSV file", field="path")
    by_stem: dict[str, list[Frame]] = defaultdict(list)
    for frame in frames:
        by_stem[frame.source_name].append(frame)
    try:
        rows = csv_rows(text)
    except ValueError as exc:
        raise PointsProblem(f"{name} {exc}", field="path") from None
    header = rows[0][1] if rows else None
    if header is None or [h.strip().lower() for h in header] != list(COLUMNS):
        raise PointsProblem(f"{name} line 1: the header must be {','.join(COLUMNS)}, got {','.join(header or [])!r}",
                            field="path")
    out: dict[int, list[tuple[float, float]]] = defaultdict(list)
    for line, cells in rows[1:]:
        if not any(c.strip() for c in cells):
            continue
        where = f"{name} line {line}"
        if len(cells) != len(COLUMNS):
            raise PointsProblem(f"{where}: {len(cells)} values, expected 3 (frame,x,y)", field="path")
        stem, x, y = (c.strip() for c in cells)
        found = by_stem.get(stem, [])
        if not found:
            raise PointsProblem(f"{where}: frame {stem!r} is not in activity {activity!r}", field="path")
        if len(found) > 1:
            sequences = ", ".join(sorted(f.sequence.name for f in found))
            raise PointsProblem(f"{where}: frame {stem!r} is in several sequences of {activity!r} ({sequences})", field="path")
        frame = found[0]
        x, y = _number(x, "x", where), _number(y, "y", where)
        if not (-0.5 <= x <= frame.width - 0.5 and -0.5 <= y <= frame.height - 0.5):
            raise PointsProblem(
                f"{where}: ({x:g}, {y:g}) lies outside frame {stem!r} ({frame.width}x{frame.height}: "
                f"x in [-0.5, {frame.width - 0.5:g}], y in [-0.5, {frame.height - 0.5:g}])", field="path")
        out[frame.id].append((x, y))
    if not out:
        raise PointsProblem(f"{name}: no points (only a header)", field="path")
    return dict(out)


def _number(text: str, column: str, where: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value):
        raise PointsProblem(f"{where}: {column} {text!r} is not a number", field="path")
    return value


def sources_of(annotations: Iterable[Annotation]) -> dict[int, AttentionPoints]:
    """The points records of these annotations, by annotation id (those made from points)."""
    ids = [a.id for a in annotations]
    if not ids:
        return {}
    rows = db.session.execute(db.select(AttentionPoints).where(AttentionPoints.annotation_id.in_(ids))).scalars()
    return {r.annotation_id: r for r in rows}


def activity_sources(truths: dict[int, Annotation], activity_of: dict[int, str]) -> dict[str, str]:
    """Per activity whose ground truth is (partly) attention points, in words, for the score reports.

    Args:
        truths: Frame id -> its ground-truth annotation (the frames the report scores).
        activity_of: Frame id -> its activity's name.
    """
    records = sources_of(truths.values())
    found: dict[str, list[AttentionPoints]] = defaultdict(list)
    mixed: set[str] = set()
    for fid, annotation in truths.items():
        if (record := records.get(annotation.id)) is not None:
            found[activity_of[fid]].append(record)
        else:
            mixed.add(activity_of[fid])
    out = {}
    for act in sorted(found):
        sigmas = sorted({(r.sigma_px, r.sigma_scaled) for r in found[act]})
        low, high = sigmas[0][0], sigmas[-1][0]
        sigma = f"sigma {low:g} px" if low == high else f"sigma {low:g}-{high:g} px"
        if sigmas[0][1]:
            sigma += f" ({DEFAULT_SIGMA:g} px at {REFERENCE_WIDTH} px wide, scaled to each frame)"
        out[act] = (f"attention points, {sigma}: a Gaussian around each point, binarised within one sigma; a frame "
                    f"without a point has no action-object{'; some frames have drawn masks instead' if act in mixed else ''}")
    return out
