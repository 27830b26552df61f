"""Superpixels (cached per frame), soft masks and the pictures made of them.

Soft masks: ``egonet.clicks.soft_mask`` on superpixels computed once per
frame and cached under ``CACHE_ROOT/superpixels/<settings key>/`` as a
compressed ``.npz`` named by the frame's content hash, written atomically.
The mean map of a frame and the overlays are ``egonet.clicks.MaskMean`` and
``egonet.overlay.overlay``; this module finds the trials and the files.

For the scorer: ``study_participants(study_ids)`` (optionally without
those who failed a check) and ``participant_soft_masks(participant)`` (the
timed part only: practice and catch trials are never scored as data).
"""

import hashlib
import io as _io
import json
import zipfile
from collections import defaultdict
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from flask import current_app
from sqlalchemy.orm import selectinload

from app.extensions import db
from app.models import Frame
from app.models.studies import ANSWERED, FrameKind, Participant, Study, StudyFrame, Trial
from app.services import media
from app.services.studies.building import sigma_for
from app.services.studies.checks import checks_of
from egonet import clicks as egonet_clicks
from egonet import io
from egonet.overlay import overlay as egonet_overlay


def settings_key(settings: dict[str, Any]) -> str:
    """A short stable name for a set of superpixel options."""
    return hashlib.sha256(json.dumps(settings, sort_keys=True).encode()).hexdigest()[:16]


def labels_path(frame: Frame, settings: dict[str, Any]) -> Path:
    """Where the frame's labels for these settings are cached (named by content, so re-imports share it)."""
    root = Path(current_app.config["CACHE_ROOT"]) / "superpixels" / settings_key(settings)
    return root / frame.content_hash[:2] / f"{frame.content_hash}.npz"


def cached_superpixels(frame: Frame, settings: dict[str, Any]) -> bool:
    return labels_path(frame, settings).exists()


def frame_regions(frame: Frame, settings: dict[str, Any]) -> egonet_clicks.Regions:
    """The frame's regions (labels, uint16 where they fit, and the ids the region cap split): from the cache,
    or computed once and cached."""
    path = labels_path(frame, settings)
    try:
        with np.load(path, allow_pickle=False) as data:
            labels, capped = data["labels"], data["capped"] if "capped" in data else np.zeros(0, np.int32)
        if labels.shape == (frame.height, frame.width):
            return egonet_clicks.Regions(labels, capped)
    except (OSError, ValueError, KeyError, zipfile.BadZipFile):
        pass  # missing or unreadable: compute it again
    rgb = io.read_image(media.local_path(frame.rgb_path))
    found = egonet_clicks.regions(rgb, **settings)
    # uint16 holds any realistic region count and halves the file.
    stored = found.labels.astype(np.uint16) if found.labels.max() < 2**16 else found.labels
    buffer = _io.BytesIO()
    np.savez_compressed(buffer, labels=stored, capped=found.capped)
    media.write_atomic(path, buffer.getvalue())
    return egonet_clicks.Regions(stored, found.capped)


def superpixel_labels(frame: Frame, settings: dict[str, Any]) -> np.ndarray:
    """The frame's superpixel labels, int (H, W) (``frame_regions``)."""
    return frame_regions(frame, settings).labels


def precompute_superpixels(study: Study, *, on_progress=None) -> int:
    """Compute and cache the superpixels of every study frame; return how many were computed."""
    computed = 0
    for sf in study.frames:
        if not cached_superpixels(sf.frame, study.superpixels):
            superpixel_labels(sf.frame, study.superpixels)
            computed += 1
        if on_progress is not None:
            on_progress(1)
    return computed


def trial_soft_mask(trial: Trial) -> np.ndarray:
    """The trial's soft mask, float32 (H, W) in [0, 1] at the frame's native size.

    Raises:
        ValueError: if the trial has no answer (pending or expired).
    """
    if trial.outcome not in ANSWERED:
        raise ValueError(f"trial {trial.id} has no answer ({trial.outcome or 'pending'})")
    frame, study = trial.frame, trial.participant.study
    points = [(c.x, c.y) for c in trial.clicks]
    if not points:  # an answer of none: no need for superpixels
        return np.zeros((frame.height, frame.width), np.float32)
    labels = superpixel_labels(frame, study.superpixels)
    return egonet_clicks.soft_mask((frame.height, frame.width), points, sigma=sigma_for(study, frame), labels=labels)


def answered_trials(study_frame: StudyFrame) -> list[Trial]:
    """The answered trials of one study frame, by participant number."""
    return list(
        db.session.execute(
            db.select(Trial)
            .join(Participant)
            .where(Trial.study_frame_id == study_frame.id, Trial.outcome.in_(ANSWERED))
            .order_by(Participant.number)
            .options(selectinload(Trial.clicks))
        ).scalars()
    )


def mean_soft_mask(study_frame: StudyFrame) -> tuple[np.ndarray | None, int]:
    """The mean of the participants' soft masks of a frame (the paper's Fig. 5), and how many it averages.

    Pilots are left out, as from every mean, score and count of data (their own masks are shown and exported, marked).
    """
    mean = egonet_clicks.MaskMean()
    for trial in answered_trials(study_frame):
        if not trial.participant.pilot:
            mean.add(trial_soft_mask(trial))
    return mean.mean(), mean.count


