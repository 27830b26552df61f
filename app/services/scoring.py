"""The score table (the paper's Table 2 for this project's data): MF and AP per activity.

Rows, in this order:

* **models**: each completed training run (``app.services.training``),
  scored on its held-out predictions only (the activity left out in each
  leave-one-activity-out fold, or the test split of a single split);
* **baselines** (``egonet.baselines``), scored on every labelled frame:
  the Action-Object Prior "AOP", fitted inside each leave-one-activity-out
  fold (the frames of activity A are scored with the mean ground-truth mask
  of the labelled frames of every *other* activity), the "centre prior" and
  bottom-up "saliency" (spectral residual);
* **people**: each participant of the chosen studies, scored on exactly the
  frames they saw and answered, their click soft masks against the same
  ground truth; MF only, as in the paper (AP says little about near-binary
  maps).

Columns are the activities and their mean. Every cell holds MF, AP and the
number of frames scored. The metric is ``egonet.metrics`` (see
:data:`DEFINITION`): by default pixel counts are pooled over all the frames
of the activity at 99 thresholds ``k / 100``. The **mean** column is the
unweighted mean of a row's per-activity values, over the activities the row
has frames in (marked with ``*`` when that is not every column). Each row
also keeps the curve pooled over all its frames, for the overall
precision-recall plot.

Ground truth is each frame's finished annotation
(``app.services.ground_truth``). Computing a row streams its maps through
one ``ScoreAccumulator`` per activity and stores the accumulators' sufficient
statistics (per-threshold TP/FP/FN and per-map curve sums) as JSON under
``CACHE_ROOT/scores/``, named by a hash of everything the row depends on
(the ground-truth annotations' ids, versions and update times, the run or the
participant's answers, the number of thresholds, the scorer's version). A
later report with the same inputs reads the statistics back instead of
scoring again, in pooled or per-image mode alike.
"""

from __future__ import annotations

import csv
import hashlib
import io as _io
import json
from collections import defaultdict
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
from flask import current_app
from sqlalchemy import func

from app.errors import Problem
from app.extensions import db
from app.models import Activity, Annotation, Frame
from app.models import Sequence as FrameSequence
from app.models.studies import ANSWERED, Participant, Study, Trial
from app.models.training import Prediction, TrainingRun
from app.services import ground_truth, media, training
from app.services import studies as studies_service
from egonet import io
from egonet.baselines import ActionObjectPrior, CenterPrior, SpectralResidualSaliency
from egonet.metrics import (
    DEFAULT_THRESHOLDS,
    Counts,
    ScoreAccumulator,
    threshold_values,
)

# Bump when scoring changes in a way that makes cached statistics wrong.
SCORER_VERSION = 1
ALL = "all"
"""The key of a row's curve pooled over all its frames."""

MODEL, BASELINE, HUMAN = "model", "baseline", "human"
KIND_TITLES = {MODEL: "Models", BASELINE: "Baselines", HUMAN: "People (MF only)"}

# Baseline keys, names and the predictors' settings (part of the cache key).
BASELINE_NAMES = {"aop": "AOP", "center": "centre prior", "saliency": "saliency"}
AOP_SIZE = (60, 80)
CENTER_SIGMA = 0.25
SALIENCY = {"width": 64, "blur_sigma": 2.5}

DEFINITION = (
    "MF is the maximum F-score, F = 2PR / (P + R), and AP the average precision, sum over k of "
    "(R_k - R_{k+1}) P_k, over the thresholds t_k = k / (T + 1), k = 1..T (T = 99: 0.01 .. 0.99), "
    "a pixel being positive when its probability is >= t_k (maps are never normalised). "
    "P = TP / (TP + FP) (1 when nothing is predicted) and R = TP / (TP + FN), with the pixel "
    "counts pooled over all the frames of an activity (per-image mode: P and R averaged over "
    "frames instead). Models are scored on held-out frames only; AOP is the mean ground-truth "
    "mask of the other activities' labelled frames (leave-one-activity-out); people on the "
    "frames they answered, with MF only. The mean column is the unweighted mean of the "
    "per-activity values."
)

# Line colours of the precision-recall plots, one per row in table order.
PALETTE = ("#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2", "#17becf", "#bcbd22", "#7f7f7f")


