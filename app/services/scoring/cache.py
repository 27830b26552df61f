"""The score cache: each job's per-frame counts as ``.npz`` under ``CACHE_ROOT/scores/``.

A job (a run, the baselines, a participant) is scored into one
:class:`FrameStats` per row it fills: every frame's id, activity and
per-threshold counts (``egonet.metrics.FrameCounts``), and whether a
participant answered it. That is enough to score any subset of the frames
(the frames rows share), resample them (confidence intervals, paired tests)
and score them under any convention, so a later report with the same inputs
reads the file back instead of scoring the maps again.

Files are named by a hash of everything the job depends on and of
:data:`SCORER_VERSION`, a participant's also by their id (so that their
withdrawal deletes them). Version 1 stored per-activity totals as ``.json``;
those files have other names and are never read again (delete them at
will). A file that cannot be read, or holds something else than expected,
is scored again and rewritten.
"""

from __future__ import annotations

import hashlib
import io
import json
import zipfile
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from flask import current_app

from app.services import media
from egonet.metrics import Counts, FrameCounts

# Bump when scoring changes in a way that makes cached statistics wrong.
SCORER_VERSION = 2


@dataclass(frozen=True, eq=False)
class FrameStats:
    """One row's per-frame counts, frames sorted by id.

    Attributes:
        ids: Frame ids, int64 (N,), increasing.
        activities: Each frame's activity name, str (N,).
        counts: Each frame's counts at every threshold.
        answered: False where a participant gave no answer (scored as an
            empty map); True for every other frame, bool (N,).
    """

    ids: np.ndarray
    activities: np.ndarray
    counts: FrameCounts
    answered: np.ndarray

    @property
    def n(self) -> int:
        return int(self.ids.size)

    def take(self, index: np.ndarray) -> FrameStats:
        """The frames at ``index`` (positions or a bool mask)."""
        return FrameStats(self.ids[index], self.activities[index], self.counts.take(index), self.answered[index])

    def by_activity(self) -> dict[str, np.ndarray]:
        """Each activity's frame ids (increasing)."""
        return {str(a): self.ids[self.activities == a] for a in np.unique(self.activities)}

    def select(self, frame_ids: np.ndarray) -> FrameCounts:
        """The counts of these frames (ids this row has, increasing)."""
        return self.counts.take(np.searchsorted(self.ids, frame_ids))


Stats = FrameStats


@dataclass
class StatsBuilder:
    """Collects frames one at a time, in any order; :meth:`build` sorts them by id."""

    thresholds: int
    _rows: list[tuple[int, str, Counts, bool]] = field(default_factory=list)

    def add(self, frame_id: int, activity: str, counts: Counts, *, answered: bool = True) -> None:
        self._rows.append((int(frame_id), activity, counts, answered))

    def __len__(self) -> int:
        return len(self._rows)

    def build(self) -> FrameStats:
        rows = sorted(self._rows, key=lambda r: r[0])
        ids = np.array([r[0] for r in rows], dtype=np.int64)
        if np.any(np.diff(ids) == 0):
            raise ValueError("a frame was scored twice for one row")
        counts = FrameCounts.stack([r[2] for r in rows], thresholds=self.thresholds)
        return FrameStats(ids, np.array([r[1] for r in rows], dtype=str), counts, np.array([r[3] for r in rows], dtype=bool))


def cache_path(key: dict[str, Any]) -> Path:
    """Where the statistics of a job with this key live."""
    digest = hashlib.sha256(json.dumps({"scorer": SCORER_VERSION, **key}, sort_keys=True).encode()).hexdigest()
    # A participant's files carry their id, so that their withdrawal finds them (forget_participant).
    prefix = f"participant{key['participant']}-" if "participant" in key else ""
    return Path(current_app.config["CACHE_ROOT"]) / "scores" / f"{prefix}{digest}.npz"


def read_cached(path: Path, thresholds: int) -> tuple[dict[str, FrameStats], list[str]] | None:
    """A job's statistics by name and its notes, or None when missing or unreadable (score again)."""
    try:
        # Opened here, not by np.load, so that a file that is not a zip is closed too.
        with path.open("rb") as file, np.load(file, allow_pickle=False) as data:
            if int(data["version"]) != SCORER_VERSION:
                return None
            names, notes = [str(n) for n in data["names"]], [str(n) for n in data["notes"]]
            stats = {name: _load(data, i, thresholds) for i, name in enumerate(names)}
        return stats, notes
    except (OSError, ValueError, KeyError, TypeError, EOFError, zipfile.BadZipFile):
        return None


def write_cached(path: Path, stats: dict[str, FrameStats], notes: Sequence[str]) -> None:
    """Store a job's statistics and notes (atomically: a reader never sees half a file)."""
    arrays: dict[str, np.ndarray] = {
        "version": np.array(SCORER_VERSION),
        "names": np.array(list(stats), dtype=str),
        "notes": np.array(list(notes), dtype=str),
    }
    for i, s in enumerate(stats.values()):
        arrays |= {
            f"{i}.ids": s.ids,
            f"{i}.activities": s.activities,
            f"{i}.tp": s.counts.tp,
            f"{i}.fp": s.counts.fp,
            f"{i}.positives": s.counts.positives,
            f"{i}.answered": s.answered,
        }
    buffer = io.BytesIO()
    np.savez_compressed(buffer, **arrays)
    media.write_atomic(path, buffer.getvalue())


def _load(data: Any, i: int, thresholds: int) -> FrameStats:
    ids = np.asarray(data[f"{i}.ids"], dtype=np.int64)
    counts = FrameCounts(data[f"{i}.tp"], data[f"{i}.fp"], data[f"{i}.positives"])  # checks the shapes
    activities, answered = np.asarray(data[f"{i}.activities"]), np.asarray(data[f"{i}.answered"])
    if counts.thresholds != thresholds or counts.n != ids.size or activities.shape != ids.shape or answered.dtype != bool:
        raise ValueError("statistics of another shape")
    if ids.size and np.any(np.diff(ids) <= 0):
        raise ValueError("frame ids out of order")
    return FrameStats(ids, activities.astype(str), counts, answered.reshape(ids.shape))


def forget_participant(participant_id: int) -> int:
    """Delete the cached statistics of a participant's maps (they withdrew); returns how many files went."""
    paths = list((Path(current_app.config["CACHE_ROOT"]) / "scores").glob(f"participant{participant_id}-*.npz"))
    for path in paths:
        path.unlink(missing_ok=True)
    return len(paths)