def click_pixels(points: Iterable[tuple[float, float]], shape: tuple[int, int]) -> list[tuple[int, int]]:
    """The (row, column) of the pixel each click (x, y) falls in: pixel centres are at integer coordinates, so
    pixel (r, c) spans [c - 0.5, c + 0.5) x [r - 0.5, r + 0.5) (the frame's last edge belongs to its last pixel)."""
    h, w = shape
    return [(min(int(np.floor(y + 0.5)), h - 1), min(int(np.floor(x + 0.5)), w - 1)) for x, y in points]


@dataclass(frozen=True)
class CapSummary:
    """How the region cap touched a study: its share (None: no cap), answered trials, and those that hit it."""

    share: float | None
    trials: int
    hit: int


def cap_summary(study: Study) -> CapSummary:
    """The study's region cap and how many answered trials (pilots included, as in the manifest) hit it
    (``hit_cap``); each frame's regions are read once, one frame at a time."""
    share = study.superpixels.get("max_region_share") if study.superpixels.get("method") == "hierarchical" else None
    trials = db.session.execute(
        db.select(Trial)
        .join(Participant)
        .where(Participant.study_id == study.id, Trial.outcome.in_(ANSWERED))
        .options(selectinload(Trial.clicks), selectinload(Trial.study_frame).selectinload(StudyFrame.frame))
    ).scalars()
    by_frame: dict[int, list[Trial]] = defaultdict(list)
    count = 0
    for trial in trials:
        count += 1
        if trial.clicks:
            by_frame[trial.frame.id].append(trial)
    hit = 0
    for answered in by_frame.values() if share is not None and share < 1 else ():  # no cap: nothing to hit
        frame = answered[0].frame
        found = frame_regions(frame, study.superpixels)
        hit += sum(hit_cap(found, [(c.x, c.y) for c in t.clicks]) for t in answered)
    return CapSummary(share if share is not None and share < 1 else None, count, hit)


def hit_cap(found: egonet_clicks.Regions, points: Iterable[tuple[float, float]]) -> bool:
    """Whether one of these clicks (x, y) fell on a region of ``found`` that stands where the region cap split
    one (``egonet.clicks.regions``): the trials whose masks the cap changed most."""
    if not len(found.capped):
        return False
    hit = [found.labels[r, c] for r, c in click_pixels(points, found.labels.shape)]
    return bool(np.isin(hit, found.capped).any())


def study_participants(
    study_ids: Iterable[int], *, exclude_failed_checks: bool = False, include_pilots: bool = False
) -> list[Participant]:
    """The participants of these studies, by study and number (for the scorer); never those who withdrew.

    With ``exclude_failed_checks``, those who failed a comprehension or
    attention check (``app.services.studies.checks``) are left out; pilots
    are, unless ``include_pilots``.
    """
    query = db.select(Participant).where(Participant.study_id.in_(list(study_ids)), Participant.withdrawn_at.is_(None))
    if not include_pilots:
        query = query.where(Participant.pilot.is_(False))
    people = list(db.session.execute(query.order_by(Participant.study_id, Participant.number)).scalars())
    if not exclude_failed_checks:
        return people
    results = checks_of(people)
    return [p for p in people if results[p.id].passed is not False]


def condition_name(participant: Participant) -> str | None:
    """The participant's between-subject condition (None in a study without conditions)."""
    return participant.condition.name if participant.condition is not None else None


def participant_soft_masks(participant: Participant) -> Iterator[tuple[Frame, np.ndarray]]:
    """Each answered trial of the timed part: its frame and soft mask, float32 (H, W) in [0, 1], in trial order.

    Answers of "none" give zeros; a time-out keeps the clicks made before it.
    Expired and unanswered trials are left out (the participant gave no
    answer), and so are practice and catch trials (never data).
    """
    trials = db.session.execute(
        db.select(Trial)
        .join(StudyFrame, Trial.study_frame)
        .where(Trial.participant_id == participant.id, Trial.outcome.in_(ANSWERED), StudyFrame.kind == FrameKind.MAIN)
        .order_by(Trial.position)
        .options(selectinload(Trial.clicks), selectinload(Trial.study_frame).selectinload(StudyFrame.frame))
    ).scalars()
    for trial in trials:
        yield trial.frame, trial_soft_mask(trial)


def mask_png(mask: np.ndarray) -> bytes:
    """A soft mask as a 16-bit grayscale PNG (value * 65535), precise enough for 1/100 thresholds."""
    return io.encode_probability_png(mask)


def overlay_png(
    frame: Frame,
    mask: np.ndarray | None,
    *,
    points: Iterable[tuple[float, float]] = (),
    outline: np.ndarray | None = None,
    max_width: int = 640,
) -> bytes:
    """The frame with a soft mask as a heat map, clicks as rings and an optional outline (e.g. ground truth).

    See ``egonet.overlay.overlay``: the heat map's opacity follows the mask,
    so the frame shows through where the mask is low.
    """
    rgb = io.read_image(media.local_path(frame.rgb_path))
    return io.encode_png(egonet_overlay(rgb, mask, points=list(points), outline=outline, max_width=max_width))