class ScoringProblem(Problem):
    """A score request that cannot go ahead; ``field`` names the bad input."""


# --------------------------------------------------------------------------
# The report


@dataclass(frozen=True)
class Cell:
    """One (row, activity) result; ``ap`` is None for people."""

    max_f: float
    ap: float | None
    n_frames: int


@dataclass(frozen=True)
class Curve:
    """A precision-recall curve over increasing thresholds, and where F is largest."""

    precision: tuple[float, ...]
    recall: tuple[float, ...]
    best: int


@dataclass
class Row:
    """One line of the table: a run, a baseline or a participant.

    Attributes:
        key: Stable identifier (``run:3``, ``baseline:aop``, ``participant:12``).
        name: Shown in the table (``egonet-lite (run 3)``, ``AOP``, ``P01``).
        kind: ``model``, ``baseline`` or ``human``.
        detail: A longer description (run name and folds, study name).
        cells: Results by activity name.
        overall: The result pooled over every frame of the row.
        curves: Curves by activity name, and :data:`ALL` for the pooled one.
    """

    key: str
    name: str
    kind: str
    detail: str
    cells: dict[str, Cell]
    overall: Cell
    curves: dict[str, Curve]

    def mean(self) -> tuple[float | None, float | None]:
        """The unweighted mean of the per-activity MF and AP (None without cells or, for AP, for people)."""
        if not self.cells:
            return None, None
        mf = float(np.mean([c.max_f for c in self.cells.values()]))
        aps = [c.ap for c in self.cells.values()]
        ap = float(np.mean(aps)) if all(a is not None for a in aps) else None
        return mf, ap


