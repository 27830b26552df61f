"""The score table itself: cells, curves, rows, the report and a paired comparison.

:class:`Report` holds the rows (models, baselines, people) by activity
columns and their mean, under one metric convention and one frame choice;
``formats`` writes it as plain text, CSV, LaTeX or JSON. Nothing here reads
the database: ``report`` fills it.
"""

from __future__ import annotations

import json
from collections import defaultdict
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from egonet.metrics import DEFAULT_RESAMPLES, DEFAULT_THRESHOLDS

ALL = "all"
"""The key of a row's result pooled over all its frames."""
MEAN = "mean"
"""The column of the unweighted mean over activities."""

MODEL, BASELINE, HUMAN = "model", "baseline", "human"
KIND_TITLES = {MODEL: "Models", BASELINE: "Baselines", HUMAN: "People (MF only)"}

FRAMES = {
    "shared": "each activity's frames that every row scored there has (their intersection)",
    "each": "all the frames each row has; best marked only among rows scored on the same frames",
}
"""The frame choices and what they mean."""

STATISTIC_LABELS = {
    "pooled": {"max_f": "MF", "ap": "AP"},
    "per-image": {"max_f": "mean F", "ap": "mean AP"},
    "ods-ois": {"max_f": "ODS", "ois": "OIS", "ap": "AP"},
}
"""Column labels of each convention's statistics, in the order they are shown."""

METRIC_TITLES = {
    "pooled": "Pooled: max F and AP of the pixel counts summed over all frames of an activity",
    "per-image": "Per image: the mean over frames of each frame's best F, and of each frame's AP",
    "ods-ois": "BSDS ODS / OIS: best F at one threshold for the activity (ODS), at each frame's own (OIS), and AP",
}

METRIC_SHORT = {"pooled": "pixels pooled per activity (default)", "per-image": "mean of each frame's best F", "ods-ois": "BSDS ODS / OIS"}
"""What the metric selector says beside each convention's name."""

METRIC_DEFINITIONS = {
    "pooled": (
        "MF is the maximum over thresholds of F = 2PR / (P + R) and AP the average precision, sum over k of "
        "(R_k - R_{k+1}) P_k, with P = TP / (TP + FP) (1 when nothing is predicted) and R = TP / (TP + FN) "
        "computed from the pixel counts summed over all the frames of the activity."
    ),
    "per-image": (
        "Each frame gets its own precision-recall curve; mean F is the mean over frames of each frame's best F "
        "(at its own best threshold) and mean AP the mean of the frames' APs. A frame without action-object "
        "pixels scores 0 in every row."
    ),
    "ods-ois": (
        "ODS (optimal dataset scale) is the best F at one threshold for all frames of the activity, from pooled "
        "counts (the pooled MF); OIS (optimal image scale) is F of the counts summed over frames each taken at "
        "its own best threshold (the highest on ties); AP is the pooled average precision."
    ),
}

COMMON_DEFINITION = (
    "Thresholds t_k = k / (T + 1), k = 1..T (T = 99: 0.01 .. 0.99), a pixel being positive when its probability "
    "is >= t_k (maps are never normalised). Models are scored on held-out frames only; AOP is the mean "
    "ground-truth mask of the other activities' labelled frames (leave-one-activity-out); people on the frames "
    "of their trials, MF only. The mean column is the unweighted mean of the per-activity values. 95% intervals: "
    "BCa bootstrap over frames, resampled within each activity."
)

# Line colours of the precision-recall plots, one per row in table order.
PALETTE = ("#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2", "#17becf", "#bcbd22", "#7f7f7f")


def definition(metric: str) -> str:
    """The full definition of a convention's numbers (for the page, the downloads and the JSON)."""
    return f"{METRIC_DEFINITIONS[metric]} {COMMON_DEFINITION}"


@dataclass(frozen=True)
class Cell:
    """One (row, column) result.

    Attributes:
        n_frames: Frames scored (0: the row has frames there, none shared).
        values: The convention's statistics (``max_f``, ``ap``, ``ois``);
            None for people's AP and where no frame was scored.
        ci: The 95 % interval of each statistic, None where the value is.
        sd: For a group of seeds, the standard deviation of each statistic
            across the seeds; None otherwise.
        frames_available: Frames the row has there (before the shared cut).
        frames_key: A fingerprint of the frames scored; cells with the same
            key were scored on the same frames.
        activities: For the mean, how many activities it averages.
    """

    n_frames: int
    values: Mapping[str, float | None] = field(default_factory=dict)
    ci: Mapping[str, tuple[float, float] | None] = field(default_factory=dict)
    sd: Mapping[str, float | None] | None = None
    frames_available: int = 0
    frames_key: str = ""
    activities: int = 1

    @property
    def max_f(self) -> float | None:
        return self.values.get("max_f")

    @property
    def ap(self) -> float | None:
        return self.values.get("ap")

    @property
    def no_shared_frames(self) -> bool:
        return self.n_frames == 0


