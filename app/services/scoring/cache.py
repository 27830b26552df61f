"""The score cache: each job's sufficient statistics as JSON under ``CACHE_ROOT/scores/``.

A job (a run, the baselines, a participant) is scored into one
``ScoreAccumulator`` per activity; its statistics (per-threshold TP/FP/FN
and per-map curve sums, ``ScoreAccumulator.state``) are written to a file
named by a hash of everything the job depends on, so a later report with
the same inputs reads them back instead of scoring again, in pooled or
per-image mode alike. A file that cannot be read is scored again.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any

import numpy as np
from flask import current_app

from app.services import media
from egonet.metrics import ScoreAccumulator

# Bump when scoring changes in a way that makes cached statistics wrong.
SCORER_VERSION = 1

Stats = dict[str, ScoreAccumulator]
"""One accumulator per activity."""


def cache_path(key: dict[str, Any]) -> Path:
    """Where the statistics of a job with this key live."""
    digest = hashlib.sha256(json.dumps({"scorer": SCORER_VERSION, **key}, sort_keys=True).encode()).hexdigest()
    return Path(current_app.config["CACHE_ROOT"]) / "scores" / f"{digest}.json"


def read_cached(path: Path, thresholds: int) -> tuple[dict[str, Stats], list[str]] | None:
    """A job's statistics by name and its notes, or None when missing or unreadable (score again)."""
    try:
        data = json.loads(path.read_text())
        return {name: _load(s, thresholds) for name, s in data["stats"].items()}, list(data["notes"])
    except (OSError, ValueError, KeyError, TypeError):
        return None


def write_cached(path: Path, stats: dict[str, Stats], notes: list[str]) -> None:
    """Store a job's statistics and notes (atomically: a reader never sees half a file)."""
    data = json.dumps({"stats": {name: _dump(s) for name, s in stats.items()}, "notes": notes})
    media.write_atomic(path, data.encode())


def _dump(stats: Stats) -> dict[str, Any]:
    return {
        activity: {key: value.tolist() if isinstance(value, np.ndarray) else value for key, value in acc.state().items()}
        for activity, acc in stats.items()
    }


def _load(data: dict[str, Any], thresholds: int) -> Stats:
    # EgonetError (a ValueError) when the statistics have another number of thresholds.
    return {activity: ScoreAccumulator.from_state(state, thresholds=thresholds) for activity, state in data.items()}