@dataclass
class Report:
    """The score table: rows (models, baselines, people) by activity columns and their mean.

    Attributes:
        activities: Column names, the activities any row has frames in.
        rows: In table order: models, baselines, people.
        thresholds: The number T of thresholds ``k / (T + 1)``.
        per_image: Whether P and R are averaged over frames instead of pooled.
        notes: Things a reader should know (frames left out, rows without frames).
    """

    activities: list[str]
    rows: list[Row]
    thresholds: int = DEFAULT_THRESHOLDS
    per_image: bool = False
    notes: list[str] = field(default_factory=list)

    # -- values the renderers share --------------------------------------------

    def columns(self) -> list[str]:
        """The activity columns and ``mean``."""
        return [*self.activities, "mean"]

    def value(self, row: Row, column: str, metric: str) -> float | None:
        """MF (``metric="mf"``) or AP (``"ap"``) of a row in an activity column or ``mean``."""
        if column == "mean":
            mf, ap = row.mean()
            return mf if metric == "mf" else ap
        cell = row.cells.get(column)
        if cell is None:
            return None
        return cell.max_f if metric == "mf" else cell.ap

    def complete(self, row: Row) -> bool:
        """Whether the row has frames in every activity column (else its mean is marked ``*``)."""
        return set(self.activities) <= set(row.cells)

    def partial_means(self) -> bool:
        """Whether some row's mean covers fewer activities than the table has."""
        return any(row.cells and not self.complete(row) for row in self.rows)

    def best(self) -> dict[tuple[str, str], float]:
        """The best value, rounded to 3 decimals as shown, of each (column, metric)."""
        best: dict[tuple[str, str], float] = {}
        for column in self.columns():
            for metric in ("mf", "ap"):
                values = [v for row in self.rows if (v := self.value(row, column, metric)) is not None]
                if values:
                    best[column, metric] = round(max(values), 3)
        return best

    def colour(self, row: Row) -> str:
        return PALETTE[self.rows.index(row) % len(PALETTE)]

    def groups(self) -> list[tuple[str, list[Row]]]:
        """The rows grouped by kind, with the group titles, in table order."""
        out = []
        for kind in (MODEL, BASELINE, HUMAN):
            rows = [r for r in self.rows if r.kind == kind]
            if rows:
                out.append((KIND_TITLES[kind], rows))
        return out

    def mode(self) -> str:
        return "per-image" if self.per_image else "pooled"

    # -- renderers -------------------------------------------------------------

    def to_table(self) -> str:
        """A plain-text table: activities as column pairs (MF, AP), then the mean."""
        name_width = max([len("method"), *(len(r.name) for r in self.rows)]) + 2
        head1 = " " * name_width + "".join(f"{_clip(c, 14):<15}" for c in self.columns())
        head2 = f"{'method':<{name_width}}" + "MF     AP      " * len(self.columns())
        lines = [head1.rstrip(), head2.rstrip()]
        for title, rows in self.groups():
            lines.append(f"-- {title}")
            for row in rows:
                cells = []
                for column in self.columns():
                    mf, ap = self.value(row, column, "mf"), self.value(row, column, "ap")
                    star = "*" if column == "mean" and not self.complete(row) and row.cells else " "
                    cells.append(f"{_fmt(mf):<7}{_fmt(ap)}{star}".ljust(15))
                lines.append(f"{row.name:<{name_width}}" + "".join(cells).rstrip())
        if not self.rows:
            lines.append("(nothing to score: no completed runs, labelled frames or answered trials)")
        lines.append("")
        lines.append(f"{self.thresholds} thresholds, {self.mode()} counts; mean = unweighted mean of the per-activity values.")
        if self.partial_means():
            lines.append("* mean over the activities that row has frames in.")
        lines += self.notes
        return "\n".join(lines) + "\n"

    def to_csv(self) -> str:
        """One line per row: kind, name, then MF, AP and frames of each activity, then the mean MF and AP."""
        out = _io.StringIO()
        writer = csv.writer(out, lineterminator="\n")
        header = ["method", "kind"]
        for activity in self.activities:
            header += [f"{activity} MF", f"{activity} AP", f"{activity} frames"]
        header += ["mean MF", "mean AP", "mean over activities"]
        writer.writerow(header)
        for row in self.rows:
            line: list[Any] = [row.name, row.kind]
            for activity in self.activities:
                cell = row.cells.get(activity)
                line += [_num(cell and cell.max_f), _num(cell and cell.ap), cell.n_frames if cell else ""]
            mf, ap = row.mean()
            writer.writerow([*line, _num(mf), _num(ap), len(row.cells)])
        return out.getvalue()

    def to_latex(self) -> str:
        """A booktabs tabular like the paper's Table 2: MF/AP pairs per activity, the best of each column in bold."""
        columns = self.columns()
        best = self.best()
        lines = [
            f"% Score table from EgoNet Studio: {self.thresholds} thresholds, {self.mode()} counts;",
            "% mean = unweighted mean of the per-activity values. Needs \\usepackage{booktabs}.",
            "\\begin{tabular}{l" + "cc" * len(columns) + "}",
            "\\toprule",
            " & ".join(["", *(f"\\multicolumn{{2}}{{c}}{{{_tex(c)}}}" for c in columns)]) + " \\\\",
            "".join(f"\\cmidrule(lr){{{2 + 2 * i}-{3 + 2 * i}}}" for i in range(len(columns))),
            " & ".join(["Method", *(["MF", "AP"] * len(columns))]) + " \\\\",
        ]
        for title, rows in self.groups():
            lines.append("\\midrule")
            for row in rows:
                values = []
                for column in columns:
                    for metric in ("mf", "ap"):
                        v = self.value(row, column, metric)
                        text = "--" if v is None else f"{v:.3f}"
                        if v is not None and round(v, 3) == best.get((column, metric)):
                            text = f"\\textbf{{{text}}}"
                        if column == "mean" and metric == "mf" and row.cells and not self.complete(row):
                            text += "$^*$"
                        values.append(text)
                lines.append(" & ".join([_tex(row.name), *values]) + " \\\\")
        lines += ["\\bottomrule", "\\end{tabular}"]
        return "\n".join(lines) + "\n"

    def to_json(self) -> str:
        """Everything, curves included, as a JSON document."""
        return json.dumps(self.as_dict(), indent=1) + "\n"

    def as_dict(self) -> dict[str, Any]:
        def cell(c: Cell) -> dict[str, Any]:
            return {"max_f": c.max_f, "ap": c.ap, "n_frames": c.n_frames}

        rows = []
        for row in self.rows:
            mf, ap = row.mean()
            rows.append(
                {
                    "key": row.key,
                    "name": row.name,
                    "kind": row.kind,
                    "detail": row.detail,
                    "cells": {a: cell(c) for a, c in row.cells.items()},
                    "mean": {"max_f": mf, "ap": ap, "activities": len(row.cells)},
                    ALL: cell(row.overall),
                    "curves": {
                        k: {"precision": list(c.precision), "recall": list(c.recall), "best": c.best} for k, c in row.curves.items()
                    },
                }
            )
        return {
            "definition": DEFINITION,
            "thresholds": self.thresholds,
            "threshold_values": threshold_values(self.thresholds).tolist(),
            "per_image": self.per_image,
            "activities": self.activities,
            "rows": rows,
            "notes": self.notes,
        }


