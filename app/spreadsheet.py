"""The one CSV writer and reader: every CSV the app writes goes through
``csv_text``, every one it reads (attention points) through ``csv_rows``.

A cell that a spreadsheet would run as a formula (text starting with ``=``,
``+``, ``-``, ``@``, a tab or a carriage return) gets a leading ``'``, as
OWASP's CSV-injection guidance says; numbers, and text that is a plain
number, are written unchanged, so they stay numbers.
"""

import csv
import io
import re
from collections.abc import Iterable, Sequence

FORMULA_STARTS = ("=", "+", "-", "@", "\t", "\r")
NUMBER = re.compile(r"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?")


def safe_cell(value: object) -> object:
    """``value`` as a spreadsheet will read it harmlessly: text that could start a formula gets a ``'``."""
    if isinstance(value, str) and value.startswith(FORMULA_STARTS) and not NUMBER.fullmatch(value):
        return "'" + value
    return value


def csv_text(rows: Iterable[Sequence[object]], header: Sequence[str] | None = None) -> str:
    """Rows (and an optional header) as CSV text with ``\\n`` line ends, every cell through ``safe_cell``."""
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    if header is not None:
        writer.writerow([safe_cell(h) for h in header])
    writer.writerows([safe_cell(v) for v in row] for row in rows)
    return out.getvalue()


def csv_rows(text: str) -> list[tuple[int, list[str]]]:
    """CSV text's rows, each with its line number; raises ValueError naming the line it cannot read."""
    reader = csv.reader(text.splitlines())
    try:
        return [(reader.line_num, cells) for cells in reader]
    except csv.Error as exc:  # a field past csv's size limit
        raise ValueError(f"line {reader.line_num}: not readable as CSV ({exc})") from None
