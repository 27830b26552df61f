"""Per-frame scores: every frame of one activity with each row's own best F and AP on it.

Read from the same cached per-frame counts as the table
(``report.load_sources``); each frame's scores are
``egonet.metrics.frame_scores``: its own precision-recall curve, its best F
(at its own best threshold) and its AP, the numbers the ``ois-mean``
convention averages. A frame without action-object pixels scores as the
``empty`` policy says (none under ``leave-out``: it is marked, not scored).
With ``frames="shared"`` the frames are those every row has in the
activity, as in the table; with ``"each"`` every frame some row has, blank
where a row has not got it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import reduce

import numpy as np

from app.extensions import db
from app.models import Frame
from app.models import Sequence as FrameSequence
from app.services.scoring.report import load_sources
from app.services.scoring.rows import ScoringProblem
from app.services.scoring.cells import HUMAN
from app.services.studies.codebook import PER_FRAME
from app.spreadsheet import csv_text
from egonet.metrics import DEFAULT_EMPTY, DEFAULT_THRESHOLDS, frame_scores, threshold_values
from egonet.metrics.frames import check_empty


@dataclass(frozen=True)
class FrameLine:
    """One frame: its id, where it is, and each row's (best F, its threshold, AP) on it (None: the row has not got it).

    A frame without action-object pixels (``no_truth``) left out by the
    ``leave-out`` policy has ``(None, None, None)``.
    """

    frame_id: int
    label: str
    scores: dict[str, tuple[float | None, float | None, float | None] | None]
    answered: dict[str, bool] = field(default_factory=dict)  # people: False for an unanswered trial
    truth_pixels: int = 0  # the ground truth's action-object pixels, at the native size

    @property
    def no_truth(self) -> bool:
        return self.truth_pixels == 0


@dataclass
class FrameTable:
    """The per-frame scores of one activity, rows as in the table (a group's runs each on their own)."""

    activity: str | None
    activities: list[str]
    rows: list[tuple[str, str, str]]  # (key, name, kind)
    lines: list[FrameLine]
    frames: str = "shared"
    sort: str | None = None
    empty: str = DEFAULT_EMPTY

    def to_csv(self) -> str:
        """One line per frame: its id and label, its number of action-object pixels, then each row's best F, threshold and AP."""
        header = list(PER_FRAME.columns)
        for key, _, _ in self.rows:
            header += [pattern.replace("<row>", key) for pattern in PER_FRAME.patterns]
        lines = []
        for line in self.lines:
            values: list[object] = [line.frame_id, line.label, self.activity, line.truth_pixels, self.empty]
            for key, _, _ in self.rows:
                got = line.scores.get(key) or (None, None, None)
                values += [_fixed(got[0], 4), _fixed(got[1], 2), _fixed(got[2], 4)]
            lines.append(values)
        return csv_text(lines, header=header)


def _fixed(value: float | None, digits: int) -> str:
    return "" if value is None else f"{value:.{digits}f}"


def frame_table(
    *,
    run_ids: Sequence[int] | None = None,
    study_ids: Sequence[int] | None = None,
    baselines: bool = True,
    activity: str | None = None,
    frames: str = "shared",
    answered_only: bool = False,
    sort: str | None = None,
    thresholds: int = DEFAULT_THRESHOLDS,
    empty: str = DEFAULT_EMPTY,
    fit_in_worker: bool = False,
    trained_on: Sequence[str] | None = None,
    columns: str = "activities",
) -> FrameTable:
    """Every frame of one activity with each chosen row's own scores on it.

    Args:
        run_ids, study_ids, baselines, answered_only, thresholds, fit_in_worker, trained_on, columns: As ``build_report``.
        activity: The activity; None: the first one some row has.
        frames: ``"shared"`` or ``"each"`` (see the module).
        sort: A row key: frames by that row's best F, lowest first (where a
            model fails); None: by frame id.
        empty: How a frame without action-object pixels scores (``egonet.metrics.EMPTY_POLICIES``).

    Raises:
        ScoringProblem: naming ``activity``, ``frames`` or ``sort``, or as ``build_report``.
        EgonetError: naming ``empty`` (a 400 like the others).
    """
    if frames not in ("shared", "each"):
        raise ScoringProblem(f"frames must be shared or each, got {frames!r}", field="frames")
    check_empty(empty)

    found, _ = load_sources(
        run_ids=run_ids, study_ids=study_ids, baselines=baselines, thresholds=thresholds, answered_only=answered_only,
        fit_in_worker=fit_in_worker, trained_on=trained_on, columns=columns,
    )
    by_activity = [(source, source.stats.by_activity()) for source in found]
    activities = sorted({a for _, own in by_activity for a in own})
    if activity is None and activities:
        activity = activities[0]
    if activity is not None and activity not in activities:
        raise ScoringProblem(f"activity: no row has frames of {activity!r} (activities: {', '.join(activities) or 'none'})", field="activity")
    if sort is not None and sort not in {s.key for s in found}:
        raise ScoringProblem(f"sort: there is no row {sort!r} in this table", field="sort")
    having = [(source, own[activity]) for source, own in by_activity if activity in own]
    combine = np.intersect1d if frames == "shared" else np.union1d
    ids = reduce(combine, [f for _, f in having]) if having else np.zeros(0, np.int64)
    t = threshold_values(thresholds)
    scores: dict[str, dict[int, tuple[float | None, float | None, float | None]]] = {}
    answered: dict[str, dict[int, bool]] = {}
    truth_pixels: dict[int, int] = {}
    for source, own in having:
        mine = np.intersect1d(ids, own)
        counts = source.stats.select(mine)
        own_scores = frame_scores(counts, empty=empty)
        truth_pixels.update(zip(mine.tolist(), counts.positives.tolist(), strict=True))
        human = source.kind == HUMAN
        scores[source.key] = {
            int(fid): (float(f), float(t[b]), None if human else float(ap)) if kept else (None, None, None)
            for fid, f, b, ap, kept in zip(mine, own_scores["max_f"], own_scores["best"], own_scores["ap"], own_scores["counted"], strict=True)
        }
        if human:
            flags = source.stats.answered[np.searchsorted(source.stats.ids, mine)]
            answered[source.key] = dict(zip(mine.tolist(), flags.tolist(), strict=True))
    labels = _labels(ids.tolist())
    lines = [
        FrameLine(
            fid,
            labels.get(fid, f"frame {fid}"),
            {key: s.get(fid) for key, s in scores.items()},
            {key: a[fid] for key, a in answered.items() if fid in a},
            int(truth_pixels.get(fid, 0)),
        )
        for fid in ids.tolist()
    ]
    if sort is not None:
        best_f = {line.frame_id: (line.scores.get(sort) or (None,))[0] for line in lines}
        lines.sort(key=lambda line: (best_f[line.frame_id] is None, best_f[line.frame_id] or 0.0, line.frame_id))
    rows = [(s.key, s.name, s.kind) for s, _ in having]
    return FrameTable(activity, activities, rows, lines, frames=frames, sort=sort, empty=empty)


def _labels(frame_ids: list[int]) -> dict[int, str]:
    """``sequence #index`` of each frame."""
    labels = {}
    for start in range(0, len(frame_ids), 5000):  # keep IN lists well under SQLite's variable limit
        chunk = frame_ids[start : start + 5000]
        for fid, sequence, index in db.session.execute(
            db.select(Frame.id, FrameSequence.name, Frame.index).join(FrameSequence, Frame.sequence).where(Frame.id.in_(chunk))
        ):
            labels[fid] = f"{sequence} #{index}"
    return labels
