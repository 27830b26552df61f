"""The study's results for analysis: CSV tables, one JSON document and the soft masks as 16-bit PNGs.

``EXPORTS`` names what the admin pages offer; ``export_to_folder`` writes
them all (the ``flask egonet study-export`` command). The masks' zip is
produced piece by piece while it is sent.
"""

import csv
import io as _io
import json
import zipfile
from collections import defaultdict
from collections.abc import Iterator
from datetime import datetime
from pathlib import Path
from typing import Any

from sqlalchemy import func
from sqlalchemy.orm import selectinload

from app.extensions import db
from app.models import Frame, Sequence
from app.models.studies import ANSWERED, Participant, Study, StudyFrame, Trial
from app.services import media
from app.services.studies.common import LATE_GRACE_S
from app.services.studies.masks import mask_png, trial_soft_mask
from egonet.clicks import MaskMean

TRIAL_COLUMNS = [
    "study_id", "participant", "participant_id", "trial_id", "position", "activity", "frame_id", "frame_source",
    "frame_width", "frame_height", "outcome", "clicks", "rt_ms", "shown_at", "submitted_at", "server_ms",
    "window_width", "window_height", "display_width", "display_height", "pixel_ratio", "events",
]  # fmt: skip
CLICK_COLUMNS = ["study_id", "participant", "trial_id", "position", "frame_id", "click", "x", "y", "rt_ms", "received_at"]
EVENT_COLUMNS = ["study_id", "participant", "trial_id", "position", "frame_id", "event", "kind", "client_ms", "server_at", "detail"]
EXPORTS = ("trials.csv", "clicks.csv", "events.csv", "study.json", "masks.zip")


def _iso(value: datetime | None) -> str | None:
    return value.isoformat() if value is not None else None


def _study_trials(study: Study) -> list[Trial]:
    return list(
        db.session.execute(
            db.select(Trial)
            .join(Participant)
            .where(Participant.study_id == study.id)
            .order_by(Participant.number, Trial.position)
            .options(
                selectinload(Trial.clicks),
                selectinload(Trial.events),
                selectinload(Trial.participant),
                selectinload(Trial.study_frame).selectinload(StudyFrame.frame).selectinload(Frame.sequence).selectinload(Sequence.activity),
            )
        ).scalars()
    )


def _trial_row(study: Study, trial: Trial) -> dict[str, Any]:
    frame = trial.frame
    server_ms = None
    if trial.shown_at is not None and trial.submitted_at is not None:
        server_ms = round((trial.submitted_at - trial.shown_at).total_seconds() * 1000, 1)
    return {
        "study_id": study.id,
        "participant": trial.participant.label,
        "participant_id": trial.participant_id,
        "trial_id": trial.id,
        "position": trial.position,
        "activity": frame.sequence.activity.name,
        "frame_id": frame.id,
        "frame_source": frame.source_name,
        "frame_width": frame.width,
        "frame_height": frame.height,
        "outcome": trial.outcome.value if trial.outcome else "pending",
        "clicks": len(trial.clicks),
        "rt_ms": trial.rt_ms,
        "shown_at": _iso(trial.shown_at),
        "submitted_at": _iso(trial.submitted_at),
        "server_ms": server_ms,
        "window_width": trial.window_width,
        "window_height": trial.window_height,
        "display_width": trial.display_width,
        "display_height": trial.display_height,
        "pixel_ratio": trial.pixel_ratio,
        "events": len(trial.events),
    }


def _click_rows(study: Study, trial: Trial) -> list[dict[str, Any]]:
    base = {"study_id": study.id, "participant": trial.participant.label, "trial_id": trial.id, "position": trial.position, "frame_id": trial.frame.id}
    return [
        {**base, "click": c.position, "x": c.x, "y": c.y, "rt_ms": c.rt_ms, "received_at": _iso(c.received_at)} for c in trial.clicks
    ]


def _event_rows(study: Study, trial: Trial) -> list[dict[str, Any]]:
    base = {"study_id": study.id, "participant": trial.participant.label, "trial_id": trial.id, "position": trial.position, "frame_id": trial.frame.id}
    return [
        {**base, "event": e.position, "kind": e.kind.value, "client_ms": e.client_ms, "server_at": _iso(e.server_at), "detail": e.detail}
        for e in trial.events
    ]


def export_csv(study: Study, table: str) -> str:
    """One table of the study's results as CSV: ``trials``, ``clicks`` or ``events``."""
    columns, rows_of = {
        "trials": (TRIAL_COLUMNS, lambda t: [_trial_row(study, t)]),
        "clicks": (CLICK_COLUMNS, lambda t: _click_rows(study, t)),
        "events": (EVENT_COLUMNS, lambda t: _event_rows(study, t)),
    }[table]
    out = _io.StringIO()
    writer = csv.DictWriter(out, fieldnames=columns, lineterminator="\n")
    writer.writeheader()
    for trial in _study_trials(study):
        for row in rows_of(trial):
            if "detail" in row:
                row["detail"] = json.dumps(row["detail"], sort_keys=True)
            writer.writerow(row)
    return out.getvalue()