def _fmt(value: float | None) -> str:
    return "-" if value is None else f"{value:.3f}"


def _num(value: float | None) -> str:
    return "" if value is None else f"{value:.4f}"


def _clip(text: str, width: int) -> str:
    return text if len(text) <= width else text[: width - 1] + "~"


_TEX = {
    "\\": r"\textbackslash{}", "&": r"\&", "%": r"\%", "$": r"\$", "#": r"\#", "_": r"\_", "{": r"\{", "}": r"\}",
    "~": r"\textasciitilde{}", "^": r"\textasciicircum{}",
}  # fmt: skip


def _tex(text: str) -> str:
    return "".join(_TEX.get(ch, ch) for ch in text)


# --------------------------------------------------------------------------
# Precision-recall plots (drawn as inline SVG by the Scores page)


@dataclass(frozen=True)
class PlotLine:
    name: str
    colour: str
    dashed: bool
    points: str  # SVG polyline points, "x,y x,y ..."
    best_x: float
    best_y: float
    best_label: str


@dataclass(frozen=True)
class Plot:
    """One precision-recall plot: recall on x, precision on y, both 0..1, in SVG pixels."""

    key: str
    title: str
    width: int
    height: int
    left: int
    top: int
    size_x: int
    size_y: int
    lines: list[PlotLine]
    iso_f: list[tuple[str, str]]  # (points, label) of the iso-F curves
    ticks: list[tuple[float, str]]  # (fraction, label) on both axes


PLOT_MARGIN = (36, 10, 12, 34)  # left, top, right, bottom


def pr_plot(report: Report, key: str, *, width: int = 300, height: int = 270) -> Plot:
    """The precision-recall curves of every row for one activity (or :data:`ALL`).

    Each row's curve is drawn through its (recall, precision) points in
    threshold order; a dot marks its best F. People's lines are dashed.
    Faint iso-F curves (F = 0.2 .. 0.8) help read the plot.
    """
    left, top, right, bottom = PLOT_MARGIN
    sx, sy = width - left - right, height - top - bottom

    def xy(r: float, p: float) -> tuple[float, float]:
        return round(left + r * sx, 1), round(top + (1 - p) * sy, 1)

    lines = []
    for row in report.rows:
        curve = row.curves.get(key)
        if curve is None:
            continue
        pts = [xy(r, p) for r, p in zip(curve.recall, curve.precision, strict=True)]
        bx, by = pts[curve.best]
        cell = row.overall if key == ALL else row.cells[key]
        lines.append(
            PlotLine(
                name=row.name,
                colour=report.colour(row),
                dashed=row.kind == HUMAN,
                points=" ".join(f"{x},{y}" for x, y in pts),
                best_x=bx,
                best_y=by,
                best_label=f"{row.name}: MF {cell.max_f:.3f} at t = {threshold_values(report.thresholds)[curve.best]:.2f}",
            )
        )
    iso = []
    for f in (0.2, 0.4, 0.6, 0.8):
        recalls = np.linspace(f / (2 - f), 1.0, 40)  # P = fR / (2R - f) is in [0, 1] from R = f / (2 - f)
        pts = [xy(r, f * r / (2 * r - f)) for r in recalls]
        iso.append((" ".join(f"{x},{y}" for x, y in pts), f"F={f:.1f}"))
    title = "All activities (pooled)" if key == ALL else key
    ticks = [(t, f"{t:g}") for t in (0.0, 0.25, 0.5, 0.75, 1.0)]
    return Plot(key, title, width, height, left, top, sx, sy, lines, iso, ticks)


# --------------------------------------------------------------------------
# Choosing what to score


