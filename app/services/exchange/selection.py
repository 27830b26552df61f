"""What an export holds: its options, the annotations they select, the files' names.

Every annotation that passes the filters (status, activity, annotator) is
exported; a frame's annotations are ranked, and the first one is the
frame's mask in ``masks/``: a reviewed one, then done, in progress,
rejected, the most recently updated first (the frame's ground truth when
only done and reviewed annotations are exported, as by default).
"""

from collections.abc import Iterable
from dataclasses import asdict, dataclass, field

from sqlalchemy import case, func
from sqlalchemy.orm import joinedload, selectinload

from app.errors import Problem
from app.extensions import db
from app.models import Activity, Annotation, Frame, Sequence, Status, User

FORMATS = ("png", "coco", "both")
DEFAULT_STATUSES = (Status.DONE, Status.REVIEWED)
EXPORTABLE_STATUSES = tuple(s for s in Status if s is not Status.TODO)
COCO_FILE = "annotations.json"
MASKS_DIR = "masks"
ANNOTATORS_DIR = "annotators"
IMAGES_DIR = "images"
CATEGORY = {"id": 1, "name": "action-object", "supercategory": "object"}
# Which of a frame's annotations is its mask in masks/ (the lowest rank).
_RANK = {Status.REVIEWED: 0, Status.DONE: 1, Status.IN_PROGRESS: 2, Status.REJECTED: 3, Status.TODO: 4}


class ExchangeProblem(Problem):
    """An export or import that cannot go ahead; the message names the file or option."""


class NothingToExport(ExchangeProblem):
    """The filters select no annotation (the message says which filters and what there is)."""


@dataclass(frozen=True)
class ExportOptions:
    """What to export.

    Attributes:
        fmt: ``png`` (masks), ``coco`` (annotations.json) or ``both``.
        images: Also copy each exported frame's RGB file into ``images/``.
        activities: Activity names (empty: all).
        statuses: Annotation statuses (at least one).
        annotators: Authors' user names (empty: everyone).
    """

    fmt: str = "both"
    images: bool = False
    activities: tuple[str, ...] = ()
    statuses: tuple[Status, ...] = DEFAULT_STATUSES
    annotators: tuple[str, ...] = ()

    @classmethod
    def of(cls, *, fmt: str = "both", images: bool = False, activities: Iterable[str] = (),
           statuses: Iterable[Status | str] = DEFAULT_STATUSES, annotators: Iterable[str] = ()) -> "ExportOptions":
        """Checked options; names are stripped, repeats dropped.

        Raises:
            ExchangeProblem: an unknown format or status, or no status, naming the option.
        """
        if fmt not in FORMATS:
            raise ExchangeProblem(f"--format must be one of {', '.join(FORMATS)}, got {fmt!r}", field="format")
        try:
            checked = tuple(dict.fromkeys(Status(s) for s in statuses))
        except ValueError as exc:
            raise ExchangeProblem(f"--status: {exc}; use {', '.join(EXPORTABLE_STATUSES)}", field="status") from None
        if not checked:
            raise ExchangeProblem("--status: choose at least one status to export", field="status")
        if Status.TODO in checked:
            raise ExchangeProblem("--status: todo annotations hold nothing to export", field="status")

        def names(values: Iterable[str]) -> tuple[str, ...]:
            return tuple(dict.fromkeys(v.strip() for v in values if v and v.strip()))

        return cls(fmt, bool(images), names(activities), checked, names(annotators))

    def to_dict(self) -> dict:
        return asdict(self) | {"statuses": [s.value for s in self.statuses]}

    @classmethod
    def from_dict(cls, data: dict) -> "ExportOptions":
        return cls.of(fmt=data["fmt"], images=data["images"], activities=data["activities"],
                      statuses=data["statuses"], annotators=data["annotators"])

    @property
    def writes_png(self) -> bool:
        return self.fmt in ("png", "both")

    @property
    def writes_coco(self) -> bool:
        return self.fmt in ("coco", "both")


@dataclass
class FrameExport:
    """A frame and its exported annotations, ranked: ``annotations[0]`` is the frame's mask."""

    frame: Frame
    annotations: list[Annotation] = field(default_factory=list)


@dataclass
class Plan:
    """How much an export holds, counted before it is written."""

    frames: int
    annotations: int
    pixels: int  # the frames' pixels, once per exported annotation


def activity_names() -> list[str]:
    """The activities an export can be limited to."""
    return list(db.session.execute(db.select(Activity.name).order_by(Activity.name)).scalars())


def annotator_names() -> list[str]:
    """The users with at least one annotation, whom an export can be limited to."""
    authors = db.select(Annotation.author_id).distinct()
    return list(db.session.execute(db.select(User.username).where(User.id.in_(authors)).order_by(User.username)).scalars())


