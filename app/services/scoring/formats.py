"""The report and a comparison written out: plain text, CSV, LaTeX (booktabs), JSON and a methods paragraph.

The renderers are mixins of ``table``'s :class:`Report` and :class:`Comparison`
(``self`` is the report or the comparison), so this module needs only the
table's parts. Every format carries the numbers' provenance
(``provenance.Provenance``: convention, thresholds, frames, frames without
action-object pixels, bootstrap, people's maps, code version), and every
cell its number of frames and its 95 % interval, or "n too small" (fewer
than ``egonet.metrics.MIN_FRAMES`` frames in an activity: no interval and
no p-value; JSON's ``too_few_frames``); p-values go through
``provenance.p_text`` (``< 0.001`` at the bootstrap's floor).
"""

from __future__ import annotations

import json
from typing import Any

from app.services.scoring.cells import ALL, MEAN, STATISTIC_LABELS, Cell, Difference, Row, definition, frames_text
from app.services.scoring import methods
from app.services.scoring.provenance import BIBTEX
from app.spreadsheet import csv_text
from egonet.metrics import MIN_FRAMES


def _fmt(value: float | None, digits: int = 3) -> str:
    return "-" if value is None else f"{value:.{digits}f}"


TOO_FEW = "n too small"
"""Written where an interval and a p-value would be, below ``egonet.metrics.MIN_FRAMES`` frames."""


def _interval(ci: tuple[float, float] | None, digits: int = 3) -> str:
    return "" if ci is None else f"[{ci[0]:.{digits}f}, {ci[1]:.{digits}f}]"


def _cell_interval(cell: Cell, statistic: str) -> str:
    """A cell's interval, "n too small" in its place, or nothing (no value, or no resamples)."""
    if cell.values.get(statistic) is None:
        return ""
    return TOO_FEW if cell.too_few else _interval(cell.ci.get(statistic))


def _num(value: float | None) -> str:
    return "" if value is None else f"{value:.4f}"


def _signed(ci: tuple[float, float] | None) -> str:
    return "" if ci is None else f"[{ci[0]:+.3f}, {ci[1]:+.3f}]"


def _difference_interval(d: Difference) -> str:
    return TOO_FEW if d.too_few else _signed(d.ci)


def _blank(value: int | None) -> str | int:
    return "" if value is None else value


def _text_value(cell: Cell, statistic: str, star: str) -> str:
    value = cell.values.get(statistic)
    if value is None:
        return "-"
    text = _fmt(value) + star
    sd = (cell.sd or {}).get(statistic)
    return f"{text} sd {sd:.3f}" if sd is not None else text


_TEX = {
    "\\": r"\textbackslash{}", "&": r"\&", "%": r"\%", "$": r"\$", "#": r"\#", "_": r"\_", "{": r"\{", "}": r"\}",
    "~": r"\textasciitilde{}", "^": r"\textasciicircum{}",
}  # fmt: skip


def tex(text: str) -> str:
    return "".join(_TEX.get(ch, ch) for ch in text)