def available_runs() -> list[TrainingRun]:
    """Completed training runs, newest first."""
    return training.completed_runs()


def available_studies() -> list[tuple[Study, int]]:
    """Every study with its number of participants, newest first."""
    counts = dict(db.session.execute(db.select(Participant.study_id, func.count()).group_by(Participant.study_id)).all())
    chosen = db.session.execute(db.select(Study).order_by(Study.created_at.desc(), Study.id.desc())).scalars()
    return [(s, counts.get(s.id, 0)) for s in chosen]


def _choose_runs(run_ids: Sequence[int] | None) -> list[TrainingRun]:
    runs = available_runs()
    if run_ids is None:
        return runs
    by_id = {run.id: run for run in runs}
    unknown = [i for i in run_ids if i not in by_id]
    if unknown:
        raise ScoringProblem(f"run {unknown[0]} is not a completed training run", field="runs")
    return [by_id[i] for i in dict.fromkeys(run_ids)]


def _choose_studies(study_ids: Sequence[int] | None) -> list[int]:
    if study_ids is None:
        return list(db.session.execute(db.select(Study.id).order_by(Study.id)).scalars())
    wanted = list(dict.fromkeys(study_ids))
    known = set(db.session.execute(db.select(Study.id).where(Study.id.in_(wanted))).scalars())
    unknown = [i for i in wanted if i not in known]
    if unknown:
        raise ScoringProblem(f"study {unknown[0]} does not exist", field="studies")
    return wanted


# --------------------------------------------------------------------------
# Ground truth, loaded once per report


@dataclass
class _Truth:
    frames: list[Frame]
    annotations: dict[int, Annotation]
    activity: dict[int, str]  # frame id -> activity name
    fingerprint: str

    def mask(self, frame_id: int) -> np.ndarray | None:
        annotation = self.annotations.get(frame_id)
        return ground_truth.mask_of(annotation) if annotation is not None else None


def _load_truth() -> _Truth:
    frames = ground_truth.labelled_frames()
    ids = [f.id for f in frames]
    annotations: dict[int, Annotation] = {}
    for start in range(0, len(ids), 5000):  # keep IN lists well under SQLite's variable limit
        annotations.update(ground_truth.ground_truths(ids[start : start + 5000]))
    names = dict(
        db.session.execute(
            db.select(Frame.id, Activity.name)
            .select_from(Frame)
            .join(FrameSequence, Frame.sequence)
            .join(Activity, FrameSequence.activity)
            .where(Frame.id.in_(db.select(Annotation.frame_id)))
        ).all()
    )
    digest = hashlib.sha256()
    for fid in sorted(annotations):
        a = annotations[fid]
        digest.update(f"{fid}:{a.id}:{a.version}:{a.mask_path}:{a.updated_at.isoformat()};".encode())
    return _Truth(frames, annotations, {f.id: names[f.id] for f in frames}, digest.hexdigest())


# --------------------------------------------------------------------------
# Sufficient statistics: one accumulator per activity, cached as JSON

Stats = dict[str, ScoreAccumulator]


def _dump(stats: Stats) -> dict[str, Any]:
    return {
        activity: {
            "tp": acc.counts.tp.tolist(),
            "fp": acc.counts.fp.tolist(),
            "fn": acc.counts.fn.tolist(),
            "precision_sum": acc.precision_sum.tolist(),
            "recall_sum": acc.recall_sum.tolist(),
            "n_maps": acc.n_maps,
        }
        for activity, acc in stats.items()
    }


def _load(data: dict[str, Any], thresholds: int) -> Stats:
    stats = {}
    for activity, d in data.items():
        acc = ScoreAccumulator(thresholds=thresholds)
        acc.counts = Counts(*(np.array(d[k], dtype=np.int64) for k in ("tp", "fp", "fn")))
        acc.precision_sum = np.array(d["precision_sum"], dtype=np.float64)
        acc.recall_sum = np.array(d["recall_sum"], dtype=np.float64)
        acc.n_maps = int(d["n_maps"])
        if any(a.shape != (thresholds,) for a in (*acc.counts, acc.precision_sum, acc.recall_sum)):
            raise ValueError("cached statistics have the wrong number of thresholds")
        stats[activity] = acc
    return stats


