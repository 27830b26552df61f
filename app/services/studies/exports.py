"""The study's results for analysis: CSV tables, one JSON document and the soft masks as 16-bit PNGs.

``EXPORTS`` names what the admin pages offer; ``export_to_folder`` writes
them all (the ``flask egonet study-export`` command). The masks' zip is
produced piece by piece while it is sent. Every table carries the
participant's external id, condition and whether they were a pilot (the
zip's mean masks leave pilots out); trials say whether they were
practice or catch trials and whether a click hit the true action-object
(its ground-truth mask, or a catch trial's answer region); participants.csv
has one row per participant with their status, checks, completion code
and browser, for approving payments. Sessions whose deadline passed while
nobody was there are closed first, so no trial stays pending after time-up.
"""

import io as _io
import json
import zipfile
from collections import defaultdict
from collections.abc import Iterator
from datetime import datetime
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np
from sqlalchemy import case, func
from sqlalchemy.orm import selectinload

from app.extensions import db
from app.models import Frame, Sequence
from app.models.studies import ANSWERED, FrameKind, Participant, Study, StudyFrame, Trial
from app.services import ground_truth, media
from app.services.studies import codebook
from app.services.studies.building import format_code, sigma_for
from app.services.studies.checks import checks_of, inside_box, inside_mask
from app.services.studies.common import LATE_GRACE_S
from app.services.studies.definition import definition_of
from app.services.studies.masks import condition_name, frame_regions, hit_cap, mask_png, trial_soft_mask
from app.services.studies.overview import progress
from app.services.studies.session import close_overdue
from app.spreadsheet import csv_text
from app.version import code_version
from egonet.clicks import SUPERPIXEL_DEFAULTS, MaskMean

TRIAL_COLUMNS = list(codebook.TRIALS.columns)
CLICK_COLUMNS = list(codebook.CLICKS.columns)
EVENT_COLUMNS = list(codebook.EVENTS.columns)
PARTICIPANT_COLUMNS = list(codebook.PARTICIPANTS.columns)
MANIFEST_COLUMNS = list(codebook.MANIFEST.columns)
EXPORTS = ("trials.csv", "clicks.csv", "events.csv", "participants.csv", "study.json", "definition.json", "masks.zip")


class _Truth:
    """Where clicks fall: each frame's ground-truth mask (decoded once per export) or a catch frame's box."""

    def __init__(self, study: Study):
        self.annotations = ground_truth.ground_truths([sf.frame_id for sf in study.frames])
        self.masks: dict[int, Any] = {}

    def inside(self, trial: Trial) -> list[bool] | None:
        """For each click, whether it is in the answer region; None when there is none to compare with."""
        points = [(c.x, c.y) for c in trial.clicks]
        region = trial.study_frame.region
        if trial.kind is FrameKind.CATCH and region and "box" in region:
            return inside_box(region["box"], points)
        frame_id = trial.study_frame.frame_id
        if frame_id not in self.annotations:
            return None
        if frame_id not in self.masks:
            self.masks[frame_id] = ground_truth.mask_of(self.annotations[frame_id])
        return inside_mask(self.masks[frame_id], points)

    def hit(self, trial: Trial) -> bool | None:
        if trial.kind is FrameKind.CATCH and trial.hit is not None:
            return trial.hit  # as judged when the answer came
        if trial.outcome not in ANSWERED:
            return None
        inside = self.inside(trial)
        return None if inside is None else any(inside)


def _settle(study: Study) -> None:
    close_overdue([p.id for p in study.participants])


def _who(trial: Trial) -> dict[str, Any]:
    participant = trial.participant
    return {"participant": participant.label, "external_id": participant.external_id, "condition": condition_name(participant),
            "pilot": participant.pilot}  # fmt: skip


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
                selectinload(Trial.participant).selectinload(Participant.condition),
                selectinload(Trial.study_frame).selectinload(StudyFrame.frame).selectinload(Frame.sequence).selectinload(Sequence.activity),
            )
        ).scalars()
    )


def _trial_row(study: Study, trial: Trial, truth: _Truth) -> dict[str, Any]:
    frame = trial.frame
    server_ms = None
    if trial.shown_at is not None and trial.submitted_at is not None:
        server_ms = round((trial.submitted_at - trial.shown_at).total_seconds() * 1000, 1)
    return {
        "study_id": study.id,
        **_who(trial),
        "participant_id": trial.participant_id,
        "trial_id": trial.id,
        "position": trial.position,
        "kind": trial.kind.value,
        "activity": frame.sequence.activity.name,
        "frame_id": frame.id,
        "frame_source": frame.source_name,
        "frame_width": frame.width,
        "frame_height": frame.height,
        "outcome": trial.outcome.value if trial.outcome else ("not_reached" if trial.participant.finished_at else "pending"),
        "clicks": len(trial.clicks),
        "hit": truth.hit(trial),
        "rt_ms": trial.rt_ms,
        "shown_at": _iso(trial.shown_at),
        "submitted_at": _iso(trial.submitted_at),
        "server_ms": server_ms,
        "window_width": trial.window_width,
        "window_height": trial.window_height,
        "display_width": trial.display_width,
        "display_height": trial.display_height,
        "pixel_ratio": trial.pixel_ratio,
        "sigma_px": sigma_for(study, frame),
        "events": len(trial.events),
    }