def export_json(study: Study) -> dict[str, Any]:
    """The whole study as one JSON document: settings, frames, participants with trials, clicks and events."""
    by_participant: dict[int, list[Trial]] = defaultdict(list)
    for trial in _study_trials(study):
        by_participant[trial.participant_id].append(trial)
    return {
        "study": _study_json(study),
        "frames": [
            {
                "position": sf.position,
                "frame_id": sf.frame_id,
                "activity": sf.frame.sequence.activity.name,
                "sequence": sf.frame.sequence.name,
                "source_name": sf.frame.source_name,
                "content_hash": sf.frame.content_hash,
                "width": sf.frame.width,
                "height": sf.frame.height,
            }
            for sf in study.frames
        ],
        "participants": [_participant_json(study, p, by_participant[p.id]) for p in study.participants],
    }


def _study_json(study: Study) -> dict[str, Any]:
    return {
        "id": study.id,
        "name": study.name,
        "seed": study.seed,
        "frames_per_activity": study.frames_per_activity,
        "time_limit_s": study.time_limit_s,
        "trial_limit_s": study.trial_limit_s,
        "late_grace_s": LATE_GRACE_S,
        "multiple_clicks": study.multiple_clicks,
        "sigma_px": study.sigma_px,
        "superpixels": study.superpixels,
        "instructions": study.instructions,
        "consent": study.consent,
        "created_at": _iso(study.created_at),
    }


def _participant_json(study: Study, p: Participant, trials: list[Trial]) -> dict[str, Any]:
    return {
        "id": p.id,
        "label": p.label,
        "number": p.number,
        "entry": p.entry.value,
        "order_seed": p.order_seed,
        "consented_at": _iso(p.consented_at),
        "started_at": _iso(p.started_at),
        "deadline": _iso(p.deadline),
        "finished_at": _iso(p.finished_at),
        "end_reason": p.end_reason.value if p.end_reason else None,
        "trials": [
            {
                **{k: v for k, v in _trial_row(study, t).items() if k not in ("study_id", "participant", "participant_id", "clicks", "events")},
                "clicks": [{"x": c.x, "y": c.y, "rt_ms": c.rt_ms, "received_at": _iso(c.received_at)} for c in t.clicks],
                "events": [
                    {"kind": e.kind.value, "client_ms": e.client_ms, "server_at": _iso(e.server_at), "detail": e.detail}
                    for e in t.events
                ],
            }
            for t in trials
        ],
    }


def mask_files(study: Study) -> Iterator[tuple[str, bytes]]:
    """The soft masks as 16-bit PNGs: one per answered trial and the mean per frame, plus a manifest.

    Names: ``P01/0001-frame12.png`` (participant, trial position, frame id)
    and ``mean/frame12.png``; ``manifest.csv`` lists them.
    """
    manifest = _io.StringIO()
    writer = csv.writer(manifest, lineterminator="\n")
    writer.writerow(["file", "participant", "position", "frame_id", "activity", "frame_source", "outcome", "participants"])
    means: dict[int, MaskMean] = defaultdict(MaskMean)
    for trial in _study_trials(study):
        if trial.outcome not in ANSWERED:
            continue
        frame = trial.frame
        mask = trial_soft_mask(trial)
        name = f"{trial.participant.label}/{trial.position:04d}-frame{frame.id}.png"
        writer.writerow([name, trial.participant.label, trial.position, frame.id, frame.sequence.activity.name, frame.source_name, trial.outcome.value, ""])
        yield name, mask_png(mask)
        means[frame.id].add(mask)
    for sf in study.frames:
        frame = sf.frame
        if frame.id in means:
            name = f"mean/frame{frame.id}.png"
            writer.writerow([name, "mean", "", frame.id, frame.sequence.activity.name, frame.source_name, "", means[frame.id].count])
            yield name, mask_png(means[frame.id].mean())
    yield "manifest.csv", manifest.getvalue().encode()


class _Chunks(_io.RawIOBase):
    """A write-only stream whose bytes are taken out as they come (for a streamed zip)."""

    def __init__(self):
        self.parts: list[bytes] = []

    def writable(self) -> bool:
        return True

    def write(self, data) -> int:
        self.parts.append(bytes(data))
        return len(data)

    def take(self) -> bytes:
        out = b"".join(self.parts)
        self.parts.clear()
        return out


def masks_zip(study: Study) -> Iterator[bytes]:
    """``mask_files`` as a zip archive, produced piece by piece (PNGs are stored, not recompressed)."""
    stream = _Chunks()
    with zipfile.ZipFile(stream, "w", compression=zipfile.ZIP_STORED) as archive:
        for name, data in mask_files(study):
            archive.writestr(name, data)
            yield stream.take()
    yield stream.take()


def export_to_folder(study: Study, out: Path, *, on_start=None, on_progress=None) -> list[Path]:
    """Write every export (CSV, JSON, mask PNGs under ``masks/``) into ``out``; return the files.

    ``on_start(total)`` and ``on_progress(n)`` report the files written.
    """
    out = Path(out)
    answered = db.session.execute(
        db.select(func.count(), func.count(func.distinct(Trial.study_frame_id)))
        .select_from(Trial)
        .join(Participant)
        .where(Participant.study_id == study.id, Trial.outcome.in_(ANSWERED))
    ).one()
    if on_start is not None:
        on_start(4 + answered[0] + answered[1] + 1)  # tables, JSON, masks, means, manifest
    written = []

    def write(path: Path, data: bytes) -> None:
        media.write_atomic(path, data)
        written.append(path)
        if on_progress is not None:
            on_progress(1)

    for table in ("trials", "clicks", "events"):
        write(out / f"{table}.csv", export_csv(study, table).encode())
    write(out / "study.json", json.dumps(export_json(study), indent=1).encode())
    for name, data in mask_files(study):
        write(out / "masks" / name, data)
    return written