@dataclass(frozen=True)
class Curve:
    """A pooled precision-recall curve over increasing thresholds, and where F is largest."""

    precision: tuple[float, ...]
    recall: tuple[float, ...]
    best: int


@dataclass
class Row:
    """One line of the table: a run, a group of runs that differ only in their seed, a baseline or a participant.

    Attributes:
        key: Stable identifier (``run:3``, ``seeds:3,5,7``, ``baseline:aop``, ``participant:12``).
        name: Shown in the table (``egonet-lite (run 3)``, ``AOP``, ``P01``).
        kind: ``model``, ``baseline`` or ``human``.
        detail: A longer description (run name and folds, study name).
        cells: Results by activity name.
        mean: The unweighted mean over the activities with a value (None without any).
        overall: The result on all the row's frames together (None without any).
        curves: Pooled curves by activity and :data:`ALL` (a group has none: its seeds do).
        unanswered: For a participant, trials without an answer (scored as
            empty maps unless the report keeps answered trials only).
        members: For a group of seeds, its runs' rows (on the group's frames).
        group: For a run of a group, the group's key.
        seed: For a run, its seed.
    """

    key: str
    name: str
    kind: str
    detail: str
    cells: dict[str, Cell]
    mean: Cell | None
    overall: Cell | None
    curves: dict[str, Curve]
    unanswered: int | None = None
    members: list[Row] = field(default_factory=list)
    group: str | None = None
    seed: int | None = None


@dataclass(frozen=True)
class Difference:
    """A paired difference (row A minus row B) of one statistic on the frames both rows have."""

    value: float
    ci: tuple[float, float] | None
    p_value: float | None
    n_frames: int


@dataclass
class Comparison:
    """Two rows compared on their shared frames, per activity and for the mean over activities."""

    a: tuple[str, str]  # (key, name)
    b: tuple[str, str]
    metric: str
    statistics: tuple[str, ...]
    activities: dict[str, dict[str, Difference]]
    mean: dict[str, Difference]
    resamples: int = DEFAULT_RESAMPLES
    seed: int = 0

    def headline(self) -> Difference | None:
        """The difference of the mean MF-like statistic (``max_f``), the comparison's first line."""
        return self.mean.get("max_f")

    def to_text(self) -> str:
        from app.services.scoring import formats

        return formats.comparison_text(self)

    def to_json(self) -> str:
        return json.dumps(self.as_dict(), indent=1) + "\n"

    def as_dict(self) -> dict[str, Any]:
        from app.services.scoring import formats

        return formats.comparison_dict(self)