def _click_rows(study: Study, trial: Trial, truth: _Truth) -> list[dict[str, Any]]:
    base = {"study_id": study.id, **_who(trial), "trial_id": trial.id, "position": trial.position, "kind": trial.kind.value,
            "frame_id": trial.frame.id}  # fmt: skip
    inside = truth.inside(trial) if trial.clicks else None
    return [
        {**base, "click": c.position, "x": c.x, "y": c.y, "inside": inside[i] if inside is not None else None, "rt_ms": c.rt_ms,
         "received_at": _iso(c.received_at)}  # fmt: skip
        for i, c in enumerate(trial.clicks)
    ]


def _event_rows(study: Study, trial: Trial, truth: _Truth) -> list[dict[str, Any]]:
    base = {"study_id": study.id, **_who(trial), "trial_id": trial.id, "position": trial.position, "frame_id": trial.frame.id}
    return [
        {**base, "event": e.position, "kind": e.kind.value, "client_ms": e.client_ms, "server_at": _iso(e.server_at), "detail": e.detail}
        for e in trial.events
    ]


def export_csv(study: Study, table: str) -> str:
    """One table of the study's results as CSV: ``trials``, ``clicks``, ``events`` or ``participants``.

    Cells go through the one CSV writer (``app.spreadsheet``): what a participant's browser or platform sent
    (user agent, time zone, external ids) cannot run as a formula in a spreadsheet.
    """
    _settle(study)
    if table == "participants":
        columns, rows = PARTICIPANT_COLUMNS, participant_rows(study)
    else:
        truth = _Truth(study)
        rows_of = {"trials": lambda t: [_trial_row(study, t, truth)], "clicks": lambda t: _click_rows(study, t, truth),
                   "events": lambda t: _event_rows(study, t, truth)}[table]  # fmt: skip
        columns = {"trials": TRIAL_COLUMNS, "clicks": CLICK_COLUMNS, "events": EVENT_COLUMNS}[table]
        rows = (row for trial in _study_trials(study) for row in rows_of(trial))
    return csv_text(([_csv_cell(column, row[column]) for column in columns] for row in rows), columns)


def _csv_cell(column: str, value: Any) -> Any:
    """JSON columns as one JSON text (an empty ``external`` as nothing), other values as they are."""
    if column == "external":
        return json.dumps(value, sort_keys=True) if value else ""
    return json.dumps(value, sort_keys=True) if column == "detail" else value


def participant_rows(study: Study) -> list[dict[str, Any]]:
    """One row per participant: who they are on their platform, their condition, status, checks and code, their browser."""
    people = list(study.participants)
    results = checks_of(people)
    rows = []
    for p in people:
        state, checked, env = progress(p), results[p.id], p.environment or {}
        screen, window = env.get("screen") or {}, env.get("window") or {}
        withdrawn = p.withdrawn_at is not None  # their answers are gone: no check is known
        rows.append({
            "study_id": study.id, "participant": p.label, "participant_id": p.id, "code": format_code(p.code), "entry": p.entry.value,
            "platform": p.platform, "external_id": p.external_id, "external": p.external or {}, "condition": condition_name(p),
            "pilot": p.pilot, "status": state.status, "active": p.user.active, "checks_passed": None if withdrawn else checked.passed,
            "comprehension": None if withdrawn else checked.comprehension,
            "catch_passed": None if withdrawn else checked.catch_passed, "catch_total": None if withdrawn else checked.catch_total,
            "completion_code": p.completion_code, "consented_at": _iso(p.consented_at), "started_at": _iso(p.started_at),
            "finished_at": _iso(p.finished_at), "end_reason": p.end_reason.value if p.end_reason else None,
            "answered": state.answered, "total": state.total, "user_agent": p.user_agent,
            "screen_width": screen.get("width"), "screen_height": screen.get("height"), "window_width": window.get("width"),
            "window_height": window.get("height"), "pixel_ratio": env.get("pixel_ratio"), "time_zone": env.get("time_zone"),
            "touch": env.get("touch"), "withdrawn_at": _iso(p.withdrawn_at),
            "withdrawn_by": p.withdrawn_by.username if p.withdrawn_by else None,
        })  # fmt: skip
    return rows


