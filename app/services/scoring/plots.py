"""Precision-recall plots of a score table, laid out for inline SVG (the Scores page draws them).

:func:`pr_plot` turns the curves of every row of a :class:`Report` for one
activity (or :data:`ALL`) into polyline points in SVG pixels, with a dot at
each row's best F and faint iso-F curves to read the plot by.
"""

from __future__ import annotations

from dataclasses import dataclass

from app.services.scoring.table import ALL, HUMAN, Report
from egonet.metrics import iso_f_curve, threshold_values

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
        pts = [xy(r, p) for r, p in zip(*iso_f_curve(f, points=40), strict=True)]
        iso.append((" ".join(f"{x},{y}" for x, y in pts), f"F={f:.1f}"))
    title = "All activities (pooled)" if key == ALL else key
    ticks = [(t, f"{t:g}") for t in (0.0, 0.25, 0.5, 0.75, 1.0)]
    return Plot(key, title, width, height, left, top, sx, sy, lines, iso, ticks)