def _cache_path(key: dict[str, Any]) -> Path:
    digest = hashlib.sha256(json.dumps({"scorer": SCORER_VERSION, **key}, sort_keys=True).encode()).hexdigest()
    return Path(current_app.config["CACHE_ROOT"]) / "scores" / f"{digest}.json"


def _read_cache(path: Path, thresholds: int) -> tuple[dict[str, Stats], list[str]] | None:
    try:
        data = json.loads(path.read_text())
        return {name: _load(s, thresholds) for name, s in data["stats"].items()}, list(data["notes"])
    except (OSError, ValueError, KeyError, TypeError):
        return None  # missing or unreadable: score again


def _write_cache(path: Path, stats: dict[str, Stats], notes: list[str]) -> None:
    data = json.dumps({"stats": {name: _dump(s) for name, s in stats.items()}, "notes": notes})
    media.write_atomic(path, data.encode())


def _accumulate(
    pairs: Iterable[tuple[Frame, np.ndarray]], truth: _Truth, thresholds: int, on_progress: Callable[[int], None]
) -> tuple[Stats, int]:
    """Score (frame, map) pairs per activity; return the stats and how many frames had no ground truth."""
    stats: Stats = {}
    missing = 0
    for frame, prob in pairs:
        mask = truth.mask(frame.id)
        if mask is None:
            missing += 1
            continue
        activity = truth.activity[frame.id]
        acc = stats.setdefault(activity, ScoreAccumulator(thresholds=thresholds))
        acc.add(prob, mask, name=f"prob of frame {frame.id}")
        on_progress(1)
    return stats, missing


# --------------------------------------------------------------------------
# The three sources


def _run_stats(run: TrainingRun, truth: _Truth, thresholds: int, on_progress) -> tuple[dict[str, Stats], list[str]]:
    stats, missing = _accumulate(training.held_out_predictions(run), truth, thresholds, on_progress)
    notes = [f"run {run.id}: {missing} held-out frames no longer have a ground truth and were left out."] if missing else []
    return {"": stats}, notes


def _participant_stats(participant: Participant, truth: _Truth, thresholds: int, on_progress) -> tuple[dict[str, Stats], list[str]]:
    stats, missing = _accumulate(studies_service.participant_soft_masks(participant), truth, thresholds, on_progress)
    label = f"{participant.label} of study {participant.study_id}"
    notes = [f"{label}: {missing} answered frames no longer have a ground truth and were left out."] if missing else []
    return {"": stats}, notes


def aop_fold_priors(truth_masks: dict[str, Iterable[np.ndarray]]) -> dict[str, ActionObjectPrior | None]:
    """The AOP of each leave-one-activity-out fold: the mean mask of the *other* activities.

    Each activity's masks are averaged once (``ActionObjectPrior.fit``, on
    its fixed grid); the prior of the fold that tests activity A is the
    frame-weighted mean of the other activities' means, which is the mean of
    their masks, without reading every mask once per fold.

    Args:
        truth_masks: Each activity's ground-truth masks, bool (H, W) each.

    Returns:
        The prior by activity; None for an activity when no other activity
        has labelled frames.
    """
    fitted = {}
    for activity, masks in truth_masks.items():
        counted = _Counted(masks)
        fitted[activity] = (ActionObjectPrior.fit(counted, size=AOP_SIZE).prior.astype(np.float64), counted.n)
    priors: dict[str, ActionObjectPrior | None] = {}
    for activity in fitted:
        others = [(p, n) for a, (p, n) in fitted.items() if a != activity]
        total = sum(n for _, n in others)
        priors[activity] = ActionObjectPrior(sum(p * n for p, n in others) / total) if total else None
    return priors


class _Counted:
    """An iterable that counts what it yields (how many masks a fit averaged)."""

    def __init__(self, items: Iterable[np.ndarray]):
        self.items = items
        self.n = 0

    def __iter__(self) -> Iterator[np.ndarray]:
        for item in self.items:
            self.n += 1
            yield item