def export_json(study: Study) -> dict[str, Any]:
    """The whole study as one JSON document: settings, frames, participants with trials, clicks and events."""
    _settle(study)
    by_participant: dict[int, list[Trial]] = defaultdict(list)
    for trial in _study_trials(study):
        by_participant[trial.participant_id].append(trial)
    truth = _Truth(study)
    rows = {row["participant_id"]: row for row in participant_rows(study)}
    return {
        "study": _study_json(study),
        "definition": definition_of(study),
        "frames": [
            {
                "position": sf.position,
                "kind": sf.kind.value,
                "catch_position": sf.catch_position,
                "region": sf.region,
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
        "participants": [_participant_json(study, p, by_participant[p.id], rows[p.id], truth) for p in study.participants],
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
        "sigma_scaled": study.sigma_scaled,
        "superpixels": study.superpixels,
        "status": study.status.value,
        "version": study.version,
        "instructions": study.instructions,
        "consent": study.consent,
        "created_at": _iso(study.created_at),
    }


def _participant_json(study: Study, p: Participant, trials: list[Trial], row: dict[str, Any], truth: _Truth) -> dict[str, Any]:
    left_out = ("study_id", "participant", "participant_id", "external_id", "condition", "pilot", "clicks", "events")
    return {
        "id": p.id,
        "label": p.label,
        "number": p.number,
        "entry": p.entry.value,
        "order_seed": p.order_seed,
        "platform": p.platform,
        "external_id": p.external_id,
        "external": p.external or {},
        "condition": condition_name(p),
        "pilot": p.pilot,
        "withdrawn_at": _iso(p.withdrawn_at),
        "withdrawn_by": p.withdrawn_by.username if p.withdrawn_by else None,
        "status": row["status"],
        "active": row["active"],
        "checks": None if p.withdrawn_at is not None else checks_of([p])[p.id].as_dict(),
        "completion_code": p.completion_code,
        "user_agent": p.user_agent,
        "environment": p.environment,
        "comprehension_attempts": p.comprehension_attempts,
        "consented_at": _iso(p.consented_at),
        "started_at": _iso(p.started_at),
        "deadline": _iso(p.deadline),
        "finished_at": _iso(p.finished_at),
        "end_reason": p.end_reason.value if p.end_reason else None,
        "trials": [
            {
                **{k: v for k, v in _trial_row(study, t, truth).items() if k not in left_out},
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
    """The soft masks as 16-bit PNGs and what recomputes them (the content of ``masks.zip``).

    Names: ``P01/0001-frame12.png`` (participant, trial position, frame id)
    and ``mean/frame12.png`` (pilots left out), listed in ``manifest.csv``;
    each frame's region labels as ``labels/frame12.npz``, how they were made
    in ``regions.json``, the clicks as ``clicks.csv`` and the codebook as
    ``CODEBOOK.md`` (``docs/studies.md`` shows the script that recomputes a
    mask from them).
    """
    manifest = []
    means: dict[int, MaskMean] = defaultdict(MaskMean)
    # Per frame: its manifest rows, their clicks and whether they count in the mean; the cap is judged per frame below.
    rows_of: dict[int, list[tuple[int, list[tuple[float, float]], bool]]] = defaultdict(list)
    frames: dict[int, Frame] = {}
    for trial in _study_trials(study):
        if trial.outcome not in ANSWERED:
            continue
        frame = trial.frame
        mask = trial_soft_mask(trial)
        name = f"{trial.participant.label}/{trial.position:04d}-frame{frame.id}.png"
        frames[frame.id] = frame
        rows_of[frame.id].append((len(manifest), [(c.x, c.y) for c in trial.clicks], not trial.participant.pilot))
        manifest.append([name, trial.participant.label, trial.participant.pilot, trial.position, trial.kind.value, frame.id,
                         frame.sequence.activity.name, frame.source_name, trial.outcome.value, "", sigma_for(study, frame), False])  # fmt: skip
        yield name, mask_png(mask)
        if not trial.participant.pilot:  # the means are data: pilots stay out
            means[frame.id].add(mask)
    mean_row: dict[int, int] = {}
    for sf in study.frames:
        frame = sf.frame
        if frame.id in means:
            name = f"mean/frame{frame.id}.png"
            mean_row[frame.id] = len(manifest)
            manifest.append([name, "mean", "", "", sf.kind.value, frame.id, frame.sequence.activity.name, frame.source_name, "",
                             means[frame.id].count, sigma_for(study, frame), 0])  # fmt: skip
            yield name, mask_png(means[frame.id].mean())
    described = []
    for frame_id in sorted(frames):
        frame = frames[frame_id]
        found = frame_regions(frame, study.superpixels)
        for row, points, in_mean in rows_of[frame_id]:
            manifest[row][-1] = bool(points) and hit_cap(found, points)
            if in_mean and manifest[row][-1]:
                manifest[mean_row[frame_id]][-1] += 1
        buffer = _io.BytesIO()
        np.savez_compressed(buffer, labels=found.labels)
        name = f"labels/frame{frame.id}.npz"
        described.append({"frame_id": frame.id, "file": name, "width": frame.width, "height": frame.height,
                          "sigma_px": sigma_for(study, frame), "regions": int(found.labels.max()) + 1,
                          "capped": found.capped.tolist()})  # fmt: skip
        yield name, buffer.getvalue()
    yield "regions.json", json.dumps(_regions_doc(study, described, sum(row[-1] is True for row in manifest)), indent=1).encode()
    yield "manifest.csv", csv_text(manifest, MANIFEST_COLUMNS).encode()
    yield "clicks.csv", export_csv(study, "clicks").encode()
    yield "CODEBOOK.md", codebook.markdown().encode()


def _versions(*names: str) -> dict[str, str]:
    """The installed versions of these packages (the regions depend on scikit-image's and OpenCV's)."""
    found = {}
    for name in names:
        try:
            found[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            pass
    return found


def _regions_doc(study: Study, frames: list[dict[str, Any]], trials_hit_cap: int) -> dict[str, Any]:
    """regions.json: what regenerates the label maps bit for bit, and how a mask is made from them."""
    settings = dict(study.superpixels)
    return {
        "code_version": code_version(),
        "libraries": _versions("numpy", "scipy", "scikit-image", "opencv-python", "opencv-python-headless"),
        "function": "egonet.clicks.regions(rgb, **settings).labels, rgb the frame's image as uint8 (H, W, 3) RGB",
        "settings": settings,
        "max_region_share": settings.get("max_region_share") if settings.get("method") == "hierarchical" else None,
        "default_max_region_share": SUPERPIXEL_DEFAULTS.max_region_share,
        "trials_hit_cap": trials_hit_cap,
        "coordinates": "x = column, y = row, native pixels; pixel centres at integer coordinates (the frame spans "
                       "[-0.5, width - 0.5] x [-0.5, height - 0.5])",
        "soft_mask": "g = max over clicks of exp(-((col - x)^2 + (row - y)^2) / (2 sigma_px^2)) at every pixel centre (float32); "
                     "each region takes the mean of g over its pixels, clipped to [0, 1]; no click: zeros",
        "frames": frames,
    }


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
    """``mask_files`` as a zip archive, produced piece by piece (PNGs and ``.npz`` are stored, not compressed again)."""
    stream = _Chunks()
    with zipfile.ZipFile(stream, "w", compression=zipfile.ZIP_STORED) as archive:
        for name, data in mask_files(study):
            packed = name.endswith((".png", ".npz"))
            archive.writestr(name, data, compress_type=zipfile.ZIP_STORED if packed else zipfile.ZIP_DEFLATED)
            yield stream.take()
    yield stream.take()


def export_to_folder(study: Study, out: Path, *, on_start=None, on_progress=None) -> list[Path]:
    """Write every export (CSV, JSON, the codebook, and under ``masks/`` what ``masks.zip`` holds) into ``out``; return the files.

    ``on_start(total)`` and ``on_progress(n)`` report the files written.
    """
    out = Path(out)
    _settle(study)
    trials, frames, averaged = db.session.execute(
        db.select(
            func.count(),
            func.count(func.distinct(Trial.study_frame_id)),
            func.count(func.distinct(case((Participant.pilot.is_(False), Trial.study_frame_id)))),
        )
        .select_from(Trial)
        .join(Participant)
        .where(Participant.study_id == study.id, Trial.outcome.in_(ANSWERED))
    ).one()
    if on_start is not None:
        # tables, JSON documents and the codebook; masks, labels per frame, means (pilots in none); regions.json,
        # manifest, clicks, codebook
        on_start(7 + trials + frames + averaged + 4)
    written = []

    def write(path: Path, data: bytes) -> None:
        media.write_atomic(path, data)
        written.append(path)
        if on_progress is not None:
            on_progress(1)

    for table in ("trials", "clicks", "events", "participants"):
        write(out / f"{table}.csv", export_csv(study, table).encode())
    write(out / "study.json", json.dumps(export_json(study), indent=1).encode())
    write(out / "definition.json", json.dumps(definition_of(study), indent=1).encode())
    write(out / "CODEBOOK.md", codebook.markdown().encode())
    for name, data in mask_files(study):
        write(out / "masks" / name, data)
    return written