def _filters(options: ExportOptions, *, statuses: bool = True) -> list:
    """The WHERE conditions of ``options`` (the query joins Frame, Sequence and Activity).

    Raises:
        ExchangeProblem: an activity or annotator that does not exist.
    """
    conditions = [Annotation.status.in_(options.statuses)] if statuses else []
    if options.activities:
        known = set(db.session.execute(db.select(Activity.name).where(Activity.name.in_(options.activities))).scalars())
        if unknown := [a for a in options.activities if a not in known]:
            raise ExchangeProblem(f"--activity: no activity named {unknown[0]!r}", field="activity")
        conditions.append(Activity.name.in_(options.activities))
    if options.annotators:
        users = dict(db.session.execute(
            db.select(User.username, User.id).where(User.username.in_(options.annotators))
        ).all())
        if unknown := [a for a in options.annotators if a not in users]:
            raise ExchangeProblem(f"--annotator: no user named {unknown[0]!r}", field="annotator")
        conditions.append(Annotation.author_id.in_(users.values()))
    return conditions


def _joined(query):
    return (
        query.join(Frame, Annotation.frame_id == Frame.id)
        .join(Sequence, Frame.sequence_id == Sequence.id)
        .join(Activity, Sequence.activity_id == Activity.id)
    )


def plan_export(options: ExportOptions) -> Plan:
    """Count what ``options`` select.

    Raises:
        NothingToExport: nothing is selected; the message says what the
            filters found with other statuses.
        ExchangeProblem: an unknown activity or annotator.
    """
    counts = db.select(func.count(Annotation.id), func.count(func.distinct(Annotation.frame_id)),
                       func.coalesce(func.sum(Frame.width * Frame.height), 0))
    annotations, frames, pixels = db.session.execute(_joined(counts).where(*_filters(options))).one()
    if not annotations:
        raise NothingToExport(_nothing_message(options), status=404, field="status")
    return Plan(frames=frames, annotations=annotations, pixels=int(pixels))


def _nothing_message(options: ExportOptions) -> str:
    wanted = " or ".join(s.value.replace("_", " ") for s in options.statuses)
    where = f" in {', '.join(options.activities)}" if options.activities else ""
    who = f" by {', '.join(options.annotators)}" if options.annotators else ""
    others = dict(db.session.execute(
        _joined(db.select(Annotation.status, func.count())).where(*_filters(options, statuses=False))
        .group_by(Annotation.status)
    ).all())
    there = [f"{n} {s.value.replace('_', ' ')}" for s, n in sorted(others.items(), key=lambda x: _RANK[x[0]])]
    hint = f" (there {'is' if sum(others.values()) == 1 else 'are'} {', '.join(there)}: choose those statuses)" if there else ""
    return f"nothing to export: no annotation is {wanted}{where}{who}{hint}"


def select_export(options: ExportOptions) -> list[FrameExport]:
    """Every selected annotation, grouped by frame in dataset order (activity, sequence, index).

    Raises:
        NothingToExport: nothing is selected.
        ExchangeProblem: an unknown activity or annotator.
    """
    plan_export(options)
    rank = case(*((Annotation.status == s, r) for s, r in _RANK.items()), else_=9)
    rows = db.session.execute(
        _joined(db.select(Annotation))
        .where(*_filters(options))
        .options(
            selectinload(Annotation.instances),
            joinedload(Annotation.author),
            joinedload(Annotation.reviewer),
            joinedload(Annotation.frame).joinedload(Frame.sequence).joinedload(Sequence.activity),
        )
        .order_by(Activity.name, Sequence.name, Frame.index, Frame.id, rank, Annotation.updated_at.desc(),
                  Annotation.id.desc())
    ).unique().scalars()
    groups: dict[int, FrameExport] = {}
    for annotation in rows:
        groups.setdefault(annotation.frame_id, FrameExport(annotation.frame)).annotations.append(annotation)
    return list(groups.values())


# --------------------------------------------------------------------------
# Names


def safe(name: str) -> str:
    """A name usable as one path component (no separators, not hidden)."""
    cleaned = "".join("_" if c in '/\\\0' else c for c in name).strip()
    return "_" + cleaned if not cleaned or cleaned.startswith(".") else cleaned


def frame_names(frames: Iterable[Frame]) -> dict[int, str]:
    """``activity/sequence/frame`` (no suffix) for each frame, unique within the database.

    ``frame`` is the frame's source name; a name used twice in a sequence
    gets ``~`` and the start of the frame's content hash.
    """
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
        names[f.id] = f"{safe(f.sequence.activity.name)}/{safe(f.sequence.name)}/{safe(stem)}"
    return names


def annotator_file(author: str, name: str) -> str:
    """Where one annotator's mask of the frame ``name`` goes."""
    return f"{ANNOTATORS_DIR}/{safe(author)}/{name}.png"