def _baseline_stats(truth: _Truth, thresholds: int, on_progress) -> tuple[dict[str, Stats], list[str]]:
    """Score the three baselines on every labelled frame, activity by activity (one pass per frame)."""
    by_activity: dict[str, list[Frame]] = defaultdict(list)
    for frame in truth.frames:
        by_activity[truth.activity[frame.id]].append(frame)

    def masks_of(frames: list[Frame]) -> Iterator[np.ndarray]:
        for frame in frames:
            yield truth.mask(frame.id)
            on_progress(1)

    folds = aop_fold_priors({a: masks_of(frames) for a, frames in by_activity.items()})
    centre = CenterPrior(sigma=CENTER_SIGMA)
    saliency = SpectralResidualSaliency(**SALIENCY)
    stats: dict[str, Stats] = {key: {} for key in BASELINE_NAMES}
    notes = []
    for activity, frames in by_activity.items():
        predictors = {"aop": folds[activity], "center": centre, "saliency": saliency}
        if folds[activity] is None:
            del predictors["aop"]
            notes.append(f"AOP: no other activity has labelled frames to fit the prior for {activity}.")
        for frame in frames:
            mask = truth.mask(frame.id)
            rgb = io.read_image(media.absolute_path(frame.rgb_path))
            for key, predictor in predictors.items():
                acc = stats[key].setdefault(activity, ScoreAccumulator(thresholds=thresholds))
                acc.add(predictor.predict(rgb, None), mask, name=f"prob of frame {frame.id}")
            on_progress(1)
    return stats, notes


# --------------------------------------------------------------------------
# Building the report


class _RowSpec(NamedTuple):
    key: str
    stats: str  # which of the job's statistics the row shows
    name: str
    kind: str
    detail: str


@dataclass
class _Job:
    """Rows that are scored in one pass, their cache key and how to score them."""

    rows: list[_RowSpec]
    cache_key: dict[str, Any]
    frames: int  # frames it will score, for progress (0 when unknown)
    score: Callable[[Callable[[int], None]], tuple[dict[str, Stats], list[str]]]


def build_report(
    *,
    run_ids: Sequence[int] | None = None,
    study_ids: Sequence[int] | None = None,
    baselines: bool = True,
    thresholds: int = DEFAULT_THRESHOLDS,
    per_image: bool = False,
    use_cache: bool = True,
    on_start: Callable[[int], None] | None = None,
    on_progress: Callable[[int], None] | None = None,
) -> Report:
    """Score the chosen runs, the baselines and the chosen studies' participants.

    Args:
        run_ids: Completed training runs to include; None for all of them.
        study_ids: Studies whose participants to include; None for all.
        baselines: Include AOP, the centre prior and saliency.
        thresholds: The number T of thresholds ``k / (T + 1)``.
        per_image: Average P and R over frames instead of pooling counts.
        use_cache: Read statistics cached by an earlier report with the
            same inputs (they are written either way).
        on_start: Called once with the number of frames to score.
        on_progress: Called with the number of frames just scored.

    Returns:
        The :class:`Report`. A source whose maps cannot be scored (say, a
        run whose predictions do not match the frames' sizes) becomes a note
        instead of a row, so the other rows still show.

    Raises:
        ScoringProblem: naming ``runs``, ``studies`` or ``thresholds``.

    Example::

        report = build_report(run_ids=[3], study_ids=[1])
        print(report.to_table())
    """
    try:
        threshold_values(thresholds)
    except ValueError as exc:
        raise ScoringProblem(str(exc), field="thresholds") from None
    runs = _choose_runs(run_ids)
    chosen_studies = _choose_studies(study_ids)
    truth = _load_truth()
    notes: list[str] = []
    jobs = [_run_job(run, truth, thresholds) for run in runs]
    if baselines and truth.frames:
        jobs.append(_baseline_job(truth, thresholds))
    jobs += _participant_jobs(chosen_studies, truth, thresholds, notes)

    cached = [(_cache_path(job.cache_key), job) for job in jobs]
    cached = [(path, job, _read_cache(path, thresholds) if use_cache else None) for path, job in cached]
    if on_start is not None:
        on_start(sum(job.frames for _, job, got in cached if got is None))
    rows = []
    for path, job, got in cached:
        if got is None:
            try:
                got = job.score(on_progress or (lambda n: None))
            except ValueError as exc:  # a map or mask that egonet.metrics refuses
                notes.append(f"{job.rows[0].name} could not be scored: {exc}")
                continue
            _write_cache(path, *got)
        stats, job_notes = got
        notes += job_notes
        for spec in job.rows:
            if not stats.get(spec.stats):
                if not job_notes:  # else the job has said why
                    notes.append(f"{spec.name} has no frames with a ground truth to score.")
                continue
            rows.append(_row(spec, stats[spec.stats], per_image=per_image))
    activities = sorted({a for r in rows for a in r.cells})
    return Report(activities=activities, rows=rows, thresholds=thresholds, per_image=per_image, notes=notes)


