"""Precision-recall plots of a score table: laid out for inline SVG (the Scores page), or as an SVG/PDF figure file.

:func:`pr_plot` turns the pooled curves of the chosen rows of a
:class:`Report` for one activity (or :data:`ALL`) into polyline points in
SVG pixels, with a dot at each row's best F and faint iso-F curves to read
the plot by. :func:`pr_figure` draws the same curves with matplotlib, for a
paper. The curves are always pooled over the frames each row is scored on
(the table's frames), whatever the table's convention.
"""

from __future__ import annotations

import io
from collections.abc import Collection
from dataclasses import dataclass

from app.services.scoring.cells import ALL, HUMAN, Row, frames_text
from app.services.scoring.table import Report
from egonet.metrics import iso_f_curve, threshold_values

MAX_SHOWN_PEOPLE = 3
"""People drawn by default (more would hide the machines' curves)."""


@dataclass(frozen=True)
class PlotLine:
    row: str  # the key of the table row that toggles it (a group's runs: the group's)
    name: str
    colour: str
    dashed: bool
    points: str  # SVG polyline points, "x,y x,y ..."
    best_x: float
    best_y: float
    best_label: str
    shown: bool


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


def default_plot_rows(report: Report) -> set[str]:
    """The rows drawn unless the reader picks others: models, baselines, and people when there are few."""
    people = [r for r in report.rows if r.kind == HUMAN]
    return {r.key for r in report.rows if r.kind != HUMAN or len(people) <= MAX_SHOWN_PEOPLE}


def _drawn(report: Report, key: str) -> list[tuple[Row, str]]:
    """(row with a curve for ``key``, the key of the table row that toggles it), in table order."""
    return [(row, row.group or row.key) for row in report.all_rows() if key in row.curves]


def _cell(row: Row, key: str):
    return row.overall if key == ALL else row.cells[key]


def pr_plot(report: Report, key: str, *, rows: Collection[str] | None = None, width: int = 300, height: int = 270) -> Plot:
    """The precision-recall curves for one activity (or :data:`ALL`).

    Args:
        report: The table.
        key: An activity, or :data:`ALL`.
        rows: Keys of the rows to show (the others are drawn hidden, so the
            page can show them without asking again); None:
            :func:`default_plot_rows`.
        width: Plot width in SVG pixels.
        height: Plot height in SVG pixels.

    Returns:
        The :class:`Plot`. People's lines are dashed; a group of seeds draws
        each of its runs in the group's colour.
    """
    shown = default_plot_rows(report) if rows is None else set(rows)
    left, top, right, bottom = PLOT_MARGIN
    sx, sy = width - left - right, height - top - bottom
    t = threshold_values(report.thresholds)

    def xy(r: float, p: float) -> tuple[float, float]:
        return round(left + r * sx, 1), round(top + (1 - p) * sy, 1)

    lines = []
    for row, toggle in _drawn(report, key):
        curve = row.curves[key]
        pts = [xy(r, p) for r, p in zip(curve.recall, curve.precision, strict=True)]
        bx, by = pts[curve.best]
        pooled_f = _pooled_f(curve)
        lines.append(
            PlotLine(
                row=toggle,
                name=row.name,
                colour=report.colour(row),
                dashed=row.kind == HUMAN,
                points=" ".join(f"{x},{y}" for x, y in pts),
                best_x=bx,
                best_y=by,
                best_label=f"{row.name}: pooled F {pooled_f:.3f} at t = {t[curve.best]:.2f} ({frames_text(_cell(row, key).n_frames)})",
                shown=toggle in shown,
            )
        )
    iso = []
    for f in (0.2, 0.4, 0.6, 0.8):
        pts = [xy(r, p) for r, p in zip(*iso_f_curve(f, points=40), strict=True)]
        iso.append((" ".join(f"{x},{y}" for x, y in pts), f"F={f:.1f}"))
    title = "All activities (pooled)" if key == ALL else key
    ticks = [(v, f"{v:g}") for v in (0.0, 0.25, 0.5, 0.75, 1.0)]
    return Plot(key, title, width, height, left, top, sx, sy, lines, iso, ticks)


def _pooled_f(curve) -> float:
    p, r = curve.precision[curve.best], curve.recall[curve.best]
    return 0.0 if p + r == 0 else 2 * p * r / (p + r)


def pr_figure(report: Report, key: str, *, rows: Collection[str] | None = None, file_format: str = "svg") -> bytes:
    """The precision-recall curves of one activity (or :data:`ALL`) as an SVG or PDF figure (matplotlib).

    Args:
        report: The table.
        key: An activity, or :data:`ALL`; an unknown one draws no curve.
        rows: Keys of the rows to draw (a group's key draws its runs); None:
            :func:`default_plot_rows`.
        file_format: ``"svg"`` or ``"pdf"``.

    Returns:
        The file's bytes: a 4.5 x 4 inch figure with iso-F curves, a dot at
        each curve's best pooled F, and a legend.
    """
    import matplotlib  # imported here: it reads its font cache when loaded

    # Text stays text in SVG (editable, searchable) and fonts are TrueType in PDF (Type 3 fonts are refused by some publishers).
    with matplotlib.rc_context({"svg.fonttype": "none", "pdf.fonttype": 42}):
        return _draw(report, key, default_plot_rows(report) if rows is None else set(rows), file_format)


def _draw(report: Report, key: str, shown: set[str], file_format: str) -> bytes:
    from matplotlib.figure import Figure

    figure = Figure(figsize=(4.5, 4.0))
    axes = figure.add_subplot()
    for f in (0.2, 0.4, 0.6, 0.8):
        recall, precision = iso_f_curve(f, points=60)
        axes.plot(recall, precision, color="#c8ccd4", linewidth=0.6, linestyle=":")
        axes.annotate(f"F={f:.1f}", (recall[-1], precision[-1]), fontsize=6, color="#9aa0aa", ha="right", va="bottom")
    labelled = set()
    for row, toggle in _drawn(report, key):
        if toggle not in shown:
            continue
        curve = row.curves[key]
        top_row = report.row(toggle)
        label = None if toggle in labelled else f"{top_row.name} (n={_cell(top_row, key).n_frames})"
        labelled.add(toggle)
        colour = report.colour(row)
        axes.plot(curve.recall, curve.precision, color=colour, linewidth=1.0 if row.group else 1.4,
                  linestyle="--" if row.kind == HUMAN else "-", label=label)  # fmt: skip
        axes.plot([curve.recall[curve.best]], [curve.precision[curve.best]], "o", color=colour, markersize=3.5)
    axes.set(xlim=(0, 1), ylim=(0, 1.02), xlabel="Recall", ylabel="Precision")
    axes.set_title(("All activities" if key == ALL else key) + " (pooled curves)", fontsize=10)
    axes.grid(color="#eceff4", linewidth=0.5)
    if labelled:
        axes.legend(fontsize=7, loc="lower left", frameon=False)
    figure.tight_layout()
    out = io.BytesIO()
    figure.savefig(out, format=file_format, metadata={"Date": None} if file_format == "svg" else {"CreationDate": None})
    return out.getvalue()