@dataclass
class Report:
    """The score table: rows (models, baselines, people) by activity columns and their mean.

    Attributes:
        activities: Column names, the activities any row has frames in.
        rows: In table order: models, baselines, people (seed groups hold their runs).
        thresholds: The number T of thresholds ``k / (T + 1)``.
        metric: The convention: ``pooled``, ``per-image`` or ``ods-ois``.
        frames: ``shared`` (each activity's frames all rows have) or ``each``.
        answered_only: Whether participants' unanswered trials were left out
            (else they count as empty maps).
        resamples: Bootstrap resamples behind the intervals (0: none).
        seed: The bootstrap's seed.
        notes: Things a reader should know (frames left out, rows without frames).
        comparison: A paired comparison of two rows, when one was asked for.
    """

    activities: list[str]
    rows: list[Row]
    thresholds: int = DEFAULT_THRESHOLDS
    metric: str = "pooled"
    frames: str = "shared"
    answered_only: bool = False
    resamples: int = DEFAULT_RESAMPLES
    seed: int = 0
    notes: list[str] = field(default_factory=list)
    comparison: Comparison | None = None

    # -- values the renderers share --------------------------------------------

    def statistics(self) -> list[str]:
        """The convention's statistics, in the order they are shown (MF-like first)."""
        return list(STATISTIC_LABELS[self.metric])

    def label(self, statistic: str) -> str:
        return STATISTIC_LABELS[self.metric][statistic]

    def columns(self) -> list[str]:
        """The activity columns and ``mean``."""
        return [*self.activities, MEAN]

    def all_rows(self) -> list[Row]:
        """Every row in table order, each group of seeds followed by its runs."""
        return [r for row in self.rows for r in (row, *row.members)]

    def row(self, key: str) -> Row | None:
        return next((r for r in self.all_rows() if r.key == key), None)

    def cell(self, row: Row, column: str) -> Cell | None:
        return row.mean if column == MEAN else row.cells.get(column)

    def value(self, row: Row, column: str, statistic: str) -> float | None:
        cell = self.cell(row, column)
        return None if cell is None else cell.values.get(statistic)

    def complete(self, row: Row) -> bool:
        """Whether the mean covers every activity column (else it is marked ``*``)."""
        return row.mean is not None and row.mean.activities == len(self.activities)

    def partial_means(self) -> bool:
        """Whether some row's mean covers fewer activities than the table has."""
        return any(row.mean is not None and not self.complete(row) for row in self.all_rows())

    def best(self) -> dict[tuple[str, str], dict[str, int]]:
        """The best rows of each (column, statistic), as rounded to 3 decimals: their keys, each with how many rows it beat or tied.

        Only rows scored on the same frames compete: within each column the
        top-level rows are split by the frames behind their cell, and a set
        of at least two rows marks its best (all of them on a tie). A
        group's runs are never marked. ``{(column, statistic): {key: size of
        its set}}``; a size below the column's number of values means the
        row is best among fewer rows than the column shows.
        """
        best: dict[tuple[str, str], dict[str, int]] = defaultdict(dict)
        for column in self.columns():
            for statistic in self.statistics():
                by_frames: dict[str, list[tuple[float, str]]] = defaultdict(list)
                for row in self.rows:
                    cell = self.cell(row, column)
                    if cell is not None and cell.values.get(statistic) is not None:
                        by_frames[cell.frames_key].append((round(cell.values[statistic], 3), row.key))
                for competing in by_frames.values():
                    if len(competing) >= 2:
                        top = max(v for v, _ in competing)
                        best[column, statistic] |= {key: len(competing) for v, key in competing if v == top}
        return dict(best)

    def values_in(self, column: str, statistic: str) -> int:
        """How many top-level rows have a value in this column."""
        return sum(1 for row in self.rows if self.value(row, column, statistic) is not None)

    def colour(self, row: Row) -> str:
        """A row's plot colour (a group's runs share the group's)."""
        top = self.row(row.group) if row.group else row
        return PALETTE[self.rows.index(top) % len(PALETTE)]

    def groups(self) -> list[tuple[str, list[Row]]]:
        """The rows grouped by kind, with the group titles, in table order."""
        out = []
        for kind in (MODEL, BASELINE, HUMAN):
            rows = [r for r in self.rows if r.kind == kind]
            if rows:
                out.append((KIND_TITLES[kind], rows))
        return out

    def definition(self) -> str:
        return definition(self.metric)

    def describe(self) -> list[str]:
        """Three lines that say what the numbers are: convention, frames, intervals."""
        people = "answered trials only" if self.answered_only else "a trial without an answer counts as an empty map"
        ci = (
            f"95% CI: BCa bootstrap over frames within each activity, {self.resamples} resamples, seed {self.seed}"
            if self.resamples
            else "no confidence intervals (0 resamples)"
        )
        return [
            f"Metric: {self.metric} - {METRIC_TITLES[self.metric]}; {self.thresholds} thresholds k/{self.thresholds + 1}.",
            f"Frames: {self.frames} - {FRAMES[self.frames]}; people: {people}.",
            f"{ci}.",
        ]

    # -- renderers (``formats``, which reads this module's labels) ----------------

    def to_table(self) -> str:
        from app.services.scoring import formats

        return formats.table_text(self)

    def to_csv(self) -> str:
        from app.services.scoring import formats

        return formats.table_csv(self)

    def to_latex(self) -> str:
        from app.services.scoring import formats

        return formats.table_latex(self)

    def to_json(self) -> str:
        return json.dumps(self.as_dict(), indent=1) + "\n"

    def as_dict(self) -> dict[str, Any]:
        from app.services.scoring import formats

        return formats.report_dict(self)

