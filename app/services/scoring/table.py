"""The score table itself: cells, curves and rows, and how the table is written out.

:class:`Report` holds the rows (models, baselines, people) by activity
columns and their mean, and renders them as plain text, CSV, LaTeX
(booktabs) or JSON. Nothing here reads the database: ``report`` fills it.
"""

from __future__ import annotations

import csv
import io
import json
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from egonet.metrics import DEFAULT_THRESHOLDS, threshold_values

ALL = "all"
"""The key of a row's curve pooled over all its frames."""

MODEL, BASELINE, HUMAN = "model", "baseline", "human"
KIND_TITLES = {MODEL: "Models", BASELINE: "Baselines", HUMAN: "People (MF only)"}

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
        out = io.StringIO()
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