def _run_job(run: TrainingRun, truth: _Truth, thresholds: int) -> _Job:
    # ``flask egonet predict`` may replace a run's held-out maps: they are part of the key.
    predictions = db.session.execute(
        db.select(func.count(), func.max(Prediction.id)).where(Prediction.run_id == run.id, Prediction.held_out.is_(True))
    ).one()
    return _Job(
        rows=[_RowSpec(f"run:{run.id}", "", f"{run.model_name} (run {run.id})", MODEL, f"{run.name}, {run.folds} folds")],
        cache_key={"run": run.id, "predictions": list(predictions), "truth": truth.fingerprint, "thresholds": thresholds},
        # Leave-one-activity-out holds every labelled frame out once.
        frames=len(truth.frames) if run.folds == "loao" else 0,
        score=lambda progress: _run_stats(run, truth, thresholds, progress),
    )


def _baseline_job(truth: _Truth, thresholds: int) -> _Job:
    return _Job(
        rows=[_RowSpec(f"baseline:{key}", key, name, BASELINE, "") for key, name in BASELINE_NAMES.items()],
        cache_key={
            "baselines": {"aop_size": AOP_SIZE, "center_sigma": CENTER_SIGMA, "saliency": SALIENCY},
            "truth": truth.fingerprint,
            "thresholds": thresholds,
        },
        frames=2 * len(truth.frames),  # the AOP pass, then the scoring pass
        score=lambda progress: _baseline_stats(truth, thresholds, progress),
    )


def _participant_jobs(study_ids: list[int], truth: _Truth, thresholds: int, notes: list[str]) -> list[_Job]:
    participants = studies_service.study_participants(study_ids)
    # Answers are never changed once given, so their number and the last
    # answered trial tell whether a participant's cached scores still hold.
    answered = {
        pid: (n, last)
        for pid, n, last in db.session.execute(
            db.select(Trial.participant_id, func.count(), func.max(Trial.id))
            .where(Trial.participant_id.in_([p.id for p in participants]), Trial.outcome.in_(ANSWERED))
            .group_by(Trial.participant_id)
        ).all()
    }
    jobs = []
    for person in participants:
        n, last = answered.get(person.id, (0, None))
        name = person.label if len(study_ids) == 1 else f"{person.label} (study {person.study_id})"
        if n == 0:
            notes.append(f"{name} has no answered trials yet.")
            continue
        jobs.append(
            _Job(
                rows=[_RowSpec(f"participant:{person.id}", "", name, HUMAN, f"{person.study.name}, participant {person.number}")],
                cache_key={"participant": person.id, "answered": [n, last], "truth": truth.fingerprint, "thresholds": thresholds},
                frames=n,
                score=lambda progress, person=person: _participant_stats(person, truth, thresholds, progress),
            )
        )
    return jobs


def _row(spec: _RowSpec, stats: Stats, *, per_image: bool) -> Row:
    def scored(acc: ScoreAccumulator) -> tuple[Cell, Curve]:
        s = acc.score(per_image=per_image)
        best = int(np.argmax(s.f))
        curve = Curve(tuple(np.round(s.precision, 5).tolist()), tuple(np.round(s.recall, 5).tolist()), best)
        return Cell(s.max_f, None if spec.kind == HUMAN else s.ap, s.n_maps), curve

    cells, curves = {}, {}
    pooled = ScoreAccumulator(thresholds=next(iter(stats.values())).thresholds)
    for activity in sorted(stats):
        cells[activity], curves[activity] = scored(stats[activity])
        pooled.merge(stats[activity])
    overall, curves[ALL] = scored(pooled)
    return Row(spec.key, spec.name, spec.kind, spec.detail, cells, overall, curves)
