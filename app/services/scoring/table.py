"""The score table itself: the report and a paired comparison.

:class:`Report` holds the rows (models, baselines, people) by activity
columns and their mean, and the :class:`~app.services.scoring.provenance.Provenance`
of its numbers (convention, frames, bootstrap, code version...); its
renderers (``formats``) write both as plain text, CSV, LaTeX, JSON or a
methods paragraph. Nothing here reads the database: ``report`` fills it.
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass, field

from app.services.scoring.cells import BASELINE, HUMAN, KIND_TITLES, MEAN, MODEL, PALETTE, STATISTIC_LABELS, Cell, Difference, Row, definition
from app.services.scoring.formats import ComparisonFormats, ReportFormats, verdict
from app.services.scoring.provenance import Provenance


@dataclass
class Comparison(ComparisonFormats):
    """Two rows compared on their shared frames, per activity and for the mean over activities."""

    a: tuple[str, str]  # (key, name)
    b: tuple[str, str]
    statistics: tuple[str, ...]
    activities: dict[str, dict[str, Difference]]
    mean: dict[str, Difference]
    provenance: Provenance = field(default_factory=lambda: Provenance(paired=True))

    @property
    def metric(self) -> str:
        return self.provenance.metric

    def p_text(self, difference: Difference) -> str:
        """The difference's p-value as written everywhere (``"< 0.001"`` at the floor)."""
        return self.provenance.p_text(difference.p_value)

    def verdict(self, difference: Difference) -> str:
        """Its interval, p-value and frames as one phrase, or "n too small" and why."""
        return verdict(difference, self.p_text(difference))

    def headline(self) -> Difference | None:
        """The difference of the mean MF-like statistic (``max_f``), the comparison's first line."""
        return self.mean.get("max_f")


@dataclass
class Report(ReportFormats):
    """The score table: rows (models, baselines, people) by activity columns and their mean.

    Attributes:
        activities: Column names, the activities any row has frames in.
        rows: In table order: models, baselines, people (seed groups hold their runs).
        provenance: How the numbers were made: the convention
            (``pooled``, ``ois-mean``, ``mean-curve`` or ``ods-ois``), the
            thresholds, the frames, the bootstrap, the code version...
        notes: Things a reader should know (frames left out, rows without frames).
        comparison: A paired comparison of two rows, when one was asked for.
    """

    activities: list[str]
    rows: list[Row]
    provenance: Provenance = field(default_factory=Provenance)
    notes: list[str] = field(default_factory=list)
    comparison: Comparison | None = None

    @property
    def metric(self) -> str:
        return self.provenance.metric

    @property
    def thresholds(self) -> int:
        return self.provenance.thresholds

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
        """What the numbers are, a ``Label: sentence.`` line per fact (convention, frames, intervals, empty frames, people's maps, code)."""
        return [f"{label}: {text}." for label, text in self.provenance.facts()]

    def frames_per_activity(self) -> dict[str, int]:
        """Frames scored in each activity: the most any top-level row has there."""
        return {a: max((c.n_frames for r in self.rows if (c := r.cells.get(a)) is not None), default=0) for a in self.activities}