def _cell_dict(cell: Cell, statistics: list[str]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for s in statistics:
        ci = cell.ci.get(s)
        out[s] = cell.values.get(s)
        out[f"{s}_ci"] = None if ci is None else [ci[0], ci[1]]
        if cell.sd is not None:
            out[f"{s}_sd"] = cell.sd.get(s)
    out |= {"n_frames": cell.n_frames, "frames_available": cell.frames_available, "no_shared_frames": cell.no_shared_frames,
            "too_few_frames": cell.too_few}  # fmt: skip
    return out


def _difference_dict(d: Difference, p_text: str) -> dict[str, Any]:
    return {"difference": d.value, "ci": None if d.ci is None else list(d.ci), "p_value": d.p_value, "p_text": p_text,
            "n_frames": d.n_frames, "too_few_frames": d.too_few}  # fmt: skip


class _Json:
    def to_json(self) -> str:
        return json.dumps(self.as_dict(), indent=1) + "\n"


class ReportFormats(_Json):
    """The report as text (a block per column), CSV (a line per row), LaTeX (the paper's Table 2) and JSON."""

    def to_table(self) -> str:
        """A plain-text table: a block per activity and one for the mean, each row's n, values, intervals and best marks."""
        lines = [*self.describe(), ""]
        if not self.rows:
            lines.append("(nothing to score: no completed runs, labelled frames or answered trials)")
        statistics = self.statistics()
        best = self.best()
        name_width = max([len("method"), *(len(r.name) + (2 if r.group else 0) for r in self.all_rows())]) + 2
        for column in self.columns() if self.rows else []:
            title = "mean (unweighted over activities)" if column == MEAN else column
            head = f"  {'method':<{name_width}}{'n':>6}"
            for s in statistics:
                head += f"  {self.label(s):>14}  {'95% CI':<16}"
            lines += [title, head.rstrip()]
            for row in self.all_rows():
                cell = self.cell(row, column)
                if cell is None:
                    continue
                name = ("  " if row.group else "") + row.name
                if cell.no_shared_frames:
                    lines.append(f"  {name:<{name_width}}{0:>6}  no shared frames (this row has {cell.frames_available} here)")
                    continue
                text = f"  {name:<{name_width}}{cell.n_frames:>6}"
                for s in statistics:
                    # The partial-mean star sits on the MF-like value of the mean line only.
                    star = "*" if column == MEAN and s == statistics[0] and not self.complete(row) else ""
                    text += f"  {_text_value(cell, s, star):>14}  {_cell_interval(cell, s):<16}"
                marks = [self.label(s) for s in statistics if row.key in best.get((column, s), {})]
                lines.append((text + (f"  <- best {', '.join(marks)}" if marks else "")).rstrip())
            lines.append("")
        if self.partial_means():
            lines.append("* mean over the activities that row has frames in.")
        if any(r.unanswered for r in self.rows):
            counted = "left out" if self.provenance.answered_only else "scored as empty maps"
            lines.append("Unanswered trials (" + counted + "): " + ", ".join(f"{r.name} {r.unanswered}" for r in self.rows if r.unanswered is not None) + ".")
        lines += self.notes
        return "\n".join(lines).rstrip() + "\n"

    def to_csv(self) -> str:
        """One line per row (a group's runs included, with the group's key): n, each statistic, its interval, per column; then the provenance."""
        statistics = self.statistics()
        grouped = any(r.members for r in self.rows)
        facts = self.provenance.columns()
        header = ["key", "method", "kind", "group", "metric", "frames", "unanswered"]
        for column in self.columns():
            header += [f"{column} frames", f"{column} n too small"]
            for s in statistics:
                label = self.label(s)
                header += [f"{column} {label}", f"{column} {label} lo", f"{column} {label} hi"] + ([f"{column} {label} sd"] if grouped else [])
        lines = []
        for row in self.all_rows():
            line: list[Any] = [row.key, row.name, row.kind, row.group or "", self.metric, self.provenance.frames, _blank(row.unanswered)]
            for column in self.columns():
                cell = self.cell(row, column)
                line += ["", ""] if cell is None else [cell.n_frames, int(cell.too_few)]
                for s in statistics:
                    ci = cell.ci.get(s) if cell else None
                    line += [_num(cell and cell.values.get(s)), _num(ci and ci[0]), _num(ci and ci[1])]
                    if grouped:
                        line.append(_num((cell.sd or {}).get(s)) if cell else "")
            lines.append([*line, row.mean.activities if row.mean else 0, *facts.values()])
        return csv_text(lines, header=[*header, "mean over activities", *facts])

    def _tex_cell(self, row: Row, column: str, statistic: str, best: dict[str, int], uniform_n: bool) -> str:
        cell = self.cell(row, column)
        if cell is None:
            return "--"
        if cell.no_shared_frames:
            return "{\\scriptsize no shared frames}"
        value = cell.values.get(statistic)
        if value is None:
            return "--"
        text = f"{value:.3f}"
        if row.key in best:
            text = f"\\textbf{{{text}}}"
        if column == MEAN and statistic == self.statistics()[0] and not self.complete(row):
            text += "$^*$"
        sd = (cell.sd or {}).get(statistic)
        if sd is not None:
            text += f"$\\pm${sd:.3f}"
        ci = cell.ci.get(statistic)
        if cell.too_few:
            text += " {\\scriptsize ($n$ too small)}"
        elif ci is not None:
            text += f" {{\\scriptsize[{ci[0]:.3f}, {ci[1]:.3f}]}}"
        if not uniform_n and statistic == self.statistics()[0]:
            text += f" {{\\scriptsize $n$={cell.n_frames}}}"
        return text

    def to_latex(self) -> str:
        """A booktabs tabular like the paper's Table 2: the statistics per activity, intervals beside, the best in bold."""
        columns, statistics = self.columns(), self.statistics()
        k = len(statistics)
        best = self.best()
        counts = {c: {self.cell(r, c).n_frames for r in self.rows if self.cell(r, c) is not None} for c in columns}
        uniform = {c: len(n) == 1 for c, n in counts.items()}
        lines = [f"% {tex(line)}" for line in self.describe()]
        lines += [
            "% Best of each column in bold, among rows scored on the same frames. Needs \\usepackage{booktabs}.",
            "\\begin{tabular}{l" + "c" * k * len(columns) + "}",
            "\\toprule",
            " & ".join(["", *(f"\\multicolumn{{{k}}}{{c}}{{{tex(c)}}}" for c in columns)]) + " \\\\",
        ]
        if self.rows and all(uniform.values()):
            lines.append(" & ".join(["", *(f"\\multicolumn{{{k}}}{{c}}{{\\scriptsize $n$ = {next(iter(counts[c]))}}}" for c in columns)]) + " \\\\")
        lines += [
            "".join(f"\\cmidrule(lr){{{2 + k * i}-{1 + k * (i + 1)}}}" for i in range(len(columns))),
            " & ".join(["Method", *([tex(self.label(s)) for s in statistics] * len(columns))]) + " \\\\",
        ]
        uniform_n = bool(self.rows) and all(uniform.values())
        for _title, rows in self.groups():
            lines.append("\\midrule")
            for row in [r for top in rows for r in (top, *top.members)]:
                name = ("\\quad " if row.group else "") + tex(row.name)
                values = [self._tex_cell(row, c, s, best.get((c, s), {}), uniform_n) for c in columns for s in statistics]
                lines.append(" & ".join([name, *values]) + " \\\\")
        lines += ["\\bottomrule", "\\end{tabular}"]
        return "\n".join(lines) + "\n"

    def _row_dict(self, row: Row) -> dict[str, Any]:
        statistics = self.statistics()
        out: dict[str, Any] = {"key": row.key, "name": row.name, "kind": row.kind, "detail": row.detail}
        if row.unanswered is not None:
            out["unanswered"] = row.unanswered
        if row.members:
            out["members"] = [m.key for m in row.members]
        if row.group:
            out["group"] = row.group
        if row.seed is not None:
            out["seed"] = row.seed
        out["cells"] = {a: _cell_dict(c, statistics) for a, c in row.cells.items()}
        out["mean"] = None if row.mean is None else _cell_dict(row.mean, statistics) | {"activities": row.mean.activities}
        out[ALL] = None if row.overall is None else _cell_dict(row.overall, statistics)
        out["curves"] = {k: {"precision": list(c.precision), "recall": list(c.recall), "best": c.best} for k, c in row.curves.items()}
        return out

    def as_dict(self) -> dict[str, Any]:
        """Everything, curves included, with what the numbers are and how they were made at the top (``frames``, ``metric``...)."""
        out = {
            **self.provenance.as_dict(),
            "statistics": {s: self.label(s) for s in self.statistics()},
            "definition": self.definition(),
            "activities": self.activities,
            "rows": [self._row_dict(row) for row in self.all_rows()],
            "notes": self.notes,
        }
        if self.comparison is not None:
            out["comparison"] = self.comparison.as_dict()
        return out

    def to_methods(self) -> str:
        """A methods paragraph made from this report's facts and frames (``methods``), and the seed paper's BibTeX entry."""
        text = methods.paragraph(self.rows, self.provenance, activities=self.activities, frames_per_activity=self.frames_per_activity())
        return text + "\n" + BIBTEX


class ComparisonFormats(_Json):
    """A comparison as text (the headline, a line per activity), CSV, LaTeX and JSON."""

    def _lines(self) -> list[tuple[str, dict[str, Difference]]]:
        return [*self.activities.items(), (MEAN, self.mean)]

    def as_dict(self) -> dict[str, Any]:
        """The comparison; ``difference``, ``ci``, ``p_value`` and ``p_text`` at the top are the mean MF-like statistic's.

        The provenance's bootstrap (the report's ``ci``) is ``bootstrap`` here: ``ci`` is the difference's interval.
        """
        head = self.headline()
        facts = self.provenance.as_dict()
        facts["bootstrap"] = facts.pop("ci")
        return {
            **facts,
            "frames": "shared by the two rows",
            "a": {"key": self.a[0], "name": self.a[1]},
            "b": {"key": self.b[0], "name": self.b[1]},
            "statistic": "max_f",
            "column": MEAN,
            **_difference_dict(head, self.p_text(head)),
            "test": "paired BCa bootstrap over the shared frames, resampled within each activity (two-sided)",
            "mean": {s: _difference_dict(d, self.p_text(d)) for s, d in self.mean.items()},
            "activities": {a: {s: _difference_dict(d, self.p_text(d)) for s, d in ds.items()} for a, ds in self.activities.items()},
            "definition": definition(self.metric),
        }

    def to_text(self) -> str:
        """The comparison as lines: the headline, then a line per activity and the mean, then the provenance."""
        labels = STATISTIC_LABELS[self.metric]
        head = self.headline()
        lines = [
            f"{self.a[1]} [{self.a[0]}] minus {self.b[1]} [{self.b[0]}], on the frames both have ({self.metric} convention).",
            f"{labels['max_f']} difference (mean over activities) {head.value:+.3f} {self.verdict(head)}.",
            *(f"{label}: {text}." for label, text in self.provenance.facts()),
            "",
        ]
        header = f"{'activity':<20}{'n':>6}"
        for s in self.statistics:
            header += f"  {labels[s] + ' diff':>12}  {'95% CI':<18}{'p':>8}"
        lines.append(header)
        for name, ds in self._lines():
            text = f"{name:<20}{next(iter(ds.values())).n_frames:>6}"
            for s in self.statistics:
                d = ds[s]
                text += f"  {d.value:>+12.3f}  {_difference_interval(d):<18}{self.p_text(d):>8}"
            lines.append(text.rstrip())
        return "\n".join(lines) + "\n"

    def to_csv(self) -> str:
        """One line per activity, the mean last, and statistic: n, the difference, its interval, p; then the provenance."""
        facts = self.provenance.columns()
        header = ["a", "b", "metric", "activity", "frames", "n too small", "statistic", "difference", "lo", "hi", "p", *facts]
        lines = [
            [self.a[0], self.b[0], self.metric, name, d.n_frames, int(d.too_few), STATISTIC_LABELS[self.metric][s], _num(d.value),
             _num(d.ci and d.ci[0]), _num(d.ci and d.ci[1]), "" if d.p_value is None else self.p_text(d), *facts.values()]
            for name, ds in self._lines() for s, d in ds.items()
        ]  # fmt: skip
        return csv_text(lines, header=header)

    def to_latex(self) -> str:
        """A booktabs tabular: a line per activity and the mean, each statistic's difference, interval and p."""
        labels = STATISTIC_LABELS[self.metric]
        lines = [f"% {tex(self.a[1])} [{tex(self.a[0])}] minus {tex(self.b[1])} [{tex(self.b[0])}], on the frames both have."]
        lines += [f"% {tex(label)}: {tex(text)}." for label, text in self.provenance.facts()]
        lines += [
            "\\begin{tabular}{lr" + "ccc" * len(self.statistics) + "}",
            "\\toprule",
            " & ".join(["Activity", "$n$", *(f"{tex(labels[s])} diff. & 95\\% CI & $p$" for s in self.statistics)]) + " \\\\",
            "\\midrule",
        ]
        for name, ds in self._lines():
            # "< 0.001" in math mode: a bare < is another glyph in LaTeX's default font encoding.
            cells = [f"{d.value:+.3f} & {tex(_difference_interval(d))} & " + ("--" if d.p_value is None else f"${self.p_text(d)}$")
                     for d in (ds[s] for s in self.statistics)]  # fmt: skip
            lines.append(" & ".join([tex(name), str(next(iter(ds.values())).n_frames), *cells]) + " \\\\")
        lines += ["\\bottomrule", "\\end{tabular}"]
        return "\n".join(lines) + "\n"


def _p_equals(text: str) -> str:
    """``"= 0.012"`` or ``"< 0.001"``: a p-value after its letter."""
    return text if text.startswith("<") else f"= {text}"


def verdict(d: Difference, p_text: str) -> str:
    """A difference's interval and p-value, or why it has none: ``"[+0.010, +0.200] p = 0.012 (40 frames)"``."""
    if d.too_few:
        return f"({frames_text(d.n_frames)}): n too small for an interval or p-value (fewer than {MIN_FRAMES} frames in an activity)"
    return f"{_signed(d.ci)} p {_p_equals(p_text)} ({frames_text(d.n_frames)})"
