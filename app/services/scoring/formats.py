"""The report and a comparison written out: plain text, CSV, LaTeX (booktabs) and JSON.

The renderers are mixins of ``table``'s :class:`Report` and :class:`Comparison`
(``self`` is the report or the comparison), so this module needs only the
table's parts. Every format says first which convention, frames and
intervals its numbers are (``Report.describe``), and every cell carries its
number of frames and its 95 % interval.
"""

from __future__ import annotations

import json
from typing import Any

from app.services.scoring.cells import ALL, MEAN, STATISTIC_LABELS, Cell, Difference, Row, definition
from app.spreadsheet import csv_text
from egonet.metrics import threshold_values


def _fmt(value: float | None, digits: int = 3) -> str:
    return "-" if value is None else f"{value:.{digits}f}"


def _interval(ci: tuple[float, float] | None, digits: int = 3) -> str:
    return "" if ci is None else f"[{ci[0]:.{digits}f}, {ci[1]:.{digits}f}]"


def _num(value: float | None) -> str:
    return "" if value is None else f"{value:.4f}"


def _signed(ci: tuple[float, float] | None) -> str:
    return "" if ci is None else f"[{ci[0]:+.3f}, {ci[1]:+.3f}]"


def _p(p: float | None) -> str:
    return "-" if p is None else f"{p:.3f}"


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
    out |= {"n_frames": cell.n_frames, "frames_available": cell.frames_available, "no_shared_frames": cell.no_shared_frames}
    return out


def _difference_dict(d: Difference) -> dict[str, Any]:
    return {"difference": d.value, "ci": None if d.ci is None else list(d.ci), "p_value": d.p_value, "n_frames": d.n_frames}


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
                    text += f"  {_text_value(cell, s, star):>14}  {_interval(cell.ci.get(s)):<16}"
                marks = [self.label(s) for s in statistics if row.key in best.get((column, s), {})]
                lines.append((text + (f"  <- best {', '.join(marks)}" if marks else "")).rstrip())
            lines.append("")
        if self.partial_means():
            lines.append("* mean over the activities that row has frames in.")
        if any(r.unanswered for r in self.rows):
            counted = "left out" if self.answered_only else "scored as empty maps"
            lines.append("Unanswered trials (" + counted + "): " + ", ".join(f"{r.name} {r.unanswered}" for r in self.rows if r.unanswered is not None) + ".")
        lines += self.notes
        return "\n".join(lines).rstrip() + "\n"

    def to_csv(self) -> str:
        """One line per row (a group's runs included, with the group's key): n, each statistic, its interval, per column."""
        table = []
        statistics = self.statistics()
        header = ["key", "method", "kind", "group", "metric", "frames", "unanswered"]
        for column in self.columns():
            header.append(f"{column} frames")
            for s in statistics:
                label = self.label(s)
                header += [f"{column} {label}", f"{column} {label} lo", f"{column} {label} hi"]
                if any(r.members for r in self.rows):
                    header.append(f"{column} {label} sd")
        header.append("mean over activities")
        for row in self.all_rows():
            line: list[Any] = [row.key, row.name, row.kind, row.group or "", self.metric, self.frames, _blank(row.unanswered)]
            for column in self.columns():
                cell = self.cell(row, column)
                line.append("" if cell is None else cell.n_frames)
                for s in statistics:
                    ci = cell.ci.get(s) if cell else None
                    line += [_num(cell and cell.values.get(s)), _num(ci and ci[0]), _num(ci and ci[1])]
                    if any(r.members for r in self.rows):
                        line.append(_num((cell.sd or {}).get(s)) if cell else "")
            table.append([*line, row.mean.activities if row.mean else 0])
        return csv_text(table, header)

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
        if ci is not None:
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
        """Everything, curves included, with what the numbers are at the top (``frames``, ``metric``)."""
        out = {
            "frames": self.frames,
            "metric": self.metric,
            "answered_only": self.answered_only,
            "statistics": {s: self.label(s) for s in self.statistics()},
            "definition": self.definition(),
            "ci": {
                "level": 0.95,
                "method": "BCa (bias-corrected and accelerated) bootstrap over frames, resampled within each activity",
                "resamples": self.resamples,
                "seed": self.seed,
            },
            "thresholds": self.thresholds,
            "threshold_values": threshold_values(self.thresholds).tolist(),
            "activities": self.activities,
            "rows": [self._row_dict(row) for row in self.all_rows()],
            "notes": self.notes,
        }
        if self.comparison is not None:
            out["comparison"] = self.comparison.as_dict()
        return out


class ComparisonFormats(_Json):
    """A comparison as text (the headline, a line per activity) and JSON."""

    def as_dict(self) -> dict[str, Any]:
        """The comparison; ``difference``, ``ci`` and ``p_value`` at the top are the mean MF-like statistic's."""
        head = self.headline()
        return {
            "frames": "shared by the two rows",
            "metric": self.metric,
            "a": {"key": self.a[0], "name": self.a[1]},
            "b": {"key": self.b[0], "name": self.b[1]},
            "statistic": "max_f",
            "column": MEAN,
            "difference": head.value,
            "ci": None if head.ci is None else list(head.ci),
            "p_value": head.p_value,
            "n_frames": head.n_frames,
            "test": "paired BCa bootstrap over the shared frames, resampled within each activity (two-sided)",
            "resamples": self.resamples,
            "seed": self.seed,
            "mean": {s: _difference_dict(d) for s, d in self.mean.items()},
            "activities": {a: {s: _difference_dict(d) for s, d in ds.items()} for a, ds in self.activities.items()},
            "definition": definition(self.metric),
        }

    def to_text(self) -> str:
        """The comparison as lines: the headline, then a line per activity and the mean."""
        labels = STATISTIC_LABELS[self.metric]
        head = self.headline()
        lines = [
            f"{self.a[1]} [{self.a[0]}] minus {self.b[1]} [{self.b[0]}], on the frames both have ({self.metric} convention).",
            f"{labels['max_f']} difference (mean over activities) {head.value:+.3f} {_signed(head.ci)} p = {_p(head.p_value)} ({head.n_frames} frames).",
            f"Paired BCa bootstrap over frames within each activity, {self.resamples} resamples, seed {self.seed}; p two-sided.",
            "",
        ]
        header = f"{'activity':<20}{'n':>6}"
        for s in self.statistics:
            header += f"  {labels[s] + ' diff':>12}  {'95% CI':<18}{'p':>6}"
        lines.append(header)
        for name, ds in [*self.activities.items(), (MEAN, self.mean)]:
            text = f"{name:<20}{next(iter(ds.values())).n_frames:>6}"
            for s in self.statistics:
                d = ds[s]
                text += f"  {d.value:>+12.3f}  {_signed(d.ci):<18}{_p(d.p_value):>6}"
            lines.append(text.rstrip())
        return "\n".join(lines) + "\n"
